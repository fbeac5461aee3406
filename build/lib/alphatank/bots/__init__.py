"""Rule-based bots (installed as ``alphatank.bots``): random, aggressive, defensive, dodge
and smart, the ``weakness`` wrapper, and the ``make_bot`` factory."""

from alphatank.bots.aggressive import AggressiveBot
from alphatank.bots.base import Bot
from alphatank.bots.defensive import DefensiveBot
from alphatank.bots.dodge import DodgeBot
from alphatank.bots.random_bot import RandomBot
from alphatank.bots.registry import (
    BOT_NAMES,
    BOTS,
    bot_from_spec,
    bot_options,
    make_bot,
    parse_bot_spec,
)
from alphatank.bots.smart import SmartBot
from alphatank.bots.weakness import Weakened

__all__ = ["BOTS", "BOT_NAMES", "AggressiveBot", "Bot", "DefensiveBot", "DodgeBot",
           "RandomBot", "SmartBot", "Weakened", "bot_from_spec", "bot_options", "make_bot",
           "parse_bot_spec"]

"""Bot factory: ``make_bot("smart", weakness=0.8, seed=1, ricochet=False)``."""

from __future__ import annotations

import inspect
from typing import Any

from alphatank.bots.aggressive import AggressiveBot
from alphatank.bots.base import Bot
from alphatank.bots.defensive import DefensiveBot
from alphatank.bots.dodge import DodgeBot
from alphatank.bots.random_bot import RandomBot
from alphatank.bots.smart import SmartBot
from alphatank.bots.weakness import Weakened
from alphatank.errors import InputError
from alphatank.sim.config import check_value


class BotError(InputError, ValueError):
    """An unknown bot, option or option value; the message lists the valid ones."""


BOTS: dict[str, type[Bot]] = {cls.name: cls for cls in
                              (RandomBot, AggressiveBot, DefensiveBot, DodgeBot, SmartBot)}
BOT_NAMES: tuple[str, ...] = tuple(BOTS)


def bot_options(name: str) -> list[str]:
    """Keyword options a bot takes besides ``seed`` (and the universal ``weakness``)."""
    cls = _lookup(name)
    return [p for p in inspect.signature(cls.__init__).parameters if p not in ("self", "seed")]


def make_bot(name: str, weakness: float | None = None, seed: int | None = None,
             **options: Any) -> Bot | Weakened:
    """A fresh bot by name. A ``weakness`` (w in [0, 1]) wraps it in :class:`Weakened`,
    whose ``weakness`` attribute a curriculum may change between episodes; ``options`` go
    to the bot's constructor (e.g. ``ricochet=False`` for ``smart``)."""
    cls = _lookup(name)
    problem = options_problem(name, options)
    if problem is not None:
        raise BotError(problem)
    bot = cls(seed=seed, **options)
    if weakness is None:
        return bot
    return Weakened(bot, weakness, seed=seed)


def options_problem(name: str, options: dict[str, Any]) -> str | None:
    """What is wrong with bot ``name``'s ``options`` (unknown keys, a value not of its
    default's type: bool, int or float, or values its constructor refuses, such as
    ``hold_min`` above ``hold_max``), or None."""
    valid = bot_options(name)
    unknown = sorted(set(options) - set(valid), key=str)
    if unknown:
        return (f"bot {name!r} has no option(s) {unknown}; valid options: {valid} "
                f"(weakness: NAME@W in a spec, the seat's own key in a table)")
    cls = _lookup(name)
    params = inspect.signature(cls.__init__).parameters
    for key, value in options.items():
        kind = type(params[key].default)
        if kind in (bool, int, float):
            _, reason = check_value((kind,), value)
            if reason is not None:
                return f"bot {name!r} option {key}: {reason}"
    try:  # the ranges are the constructor's (a bot is cheap to make: no map yet)
        cls(seed=0, **options)
    except ValueError as exc:
        return str(exc)
    return None


def parse_bot_spec(text: str) -> tuple[str, float | None, dict[str, Any]]:
    """``NAME[:KEY=VALUE...][@WEAKNESS]`` -> (name, weakness, options), e.g.
    ``"smart:ricochet=false@0.5"``. Values: true/false, numbers, else strings."""
    body, at, weak = text.strip().partition("@")
    name, *pairs = [p.strip() for p in body.split(":")]
    _lookup(name)
    options: dict[str, Any] = {}
    for pair in pairs:
        key, eq, value = pair.partition("=")
        if not eq or not key.strip():
            raise BotError(f"bot spec {text!r}: option {pair!r} must be KEY=VALUE; "
                             f"valid options of {name!r}: {bot_options(name)}")
        key = key.strip()
        if key in options:
            raise BotError(f"bot spec {text!r}: option {key!r} is given twice; give each "
                           f"option once")
        options[key] = _value(value.strip())
    weakness = None
    if at:
        try:
            weakness = float(weak)
        except ValueError:
            raise BotError(f"bot spec {text!r}: weakness after '@' must be a number in "
                             f"[0, 1], got {weak!r}") from None
    return name, weakness, options


def bot_from_spec(text: str, seed: int | None = None) -> Bot | Weakened:
    """:func:`make_bot` from a ``NAME[:KEY=VALUE...][@WEAKNESS]`` string."""
    name, weakness, options = parse_bot_spec(text)
    return make_bot(name, weakness=weakness, seed=seed, **options)


# ---- the line-up's "bot" controller kind (entry points named in alphatank.game.seats) ---

def bot_seat_fields(text: str) -> dict[str, Any]:
    """The seat-table keys of a bot spec string: ``bot``, ``options`` and, when given,
    ``weakness`` (``--seats`` items and arena seats)."""
    name, weakness, options = parse_bot_spec(text)
    fields: dict[str, Any] = {"bot": name, "options": options}
    if weakness is not None:
        fields["weakness"] = weakness
    return fields


def check_seat_bot(seat: Any) -> tuple[str, str] | None:
    """A ``bot`` seat's problem as (key, message), or None: a known bot, known options of
    the right types."""
    if seat.bot not in BOTS:
        return "bot", f"got {seat.bot!r}; valid bots: {list(BOT_NAMES)}"
    problem = options_problem(seat.bot, seat.options)
    return None if problem is None else ("options", problem)


def seat_bot(seat: Any, seed: int | None = None) -> Bot | Weakened:
    """The controller of a ``bot`` seat (its bot, weakness and options)."""
    return make_bot(seat.bot, weakness=seat.weakness, seed=seed, **seat.options)


def _value(text: str) -> Any:
    low = text.lower()
    if low in ("true", "yes", "on"):
        return True
    if low in ("false", "no", "off"):
        return False
    for cast in (int, float):
        try:
            return cast(text)
        except ValueError:
            pass
    return text


def _lookup(name: str) -> type[Bot]:
    cls = BOTS.get(name)
    if cls is None:
        raise BotError(f"unknown bot {name!r}; valid bots: {list(BOT_NAMES)}")
    return cls

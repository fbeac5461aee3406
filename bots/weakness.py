"""Weakness: a wrapper that lets any bot act only a fraction of the ticks."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from alphatank.bots.base import Bot
from alphatank.sim.policy import NOOP

if TYPE_CHECKING:
    from alphatank.sim.match import Match


class Weakened:
    """Each tick the wrapped bot acts with probability ``weakness`` (w in [0, 1]); otherwise
    the seat does nothing (NOOP). w = 0 never acts, w = 1 always acts. The coin flips come
    from the wrapper's own generator, so the wrapped bot's choices do not depend on w; at
    w = 0 or 1 no coin is drawn (the generator serves nothing else, so the play is the
    same with or without the draw)."""

    def __init__(self, bot: Bot, weakness: float, seed: int | None = None):
        self.bot, self.seed = bot, seed
        self.weakness = weakness
        self._seeder = np.random.default_rng(seed)
        self.rng = np.random.default_rng(seed)
        self.acted = 0  # ticks the wrapped bot acted this episode
        self.ticks = 0

    @property
    def weakness(self) -> float:
        """Probability of acting each tick; settable (curricula raise it over training)."""
        return self._w

    @weakness.setter
    def weakness(self, value: float) -> None:
        w = float(value)
        if not 0.0 <= w <= 1.0:
            raise ValueError(f"weakness must be in [0, 1], got {value!r}")
        self._w = w

    @property
    def name(self) -> str:
        return self.bot.name

    def __repr__(self) -> str:
        return f"Weakened({self.bot!r}, weakness={self.weakness})"

    def planned_path(self, match: Match, seat: int) -> list[tuple[int, int]] | None:
        """The wrapped bot's planned route (for overlays)."""
        return self.bot.planned_path(match, seat)

    def reset(self, match: Match, seat: int, seed: int | None = None) -> None:
        if seed is None:
            seed = int(self._seeder.integers(2**63))
        inner, coin = np.random.SeedSequence(seed).spawn(2)
        self.rng = np.random.default_rng(coin)
        self.bot.reset(match, seat, int(inner.generate_state(1, np.uint64)[0]))
        self.acted = self.ticks = 0

    def act(self, match: Match, seat: int) -> np.ndarray:
        self.ticks += 1
        w = self._w
        if w >= 1.0 or (w > 0.0 and self.rng.random() < w):
            self.acted += 1
            return self.bot.act(match, seat)
        return NOOP

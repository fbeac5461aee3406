"""RandomBot: a uniformly random action, held for 10-30 ticks."""

from __future__ import annotations

from typing import TYPE_CHECKING

from alphatank.bots.base import Bot

if TYPE_CHECKING:
    from alphatank.sim.match import Match


class RandomBot(Bot):
    """Draws (rotate, move, fire) uniformly and keeps it for a random 10-30 ticks."""

    name = "random"
    guarded = False

    def __init__(self, seed: int | None = None, hold_min: int = 10, hold_max: int = 30):
        super().__init__(seed)
        if not 1 <= hold_min <= hold_max:
            raise ValueError(f"RandomBot: need 1 <= hold_min <= hold_max, got "
                             f"hold_min={hold_min}, hold_max={hold_max}")
        self.hold_min, self.hold_max = hold_min, hold_max

    def on_reset(self, match: Match, seat: int) -> None:
        self._left = 0
        self._action = (1, 1, 0)

    def decide(self, match: Match, seat: int) -> tuple[int, int, int]:
        if self._left <= 0:
            rot, move, fire = self.rng.integers((0, 0, 0), (3, 3, 2))
            self._action = (int(rot), int(move), int(fire))
            self._left = int(self.rng.integers(self.hold_min, self.hold_max + 1))
        self._left -= 1
        return self._action

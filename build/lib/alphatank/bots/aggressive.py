"""AggressiveBot: straight-line pursuit of the nearest enemy, fires when aimed."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from alphatank.bots.base import BACK, FORWARD, NONE, STOP, Bot, wrap

if TYPE_CHECKING:
    from alphatank.sim.match import Match


class AggressiveBot(Bot):
    """Turns to the nearest enemy (leading its motion), drives straight at it until within
    ``range_frac`` of the bullet range, backs off inside ``min_frac``, and fires whenever
    the heading is within the target's angular size and no wall is in the way.
    No path finding: meant for open maps."""

    name = "aggressive"

    def __init__(self, seed: int | None = None, range_frac: float = 0.5,
                 min_frac: float = 0.2):
        super().__init__(seed)
        if not 0 < min_frac < range_frac <= 1:
            raise ValueError(f"AggressiveBot: need 0 < min_frac < range_frac <= 1, got "
                             f"min_frac={min_frac}, range_frac={range_frac}")
        self.range_frac, self.min_frac = range_frac, min_frac

    def decide(self, match: Match, seat: int) -> tuple[int, int, int]:
        seen = self.engage(match, seat)
        if seen is None:
            return NONE, STOP, 0
        target, x, y, ex, ey, dist, heading = seen
        err = wrap(self.lead_angle(match, seat, target) - heading)
        rot = self.steer(err)
        move = STOP
        if dist > self.range_frac * self.shot_range and abs(err) < math.radians(45):
            move = FORWARD
        elif dist < self.min_frac * self.shot_range:
            move = BACK
        tolerance = math.atan2(self.hit_radius * 0.8, max(dist, 1.0))
        fire = int(abs(err) < tolerance and dist < self.shot_range and self.can_fire(match, seat)
                   and self.clear_shot(match, seat, target))
        return rot, move, fire

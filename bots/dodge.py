"""DodgeBot: evasion first; keeps a safe band of distance; fires when an enemy is in line."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from alphatank.bots.base import BACK, DRIVE_RADIUS, FORWARD, NONE, STOP, Bot, Evader, wrap
from alphatank.sim.mapspec import MAX_WORLD

if TYPE_CHECKING:
    from alphatank.sim.match import Match


MAX_HORIZON_TICKS = 600  # 20 s of look-ahead at the default 30 ticks/s (9 paths of it)
MAX_DANGER_PX = 2.0 * MAX_WORLD  # past the diagonal of the largest world


class DodgeBot(Bot):
    """Watches a threat radius: any bullet that can hit it and will pass within
    ``danger_px`` in the next ``horizon_ticks`` is dodged by the best of the 9 turn/drive
    pairs (sideways away from the bullet line, never into walls). Enemy tanks closer
    than ``near_frac`` of the bullet range are fled; farther than ``far_frac`` (or out of
    sight) they are approached by BFS route; in between it turns to the enemy and fires
    when the enemy is in line and no wall is in the way."""

    name = "dodge"

    def __init__(self, seed: int | None = None, near_frac: float = 0.4, far_frac: float = 0.75,
                 horizon_ticks: int = 14, danger_px: float = 32.0):
        super().__init__(seed)
        if not 0 <= near_frac < far_frac <= 1:
            raise ValueError(f"DodgeBot: need 0 <= near_frac < far_frac <= 1, got "
                             f"near_frac={near_frac}, far_frac={far_frac}")
        if not (1 <= horizon_ticks <= MAX_HORIZON_TICKS and 0 < danger_px <= MAX_DANGER_PX):
            raise ValueError(f"DodgeBot: need 1 <= horizon_ticks <= {MAX_HORIZON_TICKS} and "
                             f"0 < danger_px <= {MAX_DANGER_PX:g}, got horizon_ticks="
                             f"{horizon_ticks}, danger_px={danger_px}")
        self.near_frac, self.far_frac = near_frac, far_frac
        self.horizon_ticks, self.danger_px = horizon_ticks, danger_px

    def on_reset(self, match: Match, seat: int) -> None:
        self.evader = Evader(self, match, seat, self.horizon_ticks, self.danger_px)
        self._dir = 1
        self._flip_at = 0
        self._attack_at = 0

    def strafe(self, match: Match, seat: int, x: float, y: float, heading: float,
               ex: float, ey: float, aim_err: float) -> tuple[int, int]:
        """Side-on to the enemy, driving to and fro (direction flips every 15-45 ticks or
        at a wall); every ``attack_every`` ticks with a bullet ready, face it to shoot."""
        t = match.tick
        if t >= self._flip_at:
            self._dir = -self._dir
            self._flip_at = t + int(self.rng.integers(15, 46))
        if self.can_fire(match, seat) and t >= self._attack_at:
            if abs(aim_err) < 0.5 * self.turn_step:
                self._attack_at = t + int(self.rng.integers(30, 90))
            return self.steer(aim_err), STOP
        side = math.atan2(ey - y, ex - x) + math.pi / 2
        err = wrap(side - heading)
        if abs(err) > math.pi / 2:
            err = wrap(err + math.pi)
        ahead = self._dir * 30.0
        probe = self.nav.clearance_at(x + ahead * math.cos(heading),
                                      y + ahead * math.sin(heading))
        if probe < DRIVE_RADIUS:  # float32-exact, so compared as numpy compared it
            self._dir = -self._dir
            self._flip_at = t + int(self.rng.integers(15, 46))
        return self.steer(err), FORWARD if self._dir > 0 else BACK

    def decide(self, match: Match, seat: int) -> tuple[int, int, int]:
        seen = self.engage(match, seat)
        if seen is None:
            return NONE, STOP, 0
        target, x, y, ex, ey, dist, heading = seen
        err = wrap(self.lead_angle(match, seat, target) - heading)
        tolerance = math.atan2(0.8 * self.hit_radius, max(dist, 1.0))
        threats = self.evader.threats(match, seat)
        if threats:  # dodge first; shoot back if the turn happens to line up
            rot, move = self.evader.evade(match, seat, threats, err)
            fire = (abs(err) < tolerance and dist < self.shot_range
                    and self.can_fire(match, seat) and self.clear_shot(match, seat, target))
            return rot, move, int(fire)
        sr = self.shot_range
        # Out of range and past both bands nothing below reads the line of sight.
        in_sight = ((dist < sr or dist <= self.far_frac * sr or dist < self.near_frac * sr)
                    and self.clear_shot(match, seat, target))
        if in_sight and dist < self.near_frac * sr:
            gx, gy = self.away_point(x, y, ex, ey)
            rot, move = self.drive(x, y, heading, gx, gy)
            if move == STOP:
                rot = self.steer(err)
        elif not in_sight or dist > self.far_frac * sr:
            gx, gy = self.route(match, x, y, self.node_of(x, y), self.node_of(ex, ey))
            rot, move = self.drive(x, y, heading, gx, gy)
        else:  # in the band: strafe side-on, hard to hit, turning to shoot when ready
            rot, move = self.strafe(match, seat, x, y, heading, ex, ey, err)
        fire = int(in_sight and abs(err) < tolerance and dist < sr
                   and self.can_fire(match, seat))
        return rot, move, fire

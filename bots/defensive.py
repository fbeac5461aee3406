"""DefensiveBot: takes the nearest buff zone, holds it, keeps its distance, snipes."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from alphatank.bots.base import NONE, STOP, Bot, Evader, wrap

if TYPE_CHECKING:
    from alphatank.sim.match import Match


class DefensiveBot(Bot):
    """Drives the BFS route to the nearest buff zone (its spawn cell when the map has
    none) and holds the zone's centre, turned to the nearest enemy. Backs away from an
    enemy that comes within ``keep_frac`` of the bullet range in the open, dodges
    bullets, and fires only when the predicted bullet path (ricochets included) reaches
    an enemy before anyone else: precise aim, few wasted shots."""

    name = "defensive"

    def __init__(self, seed: int | None = None, keep_frac: float = 0.35, evade: bool = True):
        super().__init__(seed)
        if not 0 <= keep_frac < 1:
            raise ValueError(f"DefensiveBot: keep_frac must be in [0, 1), got {keep_frac}")
        self.keep_frac, self.evade = keep_frac, bool(evade)

    def on_reset(self, match: Match, seat: int) -> None:
        self.evader = Evader(self, match, seat) if self.evade else None
        nav = self.nav
        zones = match.buffs or [match.spawn_cells[seat]]
        self.zone_nodes = np.array([nav.idx(c) for c in zones], dtype=np.int64)
        self._home: tuple[int, int] = (-1, -1)  # (from node, zone node) cache

    def home(self, me: int) -> int:
        """Nearest buff-zone node by BFS steps from ``me`` (cached per node)."""
        if self._home[0] != me:
            steps = self.nav.dist_table[me, self.zone_nodes].astype(np.float64)
            steps[steps < 0] = np.inf
            self._home = (me, int(self.zone_nodes[int(np.argmin(steps))]))
        return self._home[1]

    def decide(self, match: Match, seat: int) -> tuple[int, int, int]:
        seen = self.engage(match, seat)
        if seen is None:
            return NONE, STOP, 0
        target, x, y, ex, ey, dist, heading = seen
        tolerance = math.atan2(0.6 * self.hit_radius, max(dist, 1.0))
        if self.evader is not None:
            threats = self.evader.threats(match, seat)
            if threats:  # dodge; shoot back if the dodge happens to line up
                err = wrap(self.lead_angle(match, seat, target) - heading)
                rot, move = self.evader.evade(match, seat, threats, err)
                fire = (abs(err) < tolerance and dist <= self.shot_range
                        and self.can_fire(match, seat) and self.clear_shot(match, seat, target))
                return rot, move, int(fire)
        me = self.node_of(x, y)
        goal = self.home(me)
        aim_err = wrap(self.lead_angle(match, seat, target) - heading)

        if dist < self.keep_frac * self.shot_range and self.clear_shot(match, seat, target):
            gx, gy = self.away_point(x, y, ex, ey)
            rot, move = self.drive(x, y, heading, gx, gy)
            if move == STOP:  # facing sideways: back off while turning to the enemy
                rot = self.steer(aim_err)
        else:
            gx, gy = self.route(match, x, y, me, goal)
            rot, move = self.drive(x, y, heading, gx, gy)
            if move == STOP and me == goal and rot == NONE:
                rot = self.steer(aim_err)  # holding the zone: turn to the enemy
        fire = 0
        if self.can_fire(match, seat):
            if abs(aim_err) < tolerance and self.clear_shot(match, seat, target):
                fire = 1
            elif (match.tick % 3 == seat % 3  # bank shots: check the heading now and then
                  and dist <= self.shot_range + self.muzzle_offset):
                fire = int(self.shot_hits(match, seat, exact=False)[0]
                           and self.shot_hits(match, seat)[0])
        return rot, move, fire

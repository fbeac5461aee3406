"""SmartBot: BFS to a firing position, direct and ricochet shots, dodges bullets."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from alphatank.bots.base import NONE, STOP, Bot, Evader, wrap
from alphatank.sim.ballistics import bank_angles, path_distances, predict_path, wall_faces

if TYPE_CHECKING:
    from alphatank.sim.match import Match

GOLDEN = 0.6180339887498949


class SmartBot(Bot):
    """Hunts the nearest enemy by BFS path length.

    Movement: follows the map's BFS next-step tables (string-pulled into straight legs) to
    the nearest cell that sees the enemy's cell within shooting range, so no search runs
    per tick. Shooting: with a clear straight line it leads the target and fires when
    aimed; otherwise (``ricochet=True``) it tries one heading per tick with a predicted
    bullet path: first the one-bounce mirror solutions off every wall face, then a sweep
    of all headings it can turn to. It stops when a bank shot reaches the enemy, turns to
    it and fires once the exact prediction from its actual heading still hits. Bullets about to
    hit it are dodged (``evade``). ``ricochet=False`` is the paper's weakened teacher.
    """

    name = "smart"

    def __init__(self, seed: int | None = None, ricochet: bool = True, evade: bool = True):
        super().__init__(seed)
        self.ricochet, self.evade = bool(ricochet), bool(evade)

    def __repr__(self) -> str:
        return (f"SmartBot(seed={self.seed!r}, ricochet={self.ricochet}, "
                f"evade={self.evade})")

    def on_reset(self, match: Match, seat: int) -> None:
        self.evader = Evader(self, match, seat) if self.evade else None
        self.direct_range = self.shot_range  # from the centre; bullets start at the muzzle
        self.lattice = max(1, round(math.tau / self.turn_step))  # reachable headings
        self._goals: dict[tuple[int, int], int] = self.tables.setdefault(
            ("smart.goals", self.cfg.bullet_radius, self.shot_range), {})
        self._search_key: tuple[int, int] | None = None
        self._search_k = 0
        self._banks: list[float] = []
        key = ("faces", match.spec.width, match.spec.height)
        faces = self.tables.get(key)
        if faces is None:
            faces = self.tables[key] = wall_faces(self.nav.rects, match.spec.width,
                                                  match.spec.height)
        self.faces = faces
        self._best = (math.inf, 0.0)  # (closest approach px, heading)
        self._solution: float | None = None

    # ---- planning tables (cached per map cell pair) ---------------------------------

    def firing_cell(self, me: int, enemy: int) -> int:
        """Nearest cell (BFS) whose centre sees ``enemy``'s centre within direct range."""
        key = (me, enemy)
        goal = self._goals.get(key)
        if goal is None:
            nav = self.nav
            sees = nav.visible_row(enemy, self.cfg.bullet_radius).copy()
            d = nav.centers - nav.centers[enemy]
            sees &= (d * d).sum(axis=1) <= (0.8 * self.shot_range) ** 2
            steps = nav.dist_table[me]
            sees &= steps >= 0
            if sees.any():
                cand = np.flatnonzero(sees)
                goal = int(cand[np.argmin(steps[cand])])
            else:
                goal = enemy
            self._goals[key] = goal
        return goal

    # ---- decision -------------------------------------------------------------------

    def decide(self, match: Match, seat: int) -> tuple[int, int, int]:
        foes = self.enemies(match)
        if not foes:
            return NONE, STOP, 0
        rows = match.world.tank_rows()  # few tanks: plain Python beats numpy here
        x, y, heading = rows[seat][:3]
        me = self.node_of(x, y)
        target, enode, best = -1, -1, math.inf
        dist_table = self.nav.dist_table
        for f in foes:
            node = self.node_of(rows[f][0], rows[f][1])
            steps = int(dist_table[me, node])
            steps = math.inf if steps < 0 else steps
            if target < 0 or steps < best:
                target, enode, best = f, node, steps
        ex, ey = rows[target][:2]
        dist = math.hypot(ex - x, ey - y)

        if self.evader is not None:
            threats = self.evader.threats(match, seat)
            if threats:  # dodge; shoot back if the dodge happens to line up
                self._solution = None
                err = wrap(self.lead_angle(match, seat, target) - heading)
                rot, move = self.evader.evade(match, seat, threats, err)
                fire = (abs(err) < math.atan2(0.8 * self.hit_radius, max(dist, 1.0))
                        and dist <= self.direct_range and self.can_fire(match, seat)
                        and self.clear(match, x, y, ex, ey, self.cfg.bullet_radius))
                return rot, move, int(fire)

        bank_reach = self.shot_range + self.muzzle_offset
        # Beyond both reaches neither branch below looks at the line of sight.
        in_sight = (dist <= max(self.direct_range, bank_reach)
                    and self.clear(match, x, y, ex, ey, self.cfg.bullet_radius))
        if in_sight and dist <= self.direct_range:
            self._solution = None
            err = wrap(self.lead_angle(match, seat, target) - heading)
            tolerance = math.atan2(0.8 * self.hit_radius, max(dist, 1.0))
            fire = abs(err) < tolerance and self.can_fire(match, seat)
            if fire and match.n > 2:  # teammates may stand in the line of fire
                fire = self.shot_hits(match, seat)[0]
            elif fire:  # the bullet flies along the heading, which may clip a corner
                fire = self.heading_clear(match, seat, dist - self.hit_radius)
            return self.steer(err), STOP, int(fire)

        fire = 0
        # Bank shots only round walls: with a clear line, a bounce is only a longer way.
        if self.ricochet and not in_sight and dist <= bank_reach:
            if self._solution is not None:
                err = wrap(self._solution - heading)
                if abs(err) <= 0.5 * self.turn_step + 1e-9:
                    hits = self.shot_hits(match, seat)[0]
                    if hits and self.can_fire(match, seat):
                        fire = 1
                    elif not hits:
                        self._solution = None  # target moved: search again from here
                        self._best = (math.inf, 0.0)
                if self._solution is not None:
                    return self.steer(err), STOP, fire
            else:
                self._search(match, seat, me, enode, (ex, ey))
                if self._solution is not None:
                    return self.steer(wrap(self._solution - heading)), STOP, 0
        else:
            self._solution = None

        gx, gy = self.route(match, x, y, me, self.firing_cell(me, enode))
        rot, move = self.drive(x, y, heading, gx, gy)
        if move == STOP and rot == NONE:  # arrived: face the enemy while waiting
            rot = self.steer(wrap(math.atan2(ey - y, ex - x) - heading))
        return rot, move, fire

    def heading_clear(self, match: Match, seat: int, reach: float) -> bool:
        """A bullet fired now flies ``reach`` px along the heading without touching a
        wall (exact swept-circle query from the muzzle)."""
        x, y, a = match.world.tank_rows()[seat][:3]
        c, s = math.cos(a), math.sin(a)
        d, reach = self.muzzle_offset, max(reach, self.muzzle_offset)
        return match.world.ray((x + c * d, y + s * d), (x + c * reach, y + s * reach),
                               self.cfg.bullet_radius) is None

    def _search(self, match: Match, seat: int, me: int, enode: int,
                target_xy: tuple[float, float]) -> None:
        """Evaluate one heading for a bank shot: first the one-bounce mirror solutions
        (recomputed when this tank or the target changes cell), then a golden-ratio sweep
        over every heading the tank can turn to (multi-bounce shots)."""
        x, y, heading = match.world.tank_rows()[seat][:3]
        key = (me, enode)
        if key != self._search_key:
            self._search_key = key
            self._best = (math.inf, 0.0)
            self._banks = list(bank_angles(self.faces, x, y, target_xy[0], target_xy[1],
                                           self.cfg.bullet_radius,
                                           self.shot_range + self.muzzle_offset))
        if self._banks:  # snap to the heading lattice the tank can actually reach
            angle = heading + round(wrap(self._banks.pop(0) - heading) / self.turn_step) \
                * self.turn_step
        else:
            j = int(self._search_k * GOLDEN * self.lattice) % self.lattice
            self._search_k += 1
            angle = heading + j * self.turn_step
        d = self.muzzle_offset
        path = predict_path(match.world, x + math.cos(angle) * d, y + math.sin(angle) * d, angle,
                            exact=False)
        miss = float(path_distances(path, np.array([target_xy]))[0])
        if miss < self._best[0]:
            self._best = (miss, angle)
        if self._best[0] < 0.8 * self.hit_radius:
            self._solution = wrap(self._best[1])

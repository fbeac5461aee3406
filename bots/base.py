"""Shared machinery of the rule-based bots: seeding, steering, aiming, evasion.

Every bot sees the full match state (privileged, no pixels) and returns one action per
tick: rotate {0 ccw, 1 none, 2 cw}, move {0 back, 1 stop, 2 forward}, fire {0, 1}.
Angles are radians with y pointing down, so a positive angle change is clockwise on
screen, which is what ``rotate = 2`` does.
"""

from __future__ import annotations

import math
import weakref
from typing import TYPE_CHECKING, Any, ClassVar, NamedTuple

import numpy as np

from alphatank.bots.kernels import evade_choice, threat_slots
from alphatank.sim.ballistics import path_hits, predict_path
from alphatank.sim.navigation import NavGrid, nav_grid
from alphatank.sim.policy import ACTIONS, NOOP
from alphatank.sim.sight import WallSight, wall_sight

if TYPE_CHECKING:
    from alphatank.sim.match import Match

TAU = 2.0 * math.pi
CCW, NONE, CW = 0, 1, 2
BACK, STOP, FORWARD = 0, 1, 2
MOVE_CONE = math.radians(35.0)  # drive only while the heading error is below this
REVERSE_CONE = math.radians(110.0)  # reverse instead of turning round beyond this
DRIVE_RADIUS = 16.0  # clearance used for straight driving legs (tank half-length + 1)
AWAY_CLEARANCE = DRIVE_RADIUS + 4.0  # away_point's (float32-exact: the raster is float32)
_AWAY_TURNS = tuple(t * math.pi for t in (0.0, 0.25, -0.25, 0.5, -0.5))
ARRIVE_PX = 6.0


def wrap(a: float) -> float:
    """Angle wrapped to [-pi, pi)."""
    return (a + math.pi) % TAU - math.pi


_map_tables: weakref.WeakKeyDictionary[NavGrid, dict[Any, Any]] = weakref.WeakKeyDictionary()


def map_tables(nav: NavGrid) -> dict[Any, Any]:
    """Per-map values bots derive from a NavGrid, shared by every bot and episode on that
    map: plain-Python copies of the node and centre tables (``"node_rows"``,
    ``"centers"``) plus whatever a bot caches under its own keys."""
    tables = _map_tables.get(nav)
    if tables is None:
        tables = _map_tables[nav] = {"node_rows": nav.node.tolist(),
                                     "centers": nav.centers.tolist()}
    return tables


class Engagement(NamedTuple):
    """A bot's view of its nearest live enemy this tick."""

    target: int
    x: float
    y: float
    ex: float
    ey: float
    dist: float
    heading: float


class Bot:
    """Base class: seeding, per-episode set-up and helpers. Subclasses implement
    :meth:`decide` returning (rotate, move, fire)."""

    name: ClassVar[str] = "bot"
    guarded: ClassVar[bool] = True  # run the stuck watchdog (:meth:`guard`) on decisions

    def __init__(self, seed: int | None = None):
        self.seed = seed
        self._seeder = np.random.default_rng(seed)
        self.rng = np.random.default_rng(seed)

    def __repr__(self) -> str:
        return f"{type(self).__name__}(seed={self.seed!r})"

    # ---- Policy protocol ------------------------------------------------------------

    def reset(self, match: Match, seat: int, seed: int | None = None) -> None:
        """New episode: fresh generator (from ``seed``, else the next draw of the bot's
        own seed stream), map tables, and per-episode state."""
        if seed is None:
            seed = int(self._seeder.integers(2**63))
        self.rng = np.random.default_rng(seed)
        cfg = match.cfg
        self.cfg = cfg
        self.nav: NavGrid = nav_grid(match.spec)
        nav = self.nav
        self.tables = map_tables(nav)
        self._node_rows: list[list[int]] = self.tables["node_rows"]
        self._last_row, self._last_col = nav.node.shape[0] - 1, nav.node.shape[1] - 1
        self._centers: list[list[float]] = self.tables["centers"]
        self.turn_step = math.radians(cfg.rotation_speed) / cfg.tick_hz
        self.hit_radius = cfg.tank_height / 2 + cfg.bullet_radius
        self.muzzle_offset = cfg.tank_width / 2 + cfg.bullet_radius + 0.5
        self.shot_range = cfg.bullet_max_distance
        self._foes = [int(k) for k in np.flatnonzero(match.team_index != match.team_index[seat])]
        self._route: tuple[int, int] | None = None
        self._stuck_since = -1
        self._stuck_pose = (0.0, 0.0, 0.0)
        self._unstick_until = -1
        self._unstick_move = BACK
        self.on_reset(match, seat)

    def sight(self, match: Match) -> WallSight:
        """Fast exact wall queries on ``match``'s current world (kept on the world, so a
        bot holds no world and pickles without one)."""
        return wall_sight(match.world)

    def node_of(self, x: float, y: float) -> int:
        """``nav.node_of(x, y)`` from plain-Python tables: the floor node of a pixel."""
        cell, last_r, last_c = self.nav.cell, self._last_row, self._last_col
        r, c = int(y // cell), int(x // cell)  # clamped below without min/max calls
        row = self._node_rows[0 if r < 0 else last_r if r > last_r else r]
        return row[0 if c < 0 else last_c if c > last_c else c]

    def act(self, match: Match, seat: int) -> np.ndarray:
        """The decision as a shared read-only array (``alphatank.sim.policy.ACTIONS``)."""
        if not match.alive[seat]:
            return NOOP
        self._route = None
        rot, move, fire = self.decide(match, seat)
        if self.guarded:
            rot, move = self.guard(match, seat, rot, move)
        return ACTIONS[6 * rot + 2 * move + fire]

    def planned_path(self, match: Match, seat: int) -> list[tuple[int, int]] | None:
        """Grid cells of the BFS route the bot last steered along (for overlays)."""
        if self._route is None or not match.alive[seat]:
            return None
        return [self.nav.cell_at(k) for k in self.nav.path_idx(*self._route)]

    # ---- for subclasses -------------------------------------------------------------

    def on_reset(self, match: Match, seat: int) -> None:
        """Per-episode state of a subclass (called at the end of :meth:`reset`)."""

    def decide(self, match: Match, seat: int) -> tuple[int, int, int]:
        raise NotImplementedError

    # ---- helpers --------------------------------------------------------------------

    def steer(self, err: float) -> int:
        """Rotate action reducing heading error ``err`` (target minus heading)."""
        half = 0.5 * self.turn_step
        if err > half:
            return CW
        if err < -half:
            return CCW
        return NONE

    def drive(self, x: float, y: float, heading: float, tx: float, ty: float,
              reverse: bool = True) -> tuple[int, int]:
        """(rotate, move) that take a tank at (x, y, heading) towards (tx, ty), backing up
        when the point is behind it; stops within ARRIVE_PX."""
        dx, dy = tx - x, ty - y
        if dx * dx + dy * dy < ARRIVE_PX * ARRIVE_PX:
            return NONE, STOP
        err = wrap(math.atan2(dy, dx) - heading)
        move = FORWARD
        if reverse and abs(err) > REVERSE_CONE:
            err = wrap(err + math.pi)
            move = BACK
        if abs(err) > MOVE_CONE:
            move = STOP
        return self.steer(err), move

    def away_point(self, x: float, y: float, fx: float, fy: float,
                   reach: float = 50.0) -> tuple[float, float]:
        """A point ``reach`` px from (x, y) away from (fx, fy), turned by up to 90 degrees
        if needed to keep clear of walls."""
        base = math.atan2(y - fy, x - fx)
        first = None
        for turn in _AWAY_TURNS:  # plain Python: np.cos and math.cos give the same bits
            a = base + turn
            px, py = x + reach * math.cos(a), y + reach * math.sin(a)
            if first is None:
                first = (px, py)
            if self.nav.clearance_at(px, py) > AWAY_CLEARANCE:
                return px, py
        return first

    def route(self, match: Match, x: float, y: float, me: int, goal: int
              ) -> tuple[float, float]:
        """Next point to drive to on the BFS route from node ``me`` to node ``goal``: the
        farthest path cell a straight leg from the tank reaches, else the next cell, else
        the centre of the tank's own cell (so corners are turned from the cell centre)."""
        nav, centers = self.nav, self._centers
        self._route = (me, goal)
        if me == goal:
            gx, gy = centers[me]
            return gx, gy
        r = DRIVE_RADIUS - 2.0
        gx, gy = centers[nav.waypoint_idx(me, goal, DRIVE_RADIUS)]  # a node, never -1
        if self.ray_clear(match, x, y, gx, gy, r):
            return gx, gy
        k = int(nav.next_table[me, goal])  # looked up only when the waypoint is blocked
        if k >= 0:
            gx, gy = centers[k]
            if self.ray_clear(match, x, y, gx, gy, r):
                return gx, gy
        gx, gy = centers[me]
        return gx, gy

    def enemies(self, match: Match) -> list[int]:
        """Live tanks on teams other than this bot's seat's (its foes, found at reset; a
        handful: plain Python is cheapest)."""
        alive = match.alive
        return [k for k in self._foes if alive[k]]

    def nearest(self, match: Match, seat: int, tanks: list[int]) -> int:
        """Tank in ``tanks`` nearest in straight-line distance (-1 if none)."""
        rows = match.world.tank_rows()
        x, y = rows[seat][:2]
        best, best_d = -1, math.inf
        for k in tanks:
            ex, ey = rows[k][:2]
            d = (ex - x) ** 2 + (ey - y) ** 2
            if d < best_d:
                best, best_d = k, d
        return best

    def engage(self, match: Match, seat: int) -> Engagement | None:
        """Nearest live enemy with both positions, its distance and this tank's heading;
        None when no enemy is left."""
        target = self.nearest(match, seat, self.enemies(match))
        if target < 0:
            return None
        rows = match.world.tank_rows()
        x, y, heading = rows[seat][:3]
        ex, ey = rows[target][:2]
        return Engagement(target, x, y, ex, ey, math.hypot(ex - x, ey - y), heading)

    def can_fire(self, match: Match, seat: int) -> bool:
        """Whether a fire action this tick would spawn a bullet (cooldown ticks down
        before firing; bullet limits follow buff/debuff zones)."""
        return bool(match.cooldown[seat] <= 1
                    and match.bullets_alive[seat] < match.bullet_limit(seat))

    def lead_angle(self, match: Match, seat: int, target: int) -> float:
        """Angle to shoot a straight bullet that meets ``target`` moving at its current
        velocity (falls back to the direct angle when no intercept exists)."""
        rows = match.world.tank_rows()
        x, y = rows[seat][:2]
        ex, ey, _, vx, vy, _ = rows[target]
        rx, ry = ex - x, ey - y
        s, d0 = self.cfg.bullet_speed, self.muzzle_offset
        # |r + v t| = d0 + s t  ->  (v.v - s^2) t^2 + 2 (r.v - d0 s) t + (r.r - d0^2) = 0
        a = vx * vx + vy * vy - s * s
        b = 2.0 * (rx * vx + ry * vy - d0 * s)
        c = rx * rx + ry * ry - d0 * d0
        disc = b * b - 4 * a * c
        if a < 0 and disc >= 0:
            t = (-b - math.sqrt(disc)) / (2 * a)
            if t > 0:
                return math.atan2(ry + vy * t, rx + vx * t)
        return math.atan2(ry, rx)

    def clear_shot(self, match: Match, seat: int, target: int) -> bool:
        """A bullet-thick straight line from this tank to ``target`` misses every wall."""
        rows = match.world.tank_rows()
        x, y = rows[seat][:2]
        tx, ty = rows[target][:2]
        return self.clear(match, x, y, tx, ty, self.cfg.bullet_radius)

    def ray_clear(self, match: Match, x0: float, y0: float, x1: float, y1: float,
                  radius: float) -> bool:
        """``match.world.ray((x0, y0), (x1, y1), radius) is None``: a circle of ``radius``
        travels the segment without touching a wall. Off the bullet radius the world asks
        :func:`alphatank.sim.world.first_wall_hit`, answered here without pymunk's
        wrappers; at the bullet radius the world's own query answers."""
        if radius == self.cfg.bullet_radius:
            return match.world.ray((x0, y0), (x1, y1), radius) is None
        return self.sight(match).ray_clear(x0, y0, x1, y1, radius)

    def clear(self, match: Match, x0: float, y0: float, x1: float, y1: float,
              radius: float) -> bool:
        """Quick thick line-of-sight test for aiming decisions (pymunk's space-level
        segment query, ~3x cheaper than ``world.ray`` but it can miss a corner grazed only
        by the rim, harmless at bullet radius). Driving legs use the exact ``world.ray``:
        a tank-wide leg clips corners the thin segment's bounding box never reaches."""
        return self.sight(match).clear(x0, y0, x1, y1, radius)

    def shot_hits(self, match: Match, seat: int, exact: bool = True
                  ) -> tuple[bool, np.ndarray]:
        """Predict a bullet fired now (ricochets included): (first tank it reaches is an
        enemy, the predicted path). Teammates in the way make it False. ``exact=False``
        uses the cheaper search-grade prediction (see ``predict_path``)."""
        w = match.world
        x, y, a = w.tank_rows()[seat][:3]
        d = self.muzzle_offset
        path = predict_path(w, x + math.cos(a) * d, y + math.sin(a) * d, a, exact=exact)
        others = np.flatnonzero(match.alive)
        others = others[others != seat]
        k = path_hits(path, match.tank_xy[others], self.hit_radius)
        if k < 0:
            return False, path
        return bool(match.team_index[others[k]] != match.team_index[seat]), path

    def guard(self, match: Match, seat: int, rot: int, move: int) -> tuple[int, int]:
        """Stuck watchdog around a planned (rotate, move): if the tank has been told to
        turn or drive for 20 ticks yet neither got 8 px anywhere nor turned 8 degrees
        (pinned against a wall), drive towards the open side for 12 ticks."""
        t = match.tick
        if t < self._unstick_until:
            return rot, self._unstick_move
        if rot == NONE and move == STOP:
            self._stuck_since = -1
            return rot, move
        x, y, a = match.world.tank_rows()[seat][:3]
        sx, sy, sa = self._stuck_pose
        if (self._stuck_since < 0 or (x - sx) ** 2 + (y - sy) ** 2 > 64.0
                or abs(wrap(a - sa)) > 0.14):
            self._stuck_since, self._stuck_pose = t, (x, y, a)
            return rot, move
        if t - self._stuck_since >= 20:
            ahead = self.nav.clearance_at(x + 30 * math.cos(a), y + 30 * math.sin(a))
            behind = self.nav.clearance_at(x - 30 * math.cos(a), y - 30 * math.sin(a))
            self._unstick_move = FORWARD if ahead > behind else BACK
            self._unstick_until = t + 12
            self._stuck_since = -1
            return rot, self._unstick_move
        return rot, move


class Evader:
    """Dodges incoming bullets: picks, among the 9 (rotate, move) pairs, the one whose
    short-horizon motion keeps the tank farthest from every threatening bullet and out
    of walls. Only does work when a bullet that can hit the tank is closing in."""

    def __init__(self, bot: Bot, match: Match, seat: int, horizon_ticks: int = 12,
                 danger_px: float = 30.0):
        cfg = match.cfg
        self.bot, self.nav = bot, bot.nav
        self.dt = cfg.dt
        self.horizon = horizon_ticks
        self.danger = danger_px + cfg.bullet_radius
        self.wall_margin = cfg.tank_height / 2 + 1.0
        self.fwd, self.side, self.times = _candidate_paths(bot.turn_step, cfg.tank_speed,
                                                           self.dt, horizon_ticks)
        self.raster = bot.nav.clearance_map()  # distance to walls, 5 px raster
        self.res = 5.0
        self._score = np.zeros(9)  # evade()'s candidate scores
        # tanks whose bullets can hit this seat (own bullets never: grace, self_hit off)
        can_hit = match.world.can_hit[:, seat].copy()
        can_hit[seat] = False
        self.shooters = [int(k) for k in np.flatnonzero(can_hit)]
        # Their bullet slots (slot owners are fixed for a world's lifetime).
        self._slots = np.flatnonzero(can_hit[match.bullet_owner]).astype(np.int64)
        self._slots.setflags(write=False)
        self._found = np.zeros(len(self._slots), dtype=np.int64)  # threats()'s output
        self._soon = float(self.times[-1] * 2)
        self._danger2 = self.danger ** 2

    def threats(self, match: Match, seat: int) -> list[int]:
        """Indices (ascending) of bullets that can hit ``seat`` and pass within danger
        soon (:func:`~alphatank.bots.kernels.threat_slots`, called only while one of the
        shooters has a bullet in play)."""
        counts = match.bullets_alive.tolist()
        for k in self.shooters:
            if counts[k]:
                break
        else:
            return []
        x, y = match.world.tank_rows()[seat][:2]
        found = self._found
        k = threat_slots(match.world.bullet_state, match.bullet_active, self._slots, x, y,
                         self._soon, self._danger2, found)
        return found[:k].tolist()

    def evade(self, match: Match, seat: int, threats: list[int],
              aim_err: float = 0.0) -> tuple[int, int]:
        """Best (rotate, move) against ``threats`` (bullet indices); among equally safe
        choices, the one turning towards ``aim_err`` (radians to the bot's aim)."""
        x, y, h = match.world.tank_rows()[seat][:3]
        best = evade_choice(x, y, math.cos(h), math.sin(h), self.fwd, self.side, self.times,
                            match.world.bullet_state, np.array(threats, dtype=np.int64),
                            self.raster, 1 / self.res,
                            4 * self.danger * self.danger, self.wall_margin,
                            2 * self.danger, 0.5, self.bot.steer(aim_err), self._score)
        return best // 3, best % 3


_paths: dict[tuple[float, float, float, int], tuple[np.ndarray, ...]] = {}


def _candidate_paths(turn_step: float, speed: float, dt: float, horizon: int
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The 9 (rotate, move) candidates' paths in the tank's own frame (heading 0), and
    the horizon's times: (fwd (9, K) along the heading, side (9, K) clockwise of it,
    times (K,) seconds). A tick's motion follows the heading at its start; at run time a
    path is only rotated and shifted. Cached per setting (read-only arrays)."""
    key = (turn_step, speed, dt, horizon)
    got = _paths.get(key)
    if got is None:
        k = np.arange(1, horizon + 1, dtype=np.float64)  # ticks ahead
        rot = np.repeat(np.array([-1.0, 0.0, 1.0]), 3)  # candidate c = 3 * rot + move
        move = np.tile(np.array([-1.0, 0.0, 1.0]), 3)
        turn = rot[:, None] * turn_step * (k[None, :] - 1)  # (9, K)
        step = move[:, None] * speed * dt
        got = (np.cumsum(np.cos(turn) * step, axis=1), np.cumsum(np.sin(turn) * step, axis=1),
               k * dt)
        for a in got:
            a.setflags(write=False)
        _paths[key] = got
    return got

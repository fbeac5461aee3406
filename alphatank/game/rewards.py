"""Reward terms (RULES.md, paper 3.2.3) as small pure functions, and a tracker.

Every term is a function of one tick's events and state (plus, for the stateful
penalties, a counter the :class:`RewardTracker` keeps per tank). Each returns the reward of
that tick only, already scaled by its :class:`~alphatank.sim.config.RewardConfig` weight; a
weight of 0 switches the term off (and skips its computation). Weights carry their sign:
penalties are configured negative. The tracker returns a (envs, terms, tanks) array whose
sum over terms is the per-step reward, in the order of :data:`TERMS`.

The terms after ``rotation`` are not in the paper's Table 5 (issue 12): team outcomes
(win, loss, draw to every seat of a team, dead or alive), a per-tick cost, potential-based
engagement shaping, and the two halves of the paper's equations the original code lacked
(the Euclidean half of eq. 14, the far-distance penalty of eq. 15). All weigh 0 by
default, so the ``paper`` preset and every earlier result are unchanged.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from types import SimpleNamespace
from typing import TYPE_CHECKING

import numpy as np

from alphatank.game.kernels import progress_counts
from alphatank.sim.ballistics import predict_points
from alphatank.sim.config import ConfigError, GameConfig, RewardConfig, hit_radius

if TYPE_CHECKING:
    from alphatank.game.observe import StateBatch
    from alphatank.sim.match import Hit, Match

TERMS = ("victory", "hit", "hit_penalty", "team_hit_penalty", "trajectory_hit",
         "trajectory_distance", "bullet_close", "bullet_away", "wall_hit", "stationary",
         "bfs_progress", "aim_streak", "control_change", "rotation",
         "team_win", "team_loss", "team_draw", "step_cost", "engagement",
         "distance_progress", "trajectory_far")
T = {name: k for k, name in enumerate(TERMS)}


# ---- pure terms ---------------------------------------------------------------------

def victory(team_index: np.ndarray, winner: int | None, weight: float) -> np.ndarray:
    """``weight`` to every tank (alive or not) of the winning team; zeros on a draw."""
    if winner is None:
        return np.zeros(len(team_index))
    return np.where(team_index == winner, weight, 0.0)


def team_outcome(team_index: np.ndarray, winner: int | None, elapsed: float,
                 cfg: RewardConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(team_win, team_loss, team_draw) per tank at the end of a match, to every tank of
    a team, dead or alive. The win shrinks linearly with the ``elapsed`` fraction of
    ``max_steps``: ``team_win * (1 - team_win_time_decay * elapsed)``."""
    n = len(team_index)
    zero = np.zeros(n)
    if winner is None:
        return zero, zero.copy(), np.full(n, cfg.team_draw)
    mine = team_index == winner
    win = cfg.team_win * (1.0 - cfg.team_win_time_decay * min(max(elapsed, 0.0), 1.0))
    return np.where(mine, win, 0.0), np.where(mine, 0.0, cfg.team_loss), zero


def check_team_outcome(cfg: RewardConfig, where: str = "") -> None:
    """A draw is never worth more than a loss (waiting out the clock must not be the safe
    choice), and the time decay is a share in [0, 1]. Errors read ``<where>.<field>:
    <reason>`` as :func:`~alphatank.sim.config.from_dict`'s do (``where``: the file and
    table, e.g. ``run.toml: [rewards]``)."""
    problem = None
    if cfg.team_draw > cfg.team_loss:
        problem = ("team_draw", f"({cfg.team_draw}) must not exceed team_loss "
                                f"({cfg.team_loss}): a draw is never worth more than a loss; "
                                f"set team_draw <= team_loss")
    elif not 0.0 <= cfg.team_win_time_decay <= 1.0:
        problem = ("team_win_time_decay", f"must be in [0, 1], got {cfg.team_win_time_decay}")
    if problem is not None:
        key, reason = problem
        raise ConfigError(f"{where}.{key}: {reason}" if where else
                          f"RewardConfig.{key} {reason}", key, reason)


def hits(events: Iterable[Hit], n: int, cfg: RewardConfig
         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(hit, hit_penalty, team_hit_penalty) per tank. The victim of any hit gets
    ``hit_penalty``; its shooter gets ``hit`` for an enemy, ``team_hit_penalty`` for a
    teammate, nothing for a self-hit."""
    hit, hurt, team = np.zeros(n), np.zeros(n), np.zeros(n)
    for h in events:
        hurt[h.victim] += cfg.hit_penalty
        if not h.friendly:
            hit[h.shooter] += cfg.hit
        elif h.shooter != h.victim:
            team[h.shooter] += cfg.team_hit_penalty
    return hit, hurt, team


def trajectory(d: float, radius: float, cfg: RewardConfig) -> tuple[float, float]:
    """(trajectory_hit, trajectory_distance) of a shot whose predicted path comes within
    ``d`` px of an enemy (paper eq. 15): the hit weight when ``d <= radius``, else the
    distance weight times ``1 - d / trajectory_close_px`` when ``d`` is below it."""
    if d <= radius:
        return cfg.trajectory_hit, 0.0
    if d < cfg.trajectory_close_px:
        return 0.0, cfg.trajectory_distance * (1.0 - d / cfg.trajectory_close_px)
    return 0.0, 0.0


def trajectory_far(d: float, cfg: RewardConfig) -> float:
    """Far-distance penalty of paper eq. 15: a shot whose predicted path stays farther
    than ``trajectory_far_px`` from every enemy costs ``trajectory_far`` times
    ``min(1, (d - far) / far)`` (the paper's ``min`` has lost its first argument; 1 caps
    the penalty at the weight). Nothing when ``d`` is unknown (inf)."""
    far = cfg.trajectory_far_px
    if not far < d < math.inf:
        return 0.0
    return cfg.trajectory_far * min(1.0, (d - far) / far)


def path_min_distance(pts: Sequence[Sequence[float]], targets: Sequence[Sequence[float]]
                      ) -> float:
    """Closest approach of the polyline ``pts`` (k points x, y) to any of ``targets`` (m
    rows of x, y).

    Same result as :func:`alphatank.sim.ballistics.path_min_distance`; a scalar loop, because
    a shot's path has a handful of legs and a match a handful of tanks, where this is
    several times cheaper than the array version (it runs on every shot)."""
    best = math.inf
    for (ax, ay), (bx, by) in zip(pts, pts[1:], strict=False):
        dx, dy = bx - ax, by - ay
        len2 = dx * dx + dy * dy
        for tx, ty in targets:
            rx, ry = tx - ax, ty - ay
            u = 0.0 if len2 == 0.0 else min(1.0, max(0.0, (rx * dx + ry * dy) / len2))
            ex, ey = rx - u * dx, ry - u * dy
            best = min(best, ex * ex + ey * ey)
    return math.sqrt(best)


def streak(count: np.ndarray, condition: np.ndarray) -> np.ndarray:
    """Consecutive-tick counter: +1 while ``condition`` holds, 0 when it breaks."""
    return np.where(condition, count + 1, 0)


def wall_hit(count: np.ndarray, cfg: RewardConfig) -> np.ndarray:
    """Escalating wall penalty (paper eq. 11): ``wall_hit`` for the first
    ``wall_hit_low_ticks`` ticks of contact, then ``wall_hit_high_factor`` times it."""
    w = cfg.wall_hit
    return np.where(count == 0, 0.0,
                    np.where(count <= cfg.wall_hit_low_ticks, w, w * cfg.wall_hit_high_factor))


def stationary(count: np.ndarray, cfg: RewardConfig) -> np.ndarray:
    """``stationary`` per tick once a tank has stayed in one grid cell for
    ``stationary_ticks`` ticks (paper eq. 13)."""
    return np.where(count >= cfg.stationary_ticks, cfg.stationary, 0.0)


def bfs_progress(prev: np.ndarray, now: np.ndarray, cfg: RewardConfig) -> np.ndarray:
    """``bfs_progress`` per grid cell of BFS path distance gained towards the nearest enemy
    (the global half of paper eq. 14); 0 where either distance is unknown (< 0)."""
    ok = (prev >= 0) & (now >= 0)
    return np.where(ok, cfg.bfs_progress * (prev - now), 0.0)


def distance_progress(prev: np.ndarray, now: np.ndarray, cfg: RewardConfig) -> np.ndarray:
    """``distance_progress`` per px of Euclidean distance gained towards the nearest live
    enemy (the local half of paper eq. 14); 0 where either distance is unknown (NaN)."""
    gain = prev - now
    return np.where(np.isnan(gain), 0.0, cfg.distance_progress * gain)


def engagement_potential(bfs: np.ndarray, diameter: float, weight: float) -> np.ndarray:
    """Potential ``weight * (1 - d / diameter)`` of each tank, ``d`` its BFS distance in
    cells to the nearest live enemy; 0 where ``d < 0`` (dead, or no enemy reachable).
    Non-negative, so a loop that leaves and comes back never earns (see
    :func:`potential_shaping`)."""
    return np.where(bfs >= 0, weight * (1.0 - bfs / max(diameter, 1.0)), 0.0)


def potential_shaping(prev: np.ndarray, now: np.ndarray, gamma: float) -> np.ndarray:
    """Potential-based shaping ``gamma * phi(s') - phi(s)`` (Ng et al. 1999): its
    discounted sum over any stretch is ``gamma^k phi(s_k) - phi(s_0)``, so it cannot be
    farmed and leaves the optimal policy unchanged. Terminal and dead states have
    potential 0, so the episode's total is ``-phi(s_0)`` whatever the agent does."""
    return gamma * now - prev


def aim_streak(count: np.ndarray, cfg: RewardConfig) -> np.ndarray:
    """``aim_streak`` when the predicted path has hit an enemy for ``aim_streak_ticks``
    consecutive ticks (paper eq. 17; the tracker then restarts the count)."""
    return np.where(count >= cfg.aim_streak_ticks, cfg.aim_streak, 0.0)


def control_change(counts: np.ndarray, cfg: RewardConfig) -> np.ndarray:
    """``control_change`` for each action part (rotate, move, fire) that has changed on
    ``control_change_ticks`` consecutive ticks (paper eq. 18). ``counts``: (..., 3)."""
    return cfg.control_change * (counts >= cfg.control_change_ticks).sum(axis=-1)


def rotation(turned_deg: np.ndarray, cfg: RewardConfig) -> np.ndarray:
    """``rotation`` once a tank has turned ``rotation_limit_deg`` in total without moving
    ``rotation_reset_px`` (paper eq. 19; the tracker then restarts the sum)."""
    return np.where(turned_deg >= cfg.rotation_limit_deg, cfg.rotation, 0.0)


# ---- tracker ------------------------------------------------------------------------

def as_index(idx: np.ndarray) -> slice | np.ndarray:
    """A slice for a contiguous ascending run of indices (basic indexing is several times
    cheaper than fancy indexing on small arrays), else the array itself."""
    idx = np.asarray(idx)
    if idx.size and np.array_equal(idx, np.arange(idx[0], idx[0] + idx.size)):
        return slice(int(idx[0]), int(idx[0]) + idx.size)
    return idx


class RewardTracker:
    """Per-tank counters of the stateful terms for ``num_envs`` matches of one scenario,
    and the per-step evaluation of every enabled term."""

    def __init__(self, cfg: RewardConfig, game: GameConfig, teams: Sequence[str],
                 num_envs: int, rewarded: Sequence[int] | None = None):
        """``rewarded``: seats whose rewards are read (default all); the costly per-shot
        and per-tank predictions (trajectory, aim streak) are skipped for the others."""
        self.cfg, self.game = cfg, game
        names = sorted(set(teams))
        self.team_index = np.array([names.index(t) for t in teams])
        n = self.n = len(teams)
        cap = game.bullet_capacity
        self.capacity = cap
        self.rewarded = np.zeros(n, dtype=bool)
        self.rewarded[list(range(n)) if rewarded is None else list(rewarded)] = True
        E = num_envs
        self.terms = np.zeros((E, len(TERMS), n))
        self.radius = hit_radius(game)
        owner = np.repeat(np.arange(n), cap)
        # enemy[b, j]: tank j is an enemy of bullet b's owner.
        self.enemy = self.team_index[owner][:, None] != self.team_index[None, :]
        self.foe = self.team_index[:, None] != self.team_index[None, :]  # (n, n)
        self._foes = [np.flatnonzero(row).tolist() for row in self.foe]  # per tank
        # Bullet slots of rewarded seats (only their progress is scored), NaN = none.
        self.rw_seats = np.flatnonzero(self.rewarded)
        self.rw_bullets = (self.rw_seats[:, None] * cap + np.arange(cap)).reshape(-1)
        self.rw_enemy = self.enemy[self.rw_bullets]  # (nr, n)
        self._rw_b, self._rw_s = as_index(self.rw_bullets), as_index(self.rw_seats)
        self._progress_w = np.array([cfg.bullet_close, cfg.bullet_away])
        self._pv: SimpleNamespace | None = None  # _progress views of the whole batch
        self.bullet_prev = np.full((E, len(self.rw_bullets)), np.nan)
        self.wall_count = np.zeros((E, n), dtype=np.int64)
        self.still_count = np.zeros((E, n), dtype=np.int64)
        self.last_cell = np.zeros((E, n, 2), dtype=np.int64)
        self.bfs_prev = np.full((E, n), -1, dtype=np.int64)
        self.dist_prev = np.full((E, n), np.nan)
        self.phi_prev = np.zeros((E, n))
        self._nav: list = [None] * E  # NavGrid of each env's map (set at reset)
        self._diameter = np.ones(E)  # longest BFS distance of each env's map (cells)
        self.aim_count = np.zeros((E, n), dtype=np.int64)
        self.change_count = np.zeros((E, n, 3), dtype=np.int64)
        self.last_action = np.ones((E, n, 3), dtype=np.int64)
        self.turned = np.zeros((E, n))
        self.last_angle = np.zeros((E, n))
        self.anchor = np.zeros((E, n, 2))
        on = {name: getattr(cfg, name) != 0 for name in TERMS}
        self.on_progress = on["bullet_close"] or on["bullet_away"]
        self.on_trajectory = (on["trajectory_hit"] or on["trajectory_distance"]
                              or on["trajectory_far"])
        self.on_outcome = on["team_win"] or on["team_loss"] or on["team_draw"]
        self.on_bfs = on["bfs_progress"] or on["engagement"]
        self.on = on
        check_team_outcome(cfg)

    def __getstate__(self) -> dict:
        """Everything but cached views (they would unpickle as detached copies)."""
        return {**self.__dict__, "_pv": None}

    def reset_env(self, e: int, match: Match) -> None:
        """Start env ``e``'s counters for a new episode of ``match``."""
        self.bullet_prev[e] = np.nan
        self.wall_count[e] = 0
        self.still_count[e] = 0
        self.last_cell[e] = (match.tank_xy // match.spec.cell).astype(np.int64)[:, ::-1]
        self.aim_count[e] = 0
        self.change_count[e] = 0
        self.last_action[e] = 1
        self.turned[e] = 0.0
        self.last_angle[e] = match.tank_angle
        self.anchor[e] = match.tank_xy
        if self.on_bfs:
            from alphatank.sim.navigation import nav_grid
            nav = self._nav[e] = nav_grid(match.spec)
            self._diameter[e] = max(1, int(nav.dist_table.max()))
            d = self._bfs_distance(e, match)
            self.bfs_prev[e] = d
            self.phi_prev[e] = engagement_potential(d, self._diameter[e], self.cfg.engagement)
        if self.on["distance_progress"]:
            self.dist_prev[e] = self._euclid(match.tank_xy[None], match.alive[None])[0]

    def step(self, sl: slice, batch: StateBatch, matches: Sequence[Match],
             actions: np.ndarray) -> np.ndarray:
        """Terms of the tick just played by the envs ``sl`` (their state already gathered
        into ``batch``); ``actions``: (E, n, 3) joint actions of that tick. Returns the
        (E_sl, len(TERMS), n) view of this tick's terms."""
        cfg = self.cfg
        terms = self.terms[sl]
        terms.fill(0.0)
        for k, m in enumerate(matches[sl]):
            ev = m.events
            if ev.hits or ev.fired or m.terminated or m.truncated:
                self._events(terms[k], m)
        alive = batch.alive[sl]
        if self.on_progress:
            self._progress(sl, batch, terms)
        if self.on["wall_hit"]:
            self.wall_count[sl] = streak(self.wall_count[sl], batch.wall[sl] & alive)
            terms[:, T["wall_hit"]] = wall_hit(self.wall_count[sl], cfg)
        if self.on["stationary"]:
            cell = (batch.tank_xy[sl] // self._cell(sl, matches)).astype(np.int64)[..., ::-1]
            same = (cell == self.last_cell[sl]).all(axis=-1) & alive
            self.still_count[sl] = streak(self.still_count[sl], same)
            self.last_cell[sl] = cell
            terms[:, T["stationary"]] = stationary(self.still_count[sl], cfg)
        if self.on["control_change"]:
            act = actions[sl]
            changed = (act != self.last_action[sl]) & alive[..., None]
            self.change_count[sl] = streak(self.change_count[sl], changed)
            self.last_action[sl] = act
            terms[:, T["control_change"]] = control_change(self.change_count[sl], cfg)
        if self.on["rotation"]:
            self._rotation(sl, batch, terms)
        if self.on_bfs:
            for k, e in enumerate(range(len(matches))[sl]):
                now = self._bfs_distance(e, matches[e])
                if self.on["bfs_progress"]:
                    terms[k, T["bfs_progress"]] = bfs_progress(self.bfs_prev[e], now, cfg)
                self.bfs_prev[e] = now
                if self.on["engagement"]:
                    phi = (engagement_potential(now, self._diameter[e], cfg.engagement)
                           if not matches[e].done else np.zeros(self.n))
                    terms[k, T["engagement"]] = potential_shaping(self.phi_prev[e], phi,
                                                                  cfg.engagement_gamma)
                    self.phi_prev[e] = phi
        if self.on["distance_progress"]:
            now = self._euclid(batch.tank_xy[sl], alive)
            terms[:, T["distance_progress"]] = distance_progress(self.dist_prev[sl], now, cfg)
            self.dist_prev[sl] = now
        if self.on["step_cost"]:
            terms[:, T["step_cost"]] = cfg.step_cost
        if self.on["aim_streak"]:
            for k, e in enumerate(range(len(matches))[sl]):
                aimed = self._aimed(matches[e])
                count = streak(self.aim_count[e], aimed)
                terms[k, T["aim_streak"]] = aim_streak(count, cfg)
                self.aim_count[e] = np.where(count >= cfg.aim_streak_ticks, 0, count)
        return terms

    # ---- parts ----------------------------------------------------------------------

    def _events(self, terms: np.ndarray, match: Match) -> None:
        cfg, ev = self.cfg, match.events
        if ev.hits:
            hit, hurt, team = hits(ev.hits, self.n, cfg)
            terms[T["hit"]] = hit
            terms[T["hit_penalty"]] = hurt
            terms[T["team_hit_penalty"]] = team
        if ev.fired and self.on_trajectory:
            for f in ev.fired:
                if not self.rewarded[f.tank]:
                    continue
                d = self._shot_distance(match, f.tank, f.bullet)
                th, td = trajectory(d, self.radius, cfg)
                terms[T["trajectory_hit"], f.tank] += th
                terms[T["trajectory_distance"], f.tank] += td
                terms[T["trajectory_far"], f.tank] += trajectory_far(d, cfg)
        if match.done and cfg.victory:
            win = None if match.winner is None else match.team_names.index(match.winner)
            terms[T["victory"]] = victory(self.team_index, win, cfg.victory)
        if match.done and self.on_outcome:
            win = None if match.winner is None else match.team_names.index(match.winner)
            out = team_outcome(self.team_index, win, match.tick / self.game.max_steps, cfg)
            terms[T["team_win"]], terms[T["team_loss"]], terms[T["team_draw"]] = out

    def _shot_distance(self, match: Match, tank: int, b: int) -> float:
        """Closest approach of a just-fired bullet's predicted path to a live enemy (plain
        Python reads: this runs on every shot, on a few numbers)."""
        w = match.world
        if not w.bullet_active[b]:
            return math.inf  # hit or gone within its first tick: the hit term scores it
        alive, rows = match.alive.tolist(), w.tank_rows()
        enemies = [rows[j][:2] for j in self._foes[tank] if alive[j]]
        if not enemies:
            return math.inf
        x, y, _, vx, vy, _ = w.bullet_state[b].tolist()
        left = (int(w.bullet_expire[b]) - w.substep) * w.step_len
        path = predict_points(w, x, y, math.atan2(vy, vx), max_distance=left,
                              max_bounces=self.game.bullet_max_bounces - int(w.bullet_bounces[b]))
        return path_min_distance(path, enemies)

    def _progress(self, sl: slice, batch: StateBatch, terms: np.ndarray) -> None:
        """bullet_close / bullet_away: each live bullet of a rewarded seat closer to /
        farther from its nearest live enemy than on the previous tick, every slot at once
        (compiled: :func:`~alphatank.game.kernels.progress_counts`). NaN marks "no
        distance" (slot inactive, or no live enemy), and a slot is only ever re-fired
        after a tick in which it was inactive, so fresh bullets never compare."""
        v = self._progress_views(sl, batch, terms)
        progress_counts(v.bullet_xy, v.tank_xy, v.alive, v.act, self.rw_enemy, v.prev,
                        self.capacity, self._progress_w, v.out)
        if not v.direct:
            terms[:, T["bullet_close"]:T["bullet_away"] + 1, self._rw_s] = v.out

    def _progress_views(self, sl: slice, batch: StateBatch, terms: np.ndarray
                        ) -> SimpleNamespace:
        """Arguments of :meth:`_progress` for the envs ``sl``; cached for the whole
        batch (every step) when the rewarded seats are contiguous (reads are views and the
        terms are written in place), else built afresh (play-outs, scattered seats)."""
        full = (sl == slice(None) and isinstance(self._rw_b, slice)
                and isinstance(self._rw_s, slice))
        if full and self._pv is not None and self._pv.batch is batch:
            return self._pv
        rw_b, seats = self._rw_b, self._rw_s
        close = T["bullet_close"]
        assert T["bullet_away"] == close + 1
        act = batch.bullet_active[sl][:, rw_b]
        direct = isinstance(seats, slice)
        v = SimpleNamespace(
            batch=batch, act=act, prev=self.bullet_prev[sl],
            bullet_xy=batch.bullet_xy[sl][:, rw_b], tank_xy=batch.tank_xy[sl],
            alive=batch.alive[sl], direct=direct,
            out=(terms[:, close:close + 2, seats] if direct
                 else np.zeros((len(act), 2, len(self.rw_seats)))))
        if full:
            self._pv = v
        return v

    def _rotation(self, sl: slice, batch: StateBatch, terms: np.ndarray) -> None:
        cfg = self.cfg
        ang, xy, alive = batch.tank_angle[sl], batch.tank_xy[sl], batch.alive[sl]
        self.turned[sl] += np.degrees(np.abs(ang - self.last_angle[sl])) * alive
        self.last_angle[sl] = ang
        moved = np.hypot(*(xy - self.anchor[sl]).transpose(2, 0, 1)) >= cfg.rotation_reset_px
        self.turned[sl] = np.where(moved, 0.0, self.turned[sl])
        self.anchor[sl] = np.where(moved[..., None], xy, self.anchor[sl])
        pen = rotation(self.turned[sl], cfg)
        terms[:, T["rotation"]] = pen
        self.turned[sl] = np.where(pen != 0, 0.0, self.turned[sl])

    @staticmethod
    def _cell(sl: slice, matches: Sequence[Match]) -> np.ndarray:
        return np.array([m.spec.cell for m in matches[sl]])[:, None, None]

    def _bfs_distance(self, e: int, match: Match) -> np.ndarray:
        """BFS cells from each live tank to its nearest live enemy (-1: dead, or none
        reachable); env ``e``'s NavGrid was cached at reset."""
        nav = self._nav[e]
        nodes = nav.nodes_of(match.tank_xy)
        table = nav.dist_table[nodes[:, None], nodes[None, :]].astype(np.int64)
        ok = self.foe & match.alive[None, :] & (table >= 0)
        d = np.where(ok, table, np.iinfo(np.int64).max).min(axis=1)
        return np.where(ok.any(axis=1) & match.alive, d, -1)

    def _euclid(self, xy: np.ndarray, alive: np.ndarray) -> np.ndarray:
        """(E, n) px from each live tank to its nearest live enemy; NaN when dead or no
        enemy lives. ``xy``: (E, n, 2), ``alive``: (E, n)."""
        d = xy[:, :, None, :] - xy[:, None, :, :]
        dist = np.hypot(d[..., 0], d[..., 1])
        ok = self.foe[None] & alive[:, None, :]
        near = np.fmin.reduce(np.where(ok, dist, np.nan), axis=-1)
        near[~alive] = np.nan
        return near

    def _aimed(self, match: Match) -> np.ndarray:
        """Per tank: does a bullet fired now have a predicted path through an enemy?"""
        out = np.zeros(self.n, dtype=bool)
        w = match.world
        for i in np.flatnonzero(match.alive & self.rewarded):
            enemies = match.alive & self.foe[i]
            if enemies.any():
                mx, my = w.muzzle(int(i))
                path = predict_points(w, mx, my, float(match.tank_angle[i]))
                out[i] = path_min_distance(path, match.tank_xy[enemies].tolist()) <= self.radius
        return out

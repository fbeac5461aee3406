"""Agent-specific global state for centralised critics (MAPPO), built for many matches
and learner seats at once from one :class:`~alphatank.game.observe.StateBatch`.

One float32 vector per (env, observer seat), fixed size per scenario, clipped to
[-1, 1], with an index map (:class:`~alphatank.game.observe.ObsLayout`):

``self``          alive, position, heading sin/cos, velocity, wall contact, reload,
                  bullets in flight, in buff / debuff zone
``mate[k]``       every other tank of the observer's team (seat order): alive, position,
                  heading, velocity, relative position (map axes, and ``fwd``/``side``
                  in the observer's frame), distance, reload, bullets in flight
``enemy[k]``      every tank of the other teams (seat order): the same plus ``facing``
                  (cosine between its heading and the line from it to the observer)
``enemy_bullets`` how many enemy bullets fly (share of their capacity) and the nearest
                  one: mask, relative position, velocity, distance, closing speed
``team_bullets``  the closest approach of any bullet of the observer's team to a live
                  enemy: mask, distance
``seat[k]``       one-hot seat id: the observer's index among its team's observers
``time``          elapsed share of ``max_steps``

A dead observer's vector is all zeros but its seat id (MAPPO's death masking input).
Scales follow the observations: positions ``2 x / W - 1``, relative positions
``/ max(W, H)``, distances ``/`` map diagonal, velocities ``/`` tank or bullet speed.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from alphatank.game.observe import ObsLayout, StateBatch

SELF_FIELDS = ("alive", "x", "y", "sin", "cos", "vx", "vy", "wall", "reload", "bullets",
               "in_buff", "in_debuff")
TANK_FIELDS = ("alive", "x", "y", "sin", "cos", "vx", "vy", "rel_x", "rel_y", "fwd", "side",
               "dist", "reload", "bullets")
ENEMY_FIELDS = TANK_FIELDS + ("facing",)
BULLET_FIELDS = ("count", "mask", "rel_x", "rel_y", "vx", "vy", "dist", "closing")


class AgentState:
    """Builds the agent-specific state of ``observers`` (seat indices) in every match of
    ``batch``: ``build()`` returns the internal (E, L, size) float32 buffer (copy what you
    keep). Plugs into a :class:`~alphatank.envs.core.MatchSet` as
    ``AgentState(core.batch, core.teams, core.driven)``, built after each gather."""

    def __init__(self, batch: StateBatch, teams: Sequence[str], observers: Sequence[int]):
        n = len(teams)
        if batch.n != n:
            raise ValueError(f"batch has {batch.n} tanks, teams name {n}")
        bad = [o for o in observers if not 0 <= o < n]
        if bad or not len(observers):
            raise ValueError(f"observer seats {list(observers)} must be non-empty and in "
                             f"0..{n - 1}")
        self._args = (batch, list(teams), list(observers))
        self.batch, self.cfg = batch, batch.cfg
        self.observers = obs = np.asarray(observers, dtype=np.int64)
        team = np.array([sorted(set(teams)).index(t) for t in teams])
        L, cap = len(obs), batch.capacity
        mates = [[j for j in range(n) if j != o and team[j] == team[o]] for o in obs]
        foes = [[j for j in range(n) if team[j] != team[o]] for o in obs]
        M, F = max(map(len, mates)), max(map(len, foes))
        # Seat ids: index of each observer among the observers of its team.
        self.seat_ids = np.array([[q for q in obs if team[q] == team[o]].index(o)
                                  for o in obs], dtype=np.int64)
        self.num_seats = S = int(self.seat_ids.max()) + 1

        def padded(rows: list[list[int]], width: int) -> tuple[np.ndarray, np.ndarray]:
            idx = np.full((L, width), n, dtype=np.int64)  # n: the all-zero padding tank
            for i, r in enumerate(rows):
                idx[i, :len(r)] = r
            return idx, idx < n

        self.mate_idx, self.mate_ok = padded(mates, M)
        self.foe_idx, self.foe_ok = padded(foes, F)
        # Enemy bullet slots per observer (padding points at slot 0, masked off).
        fb = self.foe_idx[:, :, None] * cap + np.arange(cap)
        self.foe_bullets = np.where(self.foe_ok[:, :, None], fb, 0).reshape(L, F * cap)
        self.foe_bullet_ok = np.repeat(self.foe_ok, cap, axis=1)
        self._eb_share = 1.0 / np.maximum(self.foe_bullet_ok.sum(axis=1), 1)  # (L,)
        team_b = [[j * cap + k for j in [o] + m for k in range(cap)] for o, m in zip(obs, mates,
                                                                                     strict=True)]
        tb_w = (M + 1) * cap
        self.team_bullets = np.zeros((L, tb_w), dtype=np.int64)
        self.team_bullet_ok = np.zeros((L, tb_w), dtype=bool)
        for i, r in enumerate(team_b):
            self.team_bullets[i, :len(r)] = r
            self.team_bullet_ok[i, :len(r)] = True

        lay = ObsLayout("agent_state")
        lay.add("self", None, SELF_FIELDS)
        lay.add("mate", M, TANK_FIELDS)
        lay.add("enemy", F, ENEMY_FIELDS)
        lay.add("enemy_bullets", None, BULLET_FIELDS)
        lay.add("team_bullets", None, ("mask", "dist"))
        lay.add("seat", S, ("id",))
        lay.add("time", None, ("t",))
        self.layout = lay
        E = batch.num_envs
        self.out = np.zeros((E, L, lay.size), dtype=np.float32)
        self.v_self = self.out[:, :, lay["self"]]
        self.v_mate = self.out[:, :, lay["mate"]].reshape(E, L, M, len(TANK_FIELDS))
        self.v_enemy = self.out[:, :, lay["enemy"]].reshape(E, L, F, len(ENEMY_FIELDS))
        self.v_eb = self.out[:, :, lay["enemy_bullets"]]
        self.v_tb = self.out[:, :, lay["team_bullets"]]
        self.v_seat = self.out[:, :, lay["seat"]]
        self.onehot = np.eye(S, dtype=np.float32)[self.seat_ids]  # (L, S)
        # Per-tank table (alive, x, y, sin, cos, vx, vy, reload, bullets) + a zero row.
        self._tab = np.zeros((E, n + 1, 9))
        self._xy = np.zeros((E, n + 1, 2))  # px, padding row at 0
        self._count_scale = np.array([1.0 / self.cfg.cooldown_ticks, 1.0 / cap])
        self._ge = np.arange(E)[:, None]
        self._gl = np.arange(L)[None, :]

    def __reduce__(self) -> tuple:
        return (type(self), self._args)

    @property
    def size(self) -> int:
        return self.layout.size

    def build(self) -> np.ndarray:
        """States of all envs and observers from the batch's current contents."""
        b, g, obs = self.batch, self.cfg, self.observers
        n = b.n
        tab, xy = self._tab, self._xy
        tab[:, :n, 0] = b.alive
        np.multiply(b.tank_xy, b.inv, out=tab[:, :n, 1:3])
        tab[:, :n, 1:3] -= 1.0
        np.sin(b.tank_angle, out=tab[:, :n, 3])
        np.cos(b.tank_angle, out=tab[:, :n, 4])
        np.multiply(b.tank_vel, 1.0 / g.tank_speed, out=tab[:, :n, 5:7])
        np.multiply(b.counts.transpose(0, 2, 1), self._count_scale, out=tab[:, :n, 7:9])
        xy[:, :n] = b.tank_xy
        me = tab[:, obs]  # (E, L, 9)
        vs = self.v_self
        vs[..., 0:7] = me[..., 0:7]
        vs[..., 7] = b.wall[:, obs]
        vs[..., 8:10] = me[..., 7:9]
        vs[..., 10] = b.in_buff[:, obs]
        vs[..., 11] = b.in_debuff[:, obs]
        self_xy = xy[:, obs][:, :, None, :]  # (E, L, 1, 2)
        s, c = me[..., 3][..., None], me[..., 4][..., None]
        self._tanks(self.v_mate, self.mate_idx, self.mate_ok, self_xy, s, c)
        rel = self._tanks(self.v_enemy, self.foe_idx, self.foe_ok, self_xy, s, c)
        ft = tab[:, self.foe_idx]  # (E, L, F, 9)
        dist = np.hypot(rel[..., 0], rel[..., 1])
        face = -(ft[..., 4] * rel[..., 0] + ft[..., 3] * rel[..., 1])
        self.v_enemy[..., 14] = np.divide(face, dist, out=np.zeros_like(face),
                                          where=dist > 0) * ft[..., 0]
        self._enemy_bullets(self_xy)
        self._team_bullets()
        self.out[..., -1] = (b.tick / g.max_steps)[:, None]
        self.out *= b.alive[:, obs][..., None]  # dead: zeros ...
        self.v_seat[...] = self.onehot  # ... and the seat id
        np.clip(self.out, -1.0, 1.0, out=self.out)
        return self.out

    def _tanks(self, view: np.ndarray, idx: np.ndarray, ok: np.ndarray, self_xy: np.ndarray,
               s: np.ndarray, c: np.ndarray) -> np.ndarray:
        """Fill the shared fields of a tank block; returns the px offsets (E, L, K, 2)."""
        b = self.batch
        t = self._tab[:, idx]  # (E, L, K, 9); padding rows are zero
        view[..., 0:7] = t[..., 0:7]
        rel = (self._xy[:, idx] - self_xy) * ok[..., None]
        k = b.scale[..., None]
        np.multiply(rel, k, out=view[..., 7:9])
        view[..., 9] = (rel[..., 0] * c + rel[..., 1] * s) * k[..., 0]
        view[..., 10] = (rel[..., 1] * c - rel[..., 0] * s) * k[..., 0]
        view[..., 11] = np.hypot(rel[..., 0], rel[..., 1]) * b.idiag
        view[..., 12:14] = t[..., 7:9]
        return rel

    def _enemy_bullets(self, self_xy: np.ndarray) -> None:
        b, v = self.batch, self.v_eb
        act = b.bullet_active[:, self.foe_bullets] & self.foe_bullet_ok
        np.multiply(act.sum(axis=-1), self._eb_share, out=v[..., 0])
        if not act.any():
            v[..., 1:] = 0.0
            return
        rel = b.bullet_xy[:, self.foe_bullets] - self_xy  # (E, L, K, 2)
        dist = np.hypot(rel[..., 0], rel[..., 1])
        near = np.where(act, dist, np.inf).argmin(axis=-1)  # (E, L)
        ge, gl = self._ge, self._gl
        has = act[ge, gl, near]
        r, d = rel[ge, gl, near], dist[ge, gl, near]  # (E, L, 2), (E, L)
        vel = b.bullet_vel[ge, self.foe_bullets[gl, near]] * (1.0 / self.cfg.bullet_speed)
        k = b.scale[..., 0] * has
        v[..., 1] = has
        v[..., 2:4] = r * k[..., None]
        v[..., 4:6] = vel * has[..., None]
        v[..., 6] = d * b.idiag[..., 0] * has
        closing = -(vel[..., 0] * r[..., 0] + vel[..., 1] * r[..., 1])
        v[..., 7] = np.divide(closing, d, out=np.zeros_like(closing), where=d > 0) * has

    def _team_bullets(self) -> None:
        b, v = self.batch, self.v_tb
        act = b.bullet_active[:, self.team_bullets] & self.team_bullet_ok  # (E, L, Tb)
        foe = self.foe_ok[None] & b.alive[:, self.foe_idx.clip(max=b.n - 1)]  # (E, L, F)
        if not act.any() or not foe.any():
            v[...] = 0.0
            return
        d = (b.bullet_xy[:, self.team_bullets][:, :, :, None, :]
             - self._xy[:, self.foe_idx][:, :, None, :, :])
        dist = np.hypot(d[..., 0], d[..., 1])  # (E, L, Tb, F)
        ok = act[..., None] & foe[:, :, None, :]
        best = np.where(ok, dist, np.inf).min(axis=(-1, -2))
        has = np.isfinite(best)
        v[..., 0] = has
        v[..., 1] = np.where(has, best, 0.0) * b.idiag[..., 0]

"""Compiled loops of the observation and reward hot paths (numba).

A step's numpy calls each cost about a microsecond of dispatch on arrays of a few
elements, whatever their size; a loop compiled once does the same arithmetic in a
fraction of one. Every kernel performs the same IEEE operations, in the same order, as
the numpy expressions it replaces, so the values are the same bits (pinned by
``tests/test_kernels.py`` against those expressions and by the seeded-episode pins of
``tests/test_rewards.py`` and ``tests/test_observe.py``). Compiled code is cached next to
this module (``cache=True``), so a process compiles only what an earlier one has not.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def _insert(key: np.ndarray, order: np.ndarray, q: int) -> None:
    """One step of an insertion sort: ``order[:q]`` holds indices sorted by ``key``;
    put ``q`` among them after its equals (stable, as ``argsort(kind="stable")``)."""
    p = q
    while p > 0 and key[order[p - 1]] > key[q]:
        order[p] = order[p - 1]
        p -= 1
    order[p] = q


@njit(cache=True)
def progress_counts(bullet_xy: np.ndarray, tank_xy: np.ndarray, alive: np.ndarray,
                    active: np.ndarray, enemy: np.ndarray, prev: np.ndarray, cap: int,
                    weights: np.ndarray, out: np.ndarray) -> None:
    """The bullet_close / bullet_away terms of a tick, and the distances they compare.

    ``bullet_xy`` (E, S*cap, 2): the scored bullet slots, ``cap`` per seat, seat by
    seat; ``tank_xy`` (E, n, 2); ``alive`` (E, n); ``active`` (E, S*cap); ``enemy``
    (S*cap, n): tank j is an enemy of the slot's owner; ``prev`` (E, S*cap): each slot's
    distance to its nearest live enemy on the previous tick (NaN: none), replaced by this
    tick's; ``weights`` (2,): bullet_close, bullet_away. Into ``out`` (E, 2, S): per seat,
    its slots that came closer and went farther, times the weights. With no slot active
    anywhere, ``prev`` becomes NaN and ``out`` is left as it is."""
    E, nr = active.shape
    n = tank_xy.shape[1]
    if not active.any():
        prev[:, :] = np.nan
        return
    for e in range(E):
        for k in range(nr // cap):
            close = 0
            away = 0
            for s in range(k * cap, (k + 1) * cap):
                now = np.nan
                if active[e, s]:
                    bx, by = bullet_xy[e, s, 0], bullet_xy[e, s, 1]
                    for j in range(n):
                        if enemy[s, j] and alive[e, j]:
                            d = np.hypot(bx - tank_xy[e, j, 0], by - tank_xy[e, j, 1])
                            if now != now or d < now:  # np.fmin: NaN only when all are
                                now = d
                p = prev[e, s]
                if now < p:
                    close += 1
                elif now > p:
                    away += 1
                prev[e, s] = now
            out[e, 0, k] = close * weights[0]
            out[e, 1, k] = away * weights[1]


@njit(cache=True)
def paper_observation(raw: np.ndarray, n: int, inv: np.ndarray, scale: np.ndarray,
                      idiag: np.ndarray, v_scale: np.ndarray, corner_vu: np.ndarray,
                      flags: np.ndarray, counts: np.ndarray, count_scale: np.ndarray,
                      active: np.ndarray, src: np.ndarray, take: np.ndarray, put: np.ndarray,
                      observers: np.ndarray, other_idx: np.ndarray, other_bidx: np.ndarray,
                      other_bteam: np.ndarray, tank_cols: np.ndarray, bullet_cols: np.ndarray,
                      out: np.ndarray) -> None:
    """The ``paper`` observation of every env and observer into ``out`` (E, L, D),
    clipped to [-1, 1], zeros all +0.0 (``ObservationBuilder._paper_plan`` lays out the
    arguments).

    ``raw`` (E, rows, 6): the batch's world state (tanks, then bullets); ``src`` (E, S):
    one source row per env (positions and velocities of tanks then bullets, 4 each; per
    tank sin, cos and 4 corners; the flags; reload and bullets; bullet active), copied to
    ``out`` through the flat indices ``take`` -> ``put``. ``tank_cols``: block start,
    slot width, rel_x, dist; ``bullet_cols``: block start, slot width, mask, team (-1:
    none), x, rel_x, dist. Other bullets are sorted nearest first (stable, inactive
    last); the whole block is zero while no other bullet flies anywhere in the batch."""
    E = raw.shape[0]
    nb = active.shape[1]
    T = 4 * (n + nb)
    F = T + 10 * n
    C = F + 4 * n
    A = C + 2 * n
    for e in range(E):
        s = src[e]
        ix, iy = inv[e, 0, 0], inv[e, 0, 1]
        for r in range(n + nb):
            vs = v_scale[r, 0]
            x = raw[e, r, 0] * ix - 1.0
            y = raw[e, r, 1] * iy - 1.0
            vx = raw[e, r, 3] * vs
            vy = raw[e, r, 4] * vs
            if r >= n:  # bullet_table(): inactive slots zeroed (times 0, as numpy)
                a = 1.0 if active[e, r - n] else 0.0
                x, y, vx, vy = x * a, y * a, vx * a, vy * a
            s[4 * r] = x
            s[4 * r + 1] = y
            s[4 * r + 2] = vx
            s[4 * r + 3] = vy
        for j in range(n):
            sn, cs = np.sin(raw[e, j, 2]), np.cos(raw[e, j, 2])
            t = T + 10 * j
            s[t] = sn
            s[t + 1] = cs
            for c in range(4):
                for a in range(2):
                    s[t + 2 + 2 * c + a] = ((sn * corner_vu[e, 0, 0, c, a]
                                             + cs * corner_vu[e, 0, 1, c, a]) + s[4 * j + a])
            for k in range(4):
                s[F + k * n + j] = 1.0 if flags[e, k, j] else 0.0
            s[C + 2 * j] = counts[e, 0, j] * count_scale[0]
            s[C + 2 * j + 1] = counts[e, 1, j] * count_scale[1]
        for b in range(nb):
            s[A + b] = 1.0 if active[e, b] else 0.0
    flat_src = src.reshape(-1)
    flat_out = out.reshape(-1)
    for i in range(take.size):
        flat_out[put[i]] = flat_src[take[i]]
    L, n_oth = other_idx.shape
    K = other_bidx.shape[1]
    t0, tw, trel, tdist = tank_cols[0], tank_cols[1], tank_cols[2], tank_cols[3]
    b0, bw, bmask, bteam = bullet_cols[0], bullet_cols[1], bullet_cols[2], bullet_cols[3]
    bx, brel, bdist = bullet_cols[4], bullet_cols[5], bullet_cols[6]
    flying = False
    for e in range(E):
        for i in range(L):
            for q in range(K):
                if active[e, other_bidx[i, q]]:
                    flying = True
    rel = np.empty((K, 2))
    dist = np.empty(K)
    key = np.empty(K)
    order = np.empty(K, dtype=np.int64)
    for e in range(E):
        sc, dg = scale[e, 0, 0], idiag[e, 0, 0]
        ratio = dg / sc
        for i in range(L):
            o = observers[i]
            sx, sy = raw[e, o, 0], raw[e, o, 1]
            row = out[e, i]
            for k in range(n_oth):
                j = other_idx[i, k]
                rx, ry = raw[e, j, 0] - sx, raw[e, j, 1] - sy
                c = t0 + k * tw
                row[c + trel] = rx * sc
                row[c + trel + 1] = ry * sc
                row[c + tdist] = np.hypot(rx, ry) * dg
            if not flying:
                for c in range(b0, b0 + K * bw):
                    row[c] = 0.0
                continue
            for q in range(K):
                slot = other_bidx[i, q]
                rx, ry = raw[e, n + slot, 0] - sx, raw[e, n + slot, 1] - sy
                rel[q, 0], rel[q, 1] = rx, ry
                dist[q] = np.hypot(rx, ry)
                key[q] = dist[q] if active[e, slot] else np.inf
                _insert(key, order, q)
            for p in range(K):
                q = order[p]
                slot = other_bidx[i, q]
                m = 1.0 if active[e, slot] else 0.0
                c = b0 + p * bw
                row[c + bmask] = m
                if bteam >= 0:
                    row[c + bteam] = other_bteam[i, q] * m
                for f in range(4):
                    row[c + bx + f] = src[e, 4 * (n + slot) + f]
                k = m * sc
                row[c + brel] = rel[q, 0] * k
                row[c + brel + 1] = rel[q, 1] * k
                row[c + bdist] = dist[q] * (k * ratio)
    for i in range(flat_out.size):  # clipped; + 0.0 turns -0.0 (0 times a stale value) to 0.0
        v = flat_out[i]
        if v > 1.0:
            flat_out[i] = 1.0
        elif v < -1.0:
            flat_out[i] = -1.0
        else:
            flat_out[i] = v + 0.0


@njit(cache=True)
def wall_rays(xy: np.ndarray, dx: np.ndarray, dy: np.ndarray, rects: np.ndarray,
              length: float, out: np.ndarray) -> None:
    """:meth:`~alphatank.game.observe.ObservationBuilder.ray_distances`' slab test.

    ``xy`` (E, L, 2): the observers; ``dx``, ``dy`` (E, L, R): the rays' unit directions
    (numpy's cos and sin); ``rects`` (E, W, 4): x0, y0, x1, y1 of every wall. Into ``out``
    (E, L, R): px to the nearest rectangle along each ray, capped at ``length``. An
    axis-parallel ray's zero direction is nudged to 1e-12 (no division by zero); every
    min and max keeps numpy's ``minimum`` / ``maximum`` order, and the distances never
    come out as -0."""
    E, L, R = dx.shape
    W = rects.shape[1]
    for e in range(E):
        for i in range(L):
            ox, oy = xy[e, i, 0], xy[e, i, 1]
            for r in range(R):
                ux, uy = dx[e, i, r], dy[e, i, r]
                ix = 1.0 / (1e-12 if abs(ux) < 1e-12 else ux)
                iy = 1.0 / (1e-12 if abs(uy) < 1e-12 else uy)
                d = np.inf
                for w in range(W):
                    tx0 = (rects[e, w, 0] - ox) * ix
                    tx1 = (rects[e, w, 2] - ox) * ix
                    ty0 = (rects[e, w, 1] - oy) * iy
                    ty1 = (rects[e, w, 3] - oy) * iy
                    t_in = max(min(tx0, tx1), min(ty0, ty1))
                    t_out = min(max(tx0, tx1), max(ty0, ty1))
                    near = t_in if t_in > 0.0 else 0.0
                    if t_out < near:  # the ray misses this rectangle
                        near = np.inf
                    if near <= d:
                        d = near
                out[e, i, r] = d if d < length else length


@njit(cache=True)
def nearest_threat(rel: np.ndarray, vel: np.ndarray, mask: np.ndarray, cos: np.ndarray,
                   sin: np.ndarray, alive: np.ndarray, scale: float, horizon: float,
                   out: np.ndarray) -> None:
    """The ``threat`` block of :meth:`~alphatank.game.observe.ObservationBuilder.
    _build_threat` with numpy's operations in numpy's order.

    ``rel``, ``vel`` (E, L, K, 2): other tanks' bullets relative to each observer and their
    velocities; ``mask`` (E, L, K): slot in play; ``cos``, ``sin`` (E, L): the observers'
    headings; ``alive`` (E, L). Of the bullets closing in within ``horizon`` s, the one
    that will pass closest (the first on ties): into ``out`` (E, L, 4) ``near`` (1 -
    miss / ``scale``, at least 0), ``eta`` (1 - t / ``horizon``) and the closest point's
    unit direction in the own frame; zeros without one, and times 0 while dead."""
    E, L, K = mask.shape
    for e in range(E):
        for i in range(L):
            best, hit = np.inf, False
            t_k = mx_k = my_k = 0.0
            for q in range(K):
                rx, ry = rel[e, i, q, 0], rel[e, i, q, 1]
                vx, vy = vel[e, i, q, 0], vel[e, i, q, 1]
                v2 = vx * vx + vy * vy
                if not v2 > 1e-9:
                    v2 = 1e-9
                t = -(rx * vx + ry * vy) / v2
                mx, my = rx + vx * t, ry + vy * t
                miss = np.hypot(mx, my)
                ok = mask[e, i, q] > 0 and t > 0 and t < horizon
                key = miss if ok else np.inf
                if q == 0 or key < best:
                    best, hit, t_k, mx_k, my_k = key, ok, t, mx, my
            a = 1.0 if alive[e, i] else 0.0
            near = 1.0 - best / scale
            out[e, i, 0] = ((near if near > 0.0 else 0.0) if hit else 0.0) * a
            out[e, i, 1] = ((1.0 - t_k / horizon) if hit else 0.0) * a
            inv = 1.0 / (best if best > 1e-6 else 1e-6) if hit else 0.0
            c, s = cos[e, i], sin[e, i]
            out[e, i, 2] = ((mx_k * c + my_k * s) * inv) * a
            out[e, i, 3] = ((my_k * c - mx_k * s) * inv) * a


@njit(cache=True)
def path_features(envs: np.ndarray, nodes: np.ndarray, xy: np.ndarray, alive: np.ndarray,
                  observers: np.ndarray, others: np.ndarray, next_table: np.ndarray,
                  dist_table: np.ndarray, centers: np.ndarray, cos: np.ndarray,
                  sin: np.ndarray, inv_diameter: float, cols: np.ndarray,
                  out: np.ndarray) -> None:
    """The ``tank.path_*`` features of :meth:`~alphatank.game.observe.ObservationBuilder.
    _build_paths` for the envs ``envs`` of one map, with numpy's operations in numpy's
    order.

    ``nodes`` (G, n): every tank's floor node in those envs; ``xy`` (E, n, 2), ``alive``
    (E, n); ``observers`` (L,), ``others`` (L, O): seats; the map's ``next_table``,
    ``dist_table`` and node ``centers``; ``cos``, ``sin`` (E, L): the observers'
    headings; ``cols``: the fwd, side and dist columns of ``out`` (E, L, O, F). Per
    observer and other tank: the unit direction, own frame, to the next waypoint on a
    shortest path (two cells ahead, or the tank itself once it is the next cell), and
    the path's length over ``1 / inv_diameter`` (1 unreachable); times 0 while the other
    tank is dead."""
    L, n_oth = others.shape
    for g in range(envs.shape[0]):
        e = envs[g]
        for i in range(L):
            src = nodes[g, observers[i]]
            sx, sy = xy[e, observers[i], 0], xy[e, observers[i], 1]
            c, s = cos[e, i], sin[e, i]
            for k in range(n_oth):
                j = others[i, k]
                dst = nodes[g, j]
                n1 = next_table[src, dst]
                if n1 < 0:
                    n1 = src
                n2 = next_table[n1, dst]
                if n2 < 0:
                    n2 = n1
                if n1 == dst:
                    dx, dy = xy[e, j, 0] - sx, xy[e, j, 1] - sy
                else:
                    dx, dy = centers[n2, 0] - sx, centers[n2, 1] - sy
                a = 1.0 if alive[e, j] else 0.0
                m = np.hypot(dx, dy)
                w = a / (m if m > 1e-9 else 1e-9)
                out[e, i, k, cols[0]] = (dx * c + dy * s) * w
                out[e, i, k, cols[1]] = (dy * c - dx * s) * w
                steps = dist_table[src, dst]
                out[e, i, k, cols[2]] = (steps * inv_diameter if steps >= 0 else 1.0) * a


@njit(cache=True)
def nearest_bullets(bullet_xy: np.ndarray, bullet_vel: np.ndarray, active: np.ndarray,
                    bidx: np.ndarray, bteam: np.ndarray, xy: np.ndarray, first: int,
                    relv: np.ndarray, velv: np.ndarray, rmask: np.ndarray, vmask: np.ndarray,
                    block: np.ndarray, mask_col: int, team_col: int) -> None:
    """The other tanks' bullets of the egocentric kinds, nearest first (a stable sort,
    inactive slots last in slot order), as :meth:`~alphatank.game.observe.
    ObservationBuilder._other_bullets` laid them out with numpy.

    ``bullet_xy``, ``bullet_vel`` (E, nb, 2) and ``active`` (E, nb): every slot;
    ``bidx`` (L, K): each observer's other bullet slots; ``bteam`` (L, K): 1 for a
    teammate's; ``xy`` (E, L, 2): the observers. From column ``first`` of ``relv`` /
    ``velv`` (E, L, ., 2) and ``rmask`` / ``vmask`` (E, L, .): each bullet's position
    relative to the observer, its velocity and its active flag; into ``block`` (E, L, K,
    F): the mask column and, when ``team_col`` >= 0, the team flag times the mask."""
    E = relv.shape[0]
    L, K = bidx.shape
    rx, ry = np.empty(K), np.empty(K)
    key = np.empty(K)
    order = np.empty(K, dtype=np.int64)
    for e in range(E):
        for i in range(L):
            sx, sy = xy[e, i, 0], xy[e, i, 1]
            for q in range(K):
                b = bidx[i, q]
                rx[q] = bullet_xy[e, b, 0] - sx
                ry[q] = bullet_xy[e, b, 1] - sy
                key[q] = np.hypot(rx[q], ry[q]) if active[e, b] else np.inf
                _insert(key, order, q)
            for p in range(K):
                q = order[p]
                b = bidx[i, q]
                m = 1.0 if active[e, b] else 0.0
                relv[e, i, first + p, 0] = rx[q]
                relv[e, i, first + p, 1] = ry[q]
                velv[e, i, first + p, 0] = bullet_vel[e, b, 0]
                velv[e, i, first + p, 1] = bullet_vel[e, b, 1]
                rmask[e, i, first + p] = m
                vmask[e, i, first + p] = m
                block[e, i, p, mask_col] = m
                if team_col >= 0:
                    block[e, i, p, team_col] = bteam[i, q] * m


@njit(cache=True)
def shot_reach(dist: np.ndarray, t: np.ndarray, leg: np.ndarray, alive: np.ndarray,
               seats: np.ndarray, length: np.ndarray, team: np.ndarray, radius: float,
               max_distance: float, first: np.ndarray, passing: np.ndarray,
               shots: np.ndarray) -> None:
    """What :meth:`~alphatank.game.observe.StateBatch.reach_shots` makes of the traced
    shots, with numpy's operations in numpy's order.

    ``dist`` (E, S, P-1, n) and ``t`` (E, S, P-1, n): each shot leg's closest approach to
    every tank and where along the leg; ``leg`` (E, S, P-1): each leg's length; ``alive``
    (E, n); ``seats`` (S,): the shooters; ``length`` (E, S): points of each path (0: no
    shot); ``team`` (E, n). Into ``first`` (E, n): the live tank other than the shooter
    that the shot reaches first (-1: none), ``passing`` (E, n, n): its closest approach
    to each of them (inf for the others), and ``shots`` (E, n, 3): enemy reached first,
    friend reached first, closest enemy approach over ``max_distance`` (at most 1). ``dist``
    is overwritten with inf where a tank is no target."""
    E, S, P1, n = dist.shape
    r2 = radius * radius
    for e in range(E):
        for i in range(S):
            s = seats[i]
            for k in range(P1):
                for j in range(n):
                    if not alive[e, j] or j == s:
                        dist[e, i, k, j] = np.inf
            seg, hit = 0, False
            for k in range(P1):
                for j in range(n):
                    if dist[e, i, k, j] <= radius:
                        seg, hit = k, True
                        break
                if hit:
                    break
            best, near = np.inf, 0
            for j in range(n):
                d = dist[e, i, seg, j]
                m = d if d < radius else radius
                c = r2 - m * m  # numpy squares with ** 2
                chord = np.sqrt(c if c > 0.0 else 0.0)
                entry = t[e, i, seg, j] * leg[e, i, seg] - chord if d <= radius else np.inf
                if j == 0 or entry < best:
                    best, near = entry, j
            shot = length[e, i] > 0
            first[e, s] = near if hit and shot else -1
            mate = team[e, near] == team[e, s]
            closest = np.inf
            for j in range(n):
                p = dist[e, i, 0, j]
                for k in range(1, P1):
                    if dist[e, i, k, j] < p:
                        p = dist[e, i, k, j]
                passing[e, s, j] = p
                if alive[e, j] and j != s and team[e, j] != team[e, s] and p < closest:
                    closest = p
            miss = closest / max_distance
            shots[e, s, 0] = 1.0 if shot and hit and not mate else 0.0
            shots[e, s, 1] = 1.0 if shot and hit and mate else 0.0
            shots[e, s, 2] = (miss if miss < 1.0 else 1.0) if shot else 0.0

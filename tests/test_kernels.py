"""The compiled kernels give the bits of the numpy expressions they replaced."""

import math

import numpy as np
import pytest

from alphatank.bots.kernels import evade_choice, threat_slots
from alphatank.game.kernels import (
    nearest_bullets,
    nearest_threat,
    path_features,
    progress_counts,
    shot_reach,
    wall_rays,
)
from alphatank.game.observe import ObservationBuilder, StateBatch, slot_counts
from alphatank.sim.ballistics import segment_distances
from alphatank.sim.config import game_config
from alphatank.sim.mapspec import load_map
from alphatank.sim.match import Match
from alphatank.sim.navigation import nav_grid


def numpy_progress(bullet_xy, tank_xy, alive, active, enemy, prev, cap, weights):
    """The bullet_close / bullet_away terms as numpy computed them before the kernel."""
    d = bullet_xy[:, :, None, :] - tank_xy[:, None]
    dist = np.hypot(d[..., 0], d[..., 1])
    ok = enemy & alive[:, None, :] & active[..., None]
    now = np.fmin.reduce(dist, axis=-1, where=ok, initial=math.nan)
    cmp = np.stack([now < prev, now > prev])  # (2, E, nr)
    counts = np.add.reduce(cmp.reshape(2, len(now), -1, cap), axis=-1)  # (2, E, S)
    return counts.transpose(1, 0, 2) * weights[:, None], now


@pytest.mark.parametrize("seed", range(5))
def test_progress_counts_equal_the_numpy_terms_bit_for_bit(seed):
    rng = np.random.default_rng(seed)
    E, n, S, cap = 4, 4, 2, 3
    nr = S * cap
    bullet_xy = rng.uniform(0, 600, (E, nr, 2))
    tank_xy = rng.uniform(0, 600, (E, n, 2))
    tank_xy[0, 1] = tank_xy[0, 2]  # two enemies at one spot: a tie for the nearest
    alive = rng.random((E, n)) < 0.7
    active = rng.random((E, nr)) < 0.6
    owner = np.repeat([0, 1], cap)
    team = np.array([0, 1, 1, 0])
    enemy = team[owner][:, None] != team[None, :]
    prev = rng.uniform(0, 800, (E, nr))
    prev[rng.random((E, nr)) < 0.3] = np.nan  # fresh slots
    prev[1] = np.hypot(*(bullet_xy[1, :, None, :] - tank_xy[1, None]).transpose(2, 0, 1)
                       ).min(axis=1)  # no move: neither closer nor farther
    weights = np.array([0.5, -0.25])
    want, want_now = numpy_progress(bullet_xy, tank_xy, alive, active, enemy, prev, cap,
                                    weights)
    out = np.full((E, 2, S), 7.0)
    got_prev = prev.copy()
    progress_counts(bullet_xy, tank_xy, alive, active, enemy, got_prev, cap, weights, out)
    assert out.tobytes() == want.tobytes()  # -0.0 included
    assert got_prev.tobytes() == want_now.tobytes()
    assert np.count_nonzero(want), "the case scores something"


def test_progress_counts_leave_the_terms_alone_while_no_bullet_flies():
    E, n, S, cap = 2, 2, 1, 3
    prev = np.ones((E, S * cap))
    out = np.full((E, 2, S), 3.0)
    progress_counts(np.zeros((E, S * cap, 2)), np.zeros((E, n, 2)), np.ones((E, n), bool),
                    np.zeros((E, S * cap), bool), np.ones((S * cap, n), bool), prev, cap,
                    np.array([1.0, -1.0]), out)
    assert np.isnan(prev).all()
    assert (out == 3.0).all()


def numpy_rays(xy, dx, dy, rects, length):
    """ObservationBuilder.ray_distances' slab test as numpy computed it before the kernel."""
    ix = (1.0 / np.where(np.abs(dx) < 1e-12, 1e-12, dx))[..., None]
    iy = (1.0 / np.where(np.abs(dy) < 1e-12, 1e-12, dy))[..., None]
    rr = rects[:, None, None, :, :]
    ox, oy = xy[..., 0][..., None, None], xy[..., 1][..., None, None]
    tx0, tx1 = (rr[..., 0] - ox) * ix, (rr[..., 2] - ox) * ix
    ty0, ty1 = (rr[..., 1] - oy) * iy, (rr[..., 3] - oy) * iy
    near = np.maximum(np.maximum(np.minimum(tx0, tx1), np.minimum(ty0, ty1)), 0.0)
    far = np.minimum(np.maximum(tx0, tx1), np.maximum(ty0, ty1))
    near = np.where(far < near, np.inf, near)
    return np.minimum(near.min(axis=-1), length)


@pytest.mark.parametrize("seed", range(4))
def test_wall_rays_equal_the_numpy_slab_test_bit_for_bit(seed):
    rng = np.random.default_rng(seed)
    E, L, R, W = 3, 2, 8, 9
    lo = rng.uniform(0, 500, (E, W, 2))
    rects = np.concatenate([lo, lo + rng.uniform(5, 120, (E, W, 2))], axis=-1)
    xy = rng.uniform(0, 600, (E, L, 2))
    xy[0, 0] = rects[0, 0, :2]  # on a corner: zero distances, -0.0 in the slab terms
    xy[0, 1, 0] = rects[0, 1, 2]  # on a right edge
    xy[1, 0] = (rects[1, 2, :2] + rects[1, 2, 2:]) / 2  # inside a wall
    rects[2, -1] = rects[2, -2]  # a duplicate wall: a tie for the nearest
    a = rng.uniform(-math.pi, math.pi, (E, L, 1)) + np.arange(R) * (2 * math.pi / R)
    dx, dy = np.cos(a), np.sin(a)
    dx[1, 1, :4], dy[1, 1, 4:] = 0.0, -0.0  # axis-parallel rays: nudged directions
    dx[2, 0, 0], dy[2, 0, 0] = 1.0, 1e-13
    # Nudged rays grazing a wall's edge 1e-10 px off (away from the random walls): the
    # nudge decides where they enter.
    rects[2, 0] = (1050.0, 1000.0, 1150.0, 1040.0)
    rects[2, 1] = (1000.0 + 1e-10, 1100.0, 1040.0, 1150.0)
    xy[2, 1] = (1000.0, 1000.0 - 1e-10)
    dx[2, 1, 0], dy[2, 1, 0] = 1.0, 1e-13
    dx[2, 1, 2], dy[2, 1, 2] = 1e-13, 1.0
    length = 300.0
    want = numpy_rays(xy, dx, dy, rects, length)
    got = np.full((E, L, R), 7.0)
    wall_rays(xy, dx, dy, rects, length, got)
    assert got.tobytes() == want.tobytes()
    assert (got == 0.0).any() and (got == length).any() and ((got > 0) & (got < length)).any()


def numpy_threat(rel, vel, mask, c, s, alive, scale, horizon):
    """ObservationBuilder._build_threat as numpy computed it before the kernel."""
    v2 = np.maximum((vel * vel).sum(axis=-1), 1e-9)
    t = -(rel * vel).sum(axis=-1) / v2
    m = rel + vel * t[..., None]
    miss = np.hypot(m[..., 0], m[..., 1])
    ok = (mask > 0) & (t > 0) & (t < horizon)
    k = np.where(ok, miss, np.inf).argmin(axis=-1)[..., None]
    hit = np.take_along_axis(ok, k, axis=-1)[..., 0]
    miss = np.take_along_axis(miss, k, axis=-1)[..., 0]
    vt = np.zeros(mask.shape[:2] + (4,))
    vt[..., 0] = np.where(hit, np.maximum(1.0 - miss / scale, 0.0), 0.0)
    vt[..., 1] = np.where(hit, 1.0 - np.take_along_axis(t, k, axis=-1)[..., 0] / horizon, 0.0)
    mx = np.take_along_axis(m[..., 0], k, axis=-1)[..., 0]
    my = np.take_along_axis(m[..., 1], k, axis=-1)[..., 0]
    inv = np.where(hit, 1.0 / np.maximum(miss, 1e-6), 0.0)
    vt[..., 2] = (mx * c + my * s) * inv
    vt[..., 3] = (my * c - mx * s) * inv
    vt *= alive[..., None]
    return vt


@pytest.mark.parametrize("seed", range(4))
def test_nearest_threat_equals_the_numpy_block_bit_for_bit(seed):
    rng = np.random.default_rng(seed)
    E, L, K = 6, 2, 5
    rel = rng.uniform(-200, 200, (E, L, K, 2))
    vel = rng.uniform(-300, 300, (E, L, K, 2))
    vel[0, 0, 1] = 0.0  # a parked bullet (v2 floored)
    rel[1, 0, 2], vel[1, 0, 2] = (-30.0, 0.0), (300.0, 0.0)  # dead on: miss 0
    rel[1, 0, 3], vel[1, 0, 3] = (-60.0, 0.0), (300.0, 0.0)  # the same line, later
    rel[2, 1, 1], vel[2, 1, 1] = rel[2, 1, 4], vel[2, 1, 4]  # a tie: the first one wins
    mask = rng.random((E, L, K)) < 0.8
    mask[1, 0, 2:4] = True
    mask[2, 1, [1, 4]] = True
    mask[3, 0] = False  # nothing in play
    rel[4, 0, 0], vel[4, 0, 0] = (-1e-6, 0.0), (1e-5, 0.0)  # crawling: v2 floored to 1e-9
    mask[4, 0] = [True, False, False, False, False]
    ang = rng.uniform(-math.pi, math.pi, (E, L))
    alive = rng.random((E, L)) < 0.8
    alive[1, 0] = alive[2, 1] = alive[4, 0] = True
    scale, horizon = 40.0, 1.0
    want = numpy_threat(rel, vel, mask, np.cos(ang), np.sin(ang), alive, scale, horizon)
    got = np.full((E, L, 4), 7.0)
    nearest_threat(rel, vel, mask, np.cos(ang), np.sin(ang), alive, scale, horizon, got)
    assert got.tobytes() == want.tobytes()  # -0.0 included
    assert got[1, 0, 0] == 1.0 and (got[..., 0] == 0).any() and ((got[..., 0] > 0)
                                                                  & (got[..., 0] < 1)).any()


def numpy_paths(grid, envs, xy_all, alive_all, obs, oi, c, s):
    """ObservationBuilder._build_paths as numpy computed it before the kernel: fwd, side
    and dist, (G, L, O) each."""
    xy = xy_all[envs]
    nodes = grid.nodes_of(xy.reshape(-1, 2)).reshape(xy.shape[:2])
    src = np.broadcast_to(nodes[:, obs][:, :, None], (len(nodes),) + oi.shape)
    dst = nodes[:, oi]
    nxt = grid.next_table
    n1 = nxt[src, dst]
    n1 = np.where(n1 < 0, src, n1)
    n2 = nxt[n1, dst]
    n2 = np.where(n2 < 0, n1, n2)
    target = np.where((n1 == dst)[..., None], xy[:, oi], grid.centers[n2])
    d = target - xy[:, obs][:, :, None, :]
    alive = alive_all[envs][:, oi]
    k = alive / np.maximum(np.hypot(d[..., 0], d[..., 1]), 1e-9)
    c, s = c[envs][..., None], s[envs][..., None]
    steps = grid.dist_table[src, dst]
    return ((d[..., 0] * c + d[..., 1] * s) * k, (d[..., 1] * c - d[..., 0] * s) * k,
            np.where(steps >= 0, steps * (1.0 / grid.diameter), 1.0) * alive)


@pytest.mark.parametrize("seed", range(3))
def test_path_features_equal_the_numpy_paths_bit_for_bit(seed):
    rng = np.random.default_rng(seed)
    spec = load_map("maze")
    grid = nav_grid(spec)
    E, n = 5, 4
    xy = rng.uniform(0, [spec.width, spec.height], (E, n, 2))  # walls and floor alike
    floor = spec.floor_cells()
    xy[0, 1] = np.add(spec.cell_center(floor[0]), (4.0, -3.0))
    xy[0, 2] = spec.cell_center(floor[1])  # a neighbour: the path ends at the tank itself
    xy[0, 3] = xy[0, 0] + (1e-7, 0.0)  # a hair from the observer: the 1e-9 floor
    xy[2, 3] = xy[2, 0]  # on top of the observer: a zero direction
    alive = rng.random((E, n)) < 0.75
    alive[0] = True
    obs = np.array([0, 2])
    oi = np.array([[1, 2, 3], [0, 1, 3]])
    ang = rng.uniform(-math.pi, math.pi, (E, 2))
    c, s = np.cos(ang), np.sin(ang)
    envs = np.array([0, 2, 3])  # one map's envs among others
    cols = np.array([4, 1, 2])
    out = np.full((E, 2, 3, 5), 7.0)  # float64: every bit (the observation is float32)
    nodes = grid.nodes_of(xy[envs].reshape(-1, 2)).reshape(len(envs), n)
    path_features(envs, nodes, xy, alive, obs, oi, grid.next_table, grid.dist_table,
                  grid.centers, c, s, 1.0 / grid.diameter, cols, out)
    want = np.full_like(out, 7.0)
    for col, part in zip(cols, numpy_paths(grid, envs, xy, alive, obs, oi, c, s), strict=True):
        want[envs, :, :, col] = part
    assert out.tobytes() == want.tobytes()
    assert (out[[1, 4], ...] == 7.0).all()  # the other map's envs are left alone
    got = out[envs][..., cols]
    assert ((got[..., 0] != 0) & (got[..., 0] != 7)).any()


def numpy_bullets(bullet_xy, bullet_vel, active, bidx, bteam, xy):
    """ObservationBuilder._other_bullets and its use as numpy did them before the kernel:
    relative xy, velocity and mask (E, L, K[, 2]) nearest first, and the team flags."""
    act = active[:, bidx]
    rel = bullet_xy[:, bidx] - xy[:, :, None, :]
    dist = np.hypot(rel[..., 0], rel[..., 1])
    order = np.where(act, dist, np.inf).argsort(axis=-1, kind="stable")
    ge, gl = np.arange(len(xy))[:, None, None], np.arange(bidx.shape[0])[None, :, None]
    mask = act[ge, gl, order]
    team = np.multiply(bteam[gl, order], mask)
    return rel[ge, gl, order], bullet_vel[ge, bidx[gl, order]], mask, team


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("team_col", [3, -1])
def test_nearest_bullets_equal_the_numpy_sort_bit_for_bit(seed, team_col):
    rng = np.random.default_rng(seed)
    E, L, nb, K, first = 4, 2, 12, 6, 3
    bullet_xy = rng.uniform(0, 600, (E, nb, 2))
    bullet_vel = rng.uniform(-300, 300, (E, nb, 2))
    active = rng.random((E, nb)) < 0.6
    bidx = np.array([rng.permutation(nb)[:K] for _ in range(L)])
    bteam = (rng.random((L, K)) < 0.5).astype(np.float64)
    xy = rng.uniform(0, 600, (E, L, 2))
    b0, b1 = bidx[0, 1], bidx[0, 4]
    bullet_xy[0, b1] = 2 * xy[0, 0] - bullet_xy[0, b0]  # mirrored: a tie in distance
    active[0, [b0, b1]] = True
    width = first + K + 2
    relv, velv = np.full((E, L, width, 2), 7.0), np.full((E, L, width, 2), 7.0)
    rmask, vmask = np.full((E, L, width), 7.0), np.full((E, L, width), 7.0)
    block = np.full((E, L, K, 5), 7.0, dtype=np.float32)
    nearest_bullets(bullet_xy, bullet_vel, active, bidx, bteam, xy, first, relv, velv,
                    rmask, vmask, block, 1, team_col)
    rel, vel, mask, team = numpy_bullets(bullet_xy, bullet_vel, active, bidx, bteam, xy)
    span = slice(first, first + K)
    assert relv[:, :, span].tobytes() == rel.tobytes()
    assert velv[:, :, span].tobytes() == vel.tobytes()
    assert rmask[:, :, span].tobytes() == vmask[:, :, span].tobytes() == mask.astype(
        np.float64).tobytes()
    assert block[..., 1].tobytes() == mask.astype(np.float32).tobytes()
    if team_col >= 0:
        assert block[..., 3].tobytes() == team.astype(np.float32).tobytes()
    assert (block[..., [0, 2, 4] if team_col >= 0 else [0, 2, 3, 4]] == 7.0).all()
    assert (relv[:, :, :first] == 7.0).all() and (relv[:, :, first + K:] == 7.0).all()


def numpy_reach(dist, t, d, alive, seats, length, team, r, max_distance):
    """StateBatch.reach_shots' array part as numpy did it before the kernel: first,
    passing (E, S[, n]) and the shot block (E, S, 3)."""
    n = dist.shape[-1]
    target = alive[:, None, :] & (np.arange(n) != seats[:, None])
    dist[~np.broadcast_to(target[:, :, None], dist.shape)] = np.inf
    near = (dist <= r).any(axis=-1)
    seg = near.argmax(axis=-1)[..., None, None]
    hit = np.take_along_axis(near, seg[..., 0], axis=-1)[..., 0]
    d_seg = np.take_along_axis(dist, seg, axis=2)[:, :, 0]
    along = np.take_along_axis(t, seg, axis=2)[:, :, 0] * np.abs(
        np.take_along_axis(d, seg, axis=2)[:, :, 0])
    chord = np.sqrt(np.maximum(r * r - np.minimum(d_seg, r) ** 2, 0.0))
    first = np.where(d_seg <= r, along - chord, np.inf).argmin(axis=-1)
    passing = dist.min(axis=2)
    mine = team[:, seats]
    mate = np.take_along_axis(team, first, axis=1) == mine
    out = np.empty(mine.shape + (3,))
    out[..., 0] = hit & ~mate
    out[..., 1] = hit & mate
    foe = target & (team[:, None, :] != mine[..., None])
    out[..., 2] = np.minimum(np.where(foe, passing, np.inf).min(axis=-1) / max_distance, 1.0)
    out[length == 0] = 0.0
    return np.where(hit & (length > 0), first, -1), passing, out


@pytest.mark.parametrize("seed", range(4))
def test_shot_reach_equals_the_numpy_shots_bit_for_bit(seed):
    rng = np.random.default_rng(seed)
    E, n, P, r, max_distance = 6, 4, 4, 12.0, 700.0
    seats = np.array([0, 2, 3])
    xy = rng.uniform(0, 400, (E, n, 2))
    paths = rng.uniform(0, 400, (E, len(seats), P, 2))
    xy[0] = [(50.0, 50.0), (200.0, 50.0), (350.0, 50.0), (200.0, 300.0)]
    paths[0, 0] = [(70.0, 50.0), (200.0, 50.0), (350.0, 50.0), (350.0, 200.0)]  # friend first
    xy[1, 3] = xy[1, 1]  # two tanks in one spot: a tie for the first reached
    paths[1, 1, 1] = xy[1, 1] + (3.0, 0.0)
    paths[2, 0, 1:] = paths[2, 0, 0]  # a shot that goes nowhere (zero legs)
    alive = rng.random((E, n)) < 0.8
    alive[:2] = True
    team = np.array([0, 0, 1, 1])[None].repeat(E, 0)
    length = np.full((E, len(seats)), P)
    length[3, 1] = 0  # a dead shooter's stale row
    z = paths.view(np.complex128)[..., 0]
    w = (xy[..., 0] + 1j * xy[..., 1])[:, None, :]
    dist, t, d = segment_distances(z, w)
    want = numpy_reach(dist.copy(), t, d, alive, seats, length, team, r, max_distance)
    first, passing = np.full((E, n), 9), np.full((E, n, n), 9.0)
    shots = np.full((E, n, 3), 9.0)
    shot_reach(dist, t, np.abs(d[..., 0]), alive, seats, length, team, r, max_distance,
               first, passing, shots)
    assert first[:, seats].tobytes() == want[0].tobytes()
    assert passing[:, seats].tobytes() == want[1].tobytes()
    assert shots[:, seats].tobytes() == want[2].tobytes()
    assert (first[:, 1] == 9).all() and (shots[:, 1] == 9.0).all()  # not a shooter
    assert first[0, 0] == 1 and shots[0, 0, 1] == 1.0  # the friend in the way
    assert (shots[:, seats, 2] < 1.0).any()


def test_paper_observation_sorts_other_bullets_nearest_first_ties_in_slot_order():
    game = game_config("paper")
    spec = load_map("maze")
    teams = ["A", "B"]
    batch = StateBatch(game, 2, 1, *slot_counts(game, [spec]))
    batch.set_static(0, Match(game, spec, teams, seed=0))
    builder = ObservationBuilder("paper", batch, teams, [0])
    builder.set_static(0)
    cap = game.bullet_capacity
    batch.raw[0, 0, 0:2] = (300.0, 300.0)  # the observer
    batch.raw[0, 1, 0:2] = (100.0, 100.0)
    bullets = batch.raw[0, 2:2 + 2 * cap]  # seat 1's slots follow seat 0's
    far, near, tie = cap, cap + 1, cap + 2
    bullets[far, 0:2] = (300.0, 420.0)
    bullets[near, 0:2] = (300.0, 340.0)
    bullets[tie, 0:2] = (340.0, 300.0)  # as near as `near`, a later slot
    batch.bullet_active[0, [far, near, tie]] = True
    obs = builder.build()[0, 0]
    lay, at = builder.layout, builder.at
    width = lay.widths["bullet"]
    slot = obs[lay["bullet"]].reshape(-1, width)
    scale = 1.0 / max(spec.width, spec.height)
    rel_y = slot[:, at["bullet.rel_x:rel_y"]][:, 1]
    assert slot[:, at["bullet.mask"]].tolist() == [1.0, 1.0, 1.0] + [0.0] * (cap - 3)
    assert rel_y[:3].tolist() == pytest.approx([40 * scale, 0.0, 120 * scale])
    assert (np.abs(obs) <= 1.0).all()


# ---- the bots' dodge ------------------------------------------------------------------


def numpy_evade(ev, x, y, h, bullet_xy, bullet_vel, turn, raster, margin):
    """Evader.evade's choice and scores as numpy computed them before the kernel."""
    c, s = math.cos(h), math.sin(h)
    coef = np.zeros((3, 2, 1, 1))
    coef.reshape(-1)[:] = (x, y, c, s, -s, c)
    tmp, pos = np.empty((2,) + ev.fwd.shape), np.empty((2,) + ev.fwd.shape)
    np.multiply(coef[1], ev.fwd, out=tmp)
    np.add(coef[0], tmp, out=pos)
    np.multiply(coef[2], ev.side, out=tmp)
    pos += tmp
    bpos = bullet_xy[:, :, None] + bullet_vel[:, :, None] * ev.times
    d = pos[:, :, None, :] - bpos.transpose(1, 0, 2)[:, None]
    d *= d
    gap2 = (d[0] + d[1]).reshape(9, -1).min(axis=1)
    score = np.sqrt(np.minimum(gap2, 4 * ev.danger * ev.danger))
    cell = (pos * (1 / ev.res)).astype(np.intp)
    np.maximum(cell, 0, out=cell)
    np.minimum(cell, np.array([raster.shape[1] - 1, raster.shape[0] - 1]).reshape(2, 1, 1),
               out=cell)
    wall = raster[cell[1], cell[0]].min(axis=1)
    score[wall < margin] -= 2 * ev.danger
    score[3 * turn:3 * turn + 3] += 0.5
    return int(np.argmax(score)), score


def kernel_evade(ev, x, y, h, state, threats, turn, raster, margin):
    score = np.full(9, np.nan)
    best = evade_choice(x, y, math.cos(h), math.sin(h), ev.fwd, ev.side, ev.times, state,
                        np.array(threats, dtype=np.int64), raster, 1 / ev.res,
                        4 * ev.danger * ev.danger, margin, 2 * ev.danger, 0.5,
                        turn, score)
    return best, score


@pytest.fixture(scope="module")
def evader():
    from alphatank.bots import SmartBot

    match = Match(game_config("paper"), load_map("maze"), ["A", "B"], seed=0)
    bot = SmartBot(seed=0)
    bot.reset(match, 0)
    return bot.evader


@pytest.mark.parametrize("seed", range(4))
def test_evade_choice_equals_the_numpy_dodge_bit_for_bit(evader, seed):
    """Random poses (some off the map's raster, some against walls), 1-4 bullets, every
    turn preference; bullets far off make capped, equal gaps, so ties are broken as
    argmax breaks them (first best)."""
    ev, rng = evader, np.random.default_rng(seed)
    H, W = ev.raster.shape[0] * ev.res, ev.raster.shape[1] * ev.res
    best_seen, penalised = set(), 0
    for trial in range(200):
        x, y = rng.uniform(-20, W + 20), rng.uniform(-20, H + 20)
        h = rng.uniform(-math.pi, math.pi)
        n = int(rng.integers(1, 5))
        state = np.zeros((12, 6))
        slots = sorted(rng.choice(12, size=n, replace=False).tolist())
        far = trial % 5 == 0
        for b in slots:
            ang = rng.uniform(-math.pi, math.pi)
            dist = rng.uniform(5000, 6000) if far else rng.uniform(0, 120)
            state[b, 0:2] = x + dist * math.cos(ang), y + dist * math.sin(ang)
            speed = rng.uniform(100, 400)
            state[b, 3:5] = -speed * math.cos(ang + rng.normal(0, 0.3)), \
                -speed * math.sin(ang + rng.normal(0, 0.3))
        turn = trial % 3
        want = numpy_evade(ev, x, y, h, state[slots, 0:2], state[slots, 3:5], turn,
                           ev.raster, ev.wall_margin)
        got = kernel_evade(ev, x, y, h, state, slots, turn, ev.raster, ev.wall_margin)
        assert got[0] == want[0], (trial, got, want)
        assert got[1].tobytes() == want[1].tobytes(), trial
        best_seen.add(got[0])
        penalised += int((want[1] < 0.5 * ev.danger).any())
    assert len(best_seen) >= 4 and penalised, "the cases exercise choices and walls"


def test_evade_choice_compares_the_raster_in_float32(evader):
    """numpy compares the float32 raster with a Python float in float32 (NEP 50): a
    clearance equal to the margin's float32 rounding is not below it, even where the
    margin's float64 value is larger (13.7 rounds down in float32)."""
    ev = evader
    margin = 13.7
    raster = np.full(ev.raster.shape, 100.0, dtype=np.float32)
    raster[:, :] = np.float32(margin)
    raster[:, : raster.shape[1] // 2] = np.nextafter(np.float32(margin), np.float32(0))
    raster.setflags(write=False)
    state = np.zeros((4, 6))
    state[0, 0:2], state[0, 3:5] = (400.0, 300.0), (-200.0, 0.0)
    for x in (100.0, raster.shape[1] * ev.res * 0.75):
        want = numpy_evade(ev, x, 300.0, 0.3, state[[0], 0:2], state[[0], 3:5], 1, raster,
                           margin)
        got = kernel_evade(ev, x, 300.0, 0.3, state, [0], 1, raster, margin)
        assert got[0] == want[0] and got[1].tobytes() == want[1].tobytes()
    assert float(np.float32(margin)) < margin  # the case the float64 comparison gets wrong


def python_threats(state, active, slots, x, y, soon, danger2):
    """Evader.threats as plain Python computed it before the kernel."""
    out = []
    for b in slots:
        if not active[b]:
            continue
        bx, by, _, vx, vy, _ = state[b].tolist()
        rx, ry = bx - x, by - y
        closing = -(rx * vx + ry * vy)
        if closing <= 0.0:
            continue
        v2 = vx * vx + vy * vy
        t = closing / (1e-9 if v2 < 1e-9 else v2)
        mx, my = rx + vx * t, ry + vy * t
        if 0 < t < soon and mx * mx + my * my < danger2:
            out.append(b)
    return out


@pytest.mark.parametrize("seed", range(3))
def test_threat_slots_equal_the_python_scan(evader, seed):
    """Bullets around a tank, some aimed at it, some passing by or moving away, some at
    rest (the 1e-9 floor), some inactive; a run of slots with a gap."""
    ev, rng = evader, np.random.default_rng(seed)
    slots = np.array([2, 3, 4, 5, 8, 9, 10, 11], dtype=np.int64)
    slots.setflags(write=False)
    found_any = 0
    for trial in range(300):
        x, y = rng.uniform(100, 500, 2)
        state = np.zeros((12, 6))
        ang = rng.uniform(-math.pi, math.pi, 12)
        dist = rng.uniform(0, 150, 12)
        state[:, 0], state[:, 1] = x + dist * np.cos(ang), y + dist * np.sin(ang)
        speed = rng.uniform(0, 400, 12)
        speed[rng.random(12) < 0.1] = 0.0
        aim = ang + math.pi + rng.normal(0, 0.4, 12)
        state[:, 3], state[:, 4] = speed * np.cos(aim), speed * np.sin(aim)
        active = rng.random(12) < 0.7
        out = np.full(len(slots), -1, dtype=np.int64)
        k = threat_slots(state, active, slots, x, y, ev._soon, ev._danger2, out)
        want = python_threats(state, active, slots.tolist(), x, y, ev._soon, ev._danger2)
        assert out[:k].tolist() == want, trial
        found_any += bool(want) and len(want) < int(active[slots].sum())
    assert found_any > 20, "some bullets threaten and some do not"

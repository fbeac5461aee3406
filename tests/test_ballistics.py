"""The ricochet predictor agrees with real bullets; path geometry helpers."""

import math
import zlib

import numpy as np
import pytest

from alphatank.sim.ballistics import (
    bank_angles,
    path_distances,
    path_hits,
    path_min_distance,
    predict_path,
    wall_faces,
)
from alphatank.sim.config import GameConfig
from alphatank.sim.mapspec import load_map, shipped_maps
from alphatank.sim.navigation import nav_grid
from alphatank.sim.world import World


def _random_poses(spec, rng, k):
    floor = spec.floor_cells()
    poses = []
    for i in rng.choice(len(floor), size=k):
        x, y = spec.cell_center(floor[int(i)])
        off = rng.uniform(-spec.cell / 2 + 20, spec.cell / 2 - 20, size=2)
        poses.append((x + off[0], y + off[1], rng.uniform(-math.pi, math.pi)))
    return poses


def _fire_and_record(cfg, spec, pose):
    """Fire one real bullet from a lone tank; return (muzzle, angle, bounce points)."""
    world = World(cfg, spec, np.array([pose]))
    muzzle, angle = world.muzzle(0), float(world.tank_state[0, 2])
    b = world.fire(0)
    if b < 0:
        return None
    bounces = []
    while world.bullet_active[b]:
        world.step()
        bounces += [(e.x, e.y) for e in world.bounces if e.bullet == b]
    return muzzle, angle, np.array(bounces).reshape(-1, 2), world


@pytest.mark.parametrize("map_name", shipped_maps())
@pytest.mark.parametrize("preset", [{}, {"bullet_speed": 1200.0, "bullet_max_distance": 800.0}])
def test_prediction_matches_fired_bullets(map_name, preset):
    cfg = GameConfig(**preset)
    spec = load_map(map_name)
    rng = np.random.default_rng(zlib.crc32(map_name.encode()))
    checked = total_bounces = 0
    for pose in _random_poses(spec, rng, 40):
        rec = _fire_and_record(cfg, spec, pose)
        if rec is None:  # muzzle in a wall: nothing fired
            continue
        muzzle, angle, bounces, world = rec
        path = predict_path(world, muzzle[0], muzzle[1], angle)
        assert np.allclose(path[0], muzzle)
        predicted = path[1:-1]
        assert len(predicted) == len(bounces), (pose, predicted, bounces)
        assert np.array_equal(predicted, bounces)  # the physics flies this very trace
        legs = np.hypot(*np.diff(path, axis=0).T).sum()
        assert legs <= cfg.bullet_max_distance + 1e-6
        checked += 1
        total_bounces += len(bounces)
    assert checked >= 30
    assert total_bounces >= 10  # the sample really exercises ricochets


def test_bounce_limit_ends_at_contact():
    cfg = GameConfig(bullet_max_distance=5000.0)
    spec = load_map("open")
    world = World(cfg, spec, np.array([(385.0, 385.0, 0.3)]))
    path = predict_path(world, 400.0, 385.0, 0.3, max_bounces=2)
    assert len(path) == 4  # start, 2 bounces, the contact where it dies
    # every interior/end point is a contact: bullet radius away from the walls' faces
    lo, hi = spec.cell + cfg.bullet_radius, spec.width - spec.cell - cfg.bullet_radius
    for x, y in path[1:]:
        assert min(abs(x - lo), abs(x - hi), abs(y - lo), abs(y - hi)) < 1e-6
    # reflection: angle of incidence equals angle of reflection
    d0, d1 = path[1] - path[0], path[2] - path[1]
    assert abs(abs(math.atan2(d0[1], d0[0])) - abs(math.atan2(d1[1], d1[0]))) < 1e-9 or \
        abs(abs(d0[0]) / np.linalg.norm(d0) - abs(d1[0]) / np.linalg.norm(d1)) < 1e-9


def test_path_length_is_max_distance_without_walls_in_reach():
    cfg = GameConfig()
    world = World(cfg, load_map("open"), np.array([(385.0, 385.0, 0.0)]))
    path = predict_path(world, 385.0, 385.0, 0.0, max_distance=100.0)
    assert path.shape == (2, 2)
    assert np.allclose(path[1], (485.0, 385.0))


def test_path_hits_order_and_distance():
    path = np.array([[0.0, 0.0], [100.0, 0.0], [100.0, 100.0]])
    targets = np.array([[100.0, 80.0], [50.0, 5.0], [0.0, 300.0]])
    assert path_hits(path, targets, 10.0) == 1  # first along the path, not first listed
    assert path_hits(path, targets[[0, 2]], 10.0) == 0
    assert path_hits(path, targets[[2]], 10.0) == -1
    assert path_hits(path, np.zeros((0, 2)), 10.0) == -1
    d = path_distances(path, targets)
    assert np.allclose(d, [0.0, 5.0, math.hypot(100, 200)])
    assert path_min_distance(path, targets[[2]]) == pytest.approx(math.hypot(100, 200))
    assert path_min_distance(path, np.zeros((0, 2))) == math.inf
    # two targets on the same leg: the nearer along the leg wins
    two = np.array([[80.0, 3.0], [20.0, -4.0]])
    assert path_hits(path, two, 10.0) == 1


def test_bank_angles_are_real_one_bounce_shots():
    spec = load_map("battlefield")
    cfg = GameConfig()
    world = World(cfg, spec, np.array([(-500.0, -500.0, 0.0)]))
    nav = nav_grid(spec)
    faces = wall_faces(nav.rects, spec.width, spec.height)
    rng = np.random.default_rng(1)
    floor = spec.floor_cells()
    found = 0
    for _ in range(60):
        s = np.array(spec.cell_center(floor[rng.integers(len(floor))]))
        t = np.array(spec.cell_center(floor[rng.integers(len(floor))]))
        if np.hypot(*(s - t)) < 1:
            continue
        for a in bank_angles(faces, *s, *t, cfg.bullet_radius, 400.0)[:3]:
            path = predict_path(world, s[0], s[1], a, max_distance=400.0)
            if len(path) >= 3 and path_distances(path[:3], t[None])[0] < 1e-6:
                found += 1  # the mirror solution is exact when no wall is in the way
    assert found >= 20


def test_quick_trace_is_the_flight_pymunks_space_query_finds():
    """World.quick_trace (one Chipmunk call a leg) flies what trace_flight flies with
    pymunk's public space queries, starts that overlap a wall (skipped while leaving it)
    included."""
    from alphatank.sim.world import WALLS_ONLY, trace_flight

    spec = load_map("maze")
    cfg = GameConfig()
    world = World(cfg, spec, np.array([(100.0, 100.0, 0.0)]))
    space = world.space

    def public(r):
        def hit(x0, y0, x1, y1, skip):
            if not skip:
                return space.segment_query_first((x0, y0), (x1, y1), r, WALLS_ONLY)
            best = None
            for q in space.segment_query((x0, y0), (x1, y1), r, WALLS_ONLY):
                if q.shape not in skip and (best is None or q.alpha < best.alpha):
                    best = q
            return best
        return hit

    rng = np.random.default_rng(5)
    overlapped = bounced = 0
    for _ in range(300):
        r = float(rng.choice([cfg.bullet_radius, 0.0, 6.0]))
        x, y = rng.uniform(0, spec.width), rng.uniform(0, spec.height)
        a = rng.uniform(-math.pi, math.pi)
        dx, dy = math.cos(a), math.sin(a)
        got = world.quick_trace(x, y, dx, dy, 900.0, 4, r)
        want = trace_flight(public(r), x, y, dx, dy, 900.0, 4)
        assert got == want
        q = space.point_query_nearest((x, y), r, WALLS_ONLY)
        overlapped += q is not None and q.distance < r
        bounced += len(got.ricochets) > 1
    assert overlapped and bounced

"""NavGrid: BFS tables against brute force, paths, line of sight against the physics."""

from collections import deque

import numpy as np
import pytest

from alphatank.mapgen.generate import generate
from alphatank.sim.config import GameConfig
from alphatank.sim.grid import bfs, floor_graph
from alphatank.sim.mapspec import load_map, parse_map, shipped_maps
from alphatank.sim.navigation import NavGrid, nav_grid
from alphatank.sim.world import World


def _random_spec(rng, rows, cols, density):
    walls = rng.random((rows, cols)) < density
    text = "\n".join("".join("#" if w else "." for w in row) for row in walls)
    if "." not in text:
        text = "." + text[1:]
    return parse_map(text, "<random>")


def _brute_bfs(walls, start):
    rows, cols = walls.shape
    dist = np.full(walls.shape, -1)
    dist[start] = 0
    q = deque([start])
    while q:
        r, c = q.popleft()
        for nr, nc in ((r - 1, c), (r + 1, c), (r, c - 1), (r, c + 1)):
            if 0 <= nr < rows and 0 <= nc < cols and not walls[nr, nc] and dist[nr, nc] < 0:
                dist[nr, nc] = dist[r, c] + 1
                q.append((nr, nc))
    return dist


@pytest.mark.parametrize("seed", range(8))
def test_bfs_matches_brute_force_on_random_maps(seed):
    rng = np.random.default_rng(seed)
    spec = _random_spec(rng, int(rng.integers(3, 16)), int(rng.integers(3, 16)),
                        rng.uniform(0.1, 0.5))
    g = nav_grid(spec)
    for a in spec.floor_cells():
        ref = _brute_bfs(spec.walls, a)
        for b in spec.floor_cells():
            assert g.dist(a, b) == ref[b]
            path = g.path(a, b)
            if ref[b] < 0:
                assert path == [] and g.next_cell(a, b) == a
                continue
            assert len(path) == ref[b] + 1 and path[0] == a and path[-1] == b
            for (r0, c0), (r1, c1) in zip(path, path[1:], strict=False):
                assert abs(r0 - r1) + abs(c0 - c1) == 1 and not spec.walls[r1, c1]
            if a != b:
                assert g.next_cell(a, b) == path[1]


def test_walls_and_outside_are_unreachable():
    g = nav_grid(load_map("maze"))
    assert g.dist((0, 0), (1, 1)) == -1
    assert g.dist((1, 1), (99, 99)) == -1
    assert g.dist((1, 1), (1, 1)) == 0
    assert g.dist((1, 1), (9, 9)) == g.dist((9, 9), (1, 1)) > 0


def test_cell_of_and_node_of():
    spec = load_map("maze")
    g = nav_grid(spec)
    assert g.cell_of(75.0, 145.0) == (2, 1)
    assert g.cell_of(-5.0, 1e6) == (spec.rows - 1, 0)  # clipped
    xy = np.array([[75.0, 145.0], [105.0, 105.0]])
    assert g.cells_of(xy).tolist() == [[2, 1], [1, 1]]
    assert g.node_of(105.0, 105.0) == g.idx((1, 1))
    # a wall pixel maps to an adjacent floor node
    r, c = g.cell_at(g.node_of(5.0, 5.0))
    assert not spec.walls[r, c] and abs(r) + abs(c) <= 2


def test_cached_by_map_content():
    a, b = load_map("maze"), load_map("maze")
    assert a is not b and nav_grid(a) is nav_grid(b)
    assert nav_grid(load_map("open")) is not nav_grid(a)


@pytest.mark.parametrize("map_name", shipped_maps())
def test_line_of_sight_agrees_with_physics_queries(map_name):
    spec = load_map(map_name)
    g = nav_grid(spec)
    world = World(GameConfig(), spec, np.array([(-500.0, -500.0, 0.0)]))
    rng = np.random.default_rng(7)
    floor = spec.floor_cells()
    agree = blocked = checked = 0
    for _ in range(300):
        a = np.array(spec.cell_center(floor[rng.integers(len(floor))])) + rng.uniform(-20, 20, 2)
        b = np.array(spec.cell_center(floor[rng.integers(len(floor))])) + rng.uniform(-20, 20, 2)
        radius = float(rng.choice([0.0, 3.0, 15.0]))
        ours = g.line_of_sight(tuple(a), tuple(b), radius)
        q = world.ray(tuple(a), tuple(b), radius)
        # the physics query counts a start already inside the grown wall as clear; skip those
        if world.ray(tuple(a), tuple(a), radius) is not None:
            continue
        checked += 1
        agree += ours == (q is None)
        blocked += not ours
    assert checked > 200 and agree == checked
    interior_walls = spec.walls[1:-1, 1:-1].any()
    assert blocked > 10 or not interior_walls


def test_visibility_row_and_waypoints():
    spec = load_map("open")
    g = nav_grid(spec)
    a, b = g.idx((1, 1)), g.idx((9, 9))
    assert g.visible_row(a, 15.0).all()  # open interior: everything visible
    assert g.waypoint_idx(a, b, 15.0) == b  # straight line, no staircase
    maze = nav_grid(load_map("maze"))
    i, j = maze.idx((1, 1)), maze.idx((9, 9))
    w = maze.waypoint_idx(i, j, 15.0)
    path = maze.path_idx(i, j)
    assert w in path[1:] and w != j
    assert maze.line_of_sight(tuple(maze.centers[i]), tuple(maze.centers[w]), 15.0)
    assert maze.waypoint_idx(i, j, 15.0) == w  # cached, same answer


def test_clearance_map_distances():
    spec = load_map("maze")
    g = nav_grid(spec)
    pts = np.array([[105.0, 105.0], [72.5, 105.0], [175.0, 105.0], [5.0, 5.0]])
    clear = g.clearance(pts)
    # (1,1) centre: 35 px to the surrounding walls (to raster resolution); next to a wall: ~0
    assert clear[0] == pytest.approx(35.0, abs=5.0)
    assert clear[1] < 5.0
    assert clear[3] == 0.0  # inside a wall
    assert g.clearance(np.array([[-50.0, 20.0]]))[0] == 0.0  # off the grid
    assert g.clearance_map() is g.clearance_map()  # computed once


@pytest.mark.parametrize("algorithm", ["open", "maze", "scatter"])
def test_tables_and_rasters_of_a_big_map_match_plain_computations(algorithm):
    spec = generate(32, 32, algorithm, seed=3)
    g = NavGrid(spec)
    assert g.n_floor > 512  # several 256-cell chunks of visibility
    rng = np.random.default_rng(0)
    graph = floor_graph(spec.walls)
    for a in rng.integers(g.n_floor, size=5):
        assert g.dist_table[a].tolist() == bfs(graph, [int(a)])
        row = g.visible_row(int(a), 16.0)
        p = np.broadcast_to(g.centers[a], g.centers.shape)
        assert (row == g.segments_clear(p, g.centers, 16.0)).all()
    for a, b in rng.integers(g.n_floor, size=(300, 2)):
        d = g.dist_table[a, b]
        closer = [n for n in g.neighbors[a] if n >= 0 and g.dist_table[n, b] == d - 1]
        assert g.next_table[a, b] == (a if d == 0 else closer[0] if d > 0 else -1)
    # the clearance raster: every raster point against the border and every wall rectangle
    res, h, w = 5.0, spec.height, spec.width
    px, py = np.meshgrid((np.arange(int(np.ceil(w / res))) + 0.5) * res,
                         (np.arange(int(np.ceil(h / res))) + 0.5) * res)
    ref = np.minimum(np.minimum(px, w - px), np.minimum(py, h - py))
    for x0, y0, x1, y1 in g.rects:
        dx = np.maximum(np.maximum(x0 - px, px - x1), 0.0)
        dy = np.maximum(np.maximum(y0 - py, py - y1), 0.0)
        np.minimum(ref, np.hypot(dx, dy), out=ref)
    assert np.array_equal(g.clearance_map(res), ref.astype(np.float32))

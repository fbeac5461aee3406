"""Grid searches (alphatank.sim.grid) against a plain reference BFS on random grids: distance
fields, reachability, components in row-major order, and the vectorised many-source BFS
agreeing with single searches."""

from __future__ import annotations

from collections import deque

import numpy as np
import pytest

from alphatank.sim import grid


def reference_distances(walls: np.ndarray, sources: list[tuple[int, int]]) -> np.ndarray:
    rows, cols = walls.shape
    dist = np.full(walls.shape, -1, dtype=np.int64)
    queue = deque()
    for s in sources:
        if not walls[s] and dist[s] < 0:
            dist[s] = 0
            queue.append(s)
    while queue:
        r, c = queue.popleft()
        for dr, dc in ((-1, 0), (1, 0), (0, -1), (0, 1)):
            n = (r + dr, c + dc)
            if 0 <= n[0] < rows and 0 <= n[1] < cols and not walls[n] and dist[n] < 0:
                dist[n] = dist[r, c] + 1
                queue.append(n)
    return dist


def random_walls(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    shape = tuple(int(v) for v in rng.integers(3, 14, size=2))
    return rng.random(shape) < rng.uniform(0.2, 0.6)


@pytest.mark.parametrize("seed", range(40))
def test_searches_match_a_reference_bfs(seed):
    walls = random_walls(seed)
    floor = [tuple(int(v) for v in c) for c in np.argwhere(~walls)]
    if not floor:
        return
    rng = np.random.default_rng(seed + 1000)
    sources = [floor[int(i)] for i in rng.integers(len(floor), size=2)]
    assert (grid.distance_field(walls, sources) == reference_distances(walls, sources)).all()
    assert (grid.reachable_from(walls, sources[0])
            == (reference_distances(walls, sources[:1]) >= 0)).all()
    labels, k = grid.components(walls)
    seen, firsts = np.zeros(walls.shape, dtype=bool), []
    for cell in floor:  # row-major: region i starts at the i-th unseen floor cell
        if not seen[cell]:
            firsts.append(cell)
            seen |= reference_distances(walls, [cell]) >= 0
    assert k == len(firsts)
    for i, first in enumerate(firsts):
        assert ((labels == i) == (reference_distances(walls, [first]) >= 0)).all()
    assert (labels[walls] == -1).all()


def test_floor_graphs_are_shared_and_read_only():
    walls = random_walls(3)
    g = grid.floor_graph(walls)
    assert grid.floor_graph(walls.copy()) is g
    with pytest.raises(ValueError):
        g.neighbors[0, 0] = 0
    assert (grid.open_sides(np.zeros((2, 2), dtype=bool)) == 2).all()

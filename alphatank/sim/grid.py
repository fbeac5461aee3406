"""Grid graphs of maps: floor cells, 4-neighbours, breadth-first distances, components.

One home for the grid searches that map validation (:mod:`alphatank.sim.mapspec`), spawn
placement (:mod:`alphatank.sim.match`), navigation (:mod:`alphatank.sim.navigation`) and
map generation (:mod:`alphatank.mapgen`) share. ``walls`` is a (rows, cols) bool array;
outside the grid counts as wall. The primitive is the :class:`FloorGraph` (floor cells and
their 4-neighbours, cached per wall grid) with a breadth-first search over it, :func:`bfs`
(plain Python lists: fastest for a single distance field; navigation compiles its own
all-pairs search).
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np

STEPS = ((-1, 0), (1, 0), (0, -1), (0, 1))  # the 4-neighbours: up, down, left, right


@dataclass(frozen=True)
class FloorGraph:
    """Floor cells in row-major order (``cells`` (F, 2) row, col), their index in the grid
    (``index`` (rows, cols), -1 on walls), 4-neighbours in :data:`STEPS` order
    (``neighbors`` (F, 4), -1 where a wall or the edge is) and the same as Python lists
    without the -1s (``adjacency``, for single searches)."""

    cells: np.ndarray
    index: np.ndarray
    neighbors: np.ndarray

    @property
    def size(self) -> int:
        return len(self.cells)

    @cached_property
    def adjacency(self) -> tuple[tuple[int, ...], ...]:
        return tuple(tuple(v for v in row if v >= 0) for row in self.neighbors.tolist())


_CACHE_SIZE = 64
_graphs: OrderedDict[tuple, FloorGraph] = OrderedDict()


def floor_graph(walls: np.ndarray) -> FloorGraph:
    """The (cached) floor graph of a wall grid; grids with the same walls share one."""
    walls = np.asarray(walls, dtype=bool)
    key = (walls.shape, walls.tobytes())
    g = _graphs.get(key)
    if g is not None:
        _graphs.move_to_end(key)
        return g
    rows, cols = walls.shape
    rr, cc = np.nonzero(~walls)
    index = np.full(walls.shape, -1, dtype=np.int32)
    index[rr, cc] = np.arange(len(rr), dtype=np.int32)
    neighbors = np.full((len(rr), 4), -1, dtype=np.int32)
    for k, (dr, dc) in enumerate(STEPS):
        nr, nc = rr + dr, cc + dc
        ok = (nr >= 0) & (nr < rows) & (nc >= 0) & (nc < cols)
        neighbors[ok, k] = index[nr[ok], nc[ok]]
    cells = np.stack([rr, cc], axis=1).astype(np.int32)
    for arr in (cells, index, neighbors):
        arr.flags.writeable = False  # shared by every user of the same wall grid
    g = FloorGraph(cells, index, neighbors)
    _graphs[key] = g
    if len(_graphs) > _CACHE_SIZE:
        _graphs.popitem(last=False)
    return g


def bfs(graph: FloorGraph, starts: Sequence[int]) -> list[int]:
    """One breadth-first search from the floor indices ``starts``: steps from the nearest
    start for every floor cell, -1 where unreachable."""
    dist = [-1] * graph.size
    _search(graph.adjacency, dist, starts)
    return dist


def _search(adj: Sequence[Sequence[int]], dist: list[int], starts: Sequence[int]
            ) -> list[int]:
    """Breadth-first from ``starts`` over cells whose ``dist`` is still -1, writing their
    steps; returns the cells reached, starts first."""
    frontier = []
    for s in starts:
        if dist[s] < 0:
            dist[s] = 0
            frontier.append(s)
    reached, d = list(frontier), 0
    while frontier:
        d += 1
        nxt = []
        for v in frontier:
            for u in adj[v]:
                if dist[u] < 0:
                    dist[u] = d
                    nxt.append(u)
        reached += nxt
        frontier = nxt
    return reached


def _on_grid(graph: FloorGraph, values: Sequence[int]) -> np.ndarray:
    out = np.full(graph.index.shape, -1, dtype=np.int64)
    out[graph.cells[:, 0], graph.cells[:, 1]] = values
    return out


def distance_field(walls: np.ndarray, sources: Sequence[tuple[int, int]]) -> np.ndarray:
    """(rows, cols) int64 steps over floor from the nearest of ``sources``; -1 on walls and
    where unreachable."""
    g = floor_graph(walls)
    starts = [int(g.index[r, c]) for r, c in sources if g.index[r, c] >= 0]
    return _on_grid(g, bfs(g, starts))


def reachable_from(walls: np.ndarray, start: tuple[int, int]) -> np.ndarray:
    """(rows, cols) bool: the floor cells reachable from ``start``."""
    return distance_field(walls, [start]) >= 0


def components(walls: np.ndarray) -> tuple[np.ndarray, int]:
    """Connected floor regions labelled 0..k-1 in row-major order of their first cell
    (-1 on walls), and k."""
    g = floor_graph(walls)
    dist, label = [-1] * g.size, [-1] * g.size
    k = 0
    for first in range(g.size):  # row-major: each new region starts at its first cell
        if dist[first] < 0:
            for v in _search(g.adjacency, dist, [first]):
                label[v] = k
            k += 1
    return _on_grid(g, label), k


def floor_areas(walls: np.ndarray) -> list[np.ndarray]:
    """(rows, cols) bool grids of the connected floor regions, largest first (ties in
    row-major order of their first cell)."""
    labels, k = components(walls)
    areas = [labels == i for i in range(k)]
    return sorted(areas, key=lambda a: -int(a.sum()))


def open_sides(walls: np.ndarray) -> np.ndarray:
    """Number of floor 4-neighbours of every cell (outside the grid counts as wall)."""
    floor = np.pad(~np.asarray(walls, dtype=bool), 1, constant_values=False).astype(np.int64)
    return floor[:-2, 1:-1] + floor[2:, 1:-1] + floor[1:-1, :-2] + floor[1:-1, 2:]

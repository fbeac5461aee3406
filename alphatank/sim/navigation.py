"""Grid navigation computed once per map: all-pairs BFS, next steps, line of sight.

A :class:`NavGrid` numbers the floor cells of a map ``0 .. F-1`` (row-major) and holds,
as numpy arrays for bulk use:

``index``       (rows, cols) int32: floor index of each cell, -1 for walls.
``node``        (rows, cols) int32: floor index of each cell, walls mapped to the nearest
                floor cell (so any pixel position maps to a floor node).
``cells``       (F, 2) int32: (row, col) of each floor index.
``centers``     (F, 2) float64: pixel centre (x, y) of each floor index.
``neighbors``   (F, 4) int32: floor index of the up, down, left, right neighbour or -1.
``dist_table``  (F, F) int32: BFS steps between floor cells (4-neighbours), -1 unreachable.
``next_table``  (F, F) int32: first step from ``a`` towards ``b`` on a shortest path
                (``a`` itself when ``a == b``, -1 when unreachable). Ties go to the
                first neighbour in up, down, left, right order, so paths are deterministic.
``rects``       (R, 4) float64: the map's merged wall rectangles (x0, y0, x1, y1) in px.
``diameter``    the longest BFS distance between two floor cells (at least 1).

The two (F, F) tables come from compiled loops (numba) in F * F steps; the map loader
keeps F at most :data:`~alphatank.sim.mapspec.MAX_FLOOR` (4096: 64 MiB a table).

Lazily computed and cached: ``visible_row(i, radius)`` (cells seen from cell ``i``),
``waypoint_idx(i, j, radius)`` (string-pulled route target) and ``clearance_map(res)``
(distance-to-wall raster, read with ``clearance(xy)``).

Cell-based methods (``dist``, ``next_cell``, ``path``) take and return (row, col) tuples;
``*_idx`` variants work on floor indices. Line of sight is exact geometry against the map's
wall rectangles grown by a radius (a disc swept along the segment), so it agrees with the
physics' thick segment queries up to floating point. Nothing is recomputed per tick.

:func:`nav_grid` returns the NavGrid of a map, cached by the map's content (wall grid and
cell size), so every bot, reward and overlay on the same map shares one.
"""

from __future__ import annotations

import math
from collections import OrderedDict

import numpy as np
from numba import njit

from alphatank.sim.grid import distance_field, floor_graph, open_sides
from alphatank.sim.mapspec import MapSpec

Cell = tuple[int, int]
_CACHE_SIZE = 32
_cache: OrderedDict[tuple, NavGrid] = OrderedDict()


def nav_grid(spec: MapSpec) -> NavGrid:
    """The (cached) NavGrid of ``spec``; maps with the same walls and cell size share one."""
    key = (spec.walls.shape, spec.walls.tobytes(), float(spec.cell))
    grid = _cache.get(key)
    if grid is None:
        grid = NavGrid(spec)
        _cache[key] = grid
        if len(_cache) > _CACHE_SIZE:
            _cache.popitem(last=False)
    else:
        _cache.move_to_end(key)
    return grid


class NavGrid:
    """BFS distances, next-step tables and line of sight over one map's floor cells."""

    def __init__(self, spec: MapSpec):
        walls = np.asarray(spec.walls, dtype=bool)
        self.rows, self.cols = walls.shape
        self.cell = float(spec.cell)
        self.walls = walls
        graph = floor_graph(walls)
        self.cells, self.index, self.neighbors = graph.cells, graph.index, graph.neighbors
        self.n_floor = graph.size
        self.centers = (self.cells[:, ::-1].astype(np.float64) + 0.5) * self.cell
        self.node = self._nearest_floor()
        self.dist_table = _all_pairs_bfs(self.neighbors)
        self.next_table = _next_steps(self.neighbors, self.dist_table)
        self.diameter = max(int(self.dist_table.max()), 1)  # longest shortest path (cells)
        # Wall rectangles (x0, y0, x1, y1) in px, for exact line-of-sight tests.
        self.rects = np.array(spec.wall_rects, dtype=np.float64).reshape(-1, 4)
        self._visible: dict[tuple[int, float], np.ndarray] = {}
        self._waypoints: dict[float, np.ndarray] = {}
        self._clearance: dict[float, np.ndarray] = {}

    # ---- construction ---------------------------------------------------------------

    def _nearest_floor(self) -> np.ndarray:
        """Floor index of every cell; wall cells take the nearest floor cell's index (the
        first in row-major order on ties). One grid row at a time: (cols, F) numbers."""
        fr, fc = self.cells[:, 0], self.cells[:, 1]
        cols = np.arange(self.cols)[:, None]
        node = np.empty((self.rows, self.cols), dtype=np.int32)
        for r in range(self.rows):
            node[r] = np.argmin((r - fr) ** 2 + (cols - fc) ** 2, axis=1)
        return node

    # ---- cells and indices ----------------------------------------------------------

    def cell_of(self, x: float, y: float) -> Cell:
        """Grid cell (row, col) containing pixel (x, y), clipped to the grid."""
        r = min(max(int(y // self.cell), 0), self.rows - 1)
        c = min(max(int(x // self.cell), 0), self.cols - 1)
        return (r, c)

    def cells_of(self, xy: np.ndarray) -> np.ndarray:
        """Vectorised ``cell_of``: (n, 2) pixels -> (n, 2) int (row, col)."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        rc = (xy[:, ::-1] // self.cell).astype(np.int64)
        np.maximum(rc, 0, out=rc)
        return np.minimum(rc, (self.rows - 1, self.cols - 1), out=rc)

    def node_of(self, x: float, y: float) -> int:
        """Floor index for pixel (x, y): its cell, or the nearest floor cell if a wall."""
        r, c = self.cell_of(x, y)
        return int(self.node[r, c])

    def nodes_of(self, xy: np.ndarray) -> np.ndarray:
        """Vectorised ``node_of``: (n, 2) pixels -> (n,) floor indices."""
        rc = self.cells_of(xy)
        return self.node[rc[:, 0], rc[:, 1]]

    def idx(self, cell: Cell) -> int:
        """Floor index of a cell, -1 for a wall or a cell outside the grid."""
        r, c = cell
        if not (0 <= r < self.rows and 0 <= c < self.cols):
            return -1
        return int(self.index[r, c])

    def cell_at(self, i: int) -> Cell:
        r, c = self.cells[i]
        return (int(r), int(c))

    # ---- distances and paths --------------------------------------------------------

    def dist(self, a: Cell, b: Cell) -> int:
        """BFS steps from cell ``a`` to cell ``b``; -1 if unreachable or either is a wall."""
        i, j = self.idx(a), self.idx(b)
        if i < 0 or j < 0:
            return -1
        return int(self.dist_table[i, j])

    def next_cell(self, a: Cell, b: Cell) -> Cell:
        """First cell after ``a`` on a shortest path to ``b`` (``a`` if a == b or none)."""
        i, j = self.idx(a), self.idx(b)
        if i < 0 or j < 0 or self.next_table[i, j] < 0:
            return a
        return self.cell_at(int(self.next_table[i, j]))

    def path_idx(self, i: int, j: int) -> list[int]:
        """Floor indices from ``i`` to ``j`` inclusive; [] if unreachable."""
        if self.dist_table[i, j] < 0:
            return []
        out = [i]
        while i != j:
            i = int(self.next_table[i, j])
            out.append(i)
        return out

    def path(self, a: Cell, b: Cell) -> list[Cell]:
        """Cells of a shortest path from ``a`` to ``b`` inclusive; [] if unreachable."""
        i, j = self.idx(a), self.idx(b)
        if i < 0 or j < 0:
            return []
        return [self.cell_at(k) for k in self.path_idx(i, j)]

    # ---- line of sight --------------------------------------------------------------

    def segments_clear(self, p: np.ndarray, q: np.ndarray, radius: float = 0.0) -> np.ndarray:
        """For segments p[k] -> q[k] ((n, 2) each): True where a disc of ``radius`` swept
        along the segment touches no wall rectangle. Touching exactly counts as clear."""
        p = np.asarray(p, dtype=np.float64).reshape(-1, 2)
        q = np.asarray(q, dtype=np.float64).reshape(-1, 2)
        if len(self.rects) == 0:
            return np.ones(len(p), dtype=bool)
        x0, y0, x1, y1 = (self.rects[:, k][None, :] for k in range(4))
        px, py = p[:, :1], p[:, 1:]
        dx, dy = q[:, :1] - px, q[:, 1:] - py
        r = float(radius)
        # Cross of the rectangle grown by r along x (full height) and along y (full width).
        hit = (_slab(px, py, dx, dy, x0 - r, y0, x1 + r, y1)
               | _slab(px, py, dx, dy, x0, y0 - r, x1, y1 + r))
        if r > 0:  # rounded corners: segment within r of a rectangle corner
            for cx, cy in ((x0, y0), (x1, y0), (x0, y1), (x1, y1)):
                hit |= _seg_point_dist2(px, py, dx, dy, cx, cy) < r * r - 1e-9
        return ~hit.any(axis=1)

    def line_of_sight(self, a: tuple[float, float], b: tuple[float, float],
                      radius: float = 0.0) -> bool:
        """True if a disc of ``radius`` can travel straight from pixel a to pixel b."""
        return bool(self.segments_clear(np.array([a]), np.array([b]), radius)[0])

    def visible_row(self, i: int, radius: float = 0.0) -> np.ndarray:
        """(F,) bool: cells whose centre a disc of ``radius`` sees from cell ``i``'s centre.
        Computed on first use per (cell, radius) and cached."""
        key = (int(i), float(radius))
        row = self._visible.get(key)
        if row is None:
            p = np.broadcast_to(self.centers[i], self.centers.shape)
            chunks = range(0, self.n_floor, 256)  # (256, R) temporaries, whatever the map
            row = np.concatenate([self.segments_clear(p[k:k + 256], self.centers[k:k + 256],
                                                      radius) for k in chunks])
            row.setflags(write=False)
            self._visible[key] = row
        return row

    def clearance_map(self, res: float = 5.0) -> np.ndarray:
        """(ceil(H/res), ceil(W/res)) float32 raster: distance in px from each raster point
        (cell-corner aligned, spacing ``res``) to the nearest wall, the outside of the grid
        counting as wall. Computed once per resolution; look up with :meth:`clearance`."""
        grid = self._clearance.get(float(res))
        if grid is None:
            h, w = self.rows * self.cell, self.cols * self.cell
            ys = (np.arange(int(np.ceil(h / res))) + 0.5) * res
            xs = (np.arange(int(np.ceil(w / res))) + 0.5) * res
            grid = np.minimum(np.minimum(xs, w - xs)[None, :], np.minimum(ys, h - ys)[:, None])
            # No point is farther than (depth + 1) cells from a wall or the outside (depth:
            # most BFS steps from a floor cell to one beside them), so a wall rectangle can
            # only lower the points within reach of it: one window per rectangle.
            edge = ~self.walls & (open_sides(self.walls) < 4)
            depth = int(distance_field(self.walls, np.argwhere(edge).tolist()).max())
            reach = (depth + 2) * self.cell
            for x0, y0, x1, y1 in self.rects:
                c0, c1 = np.searchsorted(xs, (x0 - reach, x1 + reach))
                r0, r1 = np.searchsorted(ys, (y0 - reach, y1 + reach))
                px, py = xs[None, c0:c1], ys[r0:r1, None]
                dx = np.maximum(np.maximum(x0 - px, px - x1), 0.0)
                dy = np.maximum(np.maximum(y0 - py, py - y1), 0.0)
                window = grid[r0:r1, c0:c1]
                np.minimum(window, np.hypot(dx, dy), out=window)
            grid = grid.astype(np.float32)
            grid.setflags(write=False)
            self._clearance[float(res)] = grid
        return grid

    def clearance(self, xy: np.ndarray, res: float = 5.0) -> np.ndarray:
        """Distance to the nearest wall (to ``res`` px) at pixel points ``xy`` (..., 2);
        points outside the grid read 0."""
        grid = self.clearance_map(res)
        xy = np.asarray(xy, dtype=np.float64)
        c = np.floor(xy[..., 0] / res).astype(np.int64)
        r = np.floor(xy[..., 1] / res).astype(np.int64)
        h, w = grid.shape
        inside = (r >= 0) & (r < h) & (c >= 0) & (c < w)
        return np.where(inside, grid[np.minimum(np.maximum(r, 0), h - 1),
                                     np.minimum(np.maximum(c, 0), w - 1)], 0.0)

    def clearance_at(self, x: float, y: float, res: float = 5.0) -> float:
        """:meth:`clearance` of one point, without array work: the raster's float32 value
        as a float (compare it with a float32-exact bound to compare as numpy would)."""
        grid = self.clearance_map(res)
        r, c = math.floor(y / res), math.floor(x / res)
        h, w = grid.shape
        return float(grid[r, c]) if 0 <= r < h and 0 <= c < w else 0.0

    def waypoint_idx(self, i: int, j: int, radius: float) -> int:
        """Farthest cell on the BFS path from ``i`` to ``j`` that a disc of ``radius`` reaches
        in a straight line from ``i``'s centre (string pulling); ``i`` if unreachable.
        Cached per (i, j, radius): amortised O(1) per call."""
        table = self._waypoints.get(float(radius))
        if table is None:
            table = np.full((self.n_floor, self.n_floor), -1, dtype=np.int32)
            self._waypoints[float(radius)] = table
        w = int(table[i, j])
        if w < 0:
            w = i
            vis = self.visible_row(i, radius)
            for k in self.path_idx(i, j)[1:]:
                if not vis[k]:
                    break
                w = k
            table[i, j] = w
        return w


@njit(cache=True)
def _all_pairs_bfs(neighbors: np.ndarray) -> np.ndarray:
    """(F, F) int32 BFS steps between floor cells (-1 unreachable): one queue per source
    over the (F, 4) -1-padded neighbour table, F * F work in all."""
    f = neighbors.shape[0]
    dist = np.full((f, f), -1, dtype=np.int32)
    queue = np.empty(f, dtype=np.int32)
    for s in range(f):
        row = dist[s]
        row[s] = 0
        queue[0] = s
        head, tail = 0, 1
        while head < tail:
            v = queue[head]
            head += 1
            for k in range(neighbors.shape[1]):
                u = neighbors[v, k]
                if u >= 0 and row[u] < 0:
                    row[u] = row[v] + 1
                    queue[tail] = u
                    tail += 1
    return dist


@njit(cache=True)
def _next_steps(neighbors: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """(F, F) int32 first step from ``a`` towards ``b``: the first neighbour (in
    :data:`~alphatank.sim.grid.STEPS` order) one step closer; ``a`` if a == b, -1 if
    unreachable."""
    f = neighbors.shape[0]
    nxt = np.full((f, f), -1, dtype=np.int32)
    for a in range(f):
        nxt[a, a] = a
        for b in range(f):
            d = dist[a, b]
            if d > 0:
                for k in range(neighbors.shape[1]):
                    nb = neighbors[a, k]
                    if nb >= 0 and dist[nb, b] == d - 1:
                        nxt[a, b] = nb
                        break
    return nxt


def _slab(px, py, dx, dy, x0, y0, x1, y1) -> np.ndarray:
    """(n, m) bool: segment p + t d, t in [0, 1], crosses the open box interior."""
    with np.errstate(divide="ignore", invalid="ignore"):
        tx0, tx1 = (x0 - px) / dx, (x1 - px) / dx
        ty0, ty1 = (y0 - py) / dy, (y1 - py) / dy
    inf = np.inf
    x_in = (px > x0) & (px < x1)
    y_in = (py > y0) & (py < y1)
    txa = np.where(dx == 0, np.where(x_in, -inf, inf), np.minimum(tx0, tx1))
    txb = np.where(dx == 0, np.where(x_in, inf, -inf), np.maximum(tx0, tx1))
    tya = np.where(dy == 0, np.where(y_in, -inf, inf), np.minimum(ty0, ty1))
    tyb = np.where(dy == 0, np.where(y_in, inf, -inf), np.maximum(ty0, ty1))
    t_in = np.maximum(np.maximum(txa, tya), 0.0)
    t_out = np.minimum(np.minimum(txb, tyb), 1.0)
    return t_out - t_in > 1e-12


def _seg_point_dist2(px, py, dx, dy, cx, cy) -> np.ndarray:
    """(n, m) squared distance from segments p + t d to points c."""
    len2 = dx * dx + dy * dy
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.clip(((cx - px) * dx + (cy - py) * dy) / len2, 0.0, 1.0)
    t = np.where(len2 > 0, t, 0.0)
    ex, ey = px + t * dx - cx, py + t * dy - cy
    return ex * ex + ey * ey

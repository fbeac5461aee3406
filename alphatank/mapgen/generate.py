"""Map generation (the logic behind ``tools/mapgen.py generate`` and ``batch``).

- :func:`generate` builds a seeded map (``maze``, ``rooms``, ``open`` or ``scatter``) with a
  wall border, all floor connected, optional mirror (left-right) or rotational (180 degree)
  symmetry, spawn slots and zones placed symmetrically, and extra loops so mazes are not
  trees. Every map passes the game's own :func:`alphatank.sim.mapspec.parse_map`.
- Grid helpers shared with the lint: open sides, lines of fire between cells.

All randomness comes from ``numpy.random.default_rng(seed)``: one seed, one file.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, replace

import numpy as np

from alphatank.errors import InputError
from alphatank.sim.grid import STEPS, components, distance_field, open_sides
from alphatank.sim.mapspec import (
    MapSpec,
    map_text,
    parse_map,
)

ALGORITHMS = ("maze", "rooms", "open", "scatter")
SYMMETRIES = ("none", "mirror", "rotational")
MAX_SPAWNS = 8
MIN_SIZE, MAX_SIZE = 5, 64
_ATTEMPTS = 20  # generation attempts before falling back to an empty arena
_PAIR_CHUNK = 1 << 18  # segment x wall pairs per numpy chunk in line-of-fire tests


class MapGenError(InputError, ValueError):
    """A generator option is out of range; the message names the option and allowed values."""


# ---- options ------------------------------------------------------------------------------


@dataclass(frozen=True)
class GenOptions:
    """Everything that decides a generated map (together they name it uniquely)."""

    rows: int = 11
    cols: int = 11
    algorithm: str = "maze"
    density: float = 0.25
    symmetry: str = "none"
    spawns: int = 2
    zones: tuple[int, int] | None = (2, 2)  # (buff, debuff) cells; None: "zones: random"
    loops: float = 0.1
    seed: int = 0

    def __post_init__(self) -> None:
        for name, kinds in (("rows", (int,)), ("cols", (int,)), ("spawns", (int,)),
                            ("seed", (int,)), ("density", (int, float)),
                            ("loops", (int, float))):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, kinds) or v != v:  # v != v: NaN
                what = "an integer" if kinds == (int,) else "a number"
                raise MapGenError(f"{name} must be {what}, got {v!r}")
        if self.zones is not None and not (
                isinstance(self.zones, tuple) and len(self.zones) == 2
                and all(type(z) is int for z in self.zones)):
            raise MapGenError(f"zones must be two counts >= 0 (buff, debuff) or None "
                              f"('zones: random'), got {self.zones!r}")
        if self.algorithm not in ALGORITHMS:
            raise MapGenError(f"algorithm must be one of {list(ALGORITHMS)}, "
                              f"got {self.algorithm!r}")
        if self.symmetry not in SYMMETRIES:
            raise MapGenError(f"symmetry must be one of {list(SYMMETRIES)}, "
                              f"got {self.symmetry!r}")
        for name in ("rows", "cols"):
            v = getattr(self, name)
            if not MIN_SIZE <= v <= MAX_SIZE:
                raise MapGenError(f"{name} must be in [{MIN_SIZE}, {MAX_SIZE}], got {v}")
        if not 0.0 <= self.density < 1.0:
            raise MapGenError(f"density must be in [0, 1), got {self.density}")
        if not 0.0 <= self.loops <= 1.0:
            raise MapGenError(f"loops must be in [0, 1], got {self.loops}")
        if not 0 <= self.spawns <= MAX_SPAWNS:
            raise MapGenError(f"spawns must be in [0, {MAX_SPAWNS}], got {self.spawns}")
        if self.zones is not None and min(self.zones) < 0:
            raise MapGenError(f"zones must be two counts >= 0 (buff, debuff) or 'random', "
                              f"got {self.zones!r}")
        if self.seed < 0:
            raise MapGenError(f"seed must be >= 0, got {self.seed}")
        counts = [self.spawns, *(self.zones or (0, 0))]
        interior = (self.rows - 2) * (self.cols - 2)
        if sum(counts) > interior:
            raise MapGenError(f"{sum(counts)} spawn and zone cells do not fit in the "
                              f"{self.rows - 2}x{self.cols - 2} interior of a "
                              f"{self.rows}x{self.cols} map")
        if self.symmetry != "none":
            fixed = _fixed_interior(self.rows, self.cols, self.symmetry)
            odd = sum(n % 2 for n in counts)
            pairs = sum(n // 2 for n in counts)
            if odd > fixed:
                axis = ("the centre column (odd cols)" if self.symmetry == "mirror"
                        else "the centre cell (odd rows and cols)")
                raise MapGenError(
                    f"{self.symmetry} symmetry pairs spawns and zones; an odd count needs a cell "
                    f"on {axis}: {self.rows}x{self.cols} has {fixed} such cells for {odd} odd "
                    f"count(s) among spawns={self.spawns}, zones={self.zones}")
            if pairs > (interior - fixed) // 2:
                raise MapGenError(f"{pairs} symmetric pairs do not fit in a "
                                  f"{self.rows}x{self.cols} map")

    def args(self) -> str:
        """The ``tools/mapgen.py generate`` options that rebuild this map."""
        zones = "random" if self.zones is None else f"{self.zones[0]},{self.zones[1]}"
        return (f"--size {self.rows}x{self.cols} --algorithm {self.algorithm} "
                f"--density {_exact(self.density)} --symmetry {self.symmetry} "
                f"--spawns {self.spawns} --zones {zones} --loops {_exact(self.loops)} "
                f"--seed {self.seed}")


def _exact(value: float) -> str:
    """``value`` as ``:g`` writes it when that reads back as the same number, else every
    digit it needs (0.2366864, not 0.236686: a rebuild would draw another map)."""
    text = f"{value:g}"
    return text if float(text) == value else repr(float(value))


def generate(rows: int = 11, cols: int = 11, algorithm: str = "maze", density: float = 0.25,
             symmetry: str = "none", spawns: int = 2, zones: tuple[int, int] | None = (2, 2),
             loops: float = 0.1, seed: int = 0, name: str | None = None) -> MapSpec:
    """A seeded, valid map. ``zones=None`` writes ``zones: random`` (the match draws them).

    ``density`` is the target wall fraction of the interior (``maze`` ignores it: the corridor
    lattice fixes it); ``loops`` is the fraction of single wall cells between two floor cells
    that are knocked out afterwards (a maze with loops > 0 is not a tree).
    """
    opts = GenOptions(rows, cols, algorithm, density, symmetry, spawns,
                      None if zones is None else (int(zones[0]), int(zones[1])), loops, seed)
    return generate_from(opts, name)


def check_name(name: str) -> str:
    """``name`` if it can be a map's ``name:`` header (one line of printable text, not blank);
    MapGenError otherwise (a line break would add header lines of its own)."""
    if not name.strip() or not name.isprintable():
        raise MapGenError(f"name must be one line of printable text, got {name!r}")
    return name


def generate_from(opts: GenOptions, name: str | None = None) -> MapSpec:
    """:func:`generate` from a :class:`GenOptions`."""
    if name is not None:
        check_name(name)
    rng = np.random.default_rng(opts.seed)
    layout = None
    for _ in range(_ATTEMPTS):
        layout = _attempt(rng, opts, fallback=False)
        if layout is not None:
            break
    if layout is None:  # an empty arena always fits (GenOptions checked the counts)
        layout = _attempt(rng, opts, fallback=True)
    if layout is None:
        raise MapGenError(f"could not place spawns and zones for {opts.args()}")
    walls, slots, buffs, debuffs = layout
    chars = np.where(walls, "#", ".").astype("<U1")
    for cells, ch in ((buffs, "+"), (debuffs, "-")):
        for rc in cells:
            chars[rc] = ch
    for slot, rc in slots.items():
        chars[rc] = str(slot)
    name = name or f"{opts.algorithm}_{opts.seed:04d}"
    head = [f"name: {name}", f"description: generated by tools/mapgen.py {opts.args()}"]
    if opts.zones is None:
        head.append("zones: random")
    text = "\n".join(head) + "\n\n" + "\n".join("".join(r) for r in chars) + "\n"
    return parse_map(text, f"<generated {name}>", name=name)


# ---- symmetry -----------------------------------------------------------------------------


def image(cell: tuple[int, int], shape: tuple[int, int], symmetry: str) -> tuple[int, int]:
    """The cell that ``cell`` maps to under ``symmetry``."""
    r, c = cell
    rows, cols = shape
    if symmetry == "mirror":
        return (r, cols - 1 - c)
    if symmetry == "rotational":
        return (rows - 1 - r, cols - 1 - c)
    return (r, c)


def transform(grid: np.ndarray, symmetry: str) -> np.ndarray:
    """``grid`` seen through the symmetry (a view): mirror flips columns, rotation both axes."""
    if symmetry == "mirror":
        return grid[:, ::-1]
    if symmetry == "rotational":
        return grid[::-1, ::-1]
    return grid


def _canonical(shape: tuple[int, int], symmetry: str) -> np.ndarray:
    """Cells that are their own image or come first (row-major) before it."""
    rows, cols = shape
    idx = np.arange(rows * cols).reshape(shape)
    return idx <= transform(idx, symmetry)


def _fixed_interior(rows: int, cols: int, symmetry: str) -> int:
    if symmetry == "mirror":
        return (rows - 2) if cols % 2 else 0
    if symmetry == "rotational":
        return 1 if rows % 2 and cols % 2 else 0
    return 0


# The symmetries of a rectangle (every map), then the four more of a square: name -> the
# image of a (rows, cols) array.
RECT_IMAGES = {"id": lambda g: g, "flipv": lambda g: g[::-1], "fliph": lambda g: g[:, ::-1],
               "rot180": lambda g: g[::-1, ::-1]}
SQUARE_IMAGES = {"rot90": lambda g: np.rot90(g, 1), "rot270": lambda g: np.rot90(g, 3),
                 "transpose": lambda g: g.T, "antitranspose": lambda g: np.rot90(g, 2).T}


def map_variants(spec: MapSpec) -> list[MapSpec]:
    """The distinct images of ``spec`` under the symmetries of its grid (4 for a rectangle,
    8 for a square): walls, spawns and zones move together, so each is the same layout
    seen turned or flipped. The original comes first under its own name, each other as
    ``<name>_<image>``; images equal to an earlier one are left out."""
    body = map_text(spec).partition("\n\n")[2]
    chars = np.array([list(row) for row in body.splitlines()])
    images = dict(RECT_IMAGES)
    if spec.rows == spec.cols:
        images.update(SQUARE_IMAGES)
    out, seen = [], set()
    for tag, image in images.items():
        grid = "\n".join("".join(row) for row in image(chars))
        if grid in seen:
            continue
        seen.add(grid)
        named = spec if tag == "id" else replace(
            spec, name=f"{spec.name}_{tag}",
            description=f"{spec.name} seen as {tag} (tools/mapgen.py variants)")
        head = map_text(named).partition("\n\n")[0]
        out.append(parse_map(f"{head}\n\n{grid}\n", f"{spec.source} ({tag})", name=named.name))
    return out


# ---- grid helpers -------------------------------------------------------------------------

def _touches(a: np.ndarray, b: np.ndarray, rr: np.ndarray, cc: np.ndarray) -> np.ndarray:
    """(n_segments, n_cells): does the segment between the centres of cells ``a[i]`` and
    ``b[i]`` touch the closed square of cell ``(rr[j], cc[j])``?"""
    # Doubled coordinates: centres are odd integers, cell corners even, so tests are exact.
    ax, ay = (2 * a[:, 1] + 1)[:, None], (2 * a[:, 0] + 1)[:, None]
    bx, by = (2 * b[:, 1] + 1)[:, None], (2 * b[:, 0] + 1)[:, None]
    dx, dy = bx - ax, by - ay
    # side(x, y) = dx (y - ay) - dy (x - ax) is linear: over a square with lower corner
    # (x0, y0) and side 2 it spans side(x0, y0) + [lo, hi]; the line meets the square iff
    # that span holds 0 (and the segment's bounding box overlaps the square).
    lo = np.minimum(0, -2 * dy) + np.minimum(0, 2 * dx)
    hi = np.maximum(0, -2 * dy) + np.maximum(0, 2 * dx)
    x0, y0 = (2 * cc)[None, :], (2 * rr)[None, :]
    side = dx * y0 - dy * x0 + (dy * ax - dx * ay)
    return ((side >= -hi) & (side <= -lo) & (x0 <= np.maximum(ax, bx))
            & (x0 + 2 >= np.minimum(ax, bx)) & (y0 <= np.maximum(ay, by))
            & (y0 + 2 >= np.minimum(ay, by)))


def lines_clear(walls: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """For segments between the centres of cells ``a[i]`` and ``b[i]`` ((n, 2) row, col):
    True where no wall cell touches the segment (closed cells: grazing a corner blocks)."""
    a = np.asarray(a, dtype=np.int64).reshape(-1, 2)
    b = np.asarray(b, dtype=np.int64).reshape(-1, 2)
    clear = np.ones(len(a), dtype=bool)
    wr, wc = np.nonzero(walls)
    step = max(1, _PAIR_CHUNK // max(len(a), 1))
    for s in range(0, len(wr), step):
        clear &= ~_touches(a, b, wr[s:s + step], wc[s:s + step]).any(axis=1)
    return clear


def segment_cells(shape: tuple[int, int], a: tuple[int, int], b: tuple[int, int]
                  ) -> np.ndarray:
    """Boolean grid of the cells the segment between the centres of ``a`` and ``b`` touches."""
    rr, cc = np.indices(shape)
    hit = _touches(np.array([a]), np.array([b]), rr.ravel(), cc.ravel())
    return hit.reshape(shape)


# ---- base layouts (wall grids; the border is added later) ---------------------------------


def _maze(rng: np.random.Generator, rows: int, cols: int) -> np.ndarray:
    """Recursive-backtracker corridor maze on the odd-coordinate lattice."""
    walls = np.ones((rows, cols), dtype=bool)
    lat_r, lat_c = range(1, rows - 1, 2), range(1, cols - 1, 2)
    start = (lat_r[int(rng.integers(len(lat_r)))], lat_c[int(rng.integers(len(lat_c)))])
    walls[start] = False
    stack = [start]
    while stack:
        r, c = stack[-1]
        nbrs = [(r + 2 * dr, c + 2 * dc) for dr, dc in STEPS
                if 1 <= r + 2 * dr < rows - 1 and 1 <= c + 2 * dc < cols - 1
                and walls[r + 2 * dr, c + 2 * dc]]
        if not nbrs:
            stack.pop()
            continue
        nr, nc = nbrs[int(rng.integers(len(nbrs)))]
        walls[(r + nr) // 2, (c + nc) // 2] = False
        walls[nr, nc] = False
        stack.append((nr, nc))
    if rows % 2 == 0:  # a spare row: repeat the last lattice row (wider corridors there)
        walls[rows - 2, 1:-1] = walls[rows - 3, 1:-1]
    if cols % 2 == 0:
        walls[1:-1, cols - 2] = walls[1:-1, cols - 3]
    return walls


def _rooms(rng: np.random.Generator, rows: int, cols: int, density: float) -> np.ndarray:
    """Recursive division: split the largest room by a wall with doors until dense enough."""
    walls = np.zeros((rows, cols), dtype=bool)
    walls[[0, -1], :] = walls[:, [0, -1]] = True
    interior = (rows - 2) * (cols - 2)
    min_side = 2
    rooms = [(1, 1, rows - 1, cols - 1)]  # r0, c0, r1, c1 (end-exclusive)
    while rooms and walls[1:-1, 1:-1].sum() < density * interior:
        rooms.sort(key=lambda q: (q[2] - q[0]) * (q[3] - q[1]))
        r0, c0, r1, c1 = rooms.pop()
        h, w = r1 - r0, c1 - c0
        across_rows = h > w or (h == w and rng.random() < 0.5)
        if across_rows:  # a horizontal wall at row r; its ends must meet walls, not doors
            cands = [r for r in range(r0 + min_side, r1 - min_side)
                     if walls[r, c0 - 1] and walls[r, c1]]
        else:
            cands = [c for c in range(c0 + min_side, c1 - min_side)
                     if walls[r0 - 1, c] and walls[r1, c]]
        if not cands:
            continue
        k = cands[int(rng.integers(len(cands)))]
        length = w if across_rows else h
        n_doors = 1 + int(length >= 8 and rng.random() < 0.5)
        width = 1 + int(length >= 6 and rng.random() < 0.5)
        line = np.ones(length, dtype=bool)
        for d in rng.choice(length - width + 1, size=n_doors, replace=False):
            line[d:d + width] = False
        if across_rows:
            walls[k, c0:c1] = line
            rooms += [(r0, c0, k, c1), (k + 1, c0, r1, c1)]
        else:
            walls[r0:r1, k] = line
            rooms += [(r0, c0, r1, k), (r0, k + 1, r1, c1)]
    return walls


def _open(rng: np.random.Generator, rows: int, cols: int, density: float) -> np.ndarray:
    """An arena with pillars, bars and blocks, each kept one floor cell from the others."""
    walls = np.zeros((rows, cols), dtype=bool)
    walls[[0, -1], :] = walls[:, [0, -1]] = True
    interior = (rows - 2) * (cols - 2)
    shapes = [(h, w) for h, w in ((1, 1), (1, 2), (2, 1), (1, 3), (3, 1), (2, 2), (1, 4), (4, 1))
              if h <= rows - 4 and w <= cols - 4]
    placed = 0
    for _ in range(100):
        if placed >= density * interior or not shapes:
            break
        h, w = shapes[int(rng.integers(len(shapes)))]
        r = 2 + int(rng.integers(rows - 4 - h + 1))
        c = 2 + int(rng.integers(cols - 4 - w + 1))
        if not walls[r - 1:r + h + 1, c - 1:c + w + 1].any():
            walls[r:r + h, c:c + w] = True
            placed += h * w
    return walls


def _scatter(rng: np.random.Generator, rows: int, cols: int, density: float) -> np.ndarray:
    """Independent wall cells with probability ``density``."""
    return rng.random((rows, cols)) < density


# ---- the pipeline -------------------------------------------------------------------------

Layout = tuple[np.ndarray, dict[int, tuple[int, int]], list[tuple[int, int]],
               list[tuple[int, int]]]


def _attempt(rng: np.random.Generator, opts: GenOptions, fallback: bool) -> Layout | None:
    """One try: base layout, symmetry, border, axis cells for odd counts, connectivity,
    loops, then spawns and zones (None when they do not fit). ``fallback``: empty arena."""
    rows, cols, sym = opts.rows, opts.cols, opts.symmetry
    if fallback:
        walls = _open(rng, rows, cols, 0.0)
    elif opts.algorithm == "maze":
        walls = _maze(rng, rows, cols)
    elif opts.algorithm == "rooms":
        walls = _rooms(rng, rows, cols, opts.density)
    elif opts.algorithm == "scatter":
        walls = _scatter(rng, rows, cols, opts.density)
    else:
        walls = _open(rng, rows, cols, opts.density)
    walls = np.where(_canonical(walls.shape, sym), walls, transform(walls, sym))
    walls[[0, -1], :] = walls[:, [0, -1]] = True
    if walls.all():
        _carve(walls, _random_cell(rng, _interior(walls.shape)), sym)
    if sym != "none":
        axis = _axis_cells(walls.shape, sym)
        need = sum(n % 2 for n in (opts.spawns, *(opts.zones or (0, 0))))
        while need > int((axis & ~walls).sum()):
            _carve(walls, _random_cell(rng, axis & walls), sym)
    _connect(walls, sym)
    _add_loops(rng, walls, sym, opts.loops)
    placed = _place(rng, walls, sym, opts.spawns, opts.zones or (0, 0))
    if placed is None:
        return None
    return (walls, *placed)


def _interior(shape: tuple[int, int]) -> np.ndarray:
    inner = np.zeros(shape, dtype=bool)
    inner[1:-1, 1:-1] = True
    return inner


def _axis_cells(shape: tuple[int, int], symmetry: str) -> np.ndarray:
    """Interior cells that are their own image."""
    rows, cols = shape
    idx = np.arange(rows * cols).reshape(shape)
    return (idx == transform(idx, symmetry)) & _interior(shape)


def _random_cell(rng: np.random.Generator, mask: np.ndarray) -> tuple[int, int]:
    cells = np.argwhere(mask)
    r, c = cells[int(rng.integers(len(cells)))]
    return int(r), int(c)


def _carve(walls: np.ndarray, cell: tuple[int, int], symmetry: str) -> None:
    walls[cell] = False
    walls[image(cell, walls.shape, symmetry)] = False


def _connect(walls: np.ndarray, symmetry: str) -> None:
    """Carve the cheapest interior wall paths (and their images) from every floor region to
    the largest one until all floor is one region."""
    inner = _interior(walls.shape)
    while True:
        labels, k = components(walls)
        if k <= 1:
            return
        main = int(np.argmax(np.bincount(labels[labels >= 0])))
        # 0-1 BFS from the main region: entering an interior wall costs 1, floor 0.
        cost = np.where(labels == main, 0, walls.size)
        prev: dict[tuple[int, int], tuple[int, int]] = {}
        queue: deque[tuple[int, int]] = deque((int(r), int(c))
                                              for r, c in np.argwhere(labels == main))
        best: dict[int, tuple[int, int]] = {}  # region -> its first (cheapest) cell reached
        while queue:
            r, c = queue.popleft()
            lab = int(labels[r, c])
            if lab >= 0 and lab != main:
                best.setdefault(lab, (r, c))
            for dr, dc in STEPS:
                nr, nc = r + dr, c + dc
                if walls[nr, nc] and not inner[nr, nc]:
                    continue
                step = int(walls[nr, nc])
                if cost[r, c] + step < cost[nr, nc]:
                    cost[nr, nc] = cost[r, c] + step
                    prev[(nr, nc)] = (r, c)
                    if step:
                        queue.append((nr, nc))
                    else:
                        queue.appendleft((nr, nc))
        joined = {main}
        for lab, cell in sorted(best.items(), key=lambda kv: (cost[kv[1]], kv[0])):
            if lab in joined:
                continue
            while cell in prev:
                if walls[cell]:
                    _carve(walls, cell, symmetry)
                elif labels[cell] >= 0:
                    joined.add(int(labels[cell]))
                cell = prev[cell]


def _add_loops(rng: np.random.Generator, walls: np.ndarray, symmetry: str,
               fraction: float) -> None:
    """Knock out ``fraction`` of the single wall cells between two floor cells in a line."""
    if fraction <= 0:
        return
    f = np.pad(~walls, 1, constant_values=False)
    up, down, left, right = f[:-2, 1:-1], f[2:, 1:-1], f[1:-1, :-2], f[1:-1, 2:]
    thin = (up & down & ~left & ~right) | (left & right & ~up & ~down)
    cands = np.argwhere(walls & thin & _interior(walls.shape)
                        & _canonical(walls.shape, symmetry))
    k = int(round(fraction * len(cands)))
    if k:
        for i in rng.choice(len(cands), size=k, replace=False):
            _carve(walls, (int(cands[i][0]), int(cands[i][1])), symmetry)


def _place(rng: np.random.Generator, walls: np.ndarray, symmetry: str, n_spawns: int,
           zones: tuple[int, int]) -> tuple[dict[int, tuple[int, int]], list, list] | None:
    """Spawn slots far apart (avoiding dead ends and lines of fire), then zones."""
    shape = walls.shape
    sym = symmetry != "none"
    floor = ~walls
    canon = _canonical(shape, symmetry)
    axis = _axis_cells(shape, symmetry) if sym else np.zeros(shape, dtype=bool)
    pair_ok = floor & canon & ~axis if sym else floor.copy()
    axis_ok = floor & axis
    used = np.zeros(shape, dtype=bool)
    dead = open_sides(walls) <= 1
    dists: list[np.ndarray] = []
    seen: list[np.ndarray] = []  # cells with a line of fire from each chosen spawn
    floor_cells = np.argwhere(floor)
    self_gap = _self_gap(walls, symmetry)
    slots: dict[int, tuple[int, int]] = {}
    half = n_spawns // 2 if sym else n_spawns
    order = [(i, True) for i in range(1, half + 1)]
    if sym and n_spawns % 2:
        order.append((n_spawns, False))
    for slot, paired in order:
        mask = (pair_ok if paired else axis_ok) & ~used
        cells = np.argwhere(mask)
        if not len(cells):
            return None
        cell = _pick_spawn(rng, walls, cells, dists, seen, dead, self_gap if paired else None,
                           symmetry)
        for c in {cell, image(cell, shape, symmetry)}:
            used[c] = True
            dists.append(distance_field(walls, [c]))
            vis = np.zeros(shape, dtype=bool)
            clear = lines_clear(walls, np.broadcast_to(c, floor_cells.shape), floor_cells)
            vis[floor_cells[clear, 0], floor_cells[clear, 1]] = True
            seen.append(vis)
        slots[slot] = cell
        if sym and paired:
            slots[slot + half] = image(cell, shape, symmetry)
    near = np.zeros(shape, dtype=bool)
    for d in dists:
        near |= (d >= 0) & (d <= 1)
    placed: list[list[tuple[int, int]]] = []
    for count in zones:
        cells_out: list[tuple[int, int]] = []
        kinds = ([True] * (count // 2) + [False] * (count % 2)) if sym else [True] * count
        for paired in kinds:
            base = (pair_ok if paired else axis_ok) & ~used
            pool = np.argwhere(base & ~near)
            if not len(pool):
                pool = np.argwhere(base)
            if not len(pool):
                return None
            r, c = pool[int(rng.integers(len(pool)))]
            for cell in {(int(r), int(c)), image((int(r), int(c)), shape, symmetry)}:
                used[cell] = True
                cells_out.append(cell)
        placed.append(sorted(cells_out))
    return dict(sorted(slots.items())), placed[0], placed[1]


def _self_gap(walls: np.ndarray, symmetry: str) -> np.ndarray | None:
    """Path length from each cell to its own image (Manhattan for rotation)."""
    rows, cols = walls.shape
    if symmetry == "mirror":
        if cols % 2:
            axis = [(int(r), cols // 2) for r in np.flatnonzero(~walls[:, cols // 2])]
            d = distance_field(walls, axis)
            return np.where(d >= 0, 2 * d, -1)
        axis = [(int(r), cols // 2 - 1) for r in np.flatnonzero(~walls[:, cols // 2 - 1])]
        d = distance_field(walls, axis)
        return np.where(d >= 0, 2 * d + 1, -1)
    if symmetry == "rotational":
        r, c = np.indices(walls.shape)
        return np.abs(2 * r - (rows - 1)) + np.abs(2 * c - (cols - 1))
    return None


def _pick_spawn(rng: np.random.Generator, walls: np.ndarray, cells: np.ndarray,
                dists: list[np.ndarray], seen: list[np.ndarray], dead: np.ndarray,
                self_gap: np.ndarray | None, symmetry: str) -> tuple[int, int]:
    """A random cell among the farthest from spawns so far, preferring cells that are not
    dead ends and have no line of fire to a chosen spawn (or to their own image)."""
    rr, cc = cells[:, 0], cells[:, 1]
    far = np.full(len(cells), walls.size, dtype=np.int64)
    for d in dists:
        far = np.minimum(far, d[rr, cc])
    if self_gap is not None:
        far = np.minimum(far, self_gap[rr, cc])
    if not dists and self_gap is None:
        far = np.zeros(len(cells), dtype=np.int64)  # first spawn of an asymmetric map: anywhere
    safe = np.ones(len(cells), dtype=bool)
    for vis in seen:
        safe &= ~vis[rr, cc]
    if self_gap is not None:
        imgs = np.array([image((int(r), int(c)), walls.shape, symmetry) for r, c in cells])
        safe &= ~lines_clear(walls, cells, imgs)
    ok_far = far >= far.max() // 2
    for pref in (ok_far & safe & ~dead[rr, cc], ok_far & ~dead[rr, cc], ok_far & safe, ok_far):
        if pref.any():
            top = pref & (far >= int(0.75 * far[pref].max()))
            i = np.flatnonzero(top)[int(rng.integers(int(top.sum())))]
            return int(rr[i]), int(cc[i])
    raise AssertionError("unreachable: ok_far holds the farthest cell")

"""Maze maps: text format parser, validation and wall merging.

Format (RULES.md): optional ``key: value`` header lines, a blank line, then the grid, one
character per cell: ``#`` wall, ``.`` floor, ``1``-``8`` spawn of tank slot N, ``+`` buff
zone, ``-`` debuff zone. Lines starting with ``;`` are comments, and so is the rest of a
``cell`` or ``zones`` header line from a ``;`` (in free-text values, ``;`` is text).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np

from alphatank.errors import InputError
from alphatank.files import read_text, text_lines
from alphatank.sim.grid import components, floor_areas, reachable_from

GRID_CHARS = "#.12345678+-"
HEADER_KEYS = ("name", "cell", "description", "zones", "author")
COMMENT_KEYS = ("cell", "zones")  # values never hold ';': the rest of the line is a comment
DEFAULT_CELL = 70.0
# px per cell: the default 30 x 24 px tank turns in one (its diagonal is 38.4 px; a match
# checks the game's tank size), worlds stay drawable
CELL_RANGE = (39.0, 400.0)
MAX_GRID = 128  # cells each way
MAX_MAP_BYTES = 1 << 20  # a map file's size (a 128 x 128 grid takes 16.5 KiB)
MAX_FLOOR = 64 * 64  # floor cells: navigation keeps (F, F) tables (64 MiB each at most)
MAX_WORLD = MAX_GRID * DEFAULT_CELL  # px each way: the bots' 5 px clearance raster


class MapError(InputError, ValueError):
    """A map file is malformed; names the file, line and column (1-based)."""

    def __init__(self, message: str, source: str = "<string>", line: int = 0, col: int = 0):
        self.message, self.source, self.line, self.col = message, source, line, col
        where = source
        if line:
            where += f":{line}"
            if col:
                where += f":{col}"
        super().__init__(f"{where}: {message}")


@dataclass(frozen=True)
class MapSpec:
    """A parsed, validated map. Cells are (row, col); pixels are (x, y) with y down."""

    name: str
    walls: np.ndarray  # (rows, cols) bool
    spawns: dict[int, tuple[int, int]]  # slot (1-based) -> cell
    buffs: tuple[tuple[int, int], ...]
    debuffs: tuple[tuple[int, int], ...]
    cell: float = DEFAULT_CELL
    description: str = ""
    author: str = ""
    random_zones: bool = False
    source: str = "<string>"
    wall_rects: tuple[tuple[float, float, float, float], ...] = field(default=())

    @property
    def rows(self) -> int:
        return int(self.walls.shape[0])

    @property
    def cols(self) -> int:
        return int(self.walls.shape[1])

    @property
    def width(self) -> float:
        return self.cols * self.cell

    @property
    def height(self) -> float:
        return self.rows * self.cell

    def cell_center(self, cell: tuple[int, int]) -> tuple[float, float]:
        r, c = cell
        return ((c + 0.5) * self.cell, (r + 0.5) * self.cell)

    def floor_cells(self) -> tuple[tuple[int, int], ...]:
        """Every floor cell, row by row (found once per map)."""
        return self._floor_cells

    @functools.cached_property
    def _floor_cells(self) -> tuple[tuple[int, int], ...]:
        return tuple((int(r), int(c)) for r, c in zip(*np.nonzero(~self.walls), strict=True))

    def reachable(self, cell: tuple[int, int]) -> np.ndarray:
        """(rows, cols) bool: the floor cells reachable from the floor cell ``cell``
        (:func:`~alphatank.sim.grid.reachable_from`, from areas labelled once per map)."""
        labels = self._area_labels
        return labels == labels[cell]

    @functools.cached_property
    def _area_labels(self) -> np.ndarray:
        return components(self.walls)[0]

    def min_wall_thickness(self) -> float:
        """Thinnest wall dimension in px (a cell, or thinner if a map defines thin walls)."""
        return self.cell

    def free_cells_in(self, area: np.ndarray, taken: set[tuple[int, int]] = frozenset()
                      ) -> int:
        """Floor cells of the boolean grid ``area`` that are neither zones nor ``taken``."""
        zones = set(self.buffs) | set(self.debuffs) | set(taken)
        return sum(1 for r, c in zip(*np.nonzero(area & ~self.walls), strict=True)
                   if (int(r), int(c)) not in zones)

    def tank_room(self, n: int) -> int:
        """How many of ``n`` tanks a match can place (as :class:`~alphatank.sim.match.Match`
        does): the spawns of slots 1..n, plus free floor (no zone, no such spawn) reachable
        from the first of them; without such spawns, the roomiest floor area."""
        used = {self.spawns[s] for s in range(1, n + 1) if s in self.spawns}
        if used:
            first = self.spawns[min(s for s in self.spawns if s <= n)]
            areas = [reachable_from(self.walls, first)]
        else:
            areas = floor_areas(self.walls)
        return max(len(used) + self.free_cells_in(a, used) for a in areas)


def merge_walls(walls: np.ndarray) -> list[tuple[int, int, int, int]]:
    """Cover wall cells with few axis-aligned rectangles (r0, c0, r1, c1), end-exclusive.

    Greedy: take the first uncovered wall cell in row-major order, extend right as far as
    possible, then down while the whole run is wall and uncovered.
    """
    todo = walls.copy()
    rows, cols = todo.shape
    rects = []
    for r in range(rows):
        c = 0
        while c < cols:
            if not todo[r, c]:
                c += 1
                continue
            c1 = c
            while c1 < cols and todo[r, c1]:
                c1 += 1
            r1 = r + 1
            while r1 < rows and todo[r1, c:c1].all():
                r1 += 1
            todo[r:r1, c:c1] = False
            rects.append((r, c, r1, c1))
            c = c1
    return rects


def parse_map(text: str, source: str = "<string>", name: str | None = None) -> MapSpec:
    """Parse and validate map text; raises MapError naming source, line and column."""
    lines = text_lines(text.removeprefix("\ufeff"))
    header: dict[str, str] = {}
    grid: list[tuple[int, str]] = []  # (1-based line number, row text)
    i = 0
    content = [(n + 1, ln.rstrip("\r")) for n, ln in enumerate(lines)
               if not ln.lstrip().startswith(";")]
    # Header: lines with ':' before the first blank line.
    while i < len(content) and not content[i][1].strip():
        i += 1
    if i < len(content) and ":" in content[i][1]:
        while i < len(content) and content[i][1].strip():
            lineno, ln = content[i]
            if ":" not in ln:
                raise MapError("header line must be 'key: value' (end the header with a blank "
                               "line before the grid)", source, lineno, 1)
            key, value = (p.strip() for p in ln.split(":", 1))
            if key in COMMENT_KEYS:
                value = value.split(";", 1)[0].rstrip()
            if key not in HEADER_KEYS:
                raise MapError(f"unknown header key {key!r}; valid keys: {list(HEADER_KEYS)}",
                               source, lineno, 1)
            if key in header:
                raise MapError(f"duplicate header key {key!r}", source, lineno, 1)
            header[key] = value
            i += 1
    while i < len(content) and not content[i][1].strip():
        i += 1
    rows = 0
    for lineno, ln in content[i:]:
        row = ln.rstrip()
        if not row:
            if grid:
                grid.append((lineno, ""))
            continue
        rows += 1  # stop at the first row too many, not after the whole file
        if len(row) > MAX_GRID:
            raise MapError(f"row of {len(row)} cells; a grid has at most {MAX_GRID} each way",
                           source, lineno, MAX_GRID + 1)
        if rows > MAX_GRID:
            raise MapError(f"grid of over {MAX_GRID} rows; at most {MAX_GRID} each way",
                           source, lineno, 1)
        grid.append((lineno, row))
    while grid and not grid[-1][1]:
        grid.pop()
    if not grid:
        raise MapError("empty map: no grid rows", source, len(lines) or 1, 0)
    width = len(grid[0][1])
    for lineno, row in grid:
        if not row:
            raise MapError("blank line inside the grid", source, lineno, 1)
        for c, ch in enumerate(row):  # before the width: a tab or space is not a cell
            if ch not in GRID_CHARS:
                raise MapError(f"unknown character {ch!r}; allowed: '#' wall, '.' floor, "
                               "'1'-'8' spawn, '+' buff, '-' debuff", source, lineno, c + 1)
        if len(row) != width:
            raise MapError(f"ragged row: {len(row)} cells, expected {width} like the first row",
                           source, lineno, min(len(row), width) + 1)

    cell = DEFAULT_CELL
    if "cell" in header:
        try:
            cell = float(header["cell"])
        except ValueError:
            cell = -1.0
        lo, hi = CELL_RANGE
        if not lo <= cell <= hi:
            raise MapError(f"header 'cell' must be a positive number of px in [{lo:g}, "
                           f"{hi:g}], got {header['cell']!r}", source,
                           _header_line(content, "cell"), 1)
    if max(len(grid), width) * cell > MAX_WORLD:
        raise MapError(f"world of {width * cell:g} x {len(grid) * cell:g} px ({len(grid)} x "
                       f"{width} cells of {cell:g} px); at most {MAX_WORLD:g} px each way",
                       source, _header_line(content, "cell") or grid[0][0], 1)
    zones = header.get("zones", "")
    if zones not in ("", "random", "fixed"):
        raise MapError(f"header 'zones' must be 'random' or 'fixed', got {zones!r}",
                       source, _header_line(content, "zones"), 1)

    walls = np.zeros((len(grid), width), dtype=bool)
    spawns: dict[int, tuple[int, int]] = {}
    spawn_where: dict[int, tuple[int, int]] = {}
    buffs, debuffs = [], []
    for r, (lineno, row) in enumerate(grid):
        for c, ch in enumerate(row):
            if ch == "#":
                walls[r, c] = True
            elif ch.isdigit():
                slot = int(ch)
                if slot in spawns:
                    pl, pc = spawn_where[slot]
                    raise MapError(f"duplicate spawn {slot} (first at line {pl}, column {pc})",
                                   source, lineno, c + 1)
                spawns[slot] = (r, c)
                spawn_where[slot] = (lineno, c + 1)
            elif ch == "+":
                buffs.append((r, c))
            elif ch == "-":
                debuffs.append((r, c))
    if walls.all():
        raise MapError("map has no floor cells", source, grid[0][0], 1)
    if (~walls).sum() > MAX_FLOOR:
        raise MapError(f"{(~walls).sum()} floor cells (anything but '#'); at most {MAX_FLOOR}",
                       source, grid[0][0], 1)

    if spawns:
        first = min(spawns)
        reach = reachable_from(walls, spawns[first])
        for slot, rc in sorted(spawns.items()):
            if not reach[rc]:
                lineno, col = spawn_where[slot]
                raise MapError(f"spawn {slot} cannot be reached from spawn {first}",
                               source, lineno, col)
    rects = tuple((c0 * cell, r0 * cell, c1 * cell, r1 * cell)
                  for r0, c0, r1, c1 in merge_walls(walls))
    spec = MapSpec(
        name=header.get("name") or name or Path(source).stem,
        walls=walls, spawns=spawns, buffs=tuple(buffs), debuffs=tuple(debuffs), cell=cell,
        description=header.get("description", ""), author=header.get("author", ""),
        random_zones=zones == "random",
        source=source, wall_rects=rects)
    if spawns:
        top = max(spawns)
        room = spec.tank_room(top)
        if room < top:
            lineno, col = spawn_where[top]
            raise MapError(f"spawn slots go up to {top} but only {room} tank(s) fit: too "
                           f"few free floor cells (no zone) reachable from spawn {min(spawns)}",
                           source, lineno, col)
    return spec


def _header_line(content: list[tuple[int, str]], key: str) -> int:
    for lineno, ln in content:
        if ln.split(":", 1)[0].strip() == key:
            return lineno
    return 0


def map_text(spec: MapSpec) -> str:
    """Serialise a MapSpec back to the text format (round-trips through parse_map)."""
    chars = np.where(spec.walls, "#", ".").astype("<U1")
    for cells, ch in ((spec.buffs, "+"), (spec.debuffs, "-")):
        for r, c in cells:
            chars[r, c] = ch
    for slot, (r, c) in spec.spawns.items():
        chars[r, c] = str(slot)
    head = [f"name: {spec.name}"]
    if spec.cell != DEFAULT_CELL:
        head.append(f"cell: {spec.cell:g}")
    if spec.description:
        head.append(f"description: {spec.description}")
    if spec.random_zones:
        head.append("zones: random")
    if spec.author:
        head.append(f"author: {spec.author}")
    return "\n".join(head) + "\n\n" + "\n".join("".join(row) for row in chars) + "\n"


def shipped_maps(folder: str | None = None) -> list[str]:
    """Names of the maps shipped with the package (in its top folder, or in ``folder``,
    e.g. ``"train"``: then named ``"train/maze_0000"``, as :func:`load_map` takes them)."""
    root = resources.files("alphatank.maps")
    if folder is not None:
        root = root.joinpath(folder)
    prefix = f"{folder}/" if folder else ""
    return sorted(prefix + p.name[:-4] for p in root.iterdir() if p.name.endswith(".txt"))


def shipped_map_folders() -> list[str]:
    """Folders of shipped maps (``train``, ``test``): a scenario's ``map`` may name one."""
    root = resources.files("alphatank.maps")
    return sorted(p.name for p in root.iterdir()
                  if p.is_dir() and any(q.name.endswith(".txt") for q in p.iterdir()))


def is_shipped_map(name: str) -> bool:
    """Whether ``name`` names a shipped map as :func:`load_map` takes it (``"maze"``,
    ``"train/maze_0000"``)."""
    folder = name.rpartition("/")[0]
    if folder and folder not in shipped_map_folders():
        return False
    return name in shipped_maps(folder or None)


def load_map(name_or_path: str | Path) -> MapSpec:
    """Load a shipped map by name (``"maze"``, ``"train/maze_0000"``; a file or folder of
    that name in the working folder does not hide it) or any map file by path."""
    if not str(name_or_path):  # Path("") is the current folder
        raise MapError("empty map name or path; give a shipped map's name (e.g. 'maze') or a "
                       ".txt file", "''")
    path = Path(name_or_path)
    named = isinstance(name_or_path, str) and is_shipped_map(name_or_path)
    if not named and (path.suffix == ".txt" or path.exists()):
        if path.is_dir():
            raise MapError("is a folder, not a map file (.txt)", str(path))
        if not path.is_file():
            raise MapError("not a file (a device or pipe)" if path.exists() else
                           "no such map file", str(path))
        try:
            text = read_text(path, MAX_MAP_BYTES, "map file")
        except ValueError as exc:
            raise MapError(str(exc).removeprefix(f"{path}: "), str(path)) from None
        return parse_map(text, str(path), name=path.stem)
    res = resources.files("alphatank.maps").joinpath(f"{name_or_path}.txt")
    if not res.is_file():
        raise MapError(f"unknown map {str(name_or_path)!r}; shipped maps: {shipped_maps()} "
                       "(or give a path to a .txt file)", str(name_or_path))
    return parse_map(res.read_text(encoding="utf-8"), f"maps/{name_or_path}.txt",
                     name=str(name_or_path))

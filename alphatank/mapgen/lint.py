"""Lint warnings on top of the loader's validation, and text previews of a map.

- :func:`map_warnings`: spawns with a line of fire to another spawn at the start, dead-end
  spawns, unreachable zones and floor, skipped spawn slots.
- :func:`ascii_art` / :func:`describe`: a terminal picture and a one-line summary.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

from alphatank.files import decode_text, read_text, text_lines
from alphatank.mapgen.generate import lines_clear, segment_cells
from alphatank.sim.grid import components, open_sides
from alphatank.sim.mapspec import MapError, MapSpec, load_map, map_text


@dataclass(frozen=True)
class MapWarning:
    """A legal but questionable map feature, at a 1-based file line and column."""

    code: str  # line-of-fire | dead-end-spawn | unreachable-zone | isolated-floor |
    # spawn-slots | ignored-zones
    message: str
    line: int
    col: int
    source: str = "<string>"

    def __str__(self) -> str:
        return f"{self.source}:{self.line}:{self.col}: warning: {self.message} [{self.code}]"


def grid_lines(text: str, rows: int) -> list[int]:
    """1-based file line of each grid row of valid map ``text`` (the last ``rows`` lines that
    are neither blank nor ``;`` comments, as :func:`parse_map` reads them)."""
    lines = [n + 1 for n, ln in enumerate(text_lines(text))
             if ln.rstrip() and not ln.lstrip().startswith(";")]
    return lines[-rows:]


def map_warnings(spec: MapSpec, text: str | None = None,
                 teams: Sequence[str] | None = None) -> list[MapWarning]:
    """Warnings for a valid map; positions refer to ``text`` (default: ``map_text(spec)``).

    ``teams`` (team of slot 1, 2, ...) limits line-of-fire warnings to enemies; by default
    every pair of spawns counts."""
    lines = grid_lines(text if text is not None else map_text(spec), spec.rows)
    walls = spec.walls

    def warn(code: str, message: str, cell: tuple[int, int]) -> MapWarning:
        return MapWarning(code, message, lines[cell[0]], cell[1] + 1, spec.source)

    def where(cell: tuple[int, int]) -> str:
        return f"line {lines[cell[0]]}, column {cell[1] + 1}"

    out: list[MapWarning] = []
    slots = sorted(spec.spawns)
    missing = sorted(set(range(1, slots[-1] + 1)) - set(slots)) if slots else []
    if missing:
        out.append(warn("spawn-slots", f"spawn slots skip {missing}: a match with "
                        f"{slots[-1]} tanks draws those at random", spec.spawns[slots[-1]]))
    drawn = sorted(spec.buffs + spec.debuffs)
    if spec.random_zones and drawn:
        out.append(warn("ignored-zones", f"{len(drawn)} '+'/'-' zone cell(s), the first here, are "
                        "ignored: 'zones: random' draws each match's zones (drop the cells or "
                        "the header)", drawn[0]))
    sides = open_sides(walls)
    for slot in slots:
        cell = spec.spawns[slot]
        if sides[cell] <= 1:
            what = "is walled in" if sides[cell] == 0 else "is in a dead end (one open side)"
            out.append(warn("dead-end-spawn", f"spawn {slot} {what}", cell))
    pairs = [(a, b) for i, a in enumerate(slots) for b in slots[i + 1:]
             if teams is None or a > len(teams) or b > len(teams)
             or teams[a - 1] != teams[b - 1]]
    if pairs:
        clear = lines_clear(walls, np.array([spec.spawns[a] for a, _ in pairs]),
                            np.array([spec.spawns[b] for _, b in pairs]))
        for (a, b), ok in zip(pairs, clear, strict=True):
            if ok:
                out.append(warn("line-of-fire", f"spawn {a} has a direct line of fire to spawn "
                                f"{b} ({where(spec.spawns[b])}) at the start", spec.spawns[a]))
    labels, k = components(walls)
    if k:
        if slots:
            main, ref = int(labels[spec.spawns[slots[0]]]), f"spawn {slots[0]}"
        else:
            main, ref = int(np.argmax(np.bincount(labels[labels >= 0]))), "the largest floor area"
        for kind, cells in (("buff", spec.buffs), ("debuff", spec.debuffs)):
            for cell in cells:
                if labels[cell] != main:
                    out.append(warn("unreachable-zone",
                                    f"{kind} zone cannot be reached from {ref}", cell))
        for lab in range(k):
            if lab != main:
                members = np.argwhere(labels == lab)
                first = (int(members[0][0]), int(members[0][1]))
                out.append(warn("isolated-floor", f"{len(members)} floor cell(s) here cannot be "
                                f"reached from {ref}; random zones or tanks drawn there are cut "
                                "off", first))
    return sorted(out, key=lambda w: (w.line, w.col, w.code))


def check_map(name_or_path: str | Path, teams: Sequence[str] | None = None
              ) -> tuple[MapSpec, list[MapWarning]]:
    """Load a map with the game's loader (raising its MapError) and lint it; with
    ``teams``, MapError too if the map has no room for that many tanks."""
    spec = load_map(name_or_path)
    if teams and spec.tank_room(len(teams)) < len(teams):
        raise MapError(f"room for {spec.tank_room(len(teams))} tank(s) (free floor reachable "
                       f"from the spawns), --teams {''.join(teams)} asks for {len(teams)}",
                       spec.source)
    path = Path(name_or_path)
    if path.is_file():
        text = read_text(path)
    else:
        text = decode_text(resources.files("alphatank.maps").joinpath(
            f"{name_or_path}.txt").read_bytes())
    return spec, map_warnings(spec, text, teams)


# ---- previews -----------------------------------------------------------------------------

_ART = {"#": "##", ".": ". ", "+": "+ ", "-": "- "}


def ascii_art(spec: MapSpec, show_fire: bool = False) -> str:
    """The grid two characters per cell (square-ish in a terminal): ``##`` wall, ``.`` floor,
    digits spawns, ``+``/``-`` zones; ``show_fire`` marks floor on lines of fire with ``*``."""
    grid = map_text(spec).splitlines()[-spec.rows:]
    fire = np.zeros(spec.walls.shape, dtype=bool)
    if show_fire:
        slots = sorted(spec.spawns)
        for i, a in enumerate(slots):
            for b in slots[i + 1:]:
                pa, pb = spec.spawns[a], spec.spawns[b]
                if lines_clear(spec.walls, np.array([pa]), np.array([pb]))[0]:
                    fire |= segment_cells(spec.walls.shape, pa, pb)
    out = []
    for r, row in enumerate(grid):
        out.append("".join("* " if fire[r, c] and ch == "." else _ART.get(ch, ch + " ")
                           for c, ch in enumerate(row)).rstrip())
    return "\n".join(out)


def describe(spec: MapSpec) -> str:
    """One line: size, wall share, spawns and zones."""
    inner = spec.walls[1:-1, 1:-1]
    walls = f"{inner.mean():.0%} interior walls" if inner.size else "no interior"
    zones = ("random" if spec.random_zones
             else f"{len(spec.buffs)} buff, {len(spec.debuffs)} debuff")
    return (f"{spec.name}: {spec.rows} rows x {spec.cols} cols of {spec.cell:g} px, "
            f"{walls}, {len(spec.spawns)} spawn slot(s), "
            f"zones {zones}")

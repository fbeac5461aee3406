"""The editable map grid behind the pygame editor: paint, undo, redo, and a save that
refuses invalid maps with the loader's own message."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from alphatank.files import read_text, text_lines, write_text_atomic
from alphatank.mapgen.generate import MAX_SIZE, MapGenError
from alphatank.sim.mapspec import (
    GRID_CHARS,
    HEADER_KEYS,
    MAX_MAP_BYTES,
    MapError,
    MapSpec,
    parse_map,
)

TOOLS = GRID_CHARS  # '#', '.', '1'..'8', '+', '-'
# Where a whole-line ';' comment goes back on save: before the header ("top"), before a header
# key ("key", name), after the header lines ("head"), before grid row r ("row", r), at the end.
Anchor = tuple[str, str | int]
TOP: Anchor = ("top", "")
HEAD: Anchor = ("head", "")
END: Anchor = ("end", "")


@dataclass
class EditorModel:
    """An editable map grid with undo/redo; :meth:`save` writes only maps the game accepts."""

    grid: np.ndarray  # (rows, cols) '<U1' characters from GRID_CHARS
    header: dict[str, str] = field(default_factory=dict)
    comments: dict[Anchor, list[str]] = field(default_factory=dict)  # kept lines, by place
    _undo: list[list[tuple[int, int, str, str]]] = field(default_factory=list, repr=False)
    _redo: list[list[tuple[int, int, str, str]]] = field(default_factory=list, repr=False)
    _stroke: list[tuple[int, int, str, str]] | None = field(default=None, repr=False)
    dirty: bool = False

    @classmethod
    def blank(cls, rows: int, cols: int, name: str | None = None) -> EditorModel:
        """A floor grid inside a wall border (without a ``name``, :meth:`save` names the
        map after its file)."""
        if not (3 <= rows <= MAX_SIZE and 3 <= cols <= MAX_SIZE):
            raise MapGenError(f"map size must be in [3, {MAX_SIZE}] each way, got {rows}x{cols}")
        grid = np.full((rows, cols), ".", dtype="<U1")
        grid[[0, -1], :] = grid[:, [0, -1]] = "#"
        return cls(grid, {"name": name} if name else {})

    @classmethod
    def from_text(cls, text: str, source: str = "<string>") -> EditorModel:
        """Open map text. A grid that only fails the reachability rule still opens (so it can
        be fixed); anything the parser rejects earlier raises its MapError. Whole-line
        comments are kept next to the header line or grid row that follows them."""
        try:
            parse_map(text, source)
        except MapError as err:
            if "cannot be reached" not in err.message:
                raise
        header: dict[str, str] = {}
        rows: list[str] = []
        comments: dict[Anchor, list[str]] = {}
        pending: list[str] = []

        def place(anchor: Anchor) -> None:
            if pending:  # comments above the first header line or row stay on top
                comments.setdefault(anchor if header or rows else TOP, []).extend(pending)
                pending.clear()

        in_header = True
        for ln in text_lines(text):
            if ln.lstrip().startswith(";"):
                pending.append(ln.rstrip())
            elif in_header and ":" in ln and not rows:
                key, value = (p.strip() for p in ln.split(":", 1))
                place(("key", key))
                header[key] = value
            elif ln.strip():
                in_header = False
                place(("row", len(rows)))
                rows.append(ln.rstrip())
            elif header and in_header:
                in_header = False
                place(HEAD)
        place(END)
        grid = np.array([list(r) for r in rows], dtype="<U1")
        return cls(grid, header, comments)

    @classmethod
    def from_file(cls, path: str | Path) -> EditorModel:
        path = Path(path)
        try:
            text = read_text(path, MAX_MAP_BYTES, "map file")
        except ValueError as exc:
            raise MapError(str(exc).removeprefix(f"{path}: "), str(path)) from None
        model = cls.from_text(text, str(path))
        model.header.setdefault("name", path.stem)
        return model

    @property
    def shape(self) -> tuple[int, int]:
        return (int(self.grid.shape[0]), int(self.grid.shape[1]))

    def begin_stroke(self) -> None:
        """Group the following paints into one undo step (a mouse drag)."""
        self.end_stroke()
        self._stroke = []

    def end_stroke(self) -> None:
        if self._stroke:
            self._undo.append(self._stroke)
            self._redo.clear()
        self._stroke = None

    def paint(self, row: int, col: int, tool: str) -> bool:
        """Set one cell; a spawn digit moves that slot here. Returns whether anything changed."""
        if tool not in TOOLS:
            raise MapGenError(f"unknown tool {tool!r}; tools: {list(TOOLS)}")
        if not (0 <= row < self.shape[0] and 0 <= col < self.shape[1]):
            return False
        if self.grid[row, col] == tool:
            return False
        changes = []
        if tool.isdigit():
            for r, c in np.argwhere(self.grid == tool):
                changes.append((int(r), int(c), tool, "."))
        changes.append((row, col, str(self.grid[row, col]), tool))
        for r, c, _, new in changes:
            self.grid[r, c] = new
        if self._stroke is not None:
            self._stroke.extend(changes)
        else:
            self._undo.append(changes)
            self._redo.clear()
        self.dirty = True
        return True

    def undo(self) -> bool:
        """Revert the last paint or stroke; False when there is nothing to undo."""
        self.end_stroke()
        if not self._undo:
            return False
        changes = self._undo.pop()
        for r, c, old, _ in reversed(changes):
            self.grid[r, c] = old
        self._redo.append(changes)
        self.dirty = True
        return True

    def redo(self) -> bool:
        self.end_stroke()
        if not self._redo:
            return False
        changes = self._redo.pop()
        for r, c, _, new in changes:
            self.grid[r, c] = new
        self._undo.append(changes)
        self.dirty = True
        return True

    def text(self) -> str:
        """The map file as it would be saved (header keys in the format's order)."""
        keys = [k for k in HEADER_KEYS if k in self.header]
        keys += [k for k in self.header if k not in HEADER_KEYS]
        lines = list(self.comments.get(TOP, []))
        for k in keys:
            lines += self.comments.get(("key", k), [])
            lines.append(f"{k}: {self.header[k]}")
        if keys:
            lines += [*self.comments.get(HEAD, []), ""]
        for r, row in enumerate(self.grid):
            lines += self.comments.get(("row", r), [])
            lines.append("".join(row))
        lines += self.comments.get(END, [])
        return "\n".join(lines) + "\n"

    def check(self, source: str = "<editor>") -> MapSpec:
        """Validate with the game's parser (raises its MapError)."""
        return parse_map(self.text(), source, name=self.header.get("name"))

    def save(self, path: str | Path) -> MapSpec:
        """Write the map if the game accepts it; otherwise raise the loader's MapError. A
        map without a name is named after the file's stem."""
        path = Path(path)
        self.header.setdefault("name", path.stem)
        spec = parse_map(self.text(), str(path), name=path.stem)
        write_text_atomic(path, self.text())
        self.dirty = False
        return spec

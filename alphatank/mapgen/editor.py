"""The pygame map editor (``tools/mapgen.py edit FILE``) over :class:`EditorModel`.

Left click or drag paints the current tool, right click or drag paints floor. Tools: the
toolbar, or keys ``W`` wall, ``F``/``.`` floor, ``1``-``8`` spawn slots, ``B``/``+`` buff,
``D``/``-`` debuff. ``Ctrl+Z`` undo, ``Ctrl+Y``/``Ctrl+Shift+Z`` redo, ``Ctrl+S`` save (refused,
with the loader's message, while the map is invalid), ``Esc`` quit (twice with unsaved
changes). The map is drawn with the game's own background renderer; the status line always
shows whether the map is valid.

``run(max_frames)`` processes pygame's event queue, so tests drive the editor with posted
events under ``SDL_VIDEODRIVER=dummy``.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
import pygame  # noqa: E402

from alphatank.mapgen.model import TOOLS, EditorModel  # noqa: E402
from alphatank.sim.mapspec import MapError, MapSpec, merge_walls  # noqa: E402
from alphatank.ui.render import (  # noqa: E402
    BUFF,
    DEBUFF,
    DIM_TEXT,
    FLOOR,
    TEXT,
    WALL,
    draw_background,
    mix,
    open_window,
    team_color,
)

TOOL_KEYS = {pygame.K_w: "#", pygame.K_f: ".", pygame.K_PERIOD: ".", pygame.K_b: "+",
             pygame.K_PLUS: "+", pygame.K_EQUALS: "+", pygame.K_KP_PLUS: "+", pygame.K_d: "-",
             pygame.K_MINUS: "-", pygame.K_KP_MINUS: "-",
             **{getattr(pygame, f"K_{i}"): str(i) for i in range(1, 9)}}
TOOL_NAMES = {"#": "wall", ".": "floor", "+": "buff", "-": "debuff",
              **{str(i): f"spawn {i}" for i in range(1, 9)}}
BAR_H, STATUS_H = 34, 26
ERROR: tuple[int, int, int] = (240, 110, 100)
OK: tuple[int, int, int] = (120, 220, 130)


class MapEditor:
    """A window over an :class:`EditorModel` that saves to ``path``."""

    def __init__(self, model: EditorModel, path: str | Path, cell_px: int | None = None):
        self.model, self.path = model, Path(path)
        rows, cols = model.shape
        self.cell = cell_px or max(16, min(56, 760 // max(rows, cols)))
        self.grid_w, self.grid_h = cols * self.cell, rows * self.cell
        self.tool_w = max(28, min(48, max(self.grid_w, 12 * 28) // len(TOOLS)))
        width = max(self.grid_w, self.tool_w * len(TOOLS))
        self.screen = open_window((width, BAR_H + self.grid_h + STATUS_H),
                                  f"AlphaTank map editor - {self.path}")
        pygame.font.init()
        self.font = pygame.font.Font(None, 20)
        self.tool = "#"
        self.drag: str | None = None  # tool painted while a mouse button is held
        self.message = ""
        self.confirm_quit = False
        self.running = True
        self.frames = 0
        self._bg: pygame.Surface | None = None
        self.error: MapError | None = None
        self._changed()

    # ---- events ---------------------------------------------------------------------

    def cell_at(self, pos: tuple[int, int]) -> tuple[int, int] | None:
        """Grid cell under a window position, or None outside the grid."""
        x, y = pos
        r, c = (y - BAR_H) // self.cell, x // self.cell
        rows, cols = self.model.shape
        return (r, c) if 0 <= r < rows and 0 <= c < cols and y >= BAR_H else None

    def handle(self, event: pygame.event.Event) -> None:
        """Apply one pygame event."""
        if event.type == pygame.QUIT:
            self.request_quit()
        elif event.type == pygame.MOUSEBUTTONDOWN and event.button in (1, 3):
            x, y = event.pos
            if y < BAR_H:
                i = x // self.tool_w
                if event.button == 1 and 0 <= i < len(TOOLS):
                    self.select(TOOLS[i])
                return
            self.drag = self.tool if event.button == 1 else "."
            self.model.begin_stroke()
            self._paint(event.pos)
        elif event.type == pygame.MOUSEMOTION and self.drag is not None:
            self._paint(event.pos)
        elif event.type == pygame.MOUSEBUTTONUP and self.drag is not None:
            self.drag = None
            self.model.end_stroke()
        elif event.type == pygame.KEYDOWN:
            self._key(event.key, getattr(event, "mod", 0))

    def _key(self, key: int, mod: int) -> None:
        ctrl, shift = mod & pygame.KMOD_CTRL, mod & pygame.KMOD_SHIFT
        if key == pygame.K_ESCAPE:
            self.request_quit()
        elif ctrl and key == pygame.K_s:
            self.save()
        elif ctrl and (key == pygame.K_y or (key == pygame.K_z and shift)):
            self.message = "redo" if self.model.redo() else "nothing to redo"
            self._changed()
        elif ctrl and key == pygame.K_z:
            self.message = "undo" if self.model.undo() else "nothing to undo"
            self._changed()
        elif not ctrl and key in TOOL_KEYS:
            self.select(TOOL_KEYS[key])

    def select(self, tool: str) -> None:
        self.tool = tool
        self.message = f"tool: {TOOL_NAMES[tool]}"

    def _paint(self, pos: tuple[int, int]) -> None:
        cell = self.cell_at(pos)
        if cell is not None and self.drag is not None and self.model.paint(*cell, self.drag):
            self.confirm_quit = False
            self._changed()

    def save(self) -> bool:
        """Save if valid; otherwise keep the file and show the loader's message."""
        try:
            self.model.save(self.path)
        except MapError as err:
            self.message = f"not saved: {err}"
            return False
        self.message = f"saved {self.path}"
        return True

    def request_quit(self) -> None:
        if self.model.dirty and not self.confirm_quit:
            self.confirm_quit = True
            self.message = "unsaved changes: Esc again to quit, Ctrl+S to save"
        else:
            self.running = False

    def _changed(self) -> None:
        self._bg = None
        try:
            self.model.check(str(self.path))
            self.error = None
        except MapError as err:
            self.error = err

    # ---- drawing --------------------------------------------------------------------

    def draw(self) -> None:
        screen = self.screen
        screen.fill((16, 18, 22))
        for i, tool in enumerate(TOOLS):
            rect = pygame.Rect(i * self.tool_w + 2, 3, self.tool_w - 4, BAR_H - 6)
            self._swatch(screen, rect, tool)
            if tool == self.tool:
                pygame.draw.rect(screen, TEXT, rect.inflate(2, 2), 2, border_radius=4)
        if self._bg is None:
            self._bg = self._background()
        screen.blit(self._bg, (0, BAR_H))
        for r, c in np.argwhere(np.char.isdigit(self.model.grid)):
            rect = pygame.Rect(c * self.cell, BAR_H + r * self.cell, self.cell, self.cell)
            self._swatch(screen, rect, str(self.model.grid[r, c]))
        if self.error is not None:
            err = self.error
            where = f" (line {err.line}, col {err.col})" if err.line and err.col else ""
            status, colour = f"invalid{where}: {err.message}", ERROR
        else:
            status, colour = "valid", OK
        if self.message:
            status = f"{self.message}  |  {status}"
            if self.message.startswith("not saved"):
                status, colour = self.message, ERROR
        text = self.font.render(status, True, colour)
        screen.blit(text, (6, BAR_H + self.grid_h + (STATUS_H - text.get_height()) // 2))

    def _background(self) -> pygame.Surface:
        grid = self.model.grid
        walls = grid == "#"
        cells = {ch: [(int(r), int(c)) for r, c in np.argwhere(grid == ch)] for ch in "+-"}
        rects = tuple((c0 * self.cell, r0 * self.cell, c1 * self.cell, r1 * self.cell)
                      for r0, c0, r1, c1 in merge_walls(walls))
        # An unvalidated spec, only for drawing (the grid may be invalid while editing).
        spec = MapSpec("editor", walls, {}, tuple(cells["+"]), tuple(cells["-"]),
                       cell=float(self.cell), wall_rects=rects)
        return draw_background(spec, spec.buffs, spec.debuffs)

    def _swatch(self, surf: pygame.Surface, rect: pygame.Rect, tool: str) -> None:
        if tool.isdigit():
            slots = int(np.char.isdigit(self.model.grid).sum())
            team = 0 if int(tool) <= max(1, math.ceil(slots / 2)) else 1
            pygame.draw.rect(surf, FLOOR, rect)
            pygame.draw.circle(surf, team_color(team), rect.center, min(rect.size) * 0.38)
            label = self.font.render(tool, True, (10, 10, 10))
        else:
            colour = {"#": WALL, ".": FLOOR, "+": mix(FLOOR, BUFF, 0.6),
                      "-": mix(FLOOR, DEBUFF, 0.6)}[tool]
            pygame.draw.rect(surf, colour, rect, border_radius=3)
            label = self.font.render("" if tool == "#" else tool, True, DIM_TEXT)
        surf.blit(label, label.get_rect(center=rect.center))

    # ---- loop -----------------------------------------------------------------------

    def run(self, max_frames: int | None = None) -> int:
        """Process events and redraw until quit (or ``max_frames`` frames); returns the
        number of frames drawn."""
        clock = pygame.time.Clock()
        start = self.frames
        while self.running and (max_frames is None or self.frames - start < max_frames):
            for event in pygame.event.get():
                self.handle(event)
            self.draw()
            pygame.display.flip()
            self.frames += 1
            if max_frames is None:
                clock.tick(60)
        return self.frames - start

    def close(self) -> None:
        pygame.display.quit()

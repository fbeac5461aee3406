"""Draw a match with pygame-ce: an offscreen Surface, a window only in ``human`` mode.

The static background (floor, grid, walls, zones) is drawn once per map and zone layout
and blitted each frame; tanks, bullets, overlays, explosions and the HUD are drawn on top.
``render_mode=None`` or ``"rgb_array"`` never touches ``pygame.display``; only
``"human"`` opens a window. Colours follow the paper's Table 5 (team A green, team B red).

Overlays (the paper's Table 5 visual switches): ``aim`` (aim line, key V), ``trajectory``
(predicted bullet path with ricochets, key T), ``bfs`` (the smart bot's BFS path, key B).
"""

from __future__ import annotations

import math
import os
import sys
import tempfile
import time
from collections.abc import Iterable, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
import pygame  # noqa: E402

from alphatank.sim.episode import Episode, EpisodeHook
from alphatank.ui.modes import RENDER_MODES as RENDER_MODES  # re-export
from alphatank.ui.modes import check_render_mode

if TYPE_CHECKING:
    from alphatank.sim.match import Match, TickEvents

OVERLAYS = ("aim", "trajectory", "bfs")
OVERLAY_KEYS = {pygame.K_v: "aim", pygame.K_t: "trajectory", pygame.K_b: "bfs"}
DEFAULT_OVERLAYS = ("aim", "bfs")  # Table 5: Render Aiming True, Render BFS True, Trajectory False

Color = tuple[int, int, int]
# Team colours by team index (team names sorted): A green, B red as in the paper's Table 5.
TEAM_COLORS: tuple[Color, ...] = (
    (70, 200, 90), (230, 70, 65), (70, 140, 245), (250, 150, 30),
    (200, 95, 225), (40, 205, 205), (235, 235, 235), (170, 120, 75))
FLOOR: Color = (34, 38, 46)
GRID: Color = (44, 49, 59)
WALL: Color = (112, 120, 136)
WALL_EDGE: Color = (160, 168, 184)
WALL_SHADOW: Color = (22, 24, 30)
BUFF: Color = (255, 205, 60)
DEBUFF: Color = (175, 90, 235)
WRECK: Color = (72, 72, 76)
TEXT: Color = (235, 238, 242)
DIM_TEXT: Color = (150, 156, 166)
HUD_BG = (12, 14, 18, 190)
PANEL_BG = (12, 14, 18, 228)


def team_color(team_index: int) -> Color:
    return TEAM_COLORS[team_index % len(TEAM_COLORS)]


def mix(a: Sequence[int], b: Sequence[int], t: float) -> Color:
    """Blend colour ``a`` towards ``b`` by ``t`` in [0, 1]."""
    return (round(a[0] + (b[0] - a[0]) * t), round(a[1] + (b[1] - a[1]) * t),
            round(a[2] + (b[2] - a[2]) * t))


class DisplayUnavailable(RuntimeError):
    """No window can be opened (no display, or SDL's dummy video driver)."""


HEADLESS_DRIVERS = ("dummy", "offscreen")  # SDL video drivers whose windows show nothing


def _display_init_held() -> bytes:
    """``pygame.display.init()`` with file descriptor 2 held: what SDL, or a library it
    probed, wrote there (libwayland's "error: XDG_RUNTIME_DIR is invalid ..." with no
    display at all)."""
    if sys.stderr is not None:  # None when Python started without a stderr
        sys.stderr.flush()
    try:
        saved = os.dup(2)
    except OSError:  # no stderr to hold
        pygame.display.init()
        return b""
    with tempfile.TemporaryFile() as said:
        os.dup2(said.fileno(), 2)
        try:
            pygame.display.init()
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        said.seek(0)
        return said.read()


def init_display() -> None:
    """Initialise pygame's display, or raise DisplayUnavailable: when it cannot, or when SDL
    fell back to a video driver that shows nothing and ``SDL_VIDEODRIVER`` did not ask for
    it (with no display, pygame quietly picks ``offscreen``: a window would never show).
    What SDL printed on the way is passed on, unless refused: the refusal is then the one
    line."""
    try:
        said = _display_init_held()
    except pygame.error as exc:
        raise DisplayUnavailable(f"cannot open a window: {exc}") from exc
    driver = pygame.display.get_driver()
    if driver in HEADLESS_DRIVERS and os.environ.get("SDL_VIDEODRIVER") != driver:
        pygame.display.quit()
        raise DisplayUnavailable(f"no display: SDL fell back to its {driver!r} video "
                                 "driver, which shows nothing")
    if said:
        os.write(2, said)


def window_display() -> None:
    """:func:`init_display` for a window a person must see (``play``, ``replay --render``,
    ``arena --render``): ``SDL_VIDEODRIVER=dummy`` is refused too, where ``init_display``
    takes it as asked for (automated tests of ``render_mode="human"``)."""
    if os.environ.get("SDL_VIDEODRIVER") == "dummy":
        raise DisplayUnavailable("SDL_VIDEODRIVER=dummy shows nothing")
    init_display()


def open_window(size: tuple[int, int], caption: str = "AlphaTank") -> pygame.Surface:
    """Initialise pygame's display (:func:`init_display`) and open a window, or raise
    DisplayUnavailable."""
    init_display()
    try:
        screen = pygame.display.set_mode(size)
    except pygame.error as exc:
        raise DisplayUnavailable(f"cannot open a window: {exc}") from exc
    pygame.display.set_caption(caption)
    return screen


def parse_overlays(text: str | Iterable[str]) -> tuple[str, ...]:
    """Overlay names from "aim,bfs" (or an iterable); "none" or "" for none, "all" for all."""
    names = [s.strip() for s in text.split(",")] if isinstance(text, str) else list(text)
    names = [n for n in names if n and n != "none"]
    bad = [n for n in names if n not in (*OVERLAYS, "all")]
    if bad:
        raise ValueError(f"unknown overlay(s) {bad}; valid: {list(OVERLAYS)}, 'all' or 'none'")
    return OVERLAYS if "all" in names else tuple(dict.fromkeys(names))


class Renderer:
    """Draws matches onto an offscreen Surface of the map's size (times ``scale``).

    ``draw(match)`` returns the Surface, ``frame(match)`` an HxWx3 uint8 array,
    ``render(match)`` does what ``render_mode`` asks (array for ``rgb_array``, a window for
    ``human``). ``policies`` (one per seat, optional) let the BFS overlay show each bot's own
    path (a ``path`` attribute holding grid cells); without them it shows a shortest path
    to the nearest enemy.
    """

    def __init__(self, render_mode: str | None = "rgb_array", *,
                 overlays: Iterable[str] | str = DEFAULT_OVERLAYS, hud: bool = True,
                 explosions: bool = True, fps: float = 30.0, scale: float = 1.0,
                 labels: Sequence[str] | None = None, caption: str = "AlphaTank"):
        check_render_mode(render_mode)
        if not scale > 0:
            raise ValueError(f"scale must be > 0, got {scale!r}")
        self.render_mode = render_mode
        self.overlays = set(parse_overlays(overlays))
        self.hud, self.explosions, self.fps, self.scale = hud, explosions, fps, scale
        self.labels = list(labels) if labels is not None else None
        self.caption = caption
        self.banner = True  # winner banner at the end (play draws its own summary)
        self.screen: pygame.Surface | None = None
        self._clock: pygame.time.Clock | None = None
        self._bg_key: tuple[Any, ...] | None = None
        self._bg: pygame.Surface | None = None
        self._surface: pygame.Surface | None = None
        self._scaled: pygame.Surface | None = None
        self._fonts: dict[int, pygame.font.Font] = {}
        self._texts: dict[tuple[str, Color, int], pygame.Surface] = {}
        self._world: object | None = None
        self._prev_alive: np.ndarray | None = None
        self._booms: list[list[Any]] = []  # x, y, frames elapsed, puff/spark layout
        self._fx = pygame.Surface((220, 220), pygame.SRCALPHA)
        self._fx_rng = np.random.default_rng(0)  # explosion shapes (cosmetic only)
        self._band: pygame.Surface | None = None
        self._nav: Any = None
        self._nav_spec: object | None = None
        self._paths: dict[tuple[Any, Any], Any] = {}
        self._fsize = 18

    # ---- public ---------------------------------------------------------------------

    def toggle(self, overlay: str) -> bool:
        """Switch an overlay on or off; returns its new state."""
        if overlay not in OVERLAYS:
            raise ValueError(f"unknown overlay {overlay!r}; valid: {list(OVERLAYS)}")
        self.overlays ^= {overlay}
        return overlay in self.overlays

    def handle_key(self, key: int) -> str | None:
        """Toggle the overlay bound to ``key`` (V, T, B); returns its name or None."""
        name = OVERLAY_KEYS.get(key)
        if name is not None:
            self.toggle(name)
        return name

    def draw(self, match: Match, policies: Sequence[object | None] | None = None
             ) -> pygame.Surface:
        """Draw the match's current state; returns the offscreen Surface (map size)."""
        if not pygame.font.get_init():
            pygame.font.init()
        surf = self._canvas(match)
        surf.blit(self._background(match), (0, 0))
        self._track_kills(match)
        if "bfs" in self.overlays:
            self._draw_paths(surf, match, policies)
        if "trajectory" in self.overlays:
            self._draw_trajectories(surf, match)
        if "aim" in self.overlays:
            self._draw_aim(surf, match)
        self._draw_tanks(surf, match)
        self._draw_bullets(surf, match)
        if self.explosions:
            self._draw_booms(surf)
        if self.hud:
            self._draw_hud(surf, match)
        if self.scale != 1.0:
            size = (round(surf.get_width() * self.scale), round(surf.get_height() * self.scale))
            if self._scaled is None or self._scaled.get_size() != size:
                self._scaled = pygame.Surface(size)
            pygame.transform.smoothscale(surf, size, self._scaled)
            return self._scaled
        return surf

    def frame(self, match: Match, policies: Sequence[object | None] | None = None
              ) -> np.ndarray:
        """The match as an (H, W, 3) uint8 RGB array (H, W = map size times ``scale``)."""
        return surface_to_array(self.draw(match, policies))

    def render(self, match: Match, policies: Sequence[object | None] | None = None
               ) -> np.ndarray | None:
        """``rgb_array``: the frame; ``human``: show it in a window (returns None)."""
        if self.render_mode == "rgb_array":
            return self.frame(match, policies)
        if self.render_mode == "human":
            self.show(self.draw(match, policies))
        return None

    def show(self, surf: pygame.Surface) -> None:
        """Blit a drawn Surface to the window (opened on first use), keep it responsive
        and hold ``fps``."""
        if self.screen is None:
            self.screen = open_window(surf.get_size(), self.caption)
            self._clock = pygame.time.Clock()
        self.screen.blit(surf, (0, 0))
        pygame.display.flip()
        pygame.event.pump()
        if self._clock is not None and self.fps > 0:
            self._clock.tick(self.fps)

    def close(self) -> None:
        """Close the window if this renderer opened one."""
        if self.screen is not None:
            pygame.display.quit()
            self.screen = None

    def text(self, s: str, color: Color = TEXT, size: int | None = None) -> pygame.Surface:
        """A rendered text Surface (cached)."""
        size = size or self._fsize
        key = (s, color, size)
        out = self._texts.get(key)
        if out is None:
            if len(self._texts) > 512:
                self._texts.clear()
            font = self._fonts.get(size)
            if font is None:
                if not pygame.font.get_init():
                    pygame.font.init()
                font = self._fonts[size] = pygame.font.Font(None, size)
            out = self._texts[key] = font.render(s, True, color)
        return out

    def _fit(self, s: str, color: Color, width: float) -> pygame.Surface:
        """Text with its first word cut to the longest start (one character at least)
        that fits ``width`` px: a binary search, so a long word costs a few renders."""
        img = self.text(s, color)
        head, _, tail = s.partition(" ")
        if img.get_width() <= width or len(head) <= 1:
            return img
        lo, hi, keep = 2, len(head) - 1, 1
        while lo <= hi:
            mid = (lo + hi) // 2
            if self.text(f"{head[:mid]} {tail}", color).get_width() <= width:
                keep, lo = mid, mid + 1
            else:
                hi = mid - 1
        return self.text(f"{head[:keep]} {tail}", color)

    def panel(self, surf: pygame.Surface, lines: Sequence[tuple[str, Color]],
              title: tuple[str, Color] | None = None, footer: tuple[str, Color] | None = None,
              align: str = "center") -> None:
        """A centred box: an optional big title, lines of text (centred or, with
        ``align="left"``, left-aligned as a block) and an optional centred footer."""
        head = self.text(title[0], title[1], self._fsize * 2) if title else None
        foot = self.text(*footer) if footer else None
        rows = [self.text(s, c) for s, c in lines]
        pad = self._fsize
        all_rows = [r for r in (head, *rows, foot) if r is not None]
        w = max(r.get_width() for r in all_rows) + 2 * pad
        h = sum(r.get_height() + 4 for r in all_rows) + 2 * pad + (pad // 2 if foot else 0)
        box = pygame.Surface((w, h), pygame.SRCALPHA)
        box.fill(PANEL_BG)
        pygame.draw.rect(box, (*DIM_TEXT, 220), box.get_rect(), 2, border_radius=8)
        y = pad
        block = max((r.get_width() for r in rows), default=0)
        for r in all_rows:
            if r is foot:
                y += pad // 2
            x = (w - block) // 2 if align == "left" and r in rows else (w - r.get_width()) // 2
            box.blit(r, (x, y))
            y += r.get_height() + 4
        surf.blit(box, ((surf.get_width() - w) // 2, (surf.get_height() - h) // 2))

    # ---- caches ---------------------------------------------------------------------

    def _canvas(self, match: Match) -> pygame.Surface:
        size = (math.ceil(match.spec.width), math.ceil(match.spec.height))
        if self._surface is None or self._surface.get_size() != size:
            self._surface = pygame.Surface(size)
            self._band = None
        self._fsize = max(14, min(size) // 36)
        return self._surface

    def _background(self, match: Match) -> pygame.Surface:
        key = (id(match.spec), tuple(match.buffs), tuple(match.debuffs))
        if self._bg is None or self._bg_key != key:
            self._bg = draw_background(match.spec, match.buffs, match.debuffs)
            self._bg_key = key
        return self._bg

    def _track_kills(self, match: Match) -> None:
        """Start an explosion where a tank died since the last frame; reset on new episodes."""
        if match.world is not self._world or self._prev_alive is None:
            self._world = match.world
            self._prev_alive = match.alive.copy()
            self._booms.clear()
        died = self._prev_alive & ~match.alive
        for i in np.flatnonzero(died):
            x, y = match.tank_xy[i]
            rng = self._fx_rng
            layout = {"puffs": np.stack([rng.uniform(0, math.tau, 9), rng.uniform(0.2, 1.0, 9),
                                         rng.uniform(0.6, 1.2, 9)], axis=1).tolist(),
                      "sparks": rng.uniform(0, math.tau, 12).tolist()}
            self._booms.append([float(x), float(y), 0.0, layout])
        self._prev_alive[:] = match.alive

    # ---- layers ---------------------------------------------------------------------

    def _draw_tanks(self, surf: pygame.Surface, match: Match) -> None:
        cfg = match.cfg
        n = match.n
        hw, hh = cfg.tank_width / 2, cfg.tank_height / 2
        c, s = np.cos(match.tank_angle), np.sin(match.tank_angle)
        fwd = np.stack([c, s], axis=1)  # (n, 2)
        side = np.stack([-s, c], axis=1)
        xy = match.tank_xy
        body = xy[:, None, :] + (_BOX[None, :, :1] * hw * fwd[:, None, :]
                                 + _BOX[None, :, 1:] * hh * side[:, None, :])
        track_w = cfg.tank_height * 0.22
        tracks = [xy[:, None, :] + (_BOX[None, :, :1] * (hw + 1) * fwd[:, None, :]
                                    + (sign * (hh - track_w / 2) + _BOX[None, :, 1:] * track_w / 2)
                                    * side[:, None, :]) for sign in (-1.0, 1.0)]
        barrel_end = xy + fwd * (hw + cfg.tank_height * 0.35)
        turret_r = cfg.tank_height * 0.3
        barrel_w = max(3, round(cfg.tank_height * 0.2))
        for i in np.argsort(match.alive, kind="stable"):  # wrecks under live tanks
            pts = body[i].tolist()
            if not match.alive[i]:
                pygame.draw.polygon(surf, WRECK, pts)
                pygame.draw.polygon(surf, (40, 40, 44), pts, 2)
                pygame.draw.line(surf, (40, 40, 44), pts[0], pts[2], 2)
                pygame.draw.line(surf, (40, 40, 44), pts[1], pts[3], 2)
                continue
            col = team_color(int(match.team_index[i]))
            dark, light = mix(col, (0, 0, 0), 0.45), mix(col, (255, 255, 255), 0.45)
            if match.in_buff[i] or match.in_debuff[i]:
                ring = BUFF if match.in_buff[i] else DEBUFF
                pygame.draw.circle(surf, ring, xy[i].tolist(), hw + 6, 2)
            pygame.draw.polygon(surf, col, pts)
            for tr in tracks:
                pygame.draw.polygon(surf, dark, tr[i].tolist())
            pygame.draw.polygon(surf, mix(col, (0, 0, 0), 0.65), pts, 1)
            centre = xy[i].tolist()
            pygame.draw.line(surf, light, centre, barrel_end[i].tolist(), barrel_w)
            pygame.draw.circle(surf, dark, centre, turret_r)
            pygame.draw.circle(surf, light, centre, turret_r, 1)
        label_off = hw + 10
        for i in range(n):
            label = self.labels[i] if self.labels and i < len(self.labels) else str(i + 1)
            if not label or not match.alive[i]:
                continue
            t = self.text(label, TEXT, max(12, self._fsize * 3 // 4))
            x, y = xy[i]
            surf.blit(t, (x - t.get_width() / 2, y - label_off - t.get_height()))

    def _draw_bullets(self, surf: pygame.Surface, match: Match) -> None:
        active = np.flatnonzero(match.bullet_active)
        if active.size == 0:
            return
        xy = match.bullet_xy[active]
        tail = xy - match.bullet_vel[active] * (1.2 / match.cfg.tick_hz)
        r = match.cfg.bullet_radius
        owners = match.team_index[match.bullet_owner[active]]
        for k in range(active.size):
            col = team_color(int(owners[k]))
            p = xy[k].tolist()
            pygame.draw.line(surf, mix(col, FLOOR, 0.5), tail[k].tolist(), p, 3)
            pygame.draw.circle(surf, col, p, r + 2)
            pygame.draw.circle(surf, (255, 255, 240), p, max(1.0, r - 0.5))

    def _draw_aim(self, surf: pygame.Surface, match: Match) -> None:
        w, cfg = match.world, match.cfg
        reach = max(match.spec.width, match.spec.height) * 1.5
        for i in np.flatnonzero(match.alive):
            x, y = match.tank_xy[i]
            a = float(match.tank_angle[i])
            dx, dy = math.cos(a), math.sin(a)
            start = (x + dx * cfg.tank_width / 2, y + dy * cfg.tank_width / 2)
            hit = w.ray((float(x), float(y)), (x + dx * reach, y + dy * reach))
            end = hit.point if hit is not None else (x + dx * reach, y + dy * reach)
            col = mix(team_color(int(match.team_index[i])), FLOOR, 0.4)
            _dashed(surf, col, start, (end[0], end[1]), 7.0, 6.0)

    def _draw_trajectories(self, surf: pygame.Surface, match: Match) -> None:
        predict = _ballistics()
        if predict is None:
            return
        cfg = match.cfg
        for i in np.flatnonzero(match.alive):
            x, y = match.tank_xy[i]
            mx, my = match.world.muzzle(int(i))
            if match.world.ray((float(x), float(y)), (mx, my), cfg.bullet_radius) is not None:
                continue  # muzzle in a wall: this tank cannot fire now
            pts = predict(match.world, mx, my, float(match.tank_angle[i]),
                          cfg.bullet_max_distance, cfg.bullet_max_bounces, cfg.bullet_radius)
            if len(pts) < 2:
                continue
            col = mix(team_color(int(match.team_index[i])), (255, 255, 255), 0.5)
            plist = np.asarray(pts, dtype=float).tolist()
            pygame.draw.lines(surf, mix(col, FLOOR, 0.3), False, plist, 1)
            for p in plist[1:-1]:
                pygame.draw.circle(surf, col, p, 3, 1)

    def _draw_paths(self, surf: pygame.Surface, match: Match,
                    policies: Sequence[object | None] | None) -> None:
        spec = match.spec
        nav = self._navigation(match)
        if nav is None:
            return
        for i in np.flatnonzero(match.alive):
            if policies is not None:
                pol = policies[i] if i < len(policies) else None
                cells = planned_path(pol, match, int(i)) if pol is not None else None
            else:
                cells = self._nearest_enemy_path(match, int(i), nav)
            if cells is None or len(cells) < 2:
                continue
            pts = [spec.cell_center((int(r), int(c))) for r, c in cells]
            pts[0] = tuple(match.tank_xy[i].tolist())
            col = mix(team_color(int(match.team_index[i])), FLOOR, 0.6)
            pygame.draw.lines(surf, col, False, pts, 2)
            for p in pts[1:-1]:
                pygame.draw.circle(surf, col, p, 3)
            pygame.draw.circle(surf, col, pts[-1], 6, 2)

    def _nearest_enemy_path(self, match: Match, i: int, nav: Any
                            ) -> Sequence[tuple[int, int]] | None:
        """BFS path from tank ``i`` to the nearest live enemy (by BFS steps)."""
        enemies = np.flatnonzero(match.alive & (match.team_index != match.team_index[i]))
        if enemies.size == 0:
            return None
        me = nav.node_of(*match.tank_xy[i])
        nodes = nav.nodes_of(match.tank_xy[enemies])
        steps = nav.dist_table[me, nodes].astype(np.float64)
        steps[steps < 0] = np.inf
        key = (me, int(nodes[int(np.argmin(steps))]))
        path = self._paths.get(key)
        if path is None:
            if len(self._paths) > 4096:
                self._paths.clear()
            path = self._paths[key] = [nav.cell_at(k) for k in nav.path_idx(*key)]
        return path

    def _navigation(self, match: Match) -> Any:
        if self._nav_spec is not match.spec:
            self._nav_spec = match.spec
            try:
                from alphatank.sim.navigation import nav_grid
            except ImportError:
                self._nav = None
            else:
                self._nav = nav_grid(match.spec)
        return self._nav

    def _draw_booms(self, surf: pygame.Surface) -> None:
        """Explosions: a flash, fireball puffs turning to smoke, sparks, a shock ring."""
        duration = max(1.0, 0.8 * (self.fps or 30.0))
        fx = self._fx
        half = fx.get_width() / 2
        for boom in self._booms:
            x, y, age, layout = boom
            t = age / duration
            fade = 1.0 - t
            grow = t ** 0.5
            fx.fill((0, 0, 0, 0))
            pygame.draw.circle(fx, (255, 210, 140, int(170 * fade)), (half, half),
                               14 + 70 * grow, 2)
            if t < 0.6:
                for a in layout["sparks"]:
                    dx, dy = math.cos(a), math.sin(a)
                    r0, r1 = 10 + 70 * grow, 18 + 85 * grow
                    pygame.draw.line(fx, (255, 230, 160, int(255 * (1 - t / 0.6))),
                                     (half + dx * r0, half + dy * r0),
                                     (half + dx * r1, half + dy * r1), 2)
            pygame.draw.circle(fx, (240, 90, 20, int(150 * fade)), (half, half),
                               14 + 40 * grow)
            col = _fire_color(t)
            for a, dist, size in layout["puffs"]:
                d = dist * (6 + 30 * grow)
                pygame.draw.circle(fx, (*col, int(240 * fade ** 0.6)),
                                   (half + math.cos(a) * d, half + math.sin(a) * d),
                                   size * (11 + 12 * t))
            if t < 0.35:
                pygame.draw.circle(fx, (255, 255, 240, int(255 * (1 - t / 0.35))), (half, half),
                                   16 * (1 - t / 0.35) + 2)
            surf.blit(fx, (x - half, y - half))
            boom[2] += 1
        self._booms = [b for b in self._booms if b[2] < duration]

    def _draw_hud(self, surf: pygame.Surface, match: Match) -> None:
        w, _ = surf.get_size()
        fs = self._fsize
        band_h = fs + 10
        if self._band is None or self._band.get_width() != w:
            self._band = pygame.Surface((w, band_h), pygame.SRCALPHA)
            self._band.fill(HUD_BG)
        surf.blit(self._band, (0, 0))
        surf.blit(self._band, (0, surf.get_height() - band_h))
        # Top: teams (alive / size, hits), then time.
        x = 8
        compact = len(match.team_names) > 3
        for t, name in enumerate(match.team_names):
            members = match.team_index == t
            alive, size = int(match.alive[members].sum()), int(members.sum())
            hits = int(match.score[members].sum())
            col = team_color(t)
            pygame.draw.rect(surf, col, (x, 5 + fs // 6, fs * 2 // 3, fs * 2 // 3),
                             border_radius=3)
            x += fs
            s = (f"{name} {alive}/{size} {hits}h" if compact
                 else f"Team {name}  {alive}/{size} alive  {plural(hits, 'hit')}")
            img = self.text(s, col if alive else DIM_TEXT)
            surf.blit(img, (x, 6))
            x += img.get_width() + fs
        cfg = match.cfg
        clock = self.text(f"{match.tick / cfg.tick_hz:5.1f}s  tick {match.tick}/{cfg.max_steps}",
                          DIM_TEXT)
        if x + clock.get_width() < w - 8:
            surf.blit(clock, (w - clock.get_width() - 8, 6))
        # Bottom: per tank, its label and bullets left of its current limit: filled pips
        # (hollow = in flight), or "label 4/6" where the pips do not fit.
        y = surf.get_height() - band_h
        slot = w / match.n
        pip = max(3, fs // 5)
        cy = y + band_h / 2
        for i in range(match.n):
            x0 = 8 + i * slot
            col = team_color(int(match.team_index[i])) if match.alive[i] else DIM_TEXT
            label = self.labels[i] if self.labels and i < len(self.labels) else f"{i + 1}"
            limit = match.bullet_limit(i)
            left = max(0, limit - int(match.bullets_alive[i])) if match.alive[i] else 0
            img = self.text(label, col)
            step = pip * 2.6
            if img.get_width() + 8 + step * limit > slot - 12:
                img = self._fit(f"{label} {left}/{limit}", col, slot - 12)
                surf.blit(img, (x0, y + 6))
                continue
            surf.blit(img, (x0, y + 6))
            for k in range(limit):
                cx = x0 + img.get_width() + 8 + pip + k * step
                pygame.draw.circle(surf, col, (cx, cy), pip, 0 if k < left else 1)
        if match.done and self.banner:
            self._draw_banner(surf, match)

    def _draw_banner(self, surf: pygame.Surface, match: Match) -> None:
        if match.winner is not None:
            t = match.team_names.index(match.winner)
            title = (f"TEAM {match.winner} WINS", team_color(t))
        else:
            title = ("DRAW", TEXT)
        why = "time up" if match.truncated else "last team standing"
        if match.winner is None and match.terminated:
            why = "no tank left"
        self.panel(surf, [(f"{why} - {match.tick / match.cfg.tick_hz:.1f}s, "
                           f"{plural(int(match.score.sum()), 'hit')}", TEXT)], title=title)


class RenderHook(EpisodeHook):
    """An episode hook that shows every tick with ``renderer.render`` (a window in
    ``human`` mode), with the seats' controllers for the BFS overlay."""

    def __init__(self, renderer: Renderer):
        self.renderer = renderer

    def on_start(self, episode: Episode) -> None:
        self.renderer.render(episode.match, episode.controllers)

    def on_tick(self, episode: Episode, events: TickEvents) -> None:
        self.renderer.render(episode.match, episode.controllers)


def planned_path(policy: object, match: Match, seat: int) -> Sequence[tuple[int, int]] | None:
    """The grid cells a bot plans to drive through (its ``planned_path(match, seat)``), or
    None for seats without a plan (humans, agents)."""
    own = getattr(policy, "planned_path", None)
    return own(match, seat) if callable(own) else None


_BOX = np.array([[1.0, 1.0], [1.0, -1.0], [-1.0, -1.0], [-1.0, 1.0]])  # (fwd, side) corners


def surface_to_array(surf: pygame.Surface) -> np.ndarray:
    """A Surface's pixels as a new, writable (H, W, 3) uint8 RGB array.

    Reads the pixel buffer once (no per-pixel conversion in SDL): three strided channel
    copies, ~4x faster than ``pygame.image.tobytes`` or ``surfarray.array3d``.
    """
    w, h = surf.get_size()
    if surf.get_bytesize() != 4:
        buf = bytearray(pygame.image.tobytes(surf, "RGB"))
        return np.frombuffer(buf, dtype=np.uint8).reshape(h, w, 3)
    raw = np.frombuffer(surf.get_view("1"), dtype=np.uint8)
    raw = raw.reshape(h, surf.get_pitch())[:, : 4 * w].reshape(h, w, 4)
    out = np.empty((h, w, 3), dtype=np.uint8)
    for channel, shift in enumerate(surf.get_shifts()[:3]):
        out[..., channel] = raw[..., shift // 8]
    return out


def draw_background(spec: Any, buffs: Iterable[tuple[int, int]],
                    debuffs: Iterable[tuple[int, int]]) -> pygame.Surface:
    """Floor, grid, zones and walls of a map (drawn once per map and zone layout)."""
    cs = spec.cell
    size = (math.ceil(spec.width), math.ceil(spec.height))
    bg = pygame.Surface(size)
    bg.fill(FLOOR)
    for c in range(1, spec.cols):
        pygame.draw.line(bg, GRID, (c * cs, 0), (c * cs, size[1]))
    for r in range(1, spec.rows):
        pygame.draw.line(bg, GRID, (0, r * cs), (size[0], r * cs))
    for cells, col, sign in ((buffs, BUFF, "+"), (debuffs, DEBUFF, "-")):
        for r, c in cells:
            rect = pygame.Rect(round(c * cs), round(r * cs), math.ceil(cs), math.ceil(cs))
            pygame.draw.rect(bg, mix(FLOOR, col, 0.22), rect)
            pygame.draw.rect(bg, mix(FLOOR, col, 0.7), rect.inflate(-4, -4), 2, border_radius=4)
            cx, cy = rect.center
            arm, wd = cs * 0.18, max(2, round(cs * 0.07))
            mark = mix(FLOOR, col, 0.75)
            pygame.draw.line(bg, mark, (cx - arm, cy), (cx + arm, cy), wd)
            if sign == "+":
                pygame.draw.line(bg, mark, (cx, cy - arm), (cx, cy + arm), wd)
    walls = spec.walls
    for x0, y0, x1, y1 in spec.wall_rects:  # drop shadow, then the blocks
        pygame.draw.rect(bg, WALL_SHADOW, (x0 + 4, y0 + 4, x1 - x0, y1 - y0))
    for x0, y0, x1, y1 in spec.wall_rects:
        pygame.draw.rect(bg, WALL, (x0, y0, x1 - x0, y1 - y0))
    rows, cols = walls.shape
    for r, c in zip(*np.nonzero(walls), strict=True):  # light edges facing floor
        x0, y0, x1, y1 = c * cs, r * cs, (c + 1) * cs - 1, (r + 1) * cs - 1
        if r > 0 and not walls[r - 1, c]:
            pygame.draw.line(bg, WALL_EDGE, (x0, y0), (x1, y0), 2)
        if c > 0 and not walls[r, c - 1]:
            pygame.draw.line(bg, WALL_EDGE, (x0, y0), (x0, y1), 2)
        if r < rows - 1 and not walls[r + 1, c]:
            pygame.draw.line(bg, mix(WALL, (0, 0, 0), 0.3), (x0, y1), (x1, y1), 2)
        if c < cols - 1 and not walls[r, c + 1]:
            pygame.draw.line(bg, mix(WALL, (0, 0, 0), 0.3), (x1, y0), (x1, y1), 2)
    return bg


def _fire_color(t: float) -> Color:
    """Fireball colour over an explosion's life t in [0, 1]: yellow, orange, then smoke."""
    if t < 0.4:
        return mix((255, 220, 80), (245, 105, 20), t / 0.4)
    return mix((245, 105, 20), (70, 70, 76), (t - 0.4) / 0.6)


def plural(n: int, word: str) -> str:
    """"1 hit", "2 hits"."""
    return f"{n} {word}" if n == 1 else f"{n} {word}s"


def _dashed(surf: pygame.Surface, col: Color, a: tuple[float, float],
            b: tuple[float, float], dash: float, gap: float) -> None:
    length = math.hypot(b[0] - a[0], b[1] - a[1])
    if length < 1:
        return
    ux, uy = (b[0] - a[0]) / length, (b[1] - a[1]) / length
    d = 0.0
    while d < length:
        e = min(d + dash, length)
        pygame.draw.line(surf, col, (a[0] + ux * d, a[1] + uy * d),
                         (a[0] + ux * e, a[1] + uy * e), 2)
        d = e + gap


def _ballistics() -> Any:
    """``alphatank.sim.ballistics.predict_path`` when present, else None."""
    try:
        from alphatank.sim.ballistics import predict_path
    except ImportError:
        return None
    return predict_path


def render_bench(map_name: str = "arena8", per_team: int = 4, frames: int = 300,
                 overlays: Iterable[str] | str = OVERLAYS, seed: int = 0) -> float:
    """Frames per second of ``Renderer.frame`` (RGB array out) on a running team match.

    Tanks are driven by seeded random actions held for a few ticks, so they move, turn and
    fire; only the renderer is timed (match stepping is not).
    """
    from alphatank.sim.config import game_config
    from alphatank.sim.mapspec import load_map
    from alphatank.sim.match import Match

    teams = ["A"] * per_team + ["B"] * per_team
    cfg = game_config("paper", immortal=True, max_steps=frames + 10)
    match = Match(cfg, load_map(map_name), teams, seed=seed)
    rng = np.random.default_rng(seed)
    renderer = Renderer("rgb_array", overlays=overlays)
    actions = np.ones((match.n, 3), dtype=np.int64)
    spent = 0.0
    for k in range(frames + 10):
        if k % 8 == 0:
            actions[:, :2] = rng.integers(0, 3, size=(match.n, 2))
            actions[:, 1] = np.where(actions[:, 1] == 0, 2, actions[:, 1])
        actions[:, 2] = rng.random(match.n) < 0.3
        match.step(actions)
        t0 = time.perf_counter()
        renderer.frame(match)
        if k >= 10:  # warm-up frames fill the caches
            spent += time.perf_counter() - t0
    return frames / spent

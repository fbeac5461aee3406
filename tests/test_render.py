"""Renderer: frame sizes, colours at known poses, overlays, explosions, HUD, env render
modes, and a display that stays uninitialised unless a window is asked for."""

from __future__ import annotations

import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pygame
import pytest

from alphatank.sim.config import game_config
from alphatank.sim.mapspec import load_map
from alphatank.sim.match import Match
from alphatank.ui.render import (
    FLOOR,
    OVERLAYS,
    WALL,
    Renderer,
    draw_background,
    mix,
    parse_overlays,
    render_bench,
    surface_to_array,
    team_color,
)

ARTIFACTS = Path(__file__).resolve().parents[1] / "artifacts" / "test_render"


def _match(map_name: str = "open", teams=("A", "B"), seed: int = 0, **cfg) -> Match:
    return Match(game_config(**cfg), load_map(map_name), list(teams), seed=seed)


def _place(match: Match, tank: int, x: float, y: float, angle: float) -> None:
    match.world.place_tank(tank, x, y, angle)
    match.world.read_state()


def _local(x: float, y: float, angle: float, fwd: float, side: float = 0.0) -> tuple[int, int]:
    """Pixel (col, row) of a point given in a tank's frame (forward, left-to-right side)."""
    c, s = math.cos(angle), math.sin(angle)
    return round(x + c * fwd - s * side), round(y + s * fwd + c * side)


@pytest.mark.parametrize("map_name", ["open", "arena8", "maze"])
def test_rgb_frame_has_the_maps_size(map_name):
    m = _match(map_name)
    frame = Renderer("rgb_array").render(m)
    assert isinstance(frame, np.ndarray) and frame.dtype == np.uint8
    assert frame.shape == (round(m.spec.height), round(m.spec.width), 3)
    frame[0, 0] = 1  # frames are writable, independent arrays


@pytest.mark.parametrize("angle", [0.0, 0.9, math.pi / 2, -2.4, math.pi])
def test_tank_at_known_pose_shows_team_colour_and_barrel_along_heading(angle):
    m = _match("open")
    x, y = 385.0, 385.0
    _place(m, 0, x, y, angle)
    _place(m, 1, 200.0, 600.0, -angle)
    r = Renderer("rgb_array", overlays="none", hud=False, labels=["", ""])
    frame = r.frame(m)
    hw = m.cfg.tank_width / 2
    # Hull behind the turret, on the centre line: team A's green.
    col, row = _local(x, y, angle, -0.7 * hw)
    assert tuple(frame[row, col]) == team_color(0)
    # Team B's tank is red at the same spot of its hull.
    col, row = _local(200.0, 600.0, -angle, -0.7 * hw)
    assert tuple(frame[row, col]) == team_color(1)
    # The barrel sticks out in front (heading direction), not behind.
    barrel = mix(team_color(0), (255, 255, 255), 0.45)
    col, row = _local(x, y, angle, hw + 5)
    assert tuple(frame[row, col]) == barrel
    col, row = _local(x, y, angle, -(hw + 5))
    background = surface_to_array(draw_background(m.spec, m.buffs, m.debuffs))
    assert tuple(frame[row, col]) == tuple(background[row, col]) != barrel
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    pygame.image.save(r.draw(m), str(ARTIFACTS / f"pose_{angle:+.2f}.png"))


def test_wall_cells_are_wall_coloured_and_floor_is_floor():
    m = _match("maze")
    frame = Renderer("rgb_array", overlays="none", hud=False).frame(m)
    cs = m.spec.cell
    walls = np.argwhere(m.spec.walls)
    interior = [(r, c) for r, c in walls if 0 < r < m.spec.rows - 1 and 0 < c < m.spec.cols - 1]
    assert interior
    for r, c in [tuple(walls[0]), *interior[:5]]:
        assert tuple(frame[int((r + 0.5) * cs), int((c + 0.5) * cs)]) == WALL
    zones = set(m.buffs) | set(m.debuffs)
    free = [cell for cell in m.spec.floor_cells() if cell not in zones
            and all(np.hypot(*(m.tank_xy[i] - m.spec.cell_center(cell))) > cs for i in range(2))]
    for r, c in free[:5]:
        assert tuple(frame[int((r + 0.3) * cs), int((c + 0.3) * cs)]) == FLOOR


def test_overlays_toggle_by_key_and_draw():
    from alphatank.bots import make_bot

    m = _match("maze", seed=2)
    bots = [make_bot("smart", seed=0), make_bot("smart", seed=1)]
    for i, b in enumerate(bots):
        b.reset(m, i, seed=i)
    acts = np.ones((2, 3), dtype=np.int64)
    for _ in range(20):  # the bots plan a route
        for i, b in enumerate(bots):
            acts[i] = b.act(m, i)
        m.step(acts)
    r = Renderer("rgb_array", overlays="none", hud=False)
    base = r.frame(m, bots)
    for key, name in ((pygame.K_v, "aim"), (pygame.K_t, "trajectory"), (pygame.K_b, "bfs")):
        assert r.handle_key(key) == name and r.overlays == {name}
        drawn = r.frame(m, bots)
        assert (drawn != base).any(axis=2).sum() > 50, f"overlay {name} drew nothing"
        r.handle_key(key)
        assert r.overlays == set()
        assert np.array_equal(r.frame(m, bots), base)
    assert parse_overlays("all") == OVERLAYS and parse_overlays("none") == ()
    # 'all' with others is all (it was refused as an unknown overlay, though listed as valid)
    assert parse_overlays("all,aim") == OVERLAYS == parse_overlays(["aim", "all"])
    with pytest.raises(ValueError, match="valid"):
        parse_overlays("aim,lasers")


def _kill(m: Match, victim: int = 1) -> None:
    """Fire a bullet from right next to ``victim`` into it and step until it dies."""
    x, y = m.tank_xy[victim]
    m.world.spawn_bullet(0, x - 40.0, y, 0.0)
    for _ in range(10):
        m.step(np.ones((m.n, 3), dtype=np.int64))
        if not m.alive[victim]:
            return
    raise AssertionError("bullet did not kill")


def test_kill_draws_an_explosion_and_the_winner_banner():
    m = _match("open", seed=1)
    _place(m, 0, 150.0, 150.0, 0.0)
    _place(m, 1, 500.0, 500.0, 0.0)
    r = Renderer("rgb_array", overlays="none")
    r.frame(m)
    _kill(m)
    assert m.done and m.winner == "A"
    x, y = (int(v) for v in m.tank_xy[1])

    def fiery(frame: np.ndarray) -> int:
        patch = frame[y - 50:y + 50, x - 50:x + 50].astype(int)
        return int(((patch[..., 0] > 200) & (patch[..., 1] > 90) & (patch[..., 2] < 150)).sum())

    frames = [r.frame(m) for _ in range(6)]  # a white flash, then the fireball
    frame = frames[0]
    assert (frame[y - 5:y + 5, x - 5:x + 5] >= 235).all()
    assert max(fiery(f) for f in frames) > 1000
    # The explosion fades: a second later it is gone.
    for _ in range(30):
        later = r.frame(m)
    assert fiery(later) < 20
    # Banner in the middle, title in team A's colour.
    h, w = frame.shape[:2]
    centre = frame[h // 2 - 60:h // 2 + 60, w // 4:3 * w // 4]
    assert (centre == team_color(0)).all(axis=2).sum() > 30
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    pygame.image.save(r.draw(m), str(ARTIFACTS / "winner_banner.png"))


def test_hud_counts_alive_tanks_and_bullets():
    m = _match("arena4", teams=("A", "A", "B", "B"), seed=0)
    r = Renderer("rgb_array", overlays="none")
    before = r.frame(m)
    acts = np.array([[1, 1, 1], [1, 1, 0], [1, 1, 0], [1, 1, 0]])  # only tank 1 fires
    m.step(acts)
    assert m.bullets_alive.tolist() == [1, 0, 0, 0]
    after = r.frame(m)
    # Tank 1's first bullet pip turns from filled to hollow in the bottom band; the other
    # tanks' entries do not change.
    w = before.shape[1]
    assert not np.array_equal(before[-25:, : w // 4], after[-25:, : w // 4])
    assert np.array_equal(before[-25:, w // 4 + 5: w // 2 - 5], after[-25:, w // 4 + 5: w // 2 - 5])


def test_pettingzoo_render_test_passes():
    from pettingzoo.test import render_test

    from alphatank.envs import env

    render_test(lambda render_mode=None: env(scenario="team", render_mode=render_mode,
                                             max_cycles=50))
    assert not pygame.display.get_init()  # the human window was closed by env.close()


def test_render_mode_none_never_initialises_display_or_mixer():
    code = """
import pygame
from alphatank.envs import parallel_env
from alphatank.ui.render import Renderer
from alphatank.sim.mapspec import load_map
from alphatank.sim.match import Match
from alphatank.sim.config import game_config
env = parallel_env(scenario="team", render_mode=None)
env.reset(seed=0)
for _ in range(5):
    env.step({a: env.action_space(a).sample() for a in env.agents})
env.close()
frame = Renderer("rgb_array").frame(Match(game_config(), load_map("arena4"), ["A", "B"], seed=0))
env2 = parallel_env(scenario="team", render_mode="rgb_array")
env2.reset(seed=0)
assert env2.render().shape[2] == 3
print(pygame.display.get_init(), pygame.mixer.get_init())
"""
    env = {**os.environ, "SDL_VIDEODRIVER": "dummy", "SDL_AUDIODRIVER": "dummy"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env=env, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split()[-2:] == ["False", "None"]


def test_human_mode_opens_a_window_and_close_shuts_it():
    m = _match("open")
    r = Renderer("human", fps=0)
    assert r.render(m) is None
    assert pygame.display.get_init() and pygame.display.get_surface().get_size() == (770, 770)
    r.close()
    assert not pygame.display.get_init()


def test_a_human_mode_env_opens_its_window_on_the_first_render_only():
    import gymnasium

    import alphatank.envs  # noqa: F401

    env = gymnasium.make("AlphaTank/VsSmart-v0", render_mode="human")  # display checked
    assert not pygame.display.get_init()
    env.reset(seed=0)
    assert pygame.display.get_surface() is not None
    env.close()
    assert not pygame.display.get_init()


def test_without_a_display_human_mode_and_play_are_refused_not_silent(tmp_path):
    """With no display and no SDL_VIDEODRIVER, pygame quietly falls back to its offscreen
    driver: a human-mode env would crawl at 30 fps showing nothing and `alphatank play`
    would wait for keys on an invisible window. Both refuse in one line instead (without
    XDG_RUNTIME_DIR, libwayland's own "error: XDG_RUNTIME_DIR is invalid" came first)."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("SDL_VIDEODRIVER", "DISPLAY", "WAYLAND_DISPLAY", "XDG_RUNTIME_DIR")}
    code = ("import gymnasium, alphatank.envs\n"
            "gymnasium.make('AlphaTank/VsSmart-v0', render_mode='human')\n")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env=env, timeout=120)
    assert res.returncode != 0
    assert ("DisplayUnavailable: render_mode='human' needs a display (no display: SDL fell "
            "back to its 'offscreen' video driver" in res.stderr), res.stderr[-600:]
    res = subprocess.run([sys.executable, "-m", "alphatank.cli", "play", "--seats",
                          "human,random"], capture_output=True, text=True, env=env,
                         timeout=120, cwd=tmp_path)
    assert res.returncode == 2 and res.stderr.startswith("alphatank play: no display available")
    assert res.stderr.count("\n") == 1 and res.stdout == ""  # not even the players' keys
    assert "'offscreen' video driver" in res.stderr
    res = subprocess.run([sys.executable, "-m", "alphatank.cli", "arena", "--render"],
                         capture_output=True, text=True, env=env, timeout=120, cwd=tmp_path)
    assert res.returncode == 2 and res.stdout == ""
    assert res.stderr.startswith("alphatank arena: error: --render: no display: SDL fell back")
    assert res.stderr.count("\n") == 1


def test_a_long_first_word_is_cut_to_fit_in_a_few_renders():
    r = Renderer("rgb_array")
    word = "y" * 20_000
    img = r._fit(f"{word} (smart)", (255, 255, 255), 200)
    assert img.get_width() <= 200 and len(r._texts) <= 20  # a binary search, not 20,000
    short = r._fit("A (smart)", (255, 255, 255), 200)
    assert short is r.text("A (smart)", (255, 255, 255))  # what fits is left whole


def test_render_bench_reports_a_frame_rate():
    """The frame-rate target lives in ``alphatank bench --render``, not in a timed test."""
    fps = render_bench(frames=5)
    assert np.isfinite(fps) and fps > 0


def test_bad_arguments_are_rejected():
    with pytest.raises(ValueError, match="render_mode"):
        Renderer("ansi")
    with pytest.raises(ValueError, match="scale"):
        Renderer(scale=0)
    with pytest.raises(ValueError, match="unknown overlay"):
        Renderer().toggle("radar")

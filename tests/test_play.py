"""Interactive play driven by scripted key events posted to pygame's queue (dummy video
driver): keys move the human's tank as they mean, R resets, P/Esc pause, seat lists and
scenarios build the right line-ups, and no display gives a clear error."""

from __future__ import annotations

import argparse
import math
import os
import subprocess
import sys

import numpy as np
import pygame
import pytest

from alphatank.commands import play
from alphatank.errors import InputError
from alphatank.game.lineup import build_lineup as _build_lineup
from alphatank.game.scenarios import ScenarioError, load_scenario
from alphatank.game.scenarios import seats_scenario as parse_seats
from alphatank.ui.human import KeyboardPolicy
from alphatank.ui.render import OVERLAYS
from alphatank.ui.replay import load_replay
from alphatank.ui.session import PlaySession


def build_lineup(sc, checkpoint: str | None = None):
    """The line-up ``alphatank play`` builds: keyboards, stand-in smart for learners."""
    return _build_lineup(sc, interactive=True, stand_in="smart",
                         learner=f"checkpoint:{checkpoint}" if checkpoint else None)


def down(key: int) -> pygame.event.Event:
    return pygame.event.Event(pygame.KEYDOWN, key=key)


def up(key: int) -> pygame.event.Event:
    return pygame.event.Event(pygame.KEYUP, key=key)


def script(events: dict[int, list]) -> callable:
    return lambda frame: events.get(frame, [])


def session(seats: str = "human:wasd,bot:random@0", map_name: str = "open", seed: int = 3,
            fps: float = 30.0, **kw) -> PlaySession:
    """One tick per frame (fps = tick_hz) and no frame-rate wait, so tests are fast."""
    lineup = build_lineup(parse_seats(seats, map_name))
    return PlaySession(lineup, seed=seed, fps=fps, realtime=False, verbose=False, **kw)


def heading(m, i: int) -> np.ndarray:
    return np.array([math.cos(m.tank_angle[i]), math.sin(m.tank_angle[i])])


def test_w_drives_forward_along_the_heading():
    s = session()
    m = s.match
    start, h = m.tank_xy[0].copy(), heading(m, 0)
    a0 = float(m.tank_angle[0])
    s.run(max_frames=20, event_source=script({0: [down(pygame.K_w)]}))
    moved = m.tank_xy[0] - start
    assert m.tick == 20
    assert moved @ h > 0.8 * m.cfg.tank_speed * 19 / m.cfg.tick_hz  # forward, near full speed
    assert abs(moved @ np.array([-h[1], h[0]])) < 1.0  # no sideways drift
    assert m.tank_angle[0] == pytest.approx(a0, abs=1e-6)


def test_s_drives_backward_and_keyup_stops():
    s = session()
    m = s.match
    start, h = m.tank_xy[0].copy(), heading(m, 0)
    s.run(max_frames=30, event_source=script({0: [down(pygame.K_s)], 10: [up(pygame.K_s)]}))
    moved = m.tank_xy[0] - start
    assert moved @ h < -0.8 * m.cfg.tank_speed * 9 / m.cfg.tick_hz
    assert np.hypot(*m.tank_vel[0]) < 1.0  # released: stopped


@pytest.mark.parametrize("key,sign", [(pygame.K_a, -1), (pygame.K_d, +1)])
def test_a_and_d_turn_the_tank(key, sign):
    s = session()
    m = s.match
    a0, xy0 = float(m.tank_angle[0]), m.tank_xy[0].copy()
    s.run(max_frames=10, event_source=script({0: [down(key)]}))
    turned = float(m.tank_angle[0]) - a0
    per_tick = math.radians(m.cfg.rotation_speed) / m.cfg.tick_hz
    assert sign * turned > 0.7 * 9 * per_tick  # A counter-clockwise, D clockwise (y down)
    assert np.hypot(*(m.tank_xy[0] - xy0)) < 1.0  # turning in place


def test_f_tap_fires_exactly_one_bullet():
    s = session()
    m = s.match
    s.run(max_frames=5, event_source=script({1: [down(pygame.K_f), up(pygame.K_f)]}))
    assert s.shots[0] == 1
    owned = m.bullet_active[: m.capacity]
    assert owned.sum() == 1
    b = int(np.flatnonzero(owned)[0])
    assert (m.bullet_vel[b] / np.hypot(*m.bullet_vel[b])) @ heading(m, 0) > 0.99


def test_holding_f_fires_at_the_cooldown_rate():
    s = session()
    s.run(max_frames=31, event_source=script({0: [down(pygame.K_f)]}))
    # 30 ticks held, one shot per cooldown (the bullet limit is 6 alive).
    assert s.shots[0] == min(math.ceil(30 / s.match.cfg.cooldown_ticks), s.match.bullet_limit(0))


def test_r_resets_to_a_new_match():
    s = session()
    first = s.match
    s.run(max_frames=12, event_source=script({0: [down(pygame.K_w)], 10: [down(pygame.K_r)]}))
    assert s.match is not first and first.tick == 10
    assert s.match.tick == 2  # the new match ran frames 10 and 11
    assert len(s.episodes) == 2 and s.episodes[0].ticks == 10 and not s.episodes[0].done
    assert s.episodes[1].seed == s.episodes[0].seed + 1


def test_later_matches_never_overwrite_a_replay_file(tmp_path):
    """Match k's replay goes to the first free FILE-k, FILE-(k+1), ...: an existing
    FILE-2 (not named by the user) is kept."""
    taken = tmp_path / "m-2.npz"
    taken.write_bytes(b"someone else's")
    s = session(save_replay=tmp_path / "m.npz")
    restart = [down(pygame.K_r)]
    s.run(max_frames=12, event_source=script({4: restart, 8: restart}))
    assert [e.replay for e in s.episodes] == [tmp_path / "m.npz", tmp_path / "m-3.npz",
                                              tmp_path / "m-4.npz"]
    assert all(e.replay.is_file() for e in s.episodes)
    assert taken.read_bytes() == b"someone else's"


@pytest.mark.parametrize("key", [pygame.K_p, pygame.K_ESCAPE])
def test_p_and_esc_pause_and_resume(key):
    s = session()
    s.run(max_frames=15, event_source=script({0: [down(key)], 10: [down(key)]}))
    assert s.match.tick == 5  # frames 0-9 paused, 10-14 ticked


def test_p_fires_for_an_ijkl_player_and_only_esc_pauses():
    s = session("A=human:wasd,B=human:ijkl")
    s.run(max_frames=6, event_source=script({1: [down(pygame.K_p), up(pygame.K_p)],
                                             3: [down(pygame.K_ESCAPE)]}))
    assert s.shots.tolist() == [0, 1]
    assert s.paused and s.match.tick == 3


def test_two_humans_on_one_keyboard_and_ijkl():
    s = session("A=human:wasd,B=human:arrows,C=human:ijkl", map_name="arena4")
    m = s.match
    start = m.tank_xy.copy()
    h = [heading(m, i) for i in range(3)]
    s.run(max_frames=10, event_source=script({0: [down(pygame.K_UP), down(pygame.K_i)]}))
    moved = m.tank_xy - start
    assert np.hypot(*moved[0]) < 1.0
    assert moved[1] @ h[1] > 20 and moved[2] @ h[2] > 20


def test_overlay_keys_toggle_overlays():
    s = session(overlays="none")
    s.run(max_frames=3, event_source=script({0: [down(pygame.K_v), down(pygame.K_t)],
                                             1: [down(pygame.K_b)], 2: [down(pygame.K_t)]}))
    assert s.renderer.overlays == {"aim", "bfs"}


def test_match_end_shows_summary_and_esc_quits():
    s = session("A=human:wasd,B=bot:smart", map_name="open")
    s.match.world.spawn_bullet(0, s.match.tank_xy[1][0] - 40, s.match.tank_xy[1][1], 0.0)
    report = s.run(max_frames=200, event_source=script({30: [down(pygame.K_ESCAPE)]}))
    assert s.match.done and s.match.winner == "A"
    assert report.frames == 30 and not s.running
    assert len(report.episodes) == 1 and report.episodes[0].winner == "A"


def test_human_vs_bot_and_mixed_teams_scenario():
    sc = load_scenario("mixed_teams")
    lineup = build_lineup(sc)
    assert [type(p).__name__ for p in lineup.controllers].count("KeyboardPolicy") == 2
    assert lineup.labels[0] == "P1" and lineup.labels[3] == "P3"
    assert len(lineup.notes) == 2  # two learner seats played by the stand-in bot
    s = PlaySession(lineup, seed=0, fps=30, realtime=False, verbose=False)
    assert s.pause_keys == {"escape"}  # P is player 3's fire key
    s.run(max_frames=20, event_source=script({0: [down(pygame.K_w), down(pygame.K_i)]}))
    assert s.match.n == 8 and s.match.tick == 20


def test_seat_list_parser():
    sc = parse_seats("A=human:wasd,A=smart@0.5,B=bot:aggressive,B=learner", "arena4")
    assert sc.teams == ["A", "A", "B", "B"]
    assert sc.seats[1].bot == "smart" and sc.seats[1].weakness == 0.5
    assert [s.controller for s in sc.seats] == ["human", "bot", "bot", "learner"]
    auto = parse_seats("human,human,smart", "arena4")
    assert auto.teams == ["A", "B", "C"] and [s.keys for s in auto.seats[:2]] == ["wasd", "arrows"]
    with pytest.raises(ScenarioError, match="neither a seat kind.*unknown bot 'robot'; valid"):
        parse_seats("human,robot", "open")
    with pytest.raises(ScenarioError, match="valid bots"):
        parse_seats("human,bot:nope", "open")
    with pytest.raises(ScenarioError, match="at least 2"):
        parse_seats("human", "open")
    with pytest.raises(ScenarioError, match="two human seats use the 'wasd' keys"):
        build_lineup(parse_seats("human:wasd,human:wasd", "open"))


def test_keyboard_policy_maps_keys_to_actions():
    kb = KeyboardPolicy("arrows")
    for key in (pygame.K_UP, pygame.K_LEFT):
        kb.handle_event(down(key))
    assert kb.act(None, 0).tolist() == [0, 2, 0]  # ccw, forward, no fire
    kb.handle_event(down(pygame.K_RIGHT))
    kb.handle_event(down(pygame.K_DOWN))
    assert kb.act(None, 0).tolist() == [1, 1, 0]  # opposite keys cancel
    assert not kb.handle_event(down(pygame.K_w))  # not this player's key
    kb.handle_event(pygame.event.Event(pygame.WINDOWFOCUSLOST))
    assert kb.act(None, 0).tolist() == [1, 1, 0]
    with pytest.raises(ValueError, match="valid"):
        KeyboardPolicy("zqsd")


def test_a_60_fps_session_advances_the_30_hz_game_one_tick_per_two_frames():
    """Frame pacing: the real-time rate itself is a benchmark (``alphatank bench
    --render``), not a timed test."""
    seats = "A=smart,A=aggressive,A=dodge,A=defensive,B=smart,B=aggressive,B=dodge,B=random"
    lineup = build_lineup(parse_seats(seats, "arena8", {"immortal": True}))
    s = PlaySession(lineup, seed=1, fps=60, overlays=OVERLAYS, realtime=False, verbose=False)
    report = s.run(max_frames=120)
    assert report.frames == 120
    assert s.match.tick == 60  # 30 Hz game at 60 frames/s


def _args(*argv: str) -> argparse.Namespace:
    p = argparse.ArgumentParser()
    play.add_arguments(p)
    return p.parse_args(list(argv))


def test_play_command_refuses_dummy_driver_without_headless_test(capsys):
    assert play.run(_args("--seats", "human,smart")) == 2
    err = capsys.readouterr().err
    assert "no display" in err and "alphatank record" in err and "DISPLAY" in err


def test_play_command_runs_with_headless_test(capsys):
    rc = play.run(_args("--seats", "human,smart", "--headless-test", "--max-frames", "8"))
    assert rc == 0
    out = capsys.readouterr().out
    assert "player 1 (wasd)" in out
    # the match was cut off by --max-frames: not a draw
    assert "Unfinished after" in out and "results {'unfinished': 1}" in out


def test_play_command_overwrites_a_replay_file_only_with_force(tmp_path):
    old = tmp_path / "r.npz"
    old.write_bytes(b"old")
    args = ("--seats", "smart,random", "--headless-test", "--max-frames", "8",
            "--save-replay", str(old))
    with pytest.raises(InputError, match="exists \\(use --force"):
        play.run(_args(*args))
    assert old.read_bytes() == b"old"
    assert play.run(_args(*args, "--force")) == 0
    assert load_replay(old).ticks > 0


def test_play_command_reports_a_failing_window():
    code = ("import sys; from alphatank.commands import play; import argparse; "
            "p = argparse.ArgumentParser(); play.add_arguments(p); "
            "sys.exit(play.run(p.parse_args(['--seats', 'human,smart'])))")
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    env.update(SDL_VIDEODRIVER="x11", SDL_AUDIODRIVER="dummy")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                         timeout=120)
    assert out.returncode == 2
    assert "no display" in out.stderr and "alphatank record" in out.stderr


def test_human_vs_trained_agent_and_checkpoint_in_learner_seats(tmp_path):
    """A tiny trained checkpoint fills a `checkpoint:` seat and, via --checkpoint, the
    scenario's learner seat; the agent drives its tank."""
    import torch

    from alphatank.training.ppo import PPOConfig
    from alphatank.training.presets import LearnerSpec, TrainConfig
    from alphatank.training.runner import Trainer

    torch.set_num_threads(1)
    ppo = PPOConfig(num_steps=16, update_epochs=1, num_minibatches=2)
    cfg = TrainConfig(name="tiny", scenario="vs_aggressive", total_steps=2 * 16 * 2,
                      num_envs=2, num_workers=1, seed=0, wandb="disabled", checkpoint_every=1,
                      game={"max_steps": 40}, learners=(LearnerSpec("ppo", "ppo", (0,), ppo),))
    run = tmp_path / "tiny"
    Trainer(cfg, run, progress=False).train()

    lineup = build_lineup(parse_seats(f"human:wasd,checkpoint:{run}", "open"))
    assert lineup.labels == ["P1", "tiny"]  # the run folder's name
    s = PlaySession(lineup, seed=0, fps=30, realtime=False, verbose=False)
    start = s.match.tank_xy[1].copy(), float(s.match.tank_angle[1])
    s.run(max_frames=30)
    moved = np.hypot(*(s.match.tank_xy[1] - start[0])) + abs(s.match.tank_angle[1] - start[1])
    assert moved > 0.1  # the agent acted (an untrained net still picks moves)

    vs = build_lineup(load_scenario("vs_aggressive"), checkpoint=str(run))
    assert vs.labels == ["tiny", "aggressive"] and vs.seats[0] == f"checkpoint:{run}"
    assert not vs.notes

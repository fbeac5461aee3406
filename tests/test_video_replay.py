"""Videos and replays: `alphatank record` writes a playable MP4 (and GIF) with one frame per
tick, replay files round-trip and re-simulate to the same final state hash (also in a
fresh process), and broken files give clear errors."""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import time
import zipfile
from pathlib import Path

os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
os.environ.setdefault("SDL_AUDIODRIVER", "dummy")

import imageio.v2 as imageio
import imageio.v3 as iio
import imageio_ffmpeg
import numpy as np
import pygame
import pytest

from alphatank.bots import make_bot
from alphatank.commands import record, replay
from alphatank.game.lineup import build_lineup
from alphatank.game.scenarios import seats_scenario
from alphatank.ui.replay import (
    ReplayError,
    ReplayRecorder,
    load_replay,
    replay_episode,
    save_replay,
    simulate,
)
from alphatank.ui.session import PlaySession
from alphatank.ui.video import VideoRecorder, record_episode, record_match


def _args(module, *argv: str) -> argparse.Namespace:
    p = argparse.ArgumentParser()
    module.add_arguments(p)
    return p.parse_args(list(argv))


@pytest.fixture(scope="module")
def recorded(tmp_path_factory) -> dict:
    """One `alphatank record` run: a 2v2 bot match on arena4, MP4 + GIF + replay."""
    out = tmp_path_factory.mktemp("rec")
    mp4, gif, rep = out / "m.mp4", out / "m.gif", out / "m.npz"
    rc = record.run(_args(record, "--seats", "A=smart,A=aggressive,B=smart,B=dodge",
                          "--map", "arena4", "--seed", "4", "--max-steps", "150",
                          "--overlays", "all", "--out", str(mp4), "--gif", str(gif),
                          "--replay", str(rep)))
    assert rc == 0
    return {"mp4": mp4, "gif": gif, "replay": rep, "dir": out}


def test_record_writes_a_playable_mp4_with_a_frame_per_tick(recorded):
    rep = load_replay(recorded["replay"])
    frames, secs = imageio_ffmpeg.count_frames_and_secs(str(recorded["mp4"]))
    assert frames == rep.ticks + 1  # initial state + one frame per tick
    assert secs == pytest.approx(frames / 30, abs=0.1)  # real time at the 30 Hz tick rate
    reader = imageio.get_reader(recorded["mp4"])
    first = reader.get_data(0)
    reader.close()
    assert first.shape == (700, 910, 3)  # arena4 is 13 x 10 cells of 70 px
    assert first.std() > 10  # a real picture, not a blank
    gif = iio.imread(recorded["gif"])
    assert gif.shape[1:3] == (350, 455) and len(gif) == (frames + 1) // 2
    assert not list(recorded["dir"].glob(".*partial*"))  # written atomically


def test_replay_resimulates_to_the_recorded_hash(recorded, capsys):
    rep = load_replay(recorded["replay"])
    assert rep.actions.dtype == np.int8 and rep.actions.shape == (rep.ticks, 4, 3)
    assert rep.teams == ["A", "A", "B", "B"] and rep.seed == 4
    assert rep.seats[0].startswith("smart") and rep.labels == ["smart", "aggressive",
                                                               "smart", "dodge"]
    m = simulate(rep)
    assert m.state_hash() == rep.final_hash and m.tick == rep.ticks
    assert replay.run(_args(replay, str(recorded["replay"]))) == 0
    assert "final state hash matches" in capsys.readouterr().out


def test_replay_matches_the_live_match(tmp_path):
    """Record the actions of a live bot match by hand; the replay ends in its exact state."""
    lineup = build_lineup(seats_scenario("smart,aggressive", "maze", {"max_steps": 400}))
    ep = lineup.start(11)
    match = ep.match
    rec = ReplayRecorder(match, match_seed=ep.seeds.match_seed, seed=11)
    out = record_match(match, lineup.controllers, recorder=rec)
    path = save_replay(rec.finish(), tmp_path / "live.npz")
    assert path.stat().st_size < 20_000  # small: actions compress well
    again = simulate(load_replay(path))
    assert again.state_hash() == match.state_hash() == out.final_hash
    assert again.winner == match.winner and np.array_equal(again.alive, match.alive)


def test_replay_is_identical_in_a_fresh_process(recorded):
    code = ("import sys; from alphatank.ui.replay import load_replay, simulate; "
            "print(simulate(load_replay(sys.argv[1]), check=False).state_hash())")
    out = subprocess.run([sys.executable, "-c", code, str(recorded["replay"])],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == load_replay(recorded["replay"]).final_hash


def test_play_session_saves_replays_of_human_matches(tmp_path):
    lineup = build_lineup(seats_scenario("human:wasd,bot:smart", "battlefield"),
                          interactive=True)
    s = PlaySession(lineup, seed=5, fps=30, realtime=False, verbose=False,
                    save_replay=tmp_path / "h.npz")
    keys = {0: [pygame.event.Event(pygame.KEYDOWN, key=pygame.K_w)],
            5: [pygame.event.Event(pygame.KEYDOWN, key=pygame.K_d),
                pygame.event.Event(pygame.KEYDOWN, key=pygame.K_f)],
            25: [pygame.event.Event(pygame.KEYDOWN, key=pygame.K_r)]}
    s.run(max_frames=40, event_source=lambda k: keys.get(k, []))
    first, second = tmp_path / "h.npz", tmp_path / "h-2.npz"
    assert [e.replay for e in s.episodes] == [first, second]
    for path, ticks in ((first, 25), (second, 15)):
        rep = load_replay(path)
        assert rep.ticks == ticks and rep.seats[0] == "human:wasd"
        simulate(rep)  # raises on any difference
    assert load_replay(first).actions[:, 0, 1].max() == 2  # W was recorded as forward


def test_replay_command_records_video(recorded, tmp_path):
    out = tmp_path / "again.mp4"
    assert replay.run(_args(replay, str(recorded["replay"]), "--record", str(out))) == 0
    frames, _ = imageio_ffmpeg.count_frames_and_secs(str(out))
    assert frames == load_replay(recorded["replay"]).ticks + 1


def test_replay_command_writes_a_gif_alone(recorded, tmp_path, capsys):
    out = tmp_path / "again.gif"
    assert replay.run(_args(replay, str(recorded["replay"]), "--gif", str(out))) == 0
    assert capsys.readouterr().out.splitlines()[-1] == f"wrote {out}"
    ticks = load_replay(recorded["replay"]).ticks
    assert len(iio.imread(out)) == (ticks + 2) // 2  # every other of the ticks + 1 frames
    assert not list(tmp_path.glob("*.mp4"))


def test_replay_command_renders_in_a_window(recorded):
    args = _args(replay, str(recorded["replay"]), "--render", "--headless-test",
                 "--speed", "50", "--max-frames", "5")
    assert replay.run(args) == 0
    assert replay.run(_args(replay, str(recorded["replay"]), "--render")) == 2  # dummy driver


def test_a_replay_that_would_not_load_is_not_saved(recorded, tmp_path):
    rep = load_replay(recorded["replay"])
    rep.labels = ["only one"]  # for a two-tank match
    with pytest.raises(ReplayError, match=r"bad\.npz: not saved, it would not load: "
                                          r"meta\.labels: must be a list of \d+ strings"):
        save_replay(rep, tmp_path / "bad.npz")
    assert list(tmp_path.iterdir()) == []  # nothing left behind
    rep.labels, rep.match_seed = [], np.int64(rep.match_seed)  # numpy ints are numbers
    assert load_replay(save_replay(rep, tmp_path / "ok.npz")).match_seed == rep.match_seed


def test_tampered_replay_is_reported_as_diverged(recorded, tmp_path, capsys):
    rep = load_replay(recorded["replay"])
    rep.actions = rep.actions.copy()
    rep.actions[5:, :, 2] = 1 - rep.actions[5:, :, 2]  # flip every trigger from tick 5
    with pytest.raises(ReplayError, match="diverged"):
        simulate(rep)
    path = save_replay(rep, tmp_path / "bad.npz")
    assert replay.run(_args(replay, str(path))) == 1
    assert f"{path}: replay diverged" in capsys.readouterr().err
    mp4, gif = tmp_path / "old.mp4", tmp_path / "new.gif"
    mp4.write_bytes(b"an earlier video")
    assert replay.run(_args(replay, str(path), "--record", str(mp4), "--gif", str(gif))) == 1
    assert f"{path}: replay diverged" in capsys.readouterr().err
    assert mp4.read_bytes() == b"an earlier video" and not gif.exists()  # no video of it
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.npz", "old.mp4"]
    with pytest.raises(ReplayError, match=r"is a folder, not a replay file \(\.npz\)"):
        load_replay(tmp_path)


def test_corrupt_replay_files_give_clear_errors(recorded, tmp_path):
    junk = tmp_path / "junk.npz"
    junk.write_bytes(b"not a replay at all")
    with pytest.raises(ReplayError, match="junk.npz: not a readable replay file"):
        load_replay(junk)
    truncated = tmp_path / "cut.npz"
    truncated.write_bytes(recorded["replay"].read_bytes()[:300])
    with pytest.raises(ReplayError, match="cut.npz"):
        load_replay(truncated)
    with pytest.raises(ReplayError, match="no such replay file"):
        load_replay(tmp_path / "missing.npz")
    pipe = tmp_path / "pipe.npz"  # `alphatank replay <(curl ...)` gives a pipe
    os.mkfifo(pipe)
    with pytest.raises(ReplayError, match=r"pipe\.npz: is not a regular file \(a pipe or "
                                          r"device\); save the replay to a file"):
        load_replay(pipe)  # before: 'no such replay file'
    other = tmp_path / "other.npz"
    np.savez(other, actions=np.zeros((3, 2, 3), np.int8),
             meta=np.frombuffer(json.dumps({"format": "x"}).encode(), np.uint8))
    with pytest.raises(ReplayError, match="not an AlphaTank replay"):
        load_replay(other)
    # Actions out of range are caught before simulating.
    rep = load_replay(recorded["replay"])
    rep.actions = rep.actions.copy()
    rep.actions[0, 0, 0] = 7
    with pytest.raises(ReplayError, match=r"range\.npz: not saved, it would not load: "
                                          r"actions: out of range"):
        save_replay(rep, tmp_path / "range.npz")  # save_replay reads back what it writes
    blob = np.frombuffer(json.dumps(rep.meta()).encode(), np.uint8)
    np.savez_compressed(tmp_path / "range.npz", **rep.arrays(), meta=blob)  # by hand
    with pytest.raises(ReplayError, match="out of range"):
        load_replay(tmp_path / "range.npz")
    with zipfile.ZipFile(recorded["replay"]) as z:
        assert sorted(z.namelist()) == ["actions.npy", "meta.npy", "routes.npy"]
    extra = tmp_path / "extra.npz"  # before: every member was read (each up to 256 MiB:
    extra.write_bytes(recorded["replay"].read_bytes())  # many of them, out of memory)
    with zipfile.ZipFile(extra, "a") as z:
        for k in range(10):
            with z.open(f"x{k}.npy", "w") as f:  # declares 100 MB, holds none of it
                np.lib.format.write_array_header_1_0(
                    f, {"descr": "|u1", "fortran_order": False, "shape": (100_000_000,)})
    with pytest.raises(ReplayError, match=r"extra\.npz: arrays: unexpected member\(s\) "
                                          r"\['x0\.npy', .*'x7\.npy'\] and 2 more; a replay "
                                          "holds actions, routes and meta"):
        load_replay(extra)  # refused unread


def test_save_is_atomic_and_readable(recorded, tmp_path):
    rep = load_replay(recorded["replay"])
    path = save_replay(rep, tmp_path / "sub" / "r.npz")
    assert [p.name for p in path.parent.iterdir()] == ["r.npz"]  # no temp file left
    umask = os.umask(0)
    os.umask(umask)
    assert path.stat().st_mode & 0o777 == 0o666 & ~umask
    assert load_replay(path).final_hash == rep.final_hash
    link = tmp_path / "link.npz"  # a link to a file in folders not made yet: made, as for
    link.symlink_to(tmp_path / "new" / "deep" / "r.npz")  # any path (before: OSError)
    save_replay(rep, link)
    assert link.is_symlink() and load_replay(link).final_hash == rep.final_hash
    assert sorted(p.name for p in tmp_path.iterdir()) == ["link.npz", "new", "sub"]


def test_record_match_every_and_hold(tmp_path):
    lineup = build_lineup(seats_scenario("smart,dodge", "open", {"max_steps": 50}))
    match = lineup.start(2).match
    rec = record_match(match, lineup.controllers, mp4=tmp_path / "e.mp4", every=4, hold_s=1.0,
                       keep_frames=True, scale=0.5)
    ticks = rec.ticks
    expected = 1 + ticks // 4 + (ticks % 4 != 0) + round(rec.fps)
    assert rec.frames == expected == imageio_ffmpeg.count_frames_and_secs(str(rec.mp4))[0]
    assert rec.fps == 7.5 and rec.kept.shape == (expected, 385, 385, 3)
    with pytest.raises(ValueError, match="one policy per seat"):
        record_match(match, [make_bot("smart")])


def test_record_command_plays_human_seats_with_the_stand_in(tmp_path, capsys):
    rc = record.run(_args(record, "--scenario", "mixed_teams", "--max-steps", "20",
                          "--out", str(tmp_path / "mixed.mp4")))
    assert rc == 0
    out = capsys.readouterr().out
    assert out.count("is played by smart(w=1)") == 4  # 2 humans + 2 learners
    assert Path(tmp_path / "mixed.mp4").stat().st_size > 1000


def test_wandb_video_wraps_the_mp4(tmp_path):
    import wandb

    from alphatank.ui.video import wandb_video

    lineup = build_lineup(seats_scenario("smart,random", "open", {"max_steps": 10}))
    rec = record_match(lineup.start(0).match, lineup.controllers, mp4=tmp_path / "w.mp4")
    assert isinstance(wandb_video(rec, caption="eval"), wandb.Video)
    with pytest.raises(ValueError, match="mp4="):
        wandb_video(record_match(lineup.start(1).match, lineup.controllers))


def test_record_killed_by_sigterm_leaves_no_partial_files(tmp_path):
    """`kill` or `timeout` stops `alphatank record` as Ctrl-C does: one line, status 130,
    and the half-written video is removed (the process died with it left behind)."""
    proc = subprocess.Popen([sys.executable, "-m", "alphatank.cli", "record", "--seats",
                             "smart,dodge", "--hold", "60", "-o", "k.mp4", "--gif", "k.gif",
                             "--replay", "k.npz"], cwd=tmp_path, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 120
        while not list(tmp_path.glob(".k.partial.mp4")) and time.monotonic() < deadline:
            time.sleep(0.05)  # the video is being written
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=120)
    finally:
        proc.kill()  # no-op once it has ended; a hung one must not outlive the test
    assert (proc.returncode, err) == (130, "alphatank record: interrupted by SIGTERM\n")
    assert list(tmp_path.iterdir()) == []


def test_replay_video_of_an_unlabelled_replay_numbers_seats_from_0(tmp_path):
    """A replay without labels (made from Python) is drawn with seat numbers from 0 in its
    video, as in its window and every message (the video said 1, 2, ...)."""
    lineup = build_lineup(seats_scenario("smart,aggressive", "open", {"max_steps": 12}))
    rec = ReplayRecorder()  # no labels
    lineup.play(2, [rec])
    path = save_replay(rec.replay, tmp_path / "plain.npz")
    assert replay.run(_args(replay, str(path), "--gif", str(tmp_path / "cmd.gif"))) == 0
    video = VideoRecorder(gif=tmp_path / "from0.gif", labels=["0", "1"])
    record_episode(replay_episode(load_replay(path), [video]), video)
    assert (tmp_path / "cmd.gif").read_bytes() == (tmp_path / "from0.gif").read_bytes()

"""``alphatank replay FILE``: re-simulate a saved match bit-identically.

Without options it re-runs the match headless and checks the final state hash against the
recording. ``--record OUT.mp4`` and/or ``--gif OUT.gif`` render it to video; ``--render``
plays it in a window at real-time speed (same keys as ``alphatank play``: P/Esc pause,
R restart, V/T/B overlays).
"""

from __future__ import annotations

import argparse
import sys
import time

from alphatank.commands.argtypes import given, positive_int, replay_speed
from alphatank.commands.lineup_options import overlays
from alphatank.errors import InputError, one_line
from alphatank.files import check_distinct
from alphatank.ui.render import (
    DEFAULT_OVERLAYS,
    DisplayUnavailable,
    window_display,
)
from alphatank.ui.replay import (
    Replay,
    ReplayCheck,
    ReplayError,
    load_replay,
    replay_episode,
    simulate,
)
from alphatank.ui.session import NO_DISPLAY_HELP, PlaySession
from alphatank.ui.video import (
    VideoRecorder,
    check_outputs,
    record_episode,
    sigterm_interrupts,
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", type=given,
                   help="replay file (.npz) from `play --save-replay` or `record --replay`")
    p.add_argument("--record", type=given, metavar="OUT.mp4", help="render the replay to an MP4")
    p.add_argument("--gif", type=given, metavar="FILE",
                   help="render the replay to a GIF (with --record: as well as the MP4)")
    p.add_argument("--render", action="store_true", help="play it back in a window")
    p.add_argument("--speed", type=replay_speed,
                   help="playback speed for --render, 0.05 to 50 (default: 1, real time)")
    p.add_argument("--overlays", type=overlays, default=",".join(DEFAULT_OVERLAYS),
                   help="aim,trajectory,bfs | all | none (default: aim,bfs)")
    p.add_argument("--headless-test", action="store_true",
                   help="allow --render with SDL_VIDEODRIVER=dummy (automated tests only)")
    p.add_argument("--max-frames", type=positive_int, help="stop --render after this many frames")


def run(args: argparse.Namespace) -> int:
    if not args.render:  # a window's flag alone would be ignored: the user meant --render
        window_only = [flag for flag, on in (("--speed", args.speed is not None),
                                             ("--max-frames", args.max_frames is not None),
                                             ("--headless-test", args.headless_test)) if on]
        if window_only:
            raise InputError(f"{window_only[0]} is for the window of --render; give --render "
                             f"with it")
    try:
        check_outputs(args.record, args.gif, ("--record", "--gif"))
        check_distinct({"the replay file": args.file, "--record": args.record,
                        "--gif": args.gif})
        replay = load_replay(args.file)
    except (ReplayError, ValueError) as exc:
        print(f"alphatank replay: error: {one_line(exc)}", file=sys.stderr)
        return 2
    if args.render and not args.headless_test:  # refused before the header or any video
        try:
            window_display()
        except DisplayUnavailable as exc:
            return _no_display(str(exc))
    who = ", ".join(f"{t}:{s}" for t, s in zip(replay.teams, replay.seats, strict=False))
    print(f"{args.file}: {replay.scenario or 'match'} on {replay.map_name}, "
          f"{replay.ticks} ticks, seats [{who}], recorded result: "
          f"{'team ' + replay.winner + ' wins' if replay.winner else 'no winner'}")
    try:
        if args.record or args.gif:
            video = VideoRecorder(mp4=args.record, gif=args.gif, overlays=args.overlays,
                                  labels=_labels(replay))
            with sigterm_interrupts():  # killed: no partial files left behind
                episode = replay_episode(replay, [ReplayCheck(replay), video])  # check first
                rec = record_episode(episode, video)
            wrote = [f"{rec.mp4} ({rec.frames} frames)"] if rec.mp4 is not None else []
            print("wrote " + " and ".join(wrote + ([str(rec.gif)] if rec.gif else [])))
        if args.render:
            return _render(replay, args)
        if not (args.record or args.gif):
            t0 = time.perf_counter()
            match = simulate(replay)
            print(f"re-simulated {match.tick} ticks in {time.perf_counter() - t0:.2f}s: "
                  f"final state hash matches ({replay.final_hash[:16]}...), and so does the "
                  f"result ({'team ' + match.winner + ' wins' if match.winner else 'no winner'})")
    except ReplayError as exc:
        print(f"alphatank replay: error: {one_line(exc)}", file=sys.stderr)
        return 1
    return 0


def _no_display(why: str) -> int:
    print("alphatank replay: " + NO_DISPLAY_HELP.format(
        verb="replay FILE --render", why=f" ({why})",
        instead="render it to a video with `--record OUT.mp4` or `--gif FILE`"), file=sys.stderr)
    return 2


def _labels(replay: Replay) -> list[str]:
    """The names drawn over the tanks: the recorded labels, else the seat numbers (from 0,
    as in every message), in the window and the videos alike."""
    return replay.labels or [str(i) for i in range(len(replay.teams))]


def _render(replay: Replay, args: argparse.Namespace) -> int:
    tick_hz = replay.game_config().tick_hz
    speed = 1.0 if args.speed is None else args.speed
    session = PlaySession(fps=tick_hz * speed, overlays=args.overlays, verbose=False,
                          new_episode=lambda _seed, hooks: replay_episode(replay, hooks),
                          labels=_labels(replay))
    try:
        session.run(max_frames=args.max_frames, caption=f"AlphaTank replay: {args.file}")
    except DisplayUnavailable as exc:
        return _no_display(str(exc))
    return 0

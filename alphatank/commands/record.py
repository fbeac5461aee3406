"""``alphatank record``: play a scenario headless (bots and/or checkpoints) into an MP4.

No window is opened (pygame's display is never initialised), so it works on servers and
in CI. Human seats are played by the ``--stand-in`` bot. Optionally also writes a GIF
and a replay file of the same match.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from alphatank.commands.argtypes import (
    given,
    hold_seconds,
    positive_int,
    scale,
    video_fps,
)
from alphatank.commands.lineup_options import add_lineup_arguments, lineup_from_args
from alphatank.errors import one_line
from alphatank.files import check_distinct, check_writable
from alphatank.sim.episode import EpisodeHook
from alphatank.ui.replay import ReplayRecorder, check_replay_room
from alphatank.ui.video import (
    VideoRecorder,
    check_outputs,
    record_episode,
    sigterm_interrupts,
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_lineup_arguments(p)
    p.add_argument("-o", "--out", type=given, default="match.mp4",
                   help="MP4 to write (default: match.mp4)")
    p.add_argument("--gif", type=given, metavar="FILE",
                   help="also write a GIF: half size, every other frame at half the frame "
                        "rate, so it plays at the video's speed (15 fps at real time with "
                        "--every 1)")
    p.add_argument("--replay", type=given, metavar="FILE",
                   help="also save the match as a replay file (refused if it exists, unless "
                        "--force)")
    p.add_argument("--force", action="store_true", help="overwrite an existing --replay")
    p.add_argument("--every", type=positive_int, default=1,
                   help="draw every N-th tick (default: 1, a frame per tick)")
    p.add_argument("--fps", type=video_fps,
                   help="video frame rate, 0.01 to 1000 (default: real time)")
    p.add_argument("--hold", type=hold_seconds, default=0.0,
                   help="seconds to hold the final frame, 0 to 60 (default: 0)")
    p.add_argument("--scale", type=scale, default=1.0,
                   help="video scale, 0.1 to 8 times the map's size (default: 1)")


def run(args: argparse.Namespace) -> int:
    try:
        check_outputs(args.out, args.gif, ("--out", "--gif"))
        check_distinct({"--out": args.out, "--gif": args.gif, "--replay": args.replay})
        if args.replay:
            check_writable(args.replay, "--replay", overwrite=args.force)
        lineup = lineup_from_args(args, interactive=False)
        if args.replay:
            sc = lineup.scenario
            check_replay_room(sc.game_config(), sc.map_specs(), len(sc.seats),
                              "--replay")
        video = VideoRecorder(mp4=Path(args.out), gif=args.gif, fps=args.fps,
                              every=args.every, hold_s=args.hold,
                              overlays=args.overlays, labels=lineup.labels,
                              scale=args.scale)
    except ValueError as exc:  # bad input not an InputError (those go to alphatank.cli)
        print(f"alphatank record: error: {one_line(exc)}", file=sys.stderr)
        return 2
    for note in lineup.notes:
        print(f"note: {note}")
    hooks: list[EpisodeHook] = [video]
    if args.replay:
        hooks.append(ReplayRecorder(scenario=lineup.scenario.name, seats=lineup.seats,
                                    labels=lineup.labels, path=args.replay,
                                    policies=lineup.controllers))
    with sigterm_interrupts():  # killed: no partial files left behind
        episode = lineup.start(args.seed, hooks)
        rec = record_episode(episode, video)
    result = f"team {rec.winner} wins" if rec.winner else "draw"
    print(f"{lineup.scenario.name} seed {args.seed} on {episode.match.spec.name}: {result} "
          f"after {rec.ticks} ticks; {rec.frames} frames at {rec.fps:g} fps -> {rec.mp4}")
    if rec.gif is not None:
        print(f"gif: {rec.gif}")
    if args.replay:
        print(f"replay: {args.replay}")
    print(f"final state hash: {rec.final_hash}")
    return 0

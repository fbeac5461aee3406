"""``alphatank record``: play a scenario headless (bots and/or checkpoints) into an MP4.

No window is opened (pygame's display is never initialised), so it works on servers and
in CI. Human seats are played by the ``--stand-in`` bot. Optionally also writes a GIF
and a replay file of the same match.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from alphatank.commands.argtypes import non_negative_float, positive_float, positive_int
from alphatank.commands.play import add_lineup_arguments, lineup_from_args, start_episode
from alphatank.game.scenarios import ScenarioError
from alphatank.ui.render import parse_overlays
from alphatank.ui.replay import ReplayRecorder, save_replay
from alphatank.ui.video import record_match


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_lineup_arguments(p)
    p.add_argument("-o", "--out", default="match.mp4",
                   help="MP4 to write (default: match.mp4)")
    p.add_argument("--gif", metavar="FILE", help="also write a GIF (half size, 15 fps)")
    p.add_argument("--replay", metavar="FILE", help="also save the match as a replay file")
    p.add_argument("--every", type=positive_int, default=1,
                   help="draw every N-th tick (default: 1, a frame per tick)")
    p.add_argument("--fps", type=positive_float, help="video frame rate (default: real time)")
    p.add_argument("--hold", type=non_negative_float, default=0.0,
                   help="seconds to hold the final frame (default: 0)")
    p.add_argument("--scale", type=positive_float, default=1.0, help="video scale (default: 1)")


def run(args: argparse.Namespace) -> int:
    try:
        lineup = lineup_from_args(args, humans=False)
        overlays = parse_overlays(args.overlays)
        match, match_seed = start_episode(lineup, args.seed)
    except (ScenarioError, ValueError, FileNotFoundError) as exc:
        print(f"alphatank record: {exc}", file=sys.stderr)
        return 2
    for note in lineup.notes:
        print(f"note: {note}")
    recorder = None
    if args.replay:
        recorder = ReplayRecorder(match, match_seed=match_seed, seed=args.seed,
                                  scenario=lineup.scenario.name, seats=lineup.seats,
                                  labels=lineup.labels, policies=lineup.policies)
    rec = record_match(match, lineup.policies, mp4=Path(args.out), gif=args.gif,
                       fps=args.fps, every=args.every, hold_s=args.hold, overlays=overlays,
                       labels=lineup.labels, scale=args.scale, recorder=recorder)
    result = f"team {rec.winner} wins" if rec.winner else "draw"
    print(f"{lineup.scenario.name} seed {args.seed} on {match.spec.name}: {result} after "
          f"{rec.ticks} ticks; {rec.frames} frames at {rec.fps:g} fps -> {rec.mp4}")
    if rec.gif is not None:
        print(f"gif: {rec.gif}")
    if recorder is not None:
        path = save_replay(recorder.finish(), args.replay)
        print(f"replay: {path}")
    return 0

"""``alphatank play``: interactive matches in a window at a steady frame rate.

Seats come from a scenario (``--scenario``) or a seat list (``--map`` + ``--seats``):
humans on one keyboard (player 1 WASD + F, player 2 arrows + Space, player 3 IJKL + P),
any bot, a trained checkpoint or a shipped agent. Keys: R new match, P or Esc pause (Esc
only when a player uses IJKL + P), V/T/B toggle aim line / bullet trajectory / BFS path, Q
quits from the pause or end screen. The session itself is :mod:`alphatank.ui.session`.
"""

from __future__ import annotations

import argparse
import sys

from alphatank.commands.argtypes import given, positive_int, scale, window_fps
from alphatank.commands.lineup_options import add_lineup_arguments, lineup_from_args
from alphatank.errors import one_line
from alphatank.files import check_writable
from alphatank.ui.human import HUMAN_ORDER
from alphatank.ui.render import DisplayUnavailable, window_display
from alphatank.ui.replay import check_replay_room
from alphatank.ui.session import NO_DISPLAY_HELP, PlaySession


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_lineup_arguments(p)
    p.add_argument("--fps", type=window_fps, default=60.0,
                   help="frames per second, 1 to 1000 (default: 60)")
    p.add_argument("--scale", type=scale,
                   help="window scale, 0.1 to 8 times the map's size (default: fit the screen)")
    p.add_argument("--save-replay", type=given, metavar="FILE",
                   help="save each match as a replay: FILE (refused if it exists, unless "
                        "--force), then -2, -3, ... before its suffix (m.npz, m-2.npz, "
                        "m-3.npz; an existing one is skipped)")
    p.add_argument("--force", action="store_true", help="overwrite an existing --save-replay")
    p.add_argument("--headless-test", action="store_true",
                   help="allow SDL_VIDEODRIVER=dummy and run frames unthrottled (automated "
                        "tests only)")
    p.add_argument("--max-frames", type=positive_int, help="stop after this many frames")


def _no_display(why: str) -> int:
    print("alphatank play: " + NO_DISPLAY_HELP.format(
        verb="play", why=f" ({why})", instead="play headless and get a video with "
        "`alphatank record`"), file=sys.stderr)
    return 2


def run(args: argparse.Namespace) -> int:
    if not args.headless_test:  # refused before the keyboard lines, as arena's --render is
        try:
            window_display()
        except DisplayUnavailable as exc:
            return _no_display(str(exc))
    if args.save_replay:
        check_writable(args.save_replay, "--save-replay", overwrite=args.force)
    try:
        lineup = lineup_from_args(args, interactive=True)
        if args.save_replay:
            sc = lineup.scenario
            check_replay_room(sc.game_config(), sc.map_specs(), len(sc.seats),
                              "--save-replay")
        session = PlaySession(lineup, seed=args.seed, fps=args.fps,
                              overlays=args.overlays, scale=args.scale,
                              save_replay=args.save_replay, realtime=not args.headless_test)
    except ValueError as exc:  # bad input not an InputError (those go to alphatank.cli)
        print(f"alphatank play: error: {one_line(exc)}", file=sys.stderr)
        return 2
    for note in lineup.notes:
        print(f"note: {note}")
    for kb in session.keyboards:
        print(f"player {HUMAN_ORDER.index(kb.keys) + 1} ({kb.keys}): {kb.layout.describe()}")
    try:
        report = session.run(max_frames=args.max_frames)
    except DisplayUnavailable as exc:
        return _no_display(str(exc))
    wins: dict[str, int] = {}
    for ep in report.episodes:
        key = ep.winner or ("draw" if ep.done else "unfinished")  # quit or restarted
        wins[key] = wins.get(key, 0) + 1
    print(f"{len(report.episodes)} match(es), results {wins}; "
          f"{report.frames} frames at {report.fps:.1f} fps")
    return 0


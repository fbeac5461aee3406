"""``alphatank`` command line: one subcommand module per verb in ``alphatank.commands``."""

from __future__ import annotations

import argparse
import importlib
import sys
from typing import Any

from alphatank.extras import MissingExtraError, install_hint

# verb -> module in alphatank.commands exposing add_arguments(parser) and run(args) -> int
COMMANDS = {
    "demo": "The main job: train PPO vs the aggressive bot, evaluate, record (runs/<name>/).",
    "train": "Train PPO/SAC learners from a named preset (vs bots, self-play, teams).",
    "eval": "Evaluate a checkpoint against bots: Table-3 layout with Wilson 95%% intervals.",
    "play": "Play interactively: humans, bots and checkpoints in any seat.",
    "record": "Record a headless match to MP4/GIF (and a replay file).",
    "replay": "Re-simulate, render or record a replay file.",
    "arena": "Play every pair of seats (bots, checkpoints, agents) on both sides; W/D/L "
             "matrix and league.",
    "bench": "Measure ticks/s of the match, env steps/s, bot and renderer cost.",
    "maps": "List shipped maps or validate and print some.",
    "agents": "List the trained agents shipped with the package (agent:NAME), or export one.",
}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="alphatank", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    for verb, help_text in COMMANDS.items():
        p = sub.add_parser(verb, help=help_text, description=help_text)
        try:
            module = importlib.import_module(f"alphatank.commands.{verb}")
        except MissingExtraError as exc:  # the verb exists; running it says what to install
            p.set_defaults(_run=_unavailable(exc), _any_args=True)
            continue
        module.add_arguments(p)
        p.set_defaults(_run=module.run)
    return parser


def _unavailable(exc: MissingExtraError) -> Any:
    def run(args: argparse.Namespace) -> int:
        raise exc
    return run


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args, unknown = parser.parse_known_args(argv)
    if unknown and not getattr(args, "_any_args", False):
        parser.error(f"unrecognized arguments: {' '.join(unknown)}")
    try:
        return int(args._run(args) or 0)
    except MissingExtraError as exc:
        print(f"alphatank {args.command} needs the '{exc.extra}' extra: "
              f"{install_hint(exc.extra)}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())

"""Command-line options that choose a line-up, shared by ``play`` and ``record`` (not a
verb itself), and the ``--overlays`` type (``replay`` takes it too)."""

from __future__ import annotations

import argparse
from pathlib import Path

from alphatank.commands.argtypes import given, max_steps, seed
from alphatank.errors import InputError
from alphatank.game.lineup import Lineup, build_lineup, lineup_scenario
from alphatank.game.scenarios import bot_names
from alphatank.game.seats import SEAT_HELP, shipped_agents
from alphatank.ui.render import DEFAULT_OVERLAYS, parse_overlays


def add_lineup_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--scenario", type=given, help="scenario name or .toml path (e.g. mixed_teams)")
    p.add_argument("--map", type=given, help="map for --seats (default: battlefield for 2 seats, "
                                 "arena4 up to 4, arena8 up to 8)")
    p.add_argument("--seats", type=given, help=SEAT_HELP)
    p.add_argument("--checkpoint", type=given, metavar="SEAT",
                   help="who plays the scenario's learner seats: a checkpoint or run folder, "
                        "checkpoint:PATH, agent:NAME or bot:NAME")
    p.add_argument("--stand-in", type=given, default="smart",
                   help="bot for learner seats when no --checkpoint is given, and for human "
                        "seats where there is no keyboard (record) (default: smart)")
    p.add_argument("--seed", type=seed, default=0, help="episode seed (default: 0)")
    p.add_argument("--max-steps", type=max_steps,
                   help="episode length limit in ticks, 1 to 10,000,000")
    p.add_argument("--overlays", type=overlays, default=",".join(DEFAULT_OVERLAYS),
                   help="aim,trajectory,bfs | all | none (default: aim,bfs)")


def overlays(text: str) -> tuple[str, ...]:
    """``--overlays`` as overlay names (an argparse type: a bad name is refused naming the
    flag, before any seat is loaded)."""
    try:
        return parse_overlays(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def learner_seat(checkpoint: str | None) -> str | None:
    """``--checkpoint`` as a seat spec: a bare path means ``checkpoint:PATH``; a bare bot
    or shipped agent name that is no folder here is refused, naming the spec it means."""
    if not checkpoint or checkpoint.startswith(("checkpoint:", "agent:", "bot:")):
        return checkpoint
    if not Path(checkpoint).exists():
        kind = ("bot" if checkpoint in bot_names() else
                "agent" if checkpoint in shipped_agents() else None)
        if kind is not None:
            raise InputError(f"--checkpoint: no checkpoint or run folder {checkpoint!r} here; "
                             f"for the {kind}, give {kind}:{checkpoint}")
    return f"checkpoint:{checkpoint}"


def lineup_from_args(args: argparse.Namespace, interactive: bool) -> Lineup:
    """The line-up a ``play``/``record`` command line asks for (without a keyboard, human
    seats are played by the stand-in bot)."""
    game = {"max_steps": args.max_steps} if args.max_steps is not None else {}
    sc = lineup_scenario(args.scenario, args.seats, args.map, game)
    return build_lineup(sc, interactive=interactive, learner=learner_seat(args.checkpoint),
                        stand_in=args.stand_in)

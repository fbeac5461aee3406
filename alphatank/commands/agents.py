"""``alphatank agents``: list the trained agents shipped with the package (they load by
name wherever a checkpoint does: ``agent:NAME``), or export a run's checkpoint as one."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from alphatank.commands.argtypes import given
from alphatank.errors import InputError


def add_arguments(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest="action")
    sub.add_parser("list", help="list the shipped agents (the default)")
    ex = sub.add_parser("export", help="write a checkpoint as an agent folder (weights only)")
    ex.add_argument("checkpoint", type=given,
                    help="checkpoint folder or run folder (its latest save)")
    ex.add_argument("dest", type=given,
                    help="agent folder to write (e.g. alphatank/data/agents/NAME)")
    ex.add_argument("--description", default="", help="one line about the agent")
    ex.add_argument("--eval", type=given, metavar="FILE.json",
                    help="an `alphatank eval --json` file of this checkpoint, recorded with "
                         "the agent (its rows are checked)")
    ex.add_argument("--command", dest="commands", action="append", default=[], metavar="TEXT",
                    help="a command that made or evaluated it (repeatable)")


def run(args: argparse.Namespace) -> int:
    """Bad input raises InputError or OSError, reported by :func:`alphatank.cli.main`."""
    if args.action == "export":
        from alphatank.files import check_folder
        from alphatank.game.seats import checkpoint_source
        from alphatank.sim.config import printable_problem

        if why := printable_problem(args.description):
            raise InputError(f"--description: {why}")
        check_folder(args.dest, "dest")
        from alphatank.training.agents import export_agent
        record = {"description": args.description, "commands": list(args.commands)}
        if args.eval:
            record["eval"] = _eval_of(args.eval, args.checkpoint)
        dest = export_agent(checkpoint_source(args.checkpoint), args.dest, record)
        size = sum(f.stat().st_size for f in dest.iterdir())
        print(f"agent {dest.name}: {dest} ({size / 1e6:.2f} MB)")
        return 0
    from alphatank.game.seats import agent_path, shipped_agents
    from alphatank.training.agents import agent_summary

    names = shipped_agents()
    if not names:
        print("no shipped agents")
        return 0
    print(f"{'agent':20s} {'scenario':18s} {'seed':>4s} {'steps':>10s} {'train s':>8s}  "
          "win rate (eval)")
    for name in names:
        s = agent_summary(agent_path(name))
        rows = s["eval"] if isinstance(s["eval"], list) else [s["eval"]]
        rows = [r for r in rows if r and "win_rate" in r]
        win = ", ".join((f"vs {_against(r)} " if len(rows) > 1 else "")
                        + f"{100 * r['win_rate']:.0f}% [{100 * r['ci95_low']:.0f}, "
                        f"{100 * r['ci95_high']:.0f}] of {r['games']}" for r in rows)
        print(f"{name:20s} {s['scenario']:18s} {s['seed']:>4d} {s['steps']:>10,d} "
              f"{s['elapsed_s']:>8.0f}  {win}")
    return 0


ROW_NUMBERS = ("win_rate", "ci95_low", "ci95_high", "games")  # what the listing shows


def _eval_of(path: str, checkpoint: str) -> Any:
    """The rows of an ``alphatank eval --json`` file for the agent exported from
    ``checkpoint``: each an evaluation row of that very checkpoint, else InputError."""
    from alphatank.files import read_text
    from alphatank.game.seats import checkpoint_source
    from alphatank.training.checkpoint import CheckpointError, resolve_checkpoint_dir

    want = "give the `alphatank eval --json` file of the exported checkpoint"
    try:
        text = read_text(path)  # ValueError naming the file: unreadable, or not UTF-8
    except ValueError as exc:
        raise InputError(f"--eval: {exc}; {want}") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(f"--eval: {path}: not JSON ({exc.msg} at line {exc.lineno} column "
                         f"{exc.colno}); {want}") from None

    def folder(spec: str) -> Path:
        return resolve_checkpoint_dir(checkpoint_source(spec)).resolve()

    exported = folder(checkpoint)
    for k, row in enumerate(data if isinstance(data, list) else [data]):
        if not isinstance(row, dict) or not all(
                type(row.get(f)) in (int, float) for f in ROW_NUMBERS):
            raise InputError(f"--eval: {path}: row {k} is not a row of `alphatank eval "
                             f"--json` (numbers {', '.join(ROW_NUMBERS)})")
        played = row.get("checkpoint")
        try:
            same = isinstance(played, str) and folder(played) == exported
        except (CheckpointError, ValueError):
            same = False
        if not same:
            raise InputError(f"--eval: {path}: row {k} evaluated {played!r}, not the exported "
                             f"checkpoint {checkpoint!r}")
    return data


def _against(row: dict) -> str:
    """What an evaluation row played: its experiment column, else its opponent label."""
    return str(row.get("spec", {}).get("column") or row.get("opponent", "?"))

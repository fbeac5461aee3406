"""``alphatank plot``: learning curves of one or many runs (win rate and episode return
against env steps and wall time), from their ``metrics.jsonl``."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from alphatank.commands.argtypes import given
from alphatank.files import check_writable


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("runs", nargs="+", type=given, metavar="RUN",
                   help="run folder(s) (with metrics.jsonl)")
    p.add_argument("-o", "--out", type=given, metavar="FILE.png", default="curves.png",
                   help="the figure to write (default: %(default)s)")
    p.add_argument("--labels", metavar="A,B,...",
                   help="legend labels, one per run (default: the folder names)")


def run(args: argparse.Namespace) -> int:
    from alphatank.extras import require

    require("train", "alphatank plot")
    from alphatank.training.plots import plot_runs

    labels = [x.strip() for x in args.labels.split(",")] if args.labels else None
    if not str(args.out).lower().endswith(".png"):
        print(f"alphatank plot: error: -o must name a .png file, got {args.out!r}",
              file=sys.stderr)
        return 2
    if labels is not None and len(labels) != len(args.runs):
        print(f"alphatank plot: error: --labels: {len(labels)} label(s) for {len(args.runs)} "
              f"run(s); give one per run", file=sys.stderr)
        return 2
    for run_dir in args.runs:
        if not Path(run_dir).is_dir():
            what = "a file, not a run folder" if Path(run_dir).exists() else "no such run folder"
            print(f"alphatank plot: error: {run_dir}: {what}", file=sys.stderr)
            return 2
    check_writable(args.out, "-o")  # an InputError: alphatank.cli prints it, exit 2
    try:
        plot_runs(args.runs, args.out, labels)
    except (ValueError, OSError) as exc:
        print(f"alphatank plot: error: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {args.out}")
    return 0

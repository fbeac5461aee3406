"""``alphatank demo`` (``make demo``): train PPO against the aggressive bot for a short
budget, evaluate it over 100 games, and leave the checkpoint, the evaluation table, a
learning-curve PNG, an MP4 of a match and wandb offline logs in ``runs/<name>/``."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from alphatank.commands.argtypes import budget_minutes, given, positive_int
from alphatank.errors import InputError
from alphatank.extras import require
from alphatank.files import check_folder, write_text_atomic


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--name", help="run name (default: demo-<date>-<time>)")
    p.add_argument("--runs", type=given, default="runs", help="folder of runs (default: runs)")
    p.add_argument("--minutes", type=budget_minutes, default=8.0,
                   help="training budget in minutes, at most a week (default: 8; the whole "
                        "job stays < 10)")
    p.add_argument("--games", type=positive_int, default=100,
                   help="evaluation games (default: 100)")
    p.add_argument("--workers", type=positive_int, default=2,
                   help="env worker processes (default: 2)")
    p.add_argument("--wandb", default="offline", choices=("offline", "online", "disabled"),
                   help="wandb mode (default: offline)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    require("video", "alphatank demo")  # before minutes of training, not after
    from alphatank.training.evaluate import (
        evaluate_checkpoint,
        format_table,
        write_csv,
        write_json,
    )
    from alphatank.training.fields import FieldError
    from alphatank.training.logging import plot_learning_curve
    from alphatank.training.presets import get_preset
    from alphatank.training.runner import Trainer
    from alphatank.training.video import record_policy_match

    t0 = time.perf_counter()
    name = args.name if args.name is not None else time.strftime("demo-%Y%m%d-%H%M%S")
    try:
        cfg = get_preset("demo").with_overrides(name=name, time_limit_s=args.minutes * 60,
                                                 num_workers=args.workers, wandb=args.wandb)
    except FieldError as exc:
        flag = {"name": "--name", "num_workers": "--workers"}.get(exc.name, exc.name)
        raise InputError(f"{flag}: {exc.problem}") from None
    check_folder(args.runs, "--runs")
    run_dir = Path(args.runs) / name
    if (run_dir / "latest").exists():
        raise InputError(f"{run_dir} already holds a run; pick another --name")
    print(f"[demo] training PPO vs the aggressive bot on 'open' for up to {args.minutes:g} min "
          f"({cfg.num_envs} matches, {cfg.num_workers} worker "
          f"process{'es' if cfg.num_workers > 1 else ''}) -> {run_dir}")
    summary = Trainer(cfg, run_dir, progress=not args.no_progress).train()
    if summary["exit_code"]:  # Ctrl-C / SIGTERM: the checkpoint is saved, skip the rest
        print(f"[demo] stopped by {summary['stopped']['reason']}; the run is saved in "
              f"{run_dir} (alphatank train --resume {run_dir} continues it)")
        return summary["exit_code"]
    ckpt = run_dir / (run_dir / "latest").read_text().strip()
    steps = summary["saved_step"]  # the checkpoint's (a time limit drops a cut iteration)
    print(f"[demo] trained {steps:,} steps in {summary['elapsed_s']:.0f} s; "
          f"evaluating over {args.games} games")
    results = evaluate_checkpoint(ckpt, [None], games=args.games, seed=12345)
    table = format_table(results)
    print(table)
    write_text_atomic(run_dir / "eval.md", table + "\n")
    write_csv(results, run_dir / "eval.csv")
    write_json(results, run_dir / "eval.json")
    lo, hi = results[0].interval
    curve = plot_learning_curve(run_dir, evals=[(steps, results[0].win_rate, lo, hi)])
    from alphatank.training.checkpoint import load_policy
    video = record_policy_match(cfg.scenario, load_policy(ckpt), run_dir / "match.mp4",
                                seed=7)
    print(f"[demo] done in {(time.perf_counter() - t0) / 60:.1f} min. In {run_dir}:")
    outputs = [("checkpoint", ckpt), ("evaluation", run_dir / "eval.md"),
               ("learning curve", curve), ("match video", video)]
    if args.wandb != "disabled":
        outputs.append((f"wandb {args.wandb} logs", run_dir / "wandb"))
    for label, path in outputs:
        print(f"  {label:18s} {path}")
    return 0

"""``alphatank train``: run a named training preset (PPO / SAC, against bots, agents, teams)."""

from __future__ import annotations

import argparse
from pathlib import Path

from alphatank.commands.argtypes import seed
from alphatank.training.presets import PRESETS, WANDB_MODES, get_preset


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--preset", default="ppo_vs_aggressive",
                   help=f"training preset (default: ppo_vs_aggressive); one of {sorted(PRESETS)}")
    p.add_argument("--list", action="store_true", help="list the presets and exit")
    p.add_argument("--name", help="run name; the run lives in <runs>/<name> (default: preset)")
    p.add_argument("--runs", default="runs", help="folder of runs (default: runs)")
    p.add_argument("--resume", metavar="DIR",
                   help="continue the run saved in DIR (a run folder or a checkpoint)")
    p.add_argument("--total-steps", type=int, help="env steps to train in total")
    p.add_argument("--num-envs", type=int, help="matches stepped together")
    p.add_argument("--workers", type=int, help="env worker processes (2 uses both cores)")
    p.add_argument("--seed", type=seed, help="run seed")
    p.add_argument("--time-limit", type=float, metavar="S",
                   help="stop (with a checkpoint) after S seconds of training")
    p.add_argument("--checkpoint-every", type=int, metavar="N", help="iterations per save")
    p.add_argument("--keep-checkpoints", type=int, metavar="K",
                   help="newest saves kept (default: 3; 0 keeps all)")
    p.add_argument("--eval-every", type=int, metavar="N", help="iterations per evaluation")
    p.add_argument("--eval-games", type=int, help="games per evaluation during training")
    p.add_argument("--video-every", type=int, metavar="N", help="iterations per match video")
    p.add_argument("--wandb", choices=WANDB_MODES, help="wandb mode (default: offline)")
    p.add_argument("--tensorboard", action="store_true", default=None,
                   help="also write TensorBoard logs (needs the tensorboard package)")
    p.add_argument("--torch-threads", type=int, help="torch threads (default: 1)")
    p.add_argument("--ppo", default="", metavar="K=V,...",
                   help="PPO hyperparameters for every PPO learner, e.g. "
                        "update_epochs=4,num_steps=128 (new runs only)")
    p.add_argument("--sac", default="", metavar="K=V,...",
                   help="SAC hyperparameters for every SAC learner, e.g. utd_ratio=0.25")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def _overrides(args: argparse.Namespace) -> dict:
    return {"total_steps": args.total_steps, "num_envs": args.num_envs,
            "num_workers": args.workers, "seed": args.seed, "time_limit_s": args.time_limit,
            "checkpoint_every": args.checkpoint_every, "eval_every": args.eval_every,
            "keep_checkpoints": args.keep_checkpoints,
            "eval_games": args.eval_games, "video_every": args.video_every,
            "wandb": args.wandb, "tensorboard": args.tensorboard,
            "torch_threads": args.torch_threads}


def list_presets() -> str:
    width = max(len(n) for n in PRESETS)
    lines = []
    for name, cfg in sorted(PRESETS.items()):
        algos = "+".join(s.algo for s in cfg.learners) or "ppo"
        lines.append(f"{name:{width}s}  {cfg.scenario:18s} {algos:12s} {cfg.description}")
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    from alphatank.game.scenarios import load_scenario
    from alphatank.training.presets import with_algo_overrides
    from alphatank.training.runner import Trainer, resume_trainer

    if args.list:
        print(list_presets())
        return 0
    progress = not args.no_progress
    if args.resume:
        if args.ppo or args.sac:
            print("error: --ppo/--sac apply to new runs; a resumed run keeps its settings")
            return 2
        trainer = resume_trainer(args.resume, progress=progress, **_overrides(args))
        print(f"resuming {trainer.run_dir} at step {trainer.global_step:,}")
    else:
        try:
            cfg = get_preset(args.preset)
            cfg = cfg.with_overrides(name=args.name or cfg.name, **_overrides(args))
            cfg = with_algo_overrides(cfg, len(load_scenario(cfg.scenario).learner_seats),
                                      args.ppo, args.sac)
        except ValueError as exc:
            print(f"error: {exc}")
            return 2
        run_dir = Path(args.runs) / cfg.name
        if (run_dir / "latest").exists():
            print(f"error: {run_dir} already holds a run; continue it with --resume {run_dir} "
                  f"or pick another --name")
            return 2
        trainer = Trainer(cfg, run_dir, progress=progress)
    summary = trainer.train()
    print(f"run {summary['run_dir']}: {summary['global_step']:,} steps, "
          f"{summary['episodes']:,} episodes, {summary['elapsed_s']:.0f} s")
    for key, val in summary.items():
        if key.startswith("charts/win_rate"):
            print(f"  {key} (last 100 episodes): {val:.2f}")
    print(f"  checkpoint: {Path(summary['run_dir']) / 'latest'} -> "
          f"{(Path(summary['run_dir']) / 'latest').read_text().strip()}")
    return 0

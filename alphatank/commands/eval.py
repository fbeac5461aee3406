"""``alphatank eval``: win/loss/draw counts of checkpoints against bots, with Wilson 95%
intervals, printed in the layout of the paper's Table 3 (and as CSV / JSON)."""

from __future__ import annotations

import argparse

from alphatank.commands.argtypes import positive_int, seed
from alphatank.errors import as_input_error


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("checkpoints", nargs="+", metavar="CHECKPOINT",
                   help="checkpoint folder(s) or run folder(s) (their latest save), also as "
                        "checkpoint:PATH, or agent:NAME for a shipped agent")
    p.add_argument("--vs", default="",
                   help="comma-separated bots to play (e.g. smart,aggressive,dodge,defensive); "
                        "default: the opponents of each checkpoint's scenario")
    p.add_argument("--games", type=positive_int, default=100, help="games per row (default: 100)")
    p.add_argument("--scenario", help="play in this scenario instead of the checkpoint's own")
    p.add_argument("--team", help="team the checkpoint plays (default: its first learner's)")
    p.add_argument("--weakness", type=float, help="bot weakness 0..1 (default: as trained)")
    p.add_argument("--greedy", action="store_true", help="most likely actions, no sampling")
    p.add_argument("--seed", type=seed, default=0, help="seed of the game sequence")
    p.add_argument("--num-envs", type=positive_int, default=16, help="matches played at once")
    p.add_argument("--csv", metavar="FILE", help="also write the rows as CSV")
    p.add_argument("--json", metavar="FILE", help="also write the rows as JSON")


def run(args: argparse.Namespace) -> int:
    from alphatank.game.seats import checkpoint_source
    from alphatank.training.evaluate import (
        evaluate_checkpoint,
        format_table,
        write_csv,
        write_json,
    )
    from alphatank.training.threads import limit_threads

    limit_threads()
    opponents = [b.strip() for b in args.vs.split(",") if b.strip()] or [None]
    results = []
    try:
        for arg in args.checkpoints:
            results += evaluate_checkpoint(checkpoint_source(arg), opponents,
                                           games=args.games, seed=args.seed,
                                           scenario=args.scenario, team=args.team,
                                           deterministic=args.greedy, num_envs=args.num_envs,
                                           weakness=args.weakness)
    except ValueError as exc:  # scenario, seat, option errors (a CheckpointError is not one)
        raise as_input_error(exc) from None
    print(format_table(results))
    if args.csv:
        write_csv(results, args.csv)
    if args.json:
        write_json(results, args.json)
    return 0

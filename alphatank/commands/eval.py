"""``alphatank eval``: win/loss/draw counts of checkpoints against bots, with Wilson 95%
intervals, printed in the layout of the paper's Table 3 (and as CSV / JSON), every row
labelled with its checkpoint; ``--ratings`` adds an openskill table of the games.

Game ``i`` depends only on ``(--seed, i)`` (its match seed and, for sampled policies, the
generator its actions are drawn from), so results do not change with ``--num-envs``."""

from __future__ import annotations

import argparse


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("checkpoints", nargs="+", metavar="CHECKPOINT",
                   help="checkpoint folder(s) or run folder(s) (their latest save), also as "
                        "checkpoint:PATH, or agent:NAME for a shipped agent")
    p.add_argument("--vs", default="",
                   help="comma-separated bots to play (e.g. smart,aggressive,dodge,defensive); "
                        "default: the opponents of each checkpoint's scenario")
    p.add_argument("--games", type=int, default=100, help="games per row (default: 100)")
    p.add_argument("--scenario", help="play in this scenario instead of the checkpoint's own")
    p.add_argument("--team", help="team the checkpoint plays (default: its first learner's)")
    p.add_argument("--map", metavar="NAME|FOLDER",
                   help="play on other maps: a shipped map, a shipped folder such as 'test', "
                        "a .txt file or a folder of maps")
    p.add_argument("--weakness", type=float, help="bot weakness 0..1 (default: as trained)")
    p.add_argument("--greedy", action="store_true", help="most likely actions, no sampling")
    p.add_argument("--seed", type=int, default=0, help="seed of the game sequence")
    p.add_argument("--num-envs", type=int, default=16, help="matches played at once")
    p.add_argument("--csv", metavar="FILE", help="also write the rows as CSV")
    p.add_argument("--json", metavar="FILE",
                   help="also write the rows as JSON (with every game's outcome)")
    p.add_argument("--ratings", action="store_true",
                   help="also print an openskill table rating checkpoints and opponents "
                        "together from these games")


def run(args: argparse.Namespace) -> int:
    from alphatank.game.seats import checkpoint_source
    from alphatank.training.checkpoint import CheckpointError
    from alphatank.training.evaluate import (
        evaluate_checkpoint,
        format_table,
        rating_table,
        results_league,
        write_csv,
        write_json,
    )
    from alphatank.training.threads import limit_threads

    limit_threads()
    if args.games < 1 or args.num_envs < 1:
        flag = "--games" if args.games < 1 else "--num-envs"
        print(f"error: {flag} must be >= 1, got {getattr(args, flag[2:].replace('-', '_'))}")
        return 2
    if not 0 <= args.seed < 2**63:
        print(f"error: --seed must be in [0, 2^63), got {args.seed}")
        return 2
    if args.weakness is not None and not 0.0 <= args.weakness <= 1.0:
        print(f"error: --weakness must be in [0, 1], got {args.weakness}")
        return 2
    opponents = [b.strip() for b in args.vs.split(",") if b.strip()] or [None]
    results = []
    try:
        for arg in args.checkpoints:
            results += evaluate_checkpoint(checkpoint_source(arg), opponents,
                                           games=args.games, seed=args.seed,
                                           scenario=args.scenario, team=args.team,
                                           deterministic=args.greedy, num_envs=args.num_envs,
                                           weakness=args.weakness, map_name=args.map,
                                           label=arg)
    except (CheckpointError, ValueError) as exc:  # ScenarioError, SeatError: ValueErrors
        print(f"error: {exc}")
        return 2
    print(format_table(results))
    if args.ratings:
        print("\nopenskill (Plackett-Luce) ratings from these games (draws are ties):")
        print(rating_table(results_league(results)))
    try:
        if args.csv:
            write_csv(results, args.csv)
        if args.json:
            write_json(results, args.json, per_game=True)
    except OSError as exc:
        print(f"error: cannot write {exc.filename}: {exc.strerror}")
        return 2
    return 0

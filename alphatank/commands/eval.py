"""``alphatank eval``: win/loss/draw counts of checkpoints against bots, with Wilson 95%
intervals, printed in the layout of the paper's Table 3 (and as CSV / JSON), every row
labelled with its checkpoint; ``--ratings`` adds an openskill table of the games,
``--pool`` the rows of several checkpoints (e.g. seeds) pooled and tested for spread.

Game ``i`` depends only on ``(--seed, i)`` (its match seed and, for sampled policies, the
generator its actions are drawn from), so results do not change with ``--num-envs``."""

from __future__ import annotations

import argparse
import json
import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from alphatank.commands.argtypes import given, match_count, positive_int, seed
from alphatank.errors import InputError, as_input_error
from alphatank.files import check_distinct, check_writable, write_text_atomic

if TYPE_CHECKING:
    from alphatank.training.checkpoint import Checkpoint
    from alphatank.training.evaluate import EvalResult


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("checkpoints", nargs="+", type=given, metavar="CHECKPOINT",
                   help="checkpoint folder(s) or run folder(s) (their latest save), also as "
                        "checkpoint:PATH, agent:NAME for a shipped agent, or bot:NAME "
                        "(with --scenario) for a bot in the learner seats: its win rate in "
                        "the same games, beside an agent's")
    p.add_argument("--vs",
                   help="comma-separated bots to play (e.g. smart,aggressive,dodge,defensive); "
                        "default: the opponents of each checkpoint's scenario")
    p.add_argument("--games", type=positive_int, default=100, help="games per row (default: 100)")
    p.add_argument("--scenario", type=given,
                   help="play in this scenario instead of the checkpoint's own")
    p.add_argument("--team", type=given,
                   help="team the checkpoint plays, one with a learner seat in the scenario "
                        "(default: its first learner's)")
    p.add_argument("--map", type=given, metavar="NAME|FOLDER",
                   help="play on other maps: a shipped map, a shipped folder such as 'test', "
                        "a .txt file or a folder of maps")
    p.add_argument("--weakness", type=float, help="bot weakness 0..1 (default: as trained)")
    p.add_argument("--game", metavar="KEY=VALUE,...", default="",
                   help="change settings of the game played (over the checkpoint's own), "
                        "e.g. random_spawns=false,max_steps=600 (keys: docs/rules.md)")
    p.add_argument("--greedy", action="store_true", help="most likely actions, no sampling")
    p.add_argument("--seed", type=seed, default=0, help="seed of the game sequence")
    p.add_argument("--num-envs", type=match_count, default=16,
                   help="matches played at once (at most 4,096; the games do not change)")
    p.add_argument("--team-stats", action="store_true",
                   help="also measure cooperation in the same games: share of won games in "
                        "which every teammate hit an enemy, kills in crossfire, hits per "
                        "seat (with --json t.json, written to t.team.json)")
    p.add_argument("--csv", type=given, metavar="FILE", help="also write the rows as CSV")
    p.add_argument("--json", type=given, metavar="FILE",
                   help="also write the rows as JSON (with every game's outcome)")
    p.add_argument("--ratings", action="store_true",
                   help="also print an openskill table rating checkpoints and opponents "
                        "together from these games")
    p.add_argument("--pool", action="store_true",
                   help="also pool the rows against each opponent (several checkpoints, "
                        "e.g. one set-up's seeds): their wins together with a Wilson "
                        "interval, and whether they differ more than their games' luck "
                        "(a permutation test)")


def run(args: argparse.Namespace) -> int:
    from alphatank.training.evaluate import (
        SELF_PLAY,
        evaluate_checkpoint,
        evaluate_stand_in,
        format_table,
        rating_table,
        results_league,
        write_csv,
        write_json,
    )
    from alphatank.training.presets import parse_game
    from alphatank.training.threads import limit_threads

    limit_threads()
    if args.pool and len(args.checkpoints) < 2:
        raise InputError("--pool needs two or more checkpoints (e.g. the seeds of one set-up)")
    if args.weakness is not None and not 0.0 <= args.weakness <= 1.0:
        raise InputError(f"--weakness must be in [0, 1], got {args.weakness}")
    opponents = [b.strip() for b in (args.vs or "").split(",") if b.strip()] or [None]
    if args.vs is not None and opponents == [None]:  # read as none: the scenario's bots
        raise InputError(f"--vs: no bot named in {args.vs!r}; give comma-separated bots, "
                         "e.g. smart,dodge")
    from alphatank.bots.registry import BOT_NAMES
    unknown = [b for b in opponents if b is not None and b not in BOT_NAMES]
    if unknown:
        raise InputError(f"--vs: unknown bot {unknown[0]!r}; valid bots: {list(BOT_NAMES)}")
    twice = next((b for k, b in enumerate(opponents) if b in opponents[:k]), None)
    if twice is not None:  # the same games again: a row repeated, pooled twice by --pool
        raise InputError(f"--vs: {twice!r} is given twice; give each bot once")
    for label, path in (("--csv", args.csv), ("--json", args.json)):
        if path:
            check_writable(path, label)
    team_json = team_json_path(args.json) if args.json and args.team_stats else None
    check_distinct({"--csv": args.csv, "--json": args.json, "--team-stats": team_json})
    results = []
    try:
        game = parse_game("--game", args.game)
        sources = [load_source(arg, args.scenario) for arg in args.checkpoints]
        for ckpt in sources:
            check_game(game, args.scenario, ckpt)
        if args.pool:
            check_pool(args, sources, opponents)
        for arg, ckpt in zip(args.checkpoints, sources, strict=True):
            if ckpt is None:
                results += evaluate_stand_in(arg[4:], args.scenario, opponents,
                                             games=args.games, seed=args.seed,
                                             team=args.team, num_envs=args.num_envs,
                                             weakness=args.weakness, map_name=args.map,
                                             label=arg, team_stats=args.team_stats,
                                             game=game)
                continue
            results += evaluate_checkpoint(ckpt, opponents,
                                           games=args.games, seed=args.seed,
                                           scenario=args.scenario, team=args.team,
                                           deterministic=args.greedy, num_envs=args.num_envs,
                                           weakness=args.weakness, map_name=args.map,
                                           label=arg, team_stats=args.team_stats,
                                           game=game)
    except ValueError as exc:  # scenario, seat, option errors (a CheckpointError is not one)
        raise as_input_error(exc) from None
    print(format_table(results))
    if args.pool:
        print_pooled(results)
    if args.ratings:
        print("\nopenskill (Plackett-Luce) ratings from these games (draws are ties):")
        print(rating_table(results_league(results)))
        selfplay = [r.agent or r.name for r in results if r.opponent == SELF_PLAY]
        if selfplay:
            print(f"(not rated: {', '.join(selfplay)}, playing itself)")
    stats = [{"checkpoint": r.agent, "experiment": r.name, "opponent": r.opponent,
              **r.team_stats} for r in results if r.team_stats is not None]
    if stats:
        from alphatank.training.teamstats import format_team_stats
        for s in stats:
            print(f"{s['checkpoint']} vs {s['opponent']}: {format_team_stats(s)}")
    try:
        if args.csv:
            write_csv(results, args.csv)
        if args.json:
            write_json(results, args.json, per_game=True)
            if stats and team_json:
                write_text_atomic(team_json, json.dumps(stats, indent=1) + "\n")
    except OSError as exc:
        raise InputError(f"cannot write {exc.filename}: {exc.strerror}") from None
    return 0


def team_json_path(json_path: str) -> Path:
    """Where ``--team-stats`` writes beside ``--json FILE``: FILE.team.json next to the file
    the rows land in (a symbolic link's target, so ``/dev/stdout`` sent to a file puts it
    beside that file); InputError where that is a device or pipe, which has no folder."""
    path = Path(json_path)
    if path.exists() and not path.is_file():
        raise InputError(f"--team-stats: --json {json_path} is not a file (a device or pipe), "
                         "so FILE.team.json has no place beside it; give --json a file name "
                         "(the team figures are also printed)")
    team = Path(os.path.realpath(path)).with_suffix(".team.json")
    check_writable(team, "--team-stats")
    return team


def load_source(arg: str, scenario: str | None) -> Checkpoint | None:
    """The checkpoint a CHECKPOINT argument names, or None for a ``bot:NAME`` stand-in
    (which needs ``--scenario``)."""
    from alphatank.game.seats import checkpoint_source
    from alphatank.training.checkpoint import load_checkpoint

    if not arg.startswith("bot:"):
        return load_checkpoint(checkpoint_source(arg))
    if scenario is None:
        raise InputError(f"{arg}: a bot has no scenario of its own; give --scenario (its "
                         "learner seats are played by the bot)")
    return None


def check_game(game: dict[str, Any], scenario: str | None, ckpt: Checkpoint | None) -> None:
    """``--game`` over the game a row plays (its scenario's, then the checkpoint's own
    settings), before any game: a rule across settings it breaks (bullets faster than
    tanks) names the flag, and so do bullet limits that change the bullets a tank may
    have alive from those the checkpoint trained with (its observations hold that many
    per tank)."""
    from alphatank.game.scenarios import load_scenario
    from alphatank.sim.config import ConfigError, game_config

    if not game:
        return
    sc = load_scenario(scenario) if scenario is not None else ckpt.scenario
    own = ckpt.train_config.game if ckpt is not None else {}
    try:
        cap = game_config(sc.preset, **{**sc.game, **own, **game}).bullet_capacity
    except ConfigError as exc:
        raise InputError(f"--game {exc.key}: {exc.reason}") from None
    limits = [k for k in ("max_bullets", "buff_max_bullets", "debuff_max_bullets") if k in game]
    if ckpt is None or not limits:
        return
    trained = ckpt.scenario
    was = game_config(trained.preset, **{**trained.game, **own}).bullet_capacity
    if cap != was:
        raise InputError(
            f"--game {', '.join(limits)}: lets a tank have up to {cap} bullets alive (the "
            f"most of max_bullets, buff_max_bullets, debuff_max_bullets); {ckpt.path} "
            f"trained with {was}, and its observations hold {was} per tank: keep that "
            f"most at {was}")


def check_pool(args: argparse.Namespace, sources: Sequence[Checkpoint | None],
               opponents: Sequence[str | None]) -> None:
    """``--pool`` before any game: no checkpoint given twice (its games would be pooled
    twice), and two or more rows must meet the same opponent."""
    from alphatank.game.scenarios import load_scenario
    from alphatank.training.evaluate import row_opponents

    seen: dict[Path | str, str] = {}
    for arg, ckpt in zip(args.checkpoints, sources, strict=True):
        key = ckpt.path.resolve() if ckpt is not None else arg
        if key in seen:
            raise InputError(f"--pool: {seen[key]} and {arg} are one checkpoint ({key}), "
                             "whose games would be pooled twice; give each run once")
        seen[key] = arg
    given = load_scenario(args.scenario) if args.scenario is not None else None
    met = {arg: row_opponents(given or ckpt.scenario, opponents, args.team, args.weakness,
                              stand_in=ckpt is None)
           for arg, ckpt in zip(args.checkpoints, sources, strict=True)}
    rows = [opp for opps in met.values() for opp in opps]
    if len(set(rows)) == len(rows):
        raise InputError("--pool needs two or more checkpoints against the same opponents "
                         "(e.g. the seeds of one set-up; --vs sets them); these meet "
                         + "; ".join(f"{arg}: {', '.join(opps)}" for arg, opps in met.items()))


def print_pooled(results: Sequence[EvalResult]) -> None:
    """One line per opponent met by two or more rows (:func:`check_pool`):
    :func:`pool_runs` of their wins."""
    from alphatank.training.aggregate import pool_runs

    rows: dict[str, list[EvalResult]] = {}
    for r in results:
        rows.setdefault(r.opponent, []).append(r)
    for opp, rs in rows.items():
        if len(rs) < 2:
            continue
        pool = pool_runs([r.wins for r in rs], [r.games for r in rs])
        lo, hi = pool.interval
        losses, draws = sum(r.losses for r in rs), sum(r.draws for r in rs)
        print(f"pooled vs {opp} ({len(rs)} rows): {pool.wins}/{losses}/{draws} (W/L/D) of "
              f"{pool.games} games, {100 * pool.rate:.1f}% [{100 * lo:.1f}, {100 * hi:.1f}]; "
              f"the rows' win rates spread by {100 * pool.spread:.1f} points (sd), their "
              f"games' luck alone gives {100 * pool.noise:.1f}: permutation p = "
              f"{pool.p_text} (a small p says the rows differ more than chance)")

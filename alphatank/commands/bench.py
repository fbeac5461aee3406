"""``alphatank bench``: throughput of the bare match, and of envs, bots and the renderer.

The match ticks are also given as a ratio to the bare pymunk floor: the prototype in
``shared/bench/proto`` (walls, tank joints, bullet handlers and one batch read per tick;
no rules), the same yardstick as ``shared/bench/floor_ratio.py``, timed by the same
workload in runs interleaved with the match's.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from alphatank.commands.argtypes import given, int_in_range, match_count, positive_int
from alphatank.commands.benchfloor import find_floor, floor_us_per_tick
from alphatank.commands.benchsoak import DEFAULT_SOAK_SCENARIOS, check_soak_steps, soak
from alphatank.errors import InputError, one_line
from alphatank.files import check_writable, write_text_atomic
from alphatank.game.scenarios import ScenarioError
from alphatank.sim.config import ConfigError, game_config
from alphatank.sim.mapspec import MapError, load_map
from alphatank.sim.match import Match
from alphatank.training.presets import TORCH_THREADS_MAX

if TYPE_CHECKING:
    from alphatank.commands.benchtrain import TrainBench

TICKS_MAX = 1_000_000  # per run: the actions are drawn ahead (~300 MB for 4v4 at the most)
# The options of each mode (by dest): one of a mode not run is refused, not ignored.
SOAK_OPTIONS = ("steps", "scenarios", "sample_every")
TRAIN_OPTIONS = ("train_preset", "train_workers", "train_envs", "train_fragments",
                 "train_overlap", "train_iterations", "train_threads")
MATCH_OPTIONS = ("map", "ticks", "repeats", "preset", "floor", "env", "bots", "render",
                 "train", "sac", *TRAIN_OPTIONS)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--map", type=given, default="maze", help="map name or path (default: maze)")
    p.add_argument("--ticks", type=int_in_range(1, TICKS_MAX), default=5000,
                   help=f"ticks per run (default: 5000, at most {TICKS_MAX:,})")
    p.add_argument("--repeats", type=positive_int, default=5,
                   help="runs per setting; median ticks/s, best run for the floor ratio")
    p.add_argument("--preset", default="paper", help="game preset (paper, long_range)")
    p.add_argument("--floor", type=given, metavar="DIR",
                   help="folder of the bare pymunk prototype (sim_core.py, maze_0.txt) to "
                        "compare with (default: the nearest shared/bench/proto above the "
                        "project or the working folder; skipped when there is none)")
    p.add_argument("--env", action="store_true", help="also measure env steps/s")
    p.add_argument("--bots", action="store_true", help="also measure bot decision cost")
    p.add_argument("--render", action="store_true", help="also measure renderer fps")
    p.add_argument("--train", action="store_true",
                   help="also measure PPO training steps/s against the raw env steps/s of the "
                        "same workers and envs (alternating rounds; see benchtrain)")
    p.add_argument("--train-preset", default="ppo_vs_smart", metavar="NAME",
                   help="preset of --train (default: ppo_vs_smart, 128-step x 4-epoch PPO)")
    p.add_argument("--train-workers", type=positive_int, default=2, metavar="N",
                   help="env worker processes of --train (default: 2)")
    p.add_argument("--train-envs", type=match_count, default=32, metavar="N",
                   help="matches stepped together in --train (default: 32)")
    p.add_argument("--train-fragments", action="store_true",
                   help="--train with the workers acting whole rollouts (train --fragments)")
    p.add_argument("--train-overlap", action="store_true",
                   help="--train with the workers acting the next rollout during each "
                        "update (train --overlap)")
    p.add_argument("--train-iterations", type=positive_int, default=3, metavar="N",
                   help="training iterations per round of --train (default: 3; with "
                        "--train-overlap a round's first rollout and last update overlap "
                        "nothing, so longer rounds come nearer a long run)")
    p.add_argument("--train-threads", type=int_in_range(1, TORCH_THREADS_MAX), default=1,
                   metavar="N",
                   help="torch threads of the --train run's learner (default: 1; more help "
                        "only with idle cores: the env workers wait during each update)")
    p.add_argument("--sac", action="store_true",
                   help="also measure one SAC gradient step against its bare-torch floor, and "
                        "SAC training steps/s per update-to-data ratio")
    p.add_argument("--json", type=given, metavar="FILE", help="write the figures as JSON")
    p.add_argument("--soak", action="store_true",
                   help="instead: soak test, --steps random-action env steps over --scenarios "
                        "with RSS sampled; fails on memory growth or NaN (see benchsoak)")
    p.add_argument("--steps", type=positive_int, default=1_000_000,
                   help="env steps of the soak, split over the scenarios (default: 10^6)")
    p.add_argument("--scenarios", default=",".join(DEFAULT_SOAK_SCENARIOS),
                   help="comma-separated soak scenarios (default: %(default)s)")
    p.add_argument("--sample-every", type=positive_int, default=10_000, metavar="N",
                   help="soak: memory sample every N steps (default: %(default)s)")
    p.set_defaults(_defaults={dest: p.get_default(dest)
                              for dest in (*SOAK_OPTIONS, *MATCH_OPTIONS)})


def match_ticks_per_second(map_name: str, teams: list[str], ticks: int, seed: int = 0,
                           preset: str = "paper") -> tuple[float, int]:
    """Ticks/s of a bare match (no observations, no bots): random steering, driving, and
    firing every tick. Actions are drawn before timing. Returns (ticks/s, shots fired)."""
    match = Match(game_config(preset), load_map(map_name), teams, seed=seed)
    rng = np.random.default_rng(seed)
    n = len(teams)
    # Hold each steering choice ~15 ticks so tanks roam instead of jittering.
    held = rng.integers(0, 3, size=(ticks // 15 + 1, n, 2))
    actions = np.repeat(held, 15, axis=0)[:ticks]
    actions = np.concatenate([actions, np.ones((ticks, n, 1), dtype=actions.dtype)], axis=2)
    shots = 0
    start = time.perf_counter()
    for t in range(ticks):
        shots += len(match.step(actions[t]).fired)
        if match.done:
            match.reset(seed + t + 1)
    return ticks / (time.perf_counter() - start), shots


def run(args: argparse.Namespace) -> int:
    """Every setting is checked (one line, exit 2) before anything is measured."""
    _check_mode(args)
    if args.json:
        check_writable(args.json, "--json")
    if args.soak:
        return _soak(args)
    floor = find_floor(args.floor)  # a wrong --floor: one line from alphatank.cli
    try:
        spec = load_map(args.map)
    except MapError as exc:
        raise InputError(f"--map: {exc}") from None
    if spec.tank_room(8) < 8:
        raise MapError(f"map {spec.name!r} has room for {spec.tank_room(8)} tanks; the bench "
                       "plays 1v1 and 4v4 (8 tanks)", f"--map {args.map}")
    try:
        game_config(args.preset)
    except ConfigError as exc:
        raise InputError(f"--preset: {exc}") from None
    train = _train_bench(args) if args.train else None
    try:
        return _measure(args, floor, train)
    finally:
        if train is not None:
            train.close()  # when the match bench failed or was interrupted


def _check_mode(args: argparse.Namespace) -> None:
    """InputError naming an option of a mode that is not run (``--steps`` without
    ``--soak``, ``--train-fragments`` without ``--train``, ``--env`` with ``--soak``),
    which would be ignored without a word."""
    def changed(dests: tuple[str, ...]) -> list[str]:
        return ["--" + d.replace("_", "-") for d in dests
                if getattr(args, d) != args._defaults[d]]

    if args.soak and (extra := changed(MATCH_OPTIONS)):
        raise InputError(f"{extra[0]}: not an option of --soak (which steps envs with "
                         "random actions, nothing else); leave it out, or run it without "
                         "--soak")
    if not args.soak and (extra := changed(SOAK_OPTIONS)):
        raise InputError(f"{extra[0]}: an option of --soak; add --soak, or leave it out")
    if not args.train and (extra := changed(TRAIN_OPTIONS)):
        raise InputError(f"{extra[0]}: an option of --train; add --train, or leave it out")


def _train_bench(args: argparse.Namespace) -> TrainBench:
    """The ``--train`` run and raw env, made (and so checked as ``alphatank train`` checks
    the same settings) before anything is measured."""
    from alphatank.commands.benchtrain import TrainBench

    flags = " ".join([f"--train-preset {args.train_preset}"]
                     + ["--train-fragments"] * args.train_fragments
                     + ["--train-overlap"] * args.train_overlap)
    try:
        return TrainBench(args.train_preset, args.train_workers, args.train_envs,
                          torch_threads=args.train_threads, fragments=args.train_fragments,
                          overlap=args.train_overlap, iterations=args.train_iterations)
    except ValueError as exc:
        raise InputError(f"{flags}: {one_line(exc)}") from None


def _measure(args: argparse.Namespace, floor: Path | None, train: TrainBench | None
             ) -> int:
    """The measurements of :func:`run` once its settings are checked."""
    results: dict[str, object] = {}
    print(f"bare match on {args.map!r} ({args.preset}), tanks firing constantly, "
          f"{args.ticks} ticks x {args.repeats} runs (median):")
    for label, teams in (("1v1", ["A", "B"]), ("4v4", ["A"] * 4 + ["B"] * 4)):
        runs, floors = [], []
        for r in range(args.repeats):
            runs.append(match_ticks_per_second(args.map, teams, args.ticks, seed=r,
                                               preset=args.preset))
            if floor is not None:
                floors.append(floor_us_per_tick(floor, len(teams), args.ticks, seed=r))
        tps = statistics.median(r[0] for r in runs)
        shots = sum(r[1] for r in runs) / len(runs)
        results[f"match_{label}_ticks_per_s"] = round(tps, 1)
        line = f"  {label}: {tps:10,.0f} ticks/s   ({shots:.0f} shots per run)"
        if floors:
            best = 1e6 / max(r[0] for r in runs)
            ratio = round(best / min(floors), 3)  # printed and stored alike
            results[f"floor_{label}_us_per_tick"] = round(min(floors), 2)
            results[f"match_{label}_over_floor"] = ratio
            line += f"   {ratio:.2f}x the pymunk floor ({best:.1f} vs {min(floors):.1f} us/tick)"
        print(line)
    if floor is not None:
        print(f"  floor: bare pymunk prototype in {floor} (its own maze; best runs, "
              "interleaved; lower is better)")
    else:
        print("  floor: no shared/bench/proto found (--floor DIR to compare with it)")
    if args.env:
        from alphatank.commands.benchenv import env_bench

        results["env"] = env_bench(floor=args.floor)
    if args.bots:
        from alphatank.bots.benchmark import bot_costs

        costs = bot_costs(map_name=args.map)
        results["bot_us_per_tick"] = costs
        print("bot decision cost (median us per act):")
        for name, us in costs.items():
            print(f"  {name:12s} {us:8.1f}")
    if args.render:
        from alphatank.ui.render import render_bench

        fps = render_bench()
        results["render_fps"] = fps
        print(f"renderer 4v4 with overlays: {fps:,.0f} frames/s")
    if train is not None:
        results["train"] = train.measure()
    if args.sac:
        from alphatank.commands.benchtrain import sac_step_bench, sac_train_bench

        results["sac_step"] = sac_step_bench()
        results["sac_train"] = sac_train_bench()
    _write_json(args.json, results)
    return 0


def _soak(args: argparse.Namespace) -> int:
    from alphatank.game.scenarios import load_scenario

    scenarios = [s.strip() for s in args.scenarios.split(",") if s.strip()]
    if not scenarios:
        raise ScenarioError(f"--scenarios: need at least one scenario, got {args.scenarios!r}")
    for k, name in enumerate(scenarios):
        if name in scenarios[:k]:  # the figures are by name: one would replace the other
            raise ScenarioError(f"--scenarios: {name!r} is given twice; give each once")
        if not load_scenario(name).learner_seats:
            raise ScenarioError(f"--scenarios: {name!r} has no learner seat to step")
    check_soak_steps(args.steps, args.sample_every, len(scenarios),
                     names=("--steps", "--sample-every"))
    ok, figures = soak(scenarios, args.steps, args.sample_every)
    _write_json(args.json, figures)
    return 0 if ok else 1


def _write_json(path: str | None, figures: dict) -> None:
    """Write ``figures`` to ``path`` (if given) atomically."""
    if path:
        write_text_atomic(path, json.dumps(figures, indent=2))

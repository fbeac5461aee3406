"""``alphatank bench``: throughput of the bare match, and of envs, bots and the renderer."""

from __future__ import annotations

import argparse
import json
import statistics
import time

import numpy as np

from alphatank.sim.config import game_config
from alphatank.sim.mapspec import load_map
from alphatank.sim.match import Match


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--map", default="maze", help="map name or path (default: maze)")
    p.add_argument("--ticks", type=int, default=5000, help="ticks per run (default: 5000)")
    p.add_argument("--repeats", type=int, default=5, help="runs per setting; median reported")
    p.add_argument("--preset", default="paper", help="game preset (paper, long_range)")
    p.add_argument("--env", action="store_true", help="also measure env steps/s")
    p.add_argument("--bots", action="store_true", help="also measure bot decision cost")
    p.add_argument("--render", action="store_true", help="also measure renderer fps")
    p.add_argument("--json", metavar="FILE", help="write the figures as JSON")


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
    results: dict[str, object] = {}
    print(f"bare match on {args.map!r} ({args.preset}), tanks firing constantly, "
          f"{args.ticks} ticks x {args.repeats} runs (median):")
    for label, teams in (("1v1", ["A", "B"]), ("4v4", ["A"] * 4 + ["B"] * 4)):
        runs = [match_ticks_per_second(args.map, teams, args.ticks, seed=r, preset=args.preset)
                for r in range(args.repeats)]
        tps = statistics.median(r[0] for r in runs)
        shots = sum(r[1] for r in runs) / len(runs)
        results[f"match_{label}_ticks_per_s"] = round(tps, 1)
        print(f"  {label}: {tps:10,.0f} ticks/s   ({shots:.0f} shots per run)")
    if args.env:
        from alphatank.commands.benchenv import env_bench

        results["env"] = env_bench()
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
    if args.json:
        with open(args.json, "w", encoding="utf-8") as f:
            json.dump(results, f, indent=2)
    return 0

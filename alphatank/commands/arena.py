"""``alphatank arena``: every pair of bots, both sides, as a win/draw/loss matrix with
Wilson 95% intervals; ``--render`` shows the games in a window."""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from alphatank.commands.argtypes import positive_float, positive_int, seed
from alphatank.sim.config import ConfigError, game_config
from alphatank.sim.mapspec import MapError, load_map
from alphatank.sim.match import Match

DEFAULT_BOTS = "smart,aggressive,defensive,dodge,random"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--bots", default=DEFAULT_BOTS,
                   help="comma-separated bots, each NAME[:KEY=VALUE...][@WEAKNESS], e.g. "
                        "'smart,smart:ricochet=false,random@0.5' (default: %(default)s)")
    p.add_argument("--map", default="maze", help="shipped map name or .txt path")
    p.add_argument("--games", type=positive_int, default=20,
                   help="games per pair, sides alternating (default: %(default)s)")
    p.add_argument("--seed", type=seed, default=0, help="first match seed")
    p.add_argument("--preset", default="paper", help="game preset (paper, long_range)")
    p.add_argument("--max-steps", type=int, default=None,
                   help="ticks before a game is a draw (default: the preset's)")
    p.add_argument("--render", action="store_true", help="show every game in a window")
    p.add_argument("--fps", type=positive_float, default=60.0, help="frame rate with --render")


def run(args: argparse.Namespace) -> int:
    from alphatank.bots.arena import run_arena
    from alphatank.bots.registry import bot_from_spec

    specs = [s.strip() for s in args.bots.split(",") if s.strip()]
    try:
        for s in specs:
            bot_from_spec(s)  # names, options and their types, weakness
        spec = load_map(args.map)
        overrides = {} if args.max_steps is None else {"max_steps": args.max_steps}
        cfg = game_config(args.preset, **overrides)
    except (ValueError, MapError, ConfigError) as exc:
        print(f"alphatank arena: error: {exc}", file=sys.stderr)
        return 2
    if len(specs) < 2:
        print(f"alphatank arena: error: --bots needs at least 2 bots, got {args.bots!r}",
              file=sys.stderr)
        return 2
    if args.games < 1:
        print(f"alphatank arena: error: --games must be >= 1, got {args.games}",
              file=sys.stderr)
        return 2
    on_tick = None
    renderer = None
    if args.render:
        from alphatank.ui.render import DisplayUnavailable, Renderer

        renderer = Renderer("human", fps=args.fps, caption="AlphaTank arena")

        def on_tick(match: Match, actions: np.ndarray) -> None:
            try:
                renderer.render(match)
            except DisplayUnavailable as exc:
                raise SystemExit(f"alphatank arena: error: --render: {exc}") from exc

    pairs = len(specs) * (len(specs) - 1) // 2
    print(f"arena: {len(specs)} bots, {pairs} pairs x {args.games} games on "
          f"{spec.name!r} (preset {args.preset}, max {cfg.max_steps} ticks)", flush=True)
    t0 = time.perf_counter()
    try:
        result = run_arena(specs, spec, cfg, args.games, seed=args.seed, on_tick=on_tick)
    finally:
        if renderer is not None:
            renderer.close()
    dt = time.perf_counter() - t0
    print(result.table())
    ticks, n = sum(result.ticks), len(result.ticks)
    print(f"{n} games, {ticks} ticks in {dt:.1f}s ({ticks / max(dt, 1e-9):,.0f} ticks/s, "
          f"mean game {ticks / n / cfg.tick_hz:.1f}s of game time)")
    return 0

"""``alphatank arena``: every pair of seats (bots, checkpoints, shipped agents), both
sides, as a win/draw/loss matrix with Wilson 95% intervals and an openskill league;
``--render`` shows the games in a window."""

from __future__ import annotations

import argparse
import sys
import time

from alphatank.commands.argtypes import given, max_steps, positive_int, seed, window_fps
from alphatank.errors import InputError
from alphatank.game.arena import arena_scenario, run_arena
from alphatank.game.lineup import spec_seat
from alphatank.game.scenarios import ScenarioError
from alphatank.sim.config import game_config
from alphatank.sim.episode import EpisodeHook
from alphatank.training.stopping import StopFlag, stop_on_signals

DEFAULT_SEATS = "smart,aggressive,defensive,dodge,random"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--seats", "--bots", dest="seats", default=DEFAULT_SEATS,
                   help="comma-separated seats, each a bot NAME[:KEY=VALUE...][@WEAKNESS], "
                        "checkpoint:PATH or agent:NAME, e.g. 'smart,smart:ricochet=false,"
                        "random@0.5,checkpoint:runs/ppo' (default: %(default)s)")
    p.add_argument("--map", type=given, default="maze",
                   help="shipped map or map folder (e.g. test), or a .txt map or folder path; "
                        "a folder's games draw their map by seed (default: %(default)s)")
    p.add_argument("--games", type=positive_int, default=20,
                   help="games per pair, sides alternating (default: %(default)s)")
    p.add_argument("--seed", type=seed, default=0, help="first episode seed")
    p.add_argument("--preset", default="paper", help="game preset (paper, long_range)")
    p.add_argument("--max-steps", type=max_steps, default=None,
                   help="ticks before a game is a draw, 1 to 10,000,000 (default: the "
                        "preset's)")
    p.add_argument("--render", action="store_true",
                   help="show every game in a window (refused without a display)")
    p.add_argument("--fps", type=window_fps,
                   help="frame rate with --render, 1 to 1000 (default: 60)")


def run(args: argparse.Namespace) -> int:
    if args.fps is not None and not args.render:  # ignored, the user meant a window
        raise InputError("--fps is the frame rate of --render's window; give --render with it")
    if args.render:  # a window that would show nothing is refused before any game
        from alphatank.ui.render import DisplayUnavailable, window_display

        try:
            window_display()
        except DisplayUnavailable as exc:
            print(f"alphatank arena: error: --render: {exc}; run it on a desktop session, "
                  "or leave out --render", file=sys.stderr)
            return 2
    seats = [s.strip() for s in args.seats.split(",") if s.strip()]
    overrides = {} if args.max_steps is None else {"max_steps": args.max_steps}
    for s in seats:  # bad input raises an InputError: one line from alphatank.cli
        spec_seat(s)
    if len(seats) < 2:
        raise ScenarioError(f"--seats needs at least 2 seats, got {args.seats!r}")
    maps = arena_scenario(seats[0], seats[1], args.map, args.preset, overrides).map_specs()
    where = repr(maps[0].name) if len(maps) == 1 else f"{len(maps)} maps of {args.map!r}"
    cfg = game_config(args.preset, **overrides)
    hooks: list[EpisodeHook] = []
    renderer = None
    no_window: tuple[type[Exception], ...] = ()
    if args.render:
        from alphatank.ui.render import DisplayUnavailable, Renderer, RenderHook

        renderer = Renderer("human", fps=args.fps or 60.0, caption="AlphaTank arena")
        hooks.append(RenderHook(renderer))
        no_window = (DisplayUnavailable,)
    pairs = len(seats) * (len(seats) - 1) // 2
    header = (f"arena: {len(seats)} seats, {pairs} pairs x {args.games} games on {where} "
              f"(preset {args.preset}, max {cfg.max_steps} ticks)")
    t0 = time.perf_counter()
    stop = StopFlag()  # Ctrl-C or SIGTERM: the games played are kept (polled every tick)
    try:  # the header once the seats pass their checks: a bad one is the only line
        with stop_on_signals(stop):
            result = run_arena(seats, args.map, args.games, seed=args.seed,
                               preset=args.preset, game=overrides, hooks=hooks,
                               on_start=lambda: print(header, flush=True), stop=stop)
    except no_window as exc:
        print(f"alphatank arena: error: --render: {exc}", file=sys.stderr)
        return 2
    finally:
        if renderer is not None:
            renderer.close()
    dt = time.perf_counter() - t0
    ticks, n = sum(result.ticks), len(result.ticks)
    if n:
        print(result.table(), flush=True)
    if stop.reason is not None:
        print(f"alphatank arena: interrupted by {stop.reason}"
              + (f" after {n} of {pairs * args.games} games (their table above)" if n else ""),
              file=sys.stderr)
        return stop.exit_code
    print(f"{n} games, {ticks} ticks in {dt:.1f}s ({ticks / max(dt, 1e-9):,.0f} ticks/s, "
          f"mean game {ticks / n / cfg.tick_hz:.1f}s of game time)")
    return 0

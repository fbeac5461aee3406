"""Env throughput for ``alphatank bench --env``: env steps/s of the batched vector env.

First two references, measured in the same run and on the same clock: a bare 1v1 match
tick (no bots, observations or rewards; the ``maze`` map, steering held 15 ticks, firing
every tick: ``bench/floor_ratio.py``'s protocol) and, when the shared prototype is found
(``--floor DIR``, default: the nearest ``shared/bench/proto`` above the project or the
working folder), the bare pymunk floor tick of ``floor_ratio.py``.

Then for each scenario: steps per CPU-second in one process (one core) and the
microseconds per step as a ratio to the match tick and to the floor (lower is better;
the issue-14 target is ``x floor`` <= 2 for ``vs_smart``); the same with the observation
and reward layers switched off (their own cost per step is the difference); and with
``workers`` processes (``SubprocVectorMatchEnv``, ``num_envs`` matches each): wall-clock
steps/s, its ratio to one process's wall-clock steps/s (the scaling, from alternating runs
of the two; needs that many idle cores), and steps per CPU-second of all processes
together (parent + workers); and those workers acting whole rollouts (``train
--fragments``: one call per worker per fragment of ``steps`` steps, random actions)
against one process doing the same. The
scaling's ceiling on this machine at this moment is measured once, on the first scenario:
``workers`` independent single-process envs side by side against one alone (no pipes, no
shared memory, no waiting for each other). One env
step = one tick of one match with every learner acting (random actions, drawn before
timing). Every figure is the best of ``--repeats`` timed runs of ``--steps`` steps: short
runs make the scaling figures noisy, so measure it with runs of a second or more
(``--steps 1500 --repeats 5``). CPU-time figures are robust to other programs sharing the
cores; wall-clock ones are not. Run alone: ``python -m alphatank.commands.benchenv``.
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from alphatank.commands.argtypes import match_count, positive_int
from alphatank.commands.benchfloor import find_floor, floor_us_per_tick
from alphatank.envs.vector import SubprocVectorMatchEnv, VectorMatchEnv
from alphatank.game.observe import OBS_KINDS

DEFAULT_SCENARIOS = ("vs_random", "vs_aggressive", "vs_defensive", "vs_dodge", "vs_smart",
                     "team", "mixed_teams")


def _prepare(env: Any, steps: int, seed: int, layers: bool = True) -> np.ndarray:
    """Reset ``env``, warm it up (10 steps) and return its random actions for ``steps``
    timed steps (drawn before timing). ``layers=False`` switches the observation and
    reward layers off."""
    if not layers:
        core = env.core
        core.obs.build = lambda: core.obs.out
        core.tracker.step = lambda sl, *a: core.tracker.terms[sl]
    env.reset(seed)
    rng = np.random.default_rng(seed)
    actions = rng.integers(0, [3, 3, 2], size=(steps, env.num_envs, env.num_learners, 3))
    for k in range(10):
        env.step(actions[k % steps])
    return actions


def _timed(env: Any, actions: np.ndarray, cpu: Callable[[], float]) -> tuple[float, float]:
    """(wall-clock, CPU-time) env steps/s of one run of ``actions``."""
    w0, c0 = time.perf_counter(), cpu()
    for a in actions:
        env.step(a)
    n = env.num_envs * len(actions)
    return n / (time.perf_counter() - w0), n / max(cpu() - c0, 1e-9)


def _cpu_rate(env: Any, steps: int, seed: int, layers: bool = True, repeats: int = 3
              ) -> float:
    """Env steps per CPU-second of this process (num_envs x steps ticks) after a short
    warm-up, the best of ``repeats`` runs."""
    actions = _prepare(env, steps, seed, layers)
    return max(_timed(env, actions, time.process_time)[1] for _ in range(repeats))


def lockstep_scaling(scenario: str, workers: int, num_envs: int = 16, steps: int = 150,
                     seed: int = 0, observation: str = "paper", repeats: int = 3
                     ) -> tuple[float, float, float]:
    """``workers`` processes stepped in lockstep (``SubprocVectorMatchEnv``, ``num_envs``
    matches each) against one process with ``num_envs`` matches, in alternating runs (so
    both see the machine in the same state): the workers' wall-clock steps/s, their
    steps per CPU-second of all processes (parent + workers) and the ratio of the best
    wall-clock runs (the scaling)."""
    one = VectorMatchEnv(scenario, num_envs, seed, observation)
    many = SubprocVectorMatchEnv(scenario, num_envs * workers, seed, observation,
                                 num_workers=workers)
    try:
        pids = [p.pid for p in many._procs]
        clock = (_cpu_clock(pids) if os.path.exists(f"/proc/{pids[0]}/stat")
                 else time.process_time)
        acts_one, acts_many = _prepare(one, steps, seed), _prepare(many, steps, seed)
        wall_one, wall_many, cpu_many = 0.0, 0.0, 0.0
        for _ in range(repeats):
            wall_one = max(wall_one, _timed(one, acts_one, time.process_time)[0])
            w, c = _timed(many, acts_many, clock)
            wall_many, cpu_many = max(wall_many, w), max(cpu_many, c)
    finally:
        many.close()
    return wall_many, cpu_many, wall_many / wall_one


def _cpu_clock(pids: Sequence[int]) -> Callable[[], float]:
    """A clock of the CPU seconds used by this process plus the processes ``pids`` (read
    from /proc; Linux). So worker throughput per CPU-second is measurable even when other
    programs share the cores."""
    tick = os.sysconf("SC_CLK_TCK")

    def clock() -> float:
        total = time.process_time()
        for pid in pids:
            with open(f"/proc/{pid}/stat", encoding="ascii") as f:
                fields = f.read().rsplit(")", 1)[1].split()
            total += (int(fields[11]) + int(fields[12])) / tick  # utime + stime
        return total

    return clock


def match_tick_us(ticks: int = 1500, repeats: int = 3, seed: int = 0,
                  map_name: str = "maze") -> float:
    """CPU microseconds of one bare 1v1 match tick (no bots, observations or rewards;
    best of ``repeats``), driven like ``floor_ratio.py``'s match (and ``alphatank bench``'s):
    steering held 15 ticks, firing every tick, actions drawn before timing."""
    from alphatank.sim.config import game_config
    from alphatank.sim.mapspec import load_map
    from alphatank.sim.match import Match

    best = float("inf")
    for r in range(repeats):
        match = Match(game_config(), load_map(map_name), ["A", "B"], seed=seed + r)
        rng = np.random.default_rng(seed + r)
        held = rng.integers(0, 3, size=(ticks // 15 + 1, 2, 2))
        acts = np.repeat(held, 15, axis=0)[:ticks]
        acts = np.concatenate([acts, np.ones((ticks, 2, 1), dtype=acts.dtype)], axis=2)
        start = time.process_time()
        for t in range(ticks):
            match.step(acts[t])
            if match.done:
                match.reset(seed + r + t + 1)
        best = min(best, (time.process_time() - start) / ticks * 1e6)
    return best


def floor_tick_us(proto: Path, ticks: int = 1500, repeats: int = 3, seed: int = 0) -> float:
    """CPU microseconds of one 1v1 tick of the bare pymunk prototype in ``proto`` (best of
    ``repeats``), set up as ``floor_ratio.py`` sets it up."""
    return min(floor_us_per_tick(proto, 2, ticks, seed + r, clock=time.process_time)
               for r in range(repeats))


def _solo(scenario: str, num_envs: int, steps: int, seed: int, observation: str,
          barrier: Any, out: Any) -> None:
    """One single-process env run in a child process, started with the others at the
    barrier; puts its wall-clock seconds on ``out``."""
    env = VectorMatchEnv(scenario, num_envs, seed, observation)
    env.reset(seed)
    rng = np.random.default_rng(seed)
    actions = rng.integers(0, [3, 3, 2], size=(steps + 10, num_envs, env.num_learners, 3))
    for k in range(10):
        env.step(actions[k])
    barrier.wait()
    start = time.perf_counter()
    for k in range(10, steps + 10):
        env.step(actions[k])
    out.put(time.perf_counter() - start)


def independent_scaling(scenario: str, procs: int, num_envs: int = 16, steps: int = 150,
                        seed: int = 0, observation: str = "paper", repeats: int = 2) -> float:
    """Wall-clock steps/s of ``procs`` independent single-process envs run side by side,
    over one such env run alone (best of ``repeats`` each): what worker processes could
    reach on this machine now."""
    ctx = mp.get_context("spawn")

    def rate(k: int) -> float:
        barrier, out = ctx.Barrier(k), ctx.Queue()
        ps = [ctx.Process(target=_solo, args=(scenario, num_envs, steps, seed + i,
                                               observation, barrier, out), daemon=True)
              for i in range(k)]
        for p in ps:
            p.start()
        took = max(out.get(timeout=600) for _ in ps)
        for p in ps:
            p.join()
        return k * num_envs * steps / took

    one = max(rate(1) for _ in range(repeats))
    return max(rate(procs) for _ in range(repeats)) / one


class RandomRollout:
    """A :class:`~alphatank.envs.fragments.RolloutPolicy` of uniform random actions,
    seeded per shard: a fragment's cost without a network."""

    def start(self, env_ids: Sequence[int]) -> None:
        self.rng = np.random.default_rng(int(env_ids[0]))

    def act(self, obs: np.ndarray, inputs: dict[str, np.ndarray]
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        n, L, _ = obs.shape
        zeros = np.zeros((n, L), np.float32)
        return self.rng.integers(0, [3, 3, 2], size=(n, L, 3)), zeros, zeros

    def values(self, obs: np.ndarray, inputs: dict[str, np.ndarray]) -> np.ndarray:
        return np.zeros(obs.shape[:2], np.float32)


def fragment_scaling(scenario: str, workers: int, num_envs: int = 16, steps: int = 150,
                     seed: int = 0, observation: str = "paper", repeats: int = 3
                     ) -> tuple[float, float]:
    """Wall-clock env steps/s of ``workers`` processes acting fragments of ``steps`` steps
    (one call per worker per fragment: ``train --fragments``), and its ratio to one
    process doing the same with ``num_envs`` matches; alternating runs, best of each."""
    one = VectorMatchEnv(scenario, num_envs, seed, observation)
    many = SubprocVectorMatchEnv(scenario, num_envs * workers, seed, observation,
                                 num_workers=workers)
    policy = RandomRollout()
    try:
        obs = {id(env): env.rollout(policy, env.reset(seed), 10).next_obs
               for env in (one, many)}
        best = {id(one): 0.0, id(many): 0.0}
        for _ in range(repeats):
            for env in (one, many):
                start = time.perf_counter()
                frag = env.rollout(policy, obs[id(env)], steps)
                rate = env.num_envs * steps / (time.perf_counter() - start)
                obs[id(env)], best[id(env)] = frag.next_obs, max(best[id(env)], rate)
    finally:
        many.close()
    return best[id(many)], best[id(many)] / best[id(one)]


def env_bench(scenarios: Sequence[str] = DEFAULT_SCENARIOS, observation: str = "paper",
              num_envs: int = 16, steps: int = 150, workers: int = 2, seed: int = 0,
              floor: str | None = None, verbose: bool = True, repeats: int = 3
              ) -> dict[str, dict[str, float]]:
    """Measure every scenario; returns {scenario: {steps_per_s (per CPU-second),
    us_per_step, match_tick_us, over_match_tick, floor_us / over_floor (when the
    prototype is found), no_layers_steps_per_s, layers_us_per_step, workers_steps_per_s
    (wall clock), workers_speedup (over one process, wall clock), independent_speedup
    (the ceiling, see the module docstring), workers_steps_per_cpu_s (all processes' CPU
    time), fragments_steps_per_s / fragments_speedup (the workers acting whole
    rollouts: :func:`fragment_scaling`)}}."""
    proto = find_floor(floor)  # a wrong folder fails before anything is measured
    tick = match_tick_us(seed=seed)
    floor_us = floor_tick_us(proto, seed=seed) if proto is not None else None
    ceiling = (independent_scaling(scenarios[0], workers, num_envs, steps, seed, observation,
                                   repeats) if workers > 1 and scenarios else None)
    if verbose:
        where = f"pymunk floor {floor_us:.1f} us ({proto})" if floor_us else (
            "pymunk floor: prototype not found (--floor DIR)")
        print(f"references, CPU time per tick: bare 1v1 match tick {tick:.1f} us (maze, "
              f"firing), {where}")
        if ceiling is not None:
            print(f"scaling ceiling now: {workers} independent {scenarios[0]} processes "
                  f"side by side reach {ceiling:.2f}x one alone (wall clock)")
        print(f"env steps/s, {observation} observations, {num_envs} matches per process, "
              f"random actions, {steps} steps:")
        print(f"  {'scenario':14s} {'1 core':>8s} {'us/step':>8s} {'x tick':>7s} "
              f"{'x floor':>7s} {'no obs/rew':>10s} {'obs+rew us':>10s} "
              f"{f'{workers} procs':>8s} {'x 1 proc':>8s} {'per cpu-s':>9s} "
              f"{'fragments':>9s} {'x 1 proc':>8s}")
    results: dict[str, dict[str, float]] = {}
    for name in scenarios:
        one = _cpu_rate(VectorMatchEnv(name, num_envs, seed, observation), steps, seed,
                        repeats=repeats)
        bare = _cpu_rate(VectorMatchEnv(name, num_envs, seed, observation), steps, seed,
                         layers=False, repeats=repeats)
        us = 1e6 / one
        row = {"steps_per_s": round(one, 1), "us_per_step": round(us, 2),
               "match_tick_us": round(tick, 2), "over_match_tick": round(us / tick, 2),
               "no_layers_steps_per_s": round(bare, 1),
               "layers_us_per_step": round(us - 1e6 / bare, 2)}
        if floor_us:
            row["floor_us"] = round(floor_us, 2)
            row["over_floor"] = round(us / floor_us, 2)
        if workers > 1:
            multi, cpu, speedup = lockstep_scaling(name, workers, num_envs, steps, seed,
                                                   observation, repeats)
            row["workers_steps_per_s"] = round(multi, 1)
            if ceiling is not None:
                row["independent_speedup"] = round(ceiling, 2)
            row["workers_speedup"] = round(speedup, 2)
            row["workers_steps_per_cpu_s"] = round(cpu, 1)
            frag, frag_x = fragment_scaling(name, workers, num_envs, steps, seed, observation,
                                            repeats)
            row["fragments_steps_per_s"] = round(frag, 1)
            row["fragments_speedup"] = round(frag_x, 2)
        results[name] = row
        if verbose:
            over_floor = f"{row['over_floor']:7.2f}" if floor_us else f"{'-':>7s}"
            cells = [(k, w, ",.0f" if k.endswith("_s") else ".2f") for k, w in (
                ("workers_steps_per_s", 8), ("workers_speedup", 8),
                ("workers_steps_per_cpu_s", 9), ("fragments_steps_per_s", 9),
                ("fragments_speedup", 8))]  # "-" without worker processes
            workers_cells = " ".join(format(row[k], f"{w}{fmt}") if k in row else f"{'-':>{w}s}"
                                     for k, w, fmt in cells)
            print(f"  {name:14s} {one:8,.0f} {us:8.1f} {row['over_match_tick']:7.2f} "
                  f"{over_floor} {bare:10,.0f} {row['layers_us_per_step']:10.1f} "
                  f"{workers_cells}")
    return results


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--scenarios", nargs="+", default=list(DEFAULT_SCENARIOS))
    p.add_argument("--observation", default="paper", choices=list(OBS_KINDS))
    p.add_argument("--num-envs", type=match_count, default=16, help="matches per process")
    p.add_argument("--steps", type=positive_int, default=150, help="timed steps per run")
    p.add_argument("--repeats", type=positive_int, default=3, help="timed runs of each "
                   "measurement, the best kept (alternating runs for the scaling figures)")
    p.add_argument("--workers", type=positive_int, default=2, help="processes for the "
                   "shared-memory variant (1: skip it)")
    p.add_argument("--floor", metavar="DIR", help="folder of the shared pymunk prototype "
                   "(default: the nearest shared/bench/proto above the project or here)")


def run(args: argparse.Namespace) -> int:
    """Bad input (a scenario, --floor) is one line, exit 2, before anything is measured."""
    from alphatank.game.scenarios import ScenarioError, load_scenario

    try:
        for name in args.scenarios:
            load_scenario(name)
    except ScenarioError as e:
        print(f"error: --scenarios: {e}", file=sys.stderr)
        return 2
    try:
        env_bench(args.scenarios, args.observation, args.num_envs, args.steps, args.workers,
                  floor=args.floor, repeats=args.repeats)
    except FileNotFoundError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    from alphatank.cli import Parser  # errors in one line, exit 2

    parser = Parser(description=__doc__)
    add_arguments(parser)
    raise SystemExit(run(parser.parse_args()))

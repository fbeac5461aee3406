"""Env throughput for ``alphatank bench --env``: env steps/s of the batched vector env.

For each scenario: steps per CPU-second in one process (one core), the same with the
observation and reward layers switched off (physics + bots + bookkeeping only, so the
layers' own cost per step is the difference), and with ``workers`` processes
(``SubprocVectorMatchEnv``): wall-clock steps/s (scales only with that many idle cores)
and steps per CPU-second of all processes together (parent + workers). One env step =
one tick of one match with every learner acting (random actions, drawn before timing).
Run alone: ``python -m alphatank.commands.benchenv``.
"""

from __future__ import annotations

import argparse
import os
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from alphatank.envs.vector import SubprocVectorMatchEnv, VectorMatchEnv
from alphatank.game.observe import OBS_KINDS

DEFAULT_SCENARIOS = ("vs_random", "vs_aggressive", "vs_defensive", "vs_dodge", "vs_smart",
                     "team", "mixed_teams")


def _steps_per_s(env: Any, steps: int, seed: int, layers: bool = True,
                 repeats: int = 3, clock: Any = time.process_time) -> float:
    """Env steps/s (num_envs x steps ticks) after a short warm-up; best of ``repeats``
    runs. The default clock is this process's CPU time (steps per CPU-second, robust to
    other processes sharing the cores); worker processes need the wall clock."""
    if not layers:
        core = env.core
        core.obs.build = lambda: core.obs.out
        core.tracker.step = lambda sl, *a: core.tracker.terms[sl]
    env.reset(seed)
    rng = np.random.default_rng(seed)
    shape = (steps, env.num_envs, env.num_learners, 3)
    actions = rng.integers(0, [3, 3, 2], size=shape)
    for k in range(10):
        env.step(actions[k])
    best = 0.0
    for _ in range(repeats):
        start = clock()
        for k in range(steps):
            env.step(actions[k])
        best = max(best, env.num_envs * steps / (clock() - start))
    return best


def _cpu_clock(pids: Sequence[int]) -> Any:
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


def env_bench(scenarios: Sequence[str] = DEFAULT_SCENARIOS, observation: str = "paper",
              num_envs: int = 16, steps: int = 150, workers: int = 2, seed: int = 0,
              verbose: bool = True) -> dict[str, dict[str, float]]:
    """Measure every scenario; returns {scenario: {steps_per_s (per CPU-second),
    no_layers_steps_per_s, layers_us_per_step, workers_steps_per_s (wall clock),
    workers_steps_per_cpu_s (all processes' CPU time)}}."""
    results: dict[str, dict[str, float]] = {}
    if verbose:
        print(f"env steps/s, {observation} observations, {num_envs} matches per process, "
              f"random actions, {steps} steps:")
        print(f"  {'scenario':14s} {'1 core':>9s} {'no obs/rew':>11s} {'obs+rew us':>11s} "
              f"{f'{workers} procs':>9s} {'per cpu-s':>9s}")
    for name in scenarios:
        one = _steps_per_s(VectorMatchEnv(name, num_envs, seed, observation), steps, seed)
        bare = _steps_per_s(VectorMatchEnv(name, num_envs, seed, observation), steps, seed,
                            layers=False)
        row = {"steps_per_s": round(one, 1), "no_layers_steps_per_s": round(bare, 1),
               "layers_us_per_step": round(1e6 / one - 1e6 / bare, 2)}
        if workers > 1:
            env = SubprocVectorMatchEnv(name, num_envs * workers, seed, observation,
                                        num_workers=workers)
            try:
                multi = _steps_per_s(env, steps, seed, clock=time.perf_counter)
                pids = [p.pid for p in env._procs]
                cpu = (_steps_per_s(env, steps, seed, clock=_cpu_clock(pids))
                       if os.path.exists(f"/proc/{pids[0]}/stat") else 0.0)
            finally:
                env.close()
            row["workers_steps_per_s"] = round(multi, 1)
            row["workers_steps_per_cpu_s"] = round(cpu, 1)
        results[name] = row
        if verbose:
            print(f"  {name:14s} {one:9,.0f} {bare:11,.0f} {row['layers_us_per_step']:11.1f} "
                  f"{row.get('workers_steps_per_s', 0):9,.0f} "
                  f"{row.get('workers_steps_per_cpu_s', 0):9,.0f}")
    return results


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--scenarios", nargs="+", default=list(DEFAULT_SCENARIOS))
    p.add_argument("--observation", default="paper", choices=list(OBS_KINDS))
    p.add_argument("--num-envs", type=int, default=16, help="matches per process")
    p.add_argument("--steps", type=int, default=150, help="timed steps per run")
    p.add_argument("--workers", type=int, default=2, help="processes for the shared-memory "
                   "variant (1: skip it)")


def run(args: argparse.Namespace) -> int:
    env_bench(args.scenarios, args.observation, args.num_envs, args.steps, args.workers)
    return 0


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__)
    add_arguments(parser)
    raise SystemExit(run(parser.parse_args()))

"""Soak test for ``alphatank bench --soak``: many env steps with random actions, memory
sampled as it goes, every observation and reward checked for NaN / infinity.

Each scenario runs in one env the way a user makes it: ``gymnasium.make`` for scenarios
with one learner seat, the PettingZoo parallel env for the others. Memory is sampled every
``every`` steps, after a full garbage collection, as the resident set size (RSS,
``/proc/self/statm``) and, where glibc provides ``mallinfo2``, as the C heap bytes in use
(allocator holes and trimming make RSS lag or hide a leak; the heap in use does not).
Growth is the least-squares slope of the samples after the warm-up (the first ``warmup``
share of each scenario's steps), in MB per 10^6 steps; the soak passes when RSS grows by
less than ``limit_mb`` per 10^6 steps, or by less than :data:`NOISE_MB` in all after the
warm-up (page and allocator noise, which a short soak would extrapolate to a large rate), in
every scenario and no value was NaN or infinite. A scenario needs two samples after the
warm-up to fit a growth (:func:`min_soak_steps`); :func:`soak` (and so ``alphatank bench
--soak``) refuses fewer steps (:class:`SoakError`).
"""

from __future__ import annotations

import ctypes
import gc
import math
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from alphatank.errors import InputError

DEFAULT_SOAK_SCENARIOS = ("vs_random", "vs_smart", "team")
LIMIT_MB = 5.0  # per 10^6 steps after warm-up
NOISE_MB = 1.0  # RSS growth after warm-up too small to tell from noise (10^6 steps: 1.33 MB)
WARMUP = 0.2  # share of each scenario's steps before the growth is fitted
_PAGE = os.sysconf("SC_PAGE_SIZE") if hasattr(os, "sysconf") else 4096


def rss_mb() -> float:
    """Resident set size of this process in MB (NaN where /proc is missing)."""
    try:
        with open("/proc/self/statm", encoding="ascii") as f:
            pages = int(f.read().split()[1])
    except (OSError, ValueError, IndexError):
        return math.nan
    return pages * _PAGE / 2**20


class _MallInfo2(ctypes.Structure):
    _fields_ = [(name, ctypes.c_size_t) for name in (
        "arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks", "uordblks",
        "fordblks", "keepcost")]


def _heap_reader() -> Callable[[], float] | None:
    try:
        fn = ctypes.CDLL(None).mallinfo2
    except (OSError, AttributeError):
        return None
    fn.restype = _MallInfo2

    def heap_mb() -> float:
        info = fn()
        return (info.uordblks + info.hblkhd) / 2**20

    return heap_mb


heap_mb = _heap_reader()


def min_soak_steps(every: int, warmup: float = WARMUP) -> int:
    """The fewest steps of one scenario whose memory samples (every ``every`` steps and at
    the last) give two after the warm-up to fit a growth."""
    steps = every + 1
    # the last sample before the final one must come after the warm-up
    while (steps - 1) // every * every < int(steps * warmup):
        steps += 1
    return steps


class SoakError(InputError, ValueError):
    """Soak settings that cannot measure a growth (too few steps, no scenario)."""


def check_soak_steps(steps: int, every: int, scenarios: int, warmup: float = WARMUP,
                     names: tuple[str, str] = ("steps", "every")) -> None:
    """SoakError unless ``every`` >= 1, ``scenarios`` >= 1 and ``steps`` split over
    ``scenarios`` give each the :func:`min_soak_steps` of samples ``every`` steps;
    ``names``: how the message names ``steps`` and ``every`` (the command's flags)."""
    if every < 1:
        raise SoakError(f"{names[1]} must be an integer >= 1, got {every}")
    if scenarios < 1:
        raise SoakError("scenarios: need at least one scenario, got none")
    need = min_soak_steps(every, warmup) * scenarios
    if steps < need:
        raise SoakError(f"{names[0]} must be >= {need} with {names[1]} {every} and "
                        f"{scenarios} scenario(s) (each needs two memory samples after its "
                        f"warm-up to measure a growth), got {steps}")


def slope_per_million(steps: Sequence[float], values: Sequence[float]) -> float:
    """Least-squares slope of ``values`` over ``steps``, per 10^6 steps (NaN if < 2)."""
    x, y = np.asarray(steps, dtype=np.float64), np.asarray(values, dtype=np.float64)
    ok = np.isfinite(y)
    if ok.sum() < 2 or np.ptp(x[ok]) == 0:
        return math.nan
    return float(np.polyfit(x[ok], y[ok], 1)[0] * 1e6)


@dataclass
class SoakResult:
    """One scenario's soak: samples, growth after warm-up, bad values seen."""

    scenario: str
    steps: int
    episodes: int
    seconds: float
    samples: list[tuple[int, float, float]] = field(default_factory=list)  # step, rss, heap
    warmup_steps: int = 0
    bad_obs: int = 0
    bad_rewards: int = 0

    def _fitted(self) -> list[tuple[int, float, float]]:
        return [r for r in self.samples if r[0] >= self.warmup_steps]

    def growth(self, column: int) -> float:
        rows = self._fitted()
        return slope_per_million([r[0] for r in rows], [r[column] for r in rows])

    @property
    def rss_rise(self) -> float:
        """RSS growth in MB over the fitted samples' steps (the slope times their span)."""
        rows = self._fitted()
        return self.rss_growth * (rows[-1][0] - rows[0][0]) / 1e6 if rows else math.nan

    @property
    def rss_growth(self) -> float:
        return self.growth(1)

    @property
    def heap_growth(self) -> float:
        return self.growth(2)

    @property
    def measured(self) -> bool:
        """Enough memory samples after warm-up to fit a growth (two at least)."""
        return math.isfinite(self.rss_growth)

    def passed(self, limit_mb: float = LIMIT_MB) -> bool:
        grew = self.rss_growth >= limit_mb and self.rss_rise >= NOISE_MB
        return self.measured and self.bad_obs == 0 and self.bad_rewards == 0 and not grew

    def verdict(self, limit_mb: float = LIMIT_MB) -> str:
        return ("ok" if self.passed(limit_mb) else "FAIL" if self.measured
                else "not measured (too few steps)")

    def to_dict(self) -> dict[str, Any]:
        return {"steps": self.steps, "episodes": self.episodes,
                "seconds": round(self.seconds, 1), "warmup_steps": self.warmup_steps,
                "rss_mb_per_1e6_steps": round(self.rss_growth, 3),
                "rss_mb_rise": round(self.rss_rise, 3),
                "heap_mb_per_1e6_steps": round(self.heap_growth, 3),
                "rss_mb_first_last": [round(self.samples[0][1], 2), round(self.samples[-1][1], 2)]
                if self.samples else [],
                "bad_obs": self.bad_obs, "bad_rewards": self.bad_rewards}


def _make_env(scenario: str, seed: int) -> tuple[Any, Callable[[np.ndarray], tuple]]:
    """An env for ``scenario`` and a step function taking a (learners, 3) action array and
    returning (observations array, rewards array, episode over)."""
    import gymnasium

    from alphatank.envs import TANK_BATTLE_ID, gym_id, parallel_env
    from alphatank.game.scenarios import load_scenario

    if len(load_scenario(scenario).learner_seats) == 1:
        env = (gymnasium.make(gym_id(scenario)) if gym_id(scenario) in gymnasium.registry
               else gymnasium.make(TANK_BATTLE_ID, scenario=scenario))
        env.reset(seed=seed)

        def step(acts: np.ndarray) -> tuple:
            obs, rew, term, trunc, _ = env.step(acts[0])
            if term or trunc:
                env.reset()
            return obs, rew, term or trunc

        return env, step
    env = parallel_env(scenario=scenario)
    env.reset(seed=seed)
    names = list(env.possible_agents)

    def step_parallel(acts: np.ndarray) -> tuple:
        obs, rew, _, _, _ = env.step({a: acts[k] for k, a in enumerate(names)
                                      if a in env.agents})
        over = not env.agents
        if over:
            env.reset()
        return (np.concatenate(list(obs.values())) if obs else np.zeros(0),
                np.fromiter(rew.values(), dtype=np.float64), over)

    return env, step_parallel


def soak_scenario(scenario: str, steps: int, every: int = 10_000, warmup: float = WARMUP,
                  seed: int = 0, report: Callable[[str], None] | None = None) -> SoakResult:
    """Run ``steps`` random-action steps of ``scenario`` in one env; see the module doc."""
    from alphatank.game.scenarios import load_scenario

    env, step = _make_env(scenario, seed)
    rng = np.random.default_rng(seed)
    learners = len(load_scenario(scenario).learner_seats)
    actions = rng.integers(0, [3, 3, 2], size=(4096, learners, 3))  # drawn once, cycled
    res = SoakResult(scenario, steps, 0, 0.0, warmup_steps=int(steps * warmup))
    read_heap = heap_mb or (lambda: math.nan)
    t0 = time.perf_counter()
    try:
        for k in range(1, steps + 1):
            obs, rew, over = step(actions[k & 4095])
            if not np.isfinite(obs).all():
                res.bad_obs += 1
            if not np.isfinite(rew).all():
                res.bad_rewards += 1
            res.episodes += over
            if k % every == 0 or k == steps:
                gc.collect()  # worlds of past episodes are freed by the cycle collector
                row = (k, rss_mb(), read_heap())
                res.samples.append(row)
                if report is not None:
                    report(f"  {scenario:14s} {k:>10,d} steps {res.episodes:>7,d} episodes  "
                           f"rss {row[1]:8.2f} MB  heap {row[2]:8.2f} MB  "
                           f"{k / (time.perf_counter() - t0):7,.0f} steps/s")
    finally:
        env.close()
    res.seconds = time.perf_counter() - t0
    return res


def soak(scenarios: Sequence[str] = DEFAULT_SOAK_SCENARIOS, steps: int = 1_000_000,
         every: int = 10_000, warmup: float = WARMUP, seed: int = 0,
         limit_mb: float = LIMIT_MB,
         verbose: bool = True) -> tuple[bool, dict[str, Any]]:
    """``steps`` env steps split evenly over ``scenarios``; returns (passed, figures).
    Too few steps to measure a growth, ``every`` < 1 or no scenario: :class:`SoakError`
    before anything runs."""
    check_soak_steps(steps, every, len(scenarios), warmup)
    say = print if verbose else None
    per = max(1, steps // len(scenarios))
    if say:
        say(f"soak: {per:,} random-action steps in each of {', '.join(scenarios)}; memory "
            f"every {every:,} steps; growth fitted after the first {warmup:.0%}")
    results = [soak_scenario(s, per, every, warmup, seed, say) for s in scenarios]
    ok = all(r.passed(limit_mb) for r in results)
    if say:
        say(f"  {'scenario':14s} {'rss MB/1e6':>11s} {'heap MB/1e6':>12s} {'NaN obs':>8s} "
            f"{'NaN rew':>8s}")
        for r in results:
            say(f"  {r.scenario:14s} {r.rss_growth:11.2f} {r.heap_growth:12.3f} "
                f"{r.bad_obs:8d} {r.bad_rewards:8d}   {r.verdict(limit_mb)}")
        say(f"soak {'passed' if ok else 'FAILED'} (RSS growth after warm-up < {limit_mb:g} MB "
            f"per 10^6 steps or < {NOISE_MB:g} MB in all, no NaN/inf in observations or "
            "rewards)")
    return ok, {"limit_mb_per_1e6_steps": limit_mb, "noise_mb": NOISE_MB,
                "scenarios": {r.scenario: r.to_dict() for r in results}, "passed": ok}

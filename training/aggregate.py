"""Aggregates over seeds: median, interquartile mean (IQM) and a stratified bootstrap
interval, as rliable computes them (Agarwal et al. 2021), in a few lines of numpy.

Scores form a (runs, tasks) matrix: one row per seed, one column per task (an
evaluation target; one column for a single win rate). The IQM is the mean of the middle
half of all scores (``floor(n / 4)`` cut from each end, scipy's ``trim_mean(x, 0.25)``);
the stratified bootstrap resamples the runs of each task independently, with
replacement, and takes percentiles of the statistic over the resamples.

:func:`pool_runs` asks the other question of several runs' win counts: do the runs differ
more than the luck of their evaluation games would make one agent's runs differ?
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from alphatank.stats import wilson_interval


def iqm(scores: np.ndarray) -> float:
    """Interquartile mean of all values of ``scores``."""
    x = np.sort(np.asarray(scores, dtype=float).ravel())
    if x.size == 0:
        raise ValueError("iqm of no scores")
    cut = x.size // 4
    return float(x[cut:x.size - cut].mean())


def median(scores: np.ndarray) -> float:
    x = np.asarray(scores, dtype=float).ravel()
    if x.size == 0:
        raise ValueError("median of no scores")
    return float(np.median(x))


def stratified_bootstrap(scores: np.ndarray, stat: Callable[[np.ndarray], float] = iqm,
                         reps: int = 2000, confidence: float = 0.95, seed: int = 0
                         ) -> tuple[float, float]:
    """Percentile interval of ``stat`` over ``reps`` stratified bootstrap resamples of a
    (runs, tasks) score matrix (a 1-d array is one task)."""
    m = np.asarray(scores, dtype=float)
    if m.ndim == 1:
        m = m[:, None]
    if m.ndim != 2 or m.size == 0:
        raise ValueError(f"scores must be a non-empty (runs, tasks) matrix, got shape "
                         f"{np.shape(scores)}")
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must be in (0, 1), got {confidence}")
    runs, tasks = m.shape
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, runs, size=(reps, runs, tasks))
    resampled = np.take_along_axis(np.broadcast_to(m, (reps, runs, tasks)), idx, axis=1)
    values = np.array([stat(r) for r in resampled])
    tail = 100.0 * (1.0 - confidence) / 2.0
    lo, hi = np.percentile(values, [tail, 100.0 - tail])
    return float(lo), float(hi)


@dataclass(frozen=True)
class Pooled:
    """Several runs' wins pooled (:func:`pool_runs`); rates as fractions."""

    wins: int
    games: int
    interval: tuple[float, float]  # Wilson 95% of the pooled win rate
    spread: float  # standard deviation of the runs' win rates
    noise: float  # what the games' luck alone gives that deviation at the pooled rate
    p_value: float  # share of shuffles of the games between runs at least as spread out

    @property
    def rate(self) -> float:
        return self.wins / self.games

    @property
    def p_text(self) -> str:
        """The p-value for a table: two significant digits, below 0.001 as ``< 0.001``."""
        return "< 0.001" if self.p_value < 0.001 else f"{self.p_value:.2g}"


def pool_runs(wins: Sequence[int], games: Sequence[int], reps: int = 2000,
              seed: int = 0) -> Pooled:
    """Pool the win counts of two or more runs (each ``wins[i]`` of ``games[i]``) and test
    whether they differ more than chance: the statistic is ``sum_i games_i (rate_i -
    pooled)^2``; each of ``reps`` shuffles deals the pooled games out again, each run
    keeping its number of games (a multivariate hypergeometric draw), and the p-value is
    the share of shuffles with a statistic at least the observed one (add-one corrected).
    A large p-value says the runs play like one agent as far as their games can tell."""
    w = np.asarray(wins, dtype=np.int64)
    n = np.asarray(games, dtype=np.int64)
    if w.ndim != 1 or w.shape != n.shape or w.size < 2:
        raise ValueError(f"pool_runs needs the wins and games of two or more runs, got "
                         f"{list(wins)} and {list(games)}")
    if (n <= 0).any() or (w < 0).any() or (w > n).any():
        raise ValueError(f"pool_runs: every run needs 0 <= wins <= games and games > 0, "
                         f"got wins {w.tolist()} of games {n.tolist()}")
    total, won = int(n.sum()), int(w.sum())
    p = won / total

    def stat(k: np.ndarray) -> np.ndarray:
        return (n * (k / n - p) ** 2).sum(axis=-1)

    rng = np.random.default_rng(seed)
    dealt = np.empty((reps, w.size), dtype=np.int64)
    good = np.full(reps, won)
    left = total
    for i, size in enumerate(n.tolist()):  # deal each run its games from what is left
        dealt[:, i] = rng.hypergeometric(good, left - good, size) if size < left else good
        good -= dealt[:, i]
        left -= size
    observed = float(stat(w))
    at_least = int((stat(dealt) >= observed - 1e-12).sum())
    return Pooled(wins=won, games=total, interval=wilson_interval(won, total),
                  spread=float(np.std(w / n, ddof=1)),
                  noise=float(np.sqrt(p * (1 - p) * np.mean(1.0 / n))),
                  p_value=(at_least + 1) / (reps + 1))

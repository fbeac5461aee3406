"""Aggregates over seeds: median, interquartile mean (IQM) and a stratified bootstrap
interval, as rliable computes them (Agarwal et al. 2021), in a few lines of numpy.

Scores form a (runs, tasks) matrix: one row per seed, one column per task (an
evaluation target; one column for a single win rate). The IQM is the mean of the middle
half of all scores (``floor(n / 4)`` cut from each end, scipy's ``trim_mean(x, 0.25)``);
the stratified bootstrap resamples the runs of each task independently, with
replacement, and takes percentiles of the statistic over the resamples.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np


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

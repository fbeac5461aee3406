"""Small statistics helpers shared by the arena, evaluation and training reports."""

from __future__ import annotations

import math


def wilson_interval(successes: float, n: int, z: float = 1.96) -> tuple[float, float]:
    """Wilson score interval for a binomial proportion ``successes / n``.

    Returns ``(lo, hi)`` within [0, 1]; ``(0.0, 1.0)`` when ``n == 0`` (nothing known).
    ``successes`` may be fractional (e.g. wins + draws / 2). ``z=1.96`` gives 95 %.
    """
    if n < 0:
        raise ValueError(f"wilson_interval: n must be >= 0, got {n}")
    if not 0 <= successes <= n:
        raise ValueError(f"wilson_interval: successes must be in [0, n={n}], got {successes}")
    if z <= 0:
        raise ValueError(f"wilson_interval: z must be > 0, got {z}")
    if n == 0:
        return (0.0, 1.0)
    p = successes / n
    z2 = z * z
    denom = 1.0 + z2 / n
    centre = (p + z2 / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z2 / (4 * n * n)) / denom
    return (max(0.0, centre - half), min(1.0, centre + half))

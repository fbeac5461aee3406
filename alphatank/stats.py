"""Small statistics helpers shared by the arena, evaluation and training reports."""

from __future__ import annotations

import math
from collections.abc import Sequence

from alphatank.extras import require


def wilson_interval(successes: float, n: int, z: float = 1.96) -> tuple[float, float]:
    """Wilson score interval for a binomial proportion ``successes / n``.

    Returns ``(lo, hi)`` within [0, 1]; ``(0.0, 1.0)`` when ``n == 0`` (nothing known).
    ``successes`` may be fractional (e.g. wins + draws / 2). ``z=1.96`` gives 95 %.
    """
    if not (n >= 0 and math.isfinite(n)):  # NaN fails every comparison
        raise ValueError(f"wilson_interval: n must be a finite number >= 0, got {n}")
    if not 0 <= successes <= n:
        raise ValueError(f"wilson_interval: successes must be in [0, n={n}], got {successes}")
    if not (z > 0 and math.isfinite(z)):
        raise ValueError(f"wilson_interval: z must be a finite number > 0, got {z}")
    if n == 0:
        return (0.0, 1.0)
    p = successes / n
    z2 = z * z
    denom = 1.0 + z2 / n
    centre = (p + z2 / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z2 / (4 * n * n)) / denom
    # Rounding can leave an endpoint a hair inside p at p = 0 or 1; the interval holds p.
    return (max(0.0, min(p, centre - half)), min(1.0, max(p, centre + half)))


class League:
    """openskill (Plackett-Luce) ratings of players from a stream of 1-vs-1 results."""

    def __init__(self, names: list[str]):
        require("train", "openskill ratings")
        from openskill.models import PlackettLuce

        self.model = PlackettLuce()
        self.names = list(names)
        self.ratings = [self.model.rating(name=n) for n in self.names]

    def add(self, name: str, mu: float | None = None, sigma: float | None = None) -> int:
        """A new player (default: the model's starting rating); returns its index."""
        self.names.append(name)
        self.ratings.append(self.model.rating(mu=mu, sigma=sigma, name=name))
        return len(self.names) - 1

    def record(self, i: int, j: int, outcome: int) -> None:
        """Player i against player j: outcome +1 (i won), 0 (draw) or -1 (j won)."""
        ranks = self._ranks(i, j, outcome)  # checked before any player is read
        [[a], [b]] = self.model.rate([[self.ratings[i]], [self.ratings[j]]], ranks=ranks)
        self.ratings[i], self.ratings[j] = a, b

    def _ranks(self, i: int, j: int, outcome: int) -> list[int]:
        """openskill's ranks of a game of i against j; ValueError unless i and j are two
        players of the table and outcome is -1, 0 or 1."""
        n = len(self.ratings)
        if not (0 <= i < n and 0 <= j < n and i != j):
            raise ValueError(f"a game needs two different players of the {n}, got {i} and "
                             f"{j}")
        if outcome not in (-1, 0, 1):
            raise ValueError(f"outcome must be -1, 0 or 1, got {outcome!r}")
        return [0, 0] if outcome == 0 else ([0, 1] if outcome > 0 else [1, 0])

    def record_period(self, games: Sequence[tuple[int, int, int]]) -> None:
        """A rating period: the games ``(i, j, outcome)`` (as for :meth:`record`) all rated
        from the ratings before the period, each player's changes then added up (mu
        shifts summed, sigma shrinks multiplied). The result does not depend on the order
        of the games, as a sequence of :meth:`record` calls does."""
        before = list(self.ratings)
        shift: dict[int, float] = {}
        shrink: dict[int, float] = {}
        for i, j, outcome in games:
            ranks = self._ranks(i, j, outcome)
            [[a], [b]] = self.model.rate([[before[i]], [before[j]]], ranks=ranks)
            for k, new in ((i, a), (j, b)):
                shift[k] = shift.get(k, 0.0) + new.mu - before[k].mu
                shrink[k] = shrink.get(k, 1.0) * new.sigma / before[k].sigma
        for k in shift:
            self.ratings[k] = self.model.rating(mu=before[k].mu + shift[k],
                                                sigma=before[k].sigma * shrink[k],
                                                name=self.names[k])

    def table(self) -> list[tuple[str, float, float, float]]:
        """(name, mu, sigma, ordinal = mu - 3 sigma), best ordinal first."""
        rows = [(n, r.mu, r.sigma, r.ordinal()) for n, r in zip(self.names, self.ratings,
                                                                strict=True)]
        return sorted(rows, key=lambda row: -row[3])

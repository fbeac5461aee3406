"""Row-wise random streams for batched inference: one forward pass over many games, each
row's sampling noise drawn from that row's own generator, so a game's actions do not
depend on which other games share the batch."""

from __future__ import annotations

from typing import Any

import numpy as np


class GameStreams:
    """A stand-in for ``np.random.Generator`` in batched inference: rows come in blocks of
    ``rows_per_env`` per env, and env ``e``'s block is drawn from ``gens[e]`` (the
    generator of the game env ``e`` plays; the list is updated in place between games).
    Offers the draws the learners' samplers use (``random``, ``standard_normal``)."""

    def __init__(self, gens: list[np.random.Generator], rows_per_env: int):
        self.gens, self.k = gens, int(rows_per_env)

    def _draw(self, method: str, size: Any, dtype: Any) -> np.ndarray:
        size = (size,) if isinstance(size, int) else tuple(size)
        if size[0] != len(self.gens) * self.k:
            raise ValueError(f"expected {len(self.gens)} envs x {self.k} rows, got {size[0]}")
        out = np.empty(size, dtype=dtype)
        block = (self.k, *size[1:])
        for e, g in enumerate(self.gens):
            out[e * self.k:(e + 1) * self.k] = getattr(g, method)(block, dtype=dtype)
        return out

    def random(self, size: Any, dtype: Any = np.float64) -> np.ndarray:
        return self._draw("random", size, dtype)

    def standard_normal(self, size: Any, dtype: Any = np.float64) -> np.ndarray:
        return self._draw("standard_normal", size, dtype)

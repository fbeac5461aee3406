"""Compiled loops of the bots' per-tick work (numba), as in ``alphatank.game.kernels``.

A kernel performs the same IEEE operations, in the same order, as the numpy expressions
it replaced, so bots decide the same (pinned by ``tests/test_kernels.py`` against those
expressions and by the seeded-episode pins). Signatures are given, so each kernel is
compiled, or loaded from the cache next to this module, at import: never in the middle of
a game.
"""

from __future__ import annotations

import numpy as np
from numba import njit, types

_F8, _I8 = types.float64, types.int64
_F8_1, _F8_2 = types.Array(_F8, 1, "C"), types.Array(_F8, 2, "C")
_PATHS = types.Array(_F8, 2, "C", readonly=True)  # the cached candidate paths
_TIMES = types.Array(_F8, 1, "C", readonly=True)
_RASTER = types.Array(types.float32, 2, "C", readonly=True)


@njit(_I8(_F8, _F8, _F8, _F8, _PATHS, _PATHS, _TIMES, _F8_2, types.Array(_I8, 1, "C"),
          _RASTER, _F8, _F8, _F8, _F8, _F8, _I8, _F8_1), cache=True)
def evade_choice(x: float, y: float, c: float, s: float, fwd: np.ndarray, side: np.ndarray,
                 times: np.ndarray, bullet_state: np.ndarray, threats: np.ndarray,
                 raster: np.ndarray, inv_res: float, cap2: float, wall_margin: float,
                 penalty: float, bonus: float, turn: int, score: np.ndarray) -> int:
    """:meth:`bots.base.Evader.evade`'s choice: the candidate (3 rotate + move) whose
    path (``fwd``, ``side`` (9, K) in the tank's frame at (x, y), heading cos ``c``, sin
    ``s``) keeps farthest from the bullets ``threats`` (rows of ``bullet_state``:
    x, y, angle, vx, vy, w) flying straight over ``times`` (K,): the smallest squared gap,
    capped at ``cap2``, square-rooted; ``penalty`` off when a path point's ``raster``
    clearance (float32; rows y, columns x, cells ``1 / inv_res`` px) is under
    ``wall_margin`` (rounded to float32 and compared there, as numpy compares the raster
    with a Python float); ``bonus`` to the three candidates of rotate ``turn``. Scores
    into ``score`` (9,); returns the first best."""
    K = times.shape[0]
    last_col, last_row = raster.shape[1] - 1, raster.shape[0] - 1
    margin = np.float32(wall_margin)
    best = 0
    for i in range(9):
        gap2 = np.inf
        wall = np.inf
        for k in range(K):
            # (x + c fwd) + (-s) side and (y + s fwd) + c side, as evade's arrays add.
            px = (x + c * fwd[i, k]) + (-s) * side[i, k]
            py = (y + s * fwd[i, k]) + c * side[i, k]
            for t in range(threats.shape[0]):
                b = threats[t]
                dx = px - (bullet_state[b, 0] + bullet_state[b, 3] * times[k])
                dy = py - (bullet_state[b, 1] + bullet_state[b, 4] * times[k])
                g = dx * dx + dy * dy
                if g < gap2:
                    gap2 = g
            col = int(px * inv_res)  # truncation, as astype(intp)
            row = int(py * inv_res)
            col = 0 if col < 0 else last_col if col > last_col else col
            row = 0 if row < 0 else last_row if row > last_row else row
            if raster[row, col] < wall:
                wall = raster[row, col]
        v = np.sqrt(gap2 if gap2 < cap2 else cap2)
        if wall < margin:
            v -= penalty
        if i // 3 == turn:
            v += bonus
        score[i] = v
        if v > score[best]:
            best = i
    return best


@njit(_I8(_F8_2, types.Array(types.boolean, 1, "C"), types.Array(_I8, 1, "C", readonly=True),
          _F8, _F8, _F8, _F8, types.Array(_I8, 1, "C")), cache=True)
def threat_slots(bullet_state: np.ndarray, active: np.ndarray, slots: np.ndarray, x: float,
                 y: float, soon: float, danger2: float, out: np.ndarray) -> int:
    """:meth:`bots.base.Evader.threats`: of the ``active`` bullet ``slots`` (ascending),
    those whose straight flight (rows of ``bullet_state``: x, y, angle, vx, vy, w) passes
    within ``danger2`` (squared) of (x, y) at a time in (0, ``soon``) seconds. Into
    ``out``, in slot order; returns how many."""
    k = 0
    for i in range(slots.shape[0]):
        b = slots[i]
        if not active[b]:
            continue
        rx, ry = bullet_state[b, 0] - x, bullet_state[b, 1] - y
        vx, vy = bullet_state[b, 3], bullet_state[b, 4]
        closing = -(rx * vx + ry * vy)
        if closing <= 0.0:  # moving away or past: t <= 0
            continue
        v2 = vx * vx + vy * vy
        t = closing / (1e-9 if v2 < 1e-9 else v2)
        mx, my = rx + vx * t, ry + vy * t
        if 0 < t < soon and mx * mx + my * my < danger2:
            out[k] = b
            k += 1
    return k

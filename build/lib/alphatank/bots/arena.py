"""Round-robin tournaments between bots: every pair, both sides, win/draw/loss counts."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from alphatank.bots.registry import bot_from_spec, parse_bot_spec
from alphatank.bots.runner import GameResult, play_game
from alphatank.sim.config import GameConfig
from alphatank.sim.mapspec import MapSpec
from alphatank.sim.match import Match
from alphatank.stats import League, wilson_interval


@dataclass
class ArenaResult:
    """``wdl[i, j]`` = (wins, draws, losses) of bot i against bot j (diagonal unused)."""

    names: list[str]
    wdl: np.ndarray  # (n, n, 3) int
    league: League
    ticks: list[int] = field(default_factory=list)

    def games(self, i: int, j: int) -> int:
        return int(self.wdl[i, j].sum())

    def win_rate(self, i: int, j: int | None = None) -> tuple[float, float, float]:
        """(rate, lo, hi) of bot i's wins (draws count half) vs bot j, or vs everyone;
        lo/hi are the Wilson 95% interval."""
        w, d, n = self._totals(i, j)
        score = w + 0.5 * d
        lo, hi = wilson_interval(score, n)
        return (score / n if n else 0.0, lo, hi)

    def _totals(self, i: int, j: int | None) -> tuple[int, int, int]:
        rows = self.wdl[i] if j is None else self.wdl[i, j][None]
        w, d, loss = rows.sum(axis=0)
        return int(w), int(d), int(w + d + loss)

    def table(self) -> str:
        """The win/draw/loss matrix as text: one row per bot, one column per opponent."""
        width = max(24, *(len(n) + 2 for n in self.names))
        head = " " * width + "".join(f"{n:>{width}}" for n in [*self.names, "overall"])
        lines = ["rows: W-D-L and score (wins + draws/2) with Wilson 95% interval vs column",
                 head]
        for i, name in enumerate(self.names):
            cells = []
            for j in range(len(self.names)):
                cells.append("-" if i == j or not self.games(i, j) else self._cell(i, j))
            w, d, n = self._totals(i, None)
            rate, lo, hi = self.win_rate(i)
            cells.append(f"{rate:4.0%} [{lo:.0%},{hi:.0%}]" if n else "-")
            lines.append(f"{name:<{width}}" + "".join(f"{c:>{width}}" for c in cells))
        lines += ["", "openskill (Plackett-Luce) league, games in play order:",
                  f"{'':<{width}}{'mu':>8}{'sigma':>8}{'ordinal':>9}"]
        lines += [f"{name:<{width}}{mu:8.2f}{sigma:8.2f}{ordinal:9.2f}"
                  for name, mu, sigma, ordinal in self.league.table()]
        return "\n".join(lines)

    def _cell(self, i: int, j: int) -> str:
        w, d, loss = (int(v) for v in self.wdl[i, j])
        rate, lo, hi = self.win_rate(i, j)
        return f"{w}-{d}-{loss} {rate:.0%} [{lo:.0%},{hi:.0%}]"


def run_arena(specs: Sequence[str], spec: MapSpec, cfg: GameConfig, games: int,
              seed: int = 0, on_game: Callable[[str, str, GameResult], None] | None = None,
              on_tick: Callable[[Match, np.ndarray], None] | None = None) -> ArenaResult:
    """Play ``games`` matches for every pair of bot specs (``NAME[:KEY=VALUE][@W]``),
    alternating sides: game g of a pair uses match seed ``seed + g // 2`` with the sides
    swapped on odd g, so both sides see the same spawns and zones."""
    if games < 1:
        raise ValueError(f"games must be >= 1, got {games}")
    if len(specs) < 2:
        raise ValueError(f"an arena needs at least 2 bots, got {list(specs)}")
    for s in specs:
        parse_bot_spec(s)  # fail early, naming the valid bots
    n = len(specs)
    result = ArenaResult(list(specs), np.zeros((n, n, 3), dtype=np.int64), League(list(specs)))
    for i in range(n):
        for j in range(i + 1, n):
            bots = [bot_from_spec(specs[i], seed=seed), bot_from_spec(specs[j], seed=seed)]
            for g in range(games):
                order = (0, 1) if g % 2 == 0 else (1, 0)
                res = play_game(cfg, spec, [bots[k] for k in order], seed=seed + g // 2,
                                on_tick=on_tick)
                out_i = res.outcome(order.index(0))  # +1 / 0 / -1 for bot i
                result.wdl[i, j, 1 - out_i] += 1
                result.wdl[j, i, 1 + out_i] += 1
                result.league.record(i, j, out_i)
                result.ticks.append(res.ticks)
                if on_game is not None:
                    on_game(specs[i], specs[j], res)
    return result

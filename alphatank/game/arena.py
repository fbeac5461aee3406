"""Round-robin tournaments between seats: every pair, both sides, win/draw/loss counts
and an openskill league.

A seat is anything a ``--seats`` item may name without a team: a bot spec
``NAME[:KEY=VALUE...][@WEAKNESS]``, ``checkpoint:PATH`` or ``agent:NAME`` (see
:mod:`alphatank.game.seats`). Each seat's controller is made once and reused in all its
games. Game g of a pair is the episode of seed ``seed + g // 2`` of the two-seat scenario
(first seat team A, second team B) on the map, with the sides swapped on odd g, so both
sides see the same spawns and zones; an arena game and an env episode of that scenario
and seed are the same game.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from alphatank.game.lineup import Lineup, check_fit, seat_label, spec_seat
from alphatank.game.scenarios import Scenario, parse_scenario
from alphatank.game.seats import SeatError, controller_kind, make_controller
from alphatank.sim.episode import Episode, EpisodeHook
from alphatank.sim.match import TickEvents
from alphatank.stats import League, wilson_interval


@dataclass
class ArenaResult:
    """``wdl[i, j]`` = (wins, draws, losses) of seat i against seat j (diagonal unused);
    ``names`` are the seat specs as given."""

    names: list[str]
    wdl: np.ndarray  # (n, n, 3) int
    league: League
    ticks: list[int] = field(default_factory=list)

    def games(self, i: int, j: int) -> int:
        return int(self.wdl[i, j].sum())

    def win_rate(self, i: int, j: int | None = None) -> tuple[float, float, float]:
        """(rate, lo, hi) of seat i's wins (draws count half) vs seat j, or vs everyone;
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
        """The win/draw/loss matrix as text: one row per seat, one column per opponent."""
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


def arena_scenario(first: str, second: str, map_name: str, preset: str = "paper",
                   game: Mapping[str, Any] | None = None) -> Scenario:
    """The two-seat scenario of an arena game: ``first`` is team A, ``second`` team B
    (map errors name ``--map``, the flag that gives ``map_name``)."""
    seats = [spec_seat(first, "A").to_dict(), spec_seat(second, "B").to_dict()]
    return parse_scenario({"name": "arena", "map": map_name, "preset": preset,
                           "game": dict(game or {}), "seats": seats}, source="arena",
                          map_label="--map")


def run_arena(seats: Sequence[str], map_name: str = "maze", games: int = 20, seed: int = 0,
              *, preset: str = "paper", game: Mapping[str, Any] | None = None,
              on_game: Callable[[str, str, Episode], None] | None = None,
              hooks: Sequence[EpisodeHook] = (),
              on_start: Callable[[], None] | None = None,
              stop: Callable[[], bool] | None = None) -> ArenaResult:
    """Play ``games`` games for every pair of ``seats`` on ``map_name``, sides alternating
    (see the module docstring). ``game`` overrides the preset's GameConfig fields;
    ``on_game(first, second, episode)`` sees every finished game (``first`` is seat i of
    the pair, whichever side it played); ``hooks`` join every episode; ``on_start()`` is
    called once every seat has passed its checks, before the first game. ``stop()`` is
    polled after every tick: once it is True the game in play is dropped and the result
    of the games played is returned."""
    if games < 1:
        raise ValueError(f"games must be >= 1, got {games}")
    if len(seats) < 2:
        raise SeatError(f"an arena needs at least 2 seats, got {list(seats)}")
    parsed = [spec_seat(s) for s in seats]  # fail early, naming the valid values
    people = [s for s, p in zip(seats, parsed, strict=True)
              if controller_kind(p.controller).interactive]
    if people:
        raise SeatError(f"arena seats play by themselves; {people} needs a player at the "
                        "keyboard (alphatank play is for people)")
    ctrls = [make_controller(s) for s in parsed]
    bad = [s for s, c in zip(seats, ctrls, strict=True) if c is None]
    if bad:
        raise SeatError(f"arena seats need a controller; {bad} is a learner seat (give a "
                        "bot, checkpoint:PATH or agent:NAME)")
    # each controller in both seats of a game on each map: one that does not fit fails now
    check_fit(arena_scenario(seats[0], seats[1], map_name, preset, game),
              [(side, c) for c in ctrls for side in (0, 1)])
    if on_start is not None:
        on_start()
    labels = [seat_label(s) for s in parsed]
    n = len(seats)
    result = ArenaResult(list(seats), np.zeros((n, n, 3), dtype=np.int64), League(list(seats)))
    if stop is not None:
        hooks = [*hooks, _StopHook(stop)]
    try:
        for i in range(n):
            for j in range(i + 1, n):
                sides = []
                for a, b in ((i, j), (j, i)):
                    sc = arena_scenario(seats[a], seats[b], map_name, preset, game)
                    sides.append(Lineup(sc, [ctrls[a], ctrls[b]], [labels[a], labels[b]],
                                        [sc.seats[0].describe(), sc.seats[1].describe()]))
                for g in range(games):
                    ep = sides[g % 2].play(seed + g // 2, hooks)
                    out_i = ep.outcome(g % 2)  # +1 / 0 / -1 for seat i
                    result.wdl[i, j, 1 - out_i] += 1
                    result.wdl[j, i, 1 + out_i] += 1
                    result.league.record(i, j, out_i)
                    result.ticks.append(ep.ticks)
                    if on_game is not None:
                        on_game(seats[i], seats[j], ep)
    except _Stopped:
        pass  # the game in play is dropped; those played stand
    return result


class _Stopped(Exception):  # noqa: N818 (a stop, not an error)
    """Raised by :class:`_StopHook` to end an arena between two ticks."""


class _StopHook(EpisodeHook):
    """Ends the arena (:class:`_Stopped`) after the first tick at which ``stop()`` holds."""

    def __init__(self, stop: Callable[[], bool]):
        self.stop = stop

    def on_tick(self, episode: Episode, events: TickEvents) -> None:
        if self.stop():
            raise _Stopped

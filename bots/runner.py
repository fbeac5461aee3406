"""Play whole matches between policies (bots, checkpoints, keyboards): the loop the arena,
the benchmarks and the tests share."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from alphatank.sim.config import GameConfig
from alphatank.sim.mapspec import MapSpec
from alphatank.sim.match import Match
from alphatank.sim.policy import Policy


@dataclass(frozen=True)
class GameResult:
    """Outcome of one match: the winning team (None: draw), its length in ticks, and the
    tick each seat died at (None: survived)."""

    winner: str | None
    ticks: int
    death_tick: tuple[int | None, ...]
    teams: tuple[str, ...]

    def outcome(self, seat: int) -> int:
        """+1 win, 0 draw, -1 loss for ``seat``'s team."""
        if self.winner is None:
            return 0
        return 1 if self.teams[seat] == self.winner else -1


def seat_seeds(seed: int, n: int) -> list[int]:
    """Independent per-seat policy seeds derived from a game's seed."""
    return [int(s.generate_state(1, np.uint64)[0])
            for s in np.random.SeedSequence([seed, 0xB07]).spawn(n)]


def play_game(cfg: GameConfig, spec: MapSpec, policies: Sequence[Policy],
              teams: Sequence[str] | None = None, seed: int = 0,
              on_tick: Callable[[Match, np.ndarray], None] | None = None) -> GameResult:
    """Play one match to the end. ``teams`` defaults to one team per seat (A, B, ...).
    The match is seeded with ``seed`` and seat i's policy with ``seat_seeds(seed)[i]``.
    ``on_tick(match, actions)`` runs after every tick (instrumentation)."""
    n = len(policies)
    if teams is None:
        teams = [chr(ord("A") + i) for i in range(n)]
    if len(teams) != n:
        raise ValueError(f"{n} policies but {len(teams)} teams: {list(teams)}")
    match = Match(cfg, spec, teams, seed=seed)
    for i, (policy, s) in enumerate(zip(policies, seat_seeds(seed, n), strict=True)):
        policy.reset(match, i, s)
    actions = np.zeros((n, 3), dtype=np.int64)
    death: list[int | None] = [None] * n
    while not match.done:
        for i, policy in enumerate(policies):
            if match.alive[i]:
                actions[i] = policy.act(match, i)
        events = match.step(actions)
        for kill in events.kills:
            death[kill.victim] = match.tick
        if on_tick is not None:
            on_tick(match, actions)
    return GameResult(match.winner, match.tick, tuple(death), tuple(teams))

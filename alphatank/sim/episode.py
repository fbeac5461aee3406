"""One episode of a match: THE seeding rule and THE tick loop, with hooks.

Every way of playing a match (the envs, ``play``, ``record``, ``replay``, the arena,
evaluation) starts episodes here, so one (scenario, seed) is one game everywhere:

* :func:`episode_seeds` derives everything from one integer: ``SeedSequence(seed)``
  spawns three children, which give the map index (drawn only when the scenario has
  several maps), the match seed, and one seed per seat.
* :func:`start_episode` builds (or resets) the match on that map with that seed, resets
  every controller with its seat seed, and returns an :class:`Episode`.
* :meth:`Episode.tick` asks each live seat's controller for its action, steps the match
  and calls the hooks; :meth:`Episode.run` ticks to the end.

Hooks (:class:`EpisodeHook`) see ``on_start(episode)`` once, ``on_tick(episode, events)``
after every tick (``episode.actions`` holds the actions of that tick) and
``on_end(episode)`` once when the match is over (or reached ``tick_limit``). A renderer,
an MP4 recorder and a replay writer are hooks. This module needs only the match and the
Policy protocol; line-ups of scenarios live in :mod:`alphatank.game.lineup`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from alphatank.sim.config import GameConfig
from alphatank.sim.mapspec import MapSpec
from alphatank.sim.match import Match, TickEvents
from alphatank.sim.policy import Policy


@dataclass(frozen=True)
class EpisodeSeeds:
    """Everything an episode derives from its ``seed``."""

    seed: int
    map_index: int
    match_seed: int
    seat_seeds: tuple[int, ...]


def episode_seeds(seed: int, n_seats: int, n_maps: int = 1) -> EpisodeSeeds:
    """THE seeding rule: ``SeedSequence(seed).spawn(3)`` -> map index (a draw in
    ``range(n_maps)``, 0 without a draw when there is one map), match seed, seat seeds."""
    s_map, s_match, s_seats = np.random.SeedSequence(seed).spawn(3)
    k = int(np.random.default_rng(s_map).integers(n_maps)) if n_maps > 1 else 0
    match_seed = int(s_match.generate_state(1, np.uint64)[0])
    seats = tuple(int(x) for x in s_seats.generate_state(n_seats, np.uint64))
    return EpisodeSeeds(int(seed), k, match_seed, seats)


def episode_match(cfg: GameConfig, specs: Sequence[MapSpec], teams: Sequence[str],
                  seeds: EpisodeSeeds, match: Match | None = None) -> Match:
    """The episode's match on ``specs[seeds.map_index]`` seeded with ``seeds.match_seed``:
    ``match`` reset in place when it is already on that map, else a new one."""
    spec = specs[seeds.map_index]
    if match is not None and match.spec is spec:
        match.reset(seeds.match_seed)
        return match
    return Match(cfg, spec, teams, seed=seeds.match_seed)


def reset_controllers(match: Match, controllers: Sequence[Policy | None],
                      seeds: EpisodeSeeds) -> None:
    """Reset seat ``i``'s controller with seat seed ``i`` (``None``: a seat the caller
    drives)."""
    for seat, ctrl in enumerate(controllers):
        if ctrl is not None:
            ctrl.reset(match, seat, seeds.seat_seeds[seat])


class EpisodeHook:
    """Base class of episode hooks: override any of the three (all do nothing here)."""

    def on_start(self, episode: Episode) -> None:
        """The match is at tick 0 and every controller is reset."""

    def on_tick(self, episode: Episode, events: TickEvents) -> None:
        """A tick was played with ``episode.actions``; ``events`` are its events."""

    def on_end(self, episode: Episode) -> None:
        """The episode is over (the match ended or reached the tick limit)."""


class Episode:
    """A match, one controller per seat (already reset) and the hooks.

    ``tick_limit`` ends the episode after that many ticks even if the match goes on.
    ``actions`` (n, 3) holds the last tick's actions (dead seats keep their last row;
    the match ignores them); ``death_tick[i]`` is the tick seat i died at (None: alive);
    ``shots[i]`` counts its shots.
    """

    def __init__(self, match: Match, controllers: Sequence[Policy], *,
                 seeds: EpisodeSeeds | None = None, hooks: Sequence[EpisodeHook] = (),
                 tick_limit: int | None = None):
        if len(controllers) != match.n:
            raise ValueError(f"need one controller per seat: {match.n} seats, "
                             f"{len(controllers)} controllers")
        self.match, self.controllers, self.seeds = match, list(controllers), seeds
        self.hooks = list(hooks)
        self.tick_limit = tick_limit
        self.actions = np.ones((match.n, 3), dtype=np.int64)
        self.death_tick: list[int | None] = [None] * match.n
        self.shots = np.zeros(match.n, dtype=np.int64)
        self.ended = False
        for hook in self.hooks:
            hook.on_start(self)

    @property
    def over(self) -> bool:
        m = self.match
        return m.done or (self.tick_limit is not None and m.tick >= self.tick_limit)

    @property
    def winner(self) -> str | None:
        return self.match.winner

    @property
    def ticks(self) -> int:
        return self.match.tick

    def outcome(self, seat: int) -> int:
        """+1 win, 0 draw, -1 loss for ``seat``'s team."""
        w = self.match.winner
        return 0 if w is None else 1 if self.match.teams[seat] == w else -1

    def tick(self) -> TickEvents:
        """One tick: every live seat's controller acts, the match steps, hooks run; the
        episode ends (``on_end``) when it is over."""
        m, acts, ctrls = self.match, self.actions, self.controllers
        for seat in np.flatnonzero(m.alive).tolist():
            acts[seat] = ctrls[seat].act(m, seat)
        events = m.step(acts)
        for kill in events.kills:
            self.death_tick[kill.victim] = m.tick
        for shot in events.fired:
            self.shots[shot.tank] += 1
        for hook in self.hooks:
            hook.on_tick(self, events)
        if self.over:
            self.end()
        return events

    def end(self) -> None:
        """Finish the episode now (hooks' ``on_end``, once)."""
        if not self.ended:
            self.ended = True
            for hook in self.hooks:
                hook.on_end(self)

    def run(self) -> Episode:
        """Tick to the end; returns self."""
        while not self.over:
            self.tick()
        self.end()
        return self


def start_episode(cfg: GameConfig, specs: Sequence[MapSpec], teams: Sequence[str],
                  controllers: Sequence[Policy], seed: int, *,
                  hooks: Sequence[EpisodeHook] = (), tick_limit: int | None = None,
                  match: Match | None = None) -> Episode:
    """A new episode from ``seed`` (see :func:`episode_seeds`) with ``controllers[i]`` in
    seat i, reset with its seat seed. ``match`` is reused when it is on the chosen map."""
    seeds = episode_seeds(seed, len(teams), len(specs))
    m = episode_match(cfg, specs, teams, seeds, match)
    reset_controllers(m, controllers, seeds)
    return Episode(m, controllers, seeds=seeds, hooks=hooks, tick_limit=tick_limit)

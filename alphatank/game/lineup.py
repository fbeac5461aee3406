"""Line-ups: one controller per seat of a scenario, and episodes of it.

:func:`build_lineup` turns a scenario (a TOML file, or a ``--seats`` list through
:func:`lineup_scenario`) into a :class:`Lineup`; :meth:`Lineup.start` starts an episode
from one seed with :func:`alphatank.sim.episode.start_episode`, the seeding rule the envs
use too, so one (scenario, seed) is one game in the envs, ``play``, ``record``, the arena
and evaluation. Controllers come from the seat kinds of :mod:`alphatank.game.seats`
(resolved late: this module imports no bots, checkpoints or pygame).
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from alphatank.errors import InputError
from alphatank.game.scenarios import (
    Scenario,
    ScenarioError,
    load_scenario,
    seats_scenario,
)
from alphatank.game.seats import (
    KEYSETS,
    Seat,
    SeatError,
    controller_kind,
    make_controller,
    parse_seat_spec,
    parse_seat_table,
    plays_by_itself,
)
from alphatank.sim.episode import Episode, EpisodeHook, start_episode
from alphatank.sim.match import Match
from alphatank.sim.policy import Policy


@dataclass
class Lineup:
    """The controllers of a scenario's seats (``controllers[i]`` plays seat i), the
    labels drawn over the tanks, the seat descriptions (summaries, replays) and notes
    about stand-ins. Controllers are reused episode after episode (reset each time)."""

    scenario: Scenario
    controllers: list[Policy]
    labels: list[str]
    seats: list[str]
    notes: list[str] = field(default_factory=list)

    def start(self, seed: int, hooks: Sequence[EpisodeHook] = (),
              tick_limit: int | None = None) -> Episode:
        """A new episode from ``seed`` (map, match and seat seeds as in the envs)."""
        sc = self.scenario
        return start_episode(sc.game_config(), sc.map_specs(), sc.teams, self.controllers,
                             seed, hooks=hooks, tick_limit=tick_limit)

    def play(self, seed: int, hooks: Sequence[EpisodeHook] = ()) -> Episode:
        """One whole episode from ``seed``; returns it finished."""
        return self.start(seed, hooks).run()


def seat_label(seat: Seat) -> str:
    """The short name drawn over a seat's tank: the bot, ``P1``..``P3`` for keyboard
    players, a checkpoint's folder (``RUN`` for a run folder, ``RUN/step_N`` for one of
    its saves), the agent's name, else the kind."""
    if seat.controller == "bot":
        return str(seat.bot)
    if seat.controller == "human":
        return f"P{KEYSETS.index(str(seat.keys)) + 1}"
    if seat.controller == "checkpoint":
        folder = Path(os.path.abspath(str(seat.path)))  # "runs/x/" and "." have names too
        if folder.parent.name == "checkpoints":  # one save of a run
            return f"{folder.parent.parent.name}/{folder.name}"
        return folder.name
    if seat.controller == "agent":
        return str(seat.agent)
    return seat.controller


def spec_seat(spec: str, team: str = "A", where: str | None = None) -> Seat:
    """A validated Seat from one seat spec (``smart@0.5``, ``checkpoint:PATH``,
    ``agent:NAME``, ...; see :func:`alphatank.game.seats.parse_seat_spec`)."""
    where = where or f"seat {spec!r}"
    try:
        return parse_seat_table({"team": team, **parse_seat_spec(spec, where)}, where)
    except SeatError as exc:
        raise ScenarioError(str(exc)) from None


def build_lineup(scenario: str | Scenario, *, interactive: bool = False,
                 learner: str | None = None, stand_in: str | None = None) -> Lineup:
    """Controllers for every seat of ``scenario``.

    Human seats (any interactive kind) get keyboards when ``interactive`` (two players
    may not share a key layout), else the ``stand_in`` bot if given, else they idle.
    Learner seats get ``learner`` (a seat spec such as ``checkpoint:PATH``,
    ``agent:NAME`` or a bot) if given, else the ``stand_in`` bot; with neither,
    ScenarioError. Every other seat gets its kind's controller.
    """
    sc = load_scenario(scenario)
    controllers: list[Policy] = []
    labels, descs, notes = [], [], []
    stand = spec_seat(stand_in, where=f"stand-in {stand_in!r}") if stand_in else None
    fill = spec_seat(learner, where=f"learner seat {learner!r}") if learner else None
    for given, seat in ((stand_in, stand), (learner, fill)):
        if seat is not None and not plays_by_itself(seat):
            raise ScenarioError(f"{given!r}: a seat filled for the scenario plays by itself "
                                "(a bot, checkpoint:PATH or agent:NAME); put players in "
                                "--seats")
    if fill is not None and not sc.learner_seats:
        raise ScenarioError(f"{learner}: {sc.source} has no learner seat for it to play; "
                            f"put it in a seat instead (e.g. --seats \"human,{learner}\")")
    people = [i for i, s in enumerate(sc.seats) if controller_kind(s.controller).interactive]
    if interactive and len(people) > len(KEYSETS):
        raise ScenarioError(f"{sc.source}: seats {people} are {len(people)} players at one "
                            f"keyboard, which has {len(KEYSETS)} key sets {list(KEYSETS)}; "
                            f"give at most {len(KEYSETS)} seats to players")
    humans: dict[str, int] = {}
    for i, seat in enumerate(sc.seats):
        desc, played = seat.describe(), seat
        person = controller_kind(seat.controller).interactive  # needs a player
        if person and interactive:
            if seat.keys in humans:
                raise ScenarioError(f"{sc.source}: seats[{i}]: two human seats use the "
                                    f"{seat.keys!r} keys; give each player its own set "
                                    f"{list(KEYSETS)}")
            humans[str(seat.keys)] = i
        elif seat.controller == "learner" and fill is not None:
            played, desc = fill, fill.describe()
        elif (seat.controller == "learner" or person) and stand is not None:
            played = stand
            notes.append(f"seat {i} ({desc}) is played by {stand.describe()}")
            desc = f"{stand.describe()}(for {desc})"
        ctrl = make_controller(played, interactive=interactive)
        if ctrl is None:
            raise ScenarioError(f"{sc.source}: seats[{i}] is a learner seat: give its "
                                "controller (a checkpoint, an agent or a stand-in bot)")
        controllers.append(ctrl)
        labels.append(seat_label(played))
        descs.append(desc)
    return Lineup(sc, controllers, labels, descs, notes)


def check_fit(scenario: Scenario, placed: Sequence[tuple[int, Policy]],
              game: Mapping[str, Any] | None = None) -> None:
    """Reset each ``(seat, controller)`` of ``placed`` in that seat of a match on each of
    ``scenario``'s maps (``game`` overrides its [game] table), so a controller that does
    not fit (a checkpoint trained with another tank count, or fewer wall or zone slots)
    raises its error before any game is played."""
    cfg = scenario.game_config(**dict(game or {}))
    for spec in scenario.map_specs():
        match = Match(cfg, spec, scenario.teams, seed=0)
        for seat, ctrl in placed:
            ctrl.reset(match, seat, 0)


def check_seats_fit(scenario: Scenario, game: Mapping[str, Any] | None = None) -> None:
    """:func:`check_fit` for every seat of ``scenario`` that plays by itself and may not
    fit (checkpoints, agents, registered controllers; bots fit any map, and resetting
    them on every map costs about 7 ms a map); ScenarioError naming the seat when one
    does not fit."""
    for i, seat in enumerate(scenario.seats):
        if seat.controller == "bot" or not plays_by_itself(seat):
            continue
        try:
            check_fit(scenario, [(i, make_controller(seat))], game)
        except InputError as exc:
            raise ScenarioError(f"{scenario.source}: seats[{i}] ({seat.describe()}) does not "
                                f"fit: {exc}") from None


def lineup_scenario(scenario: str | None = None, seats: str | None = None,
                    map_name: str | None = None, game: dict[str, Any] | None = None,
                    default_seats: str = "human:wasd,bot:smart") -> Scenario:
    """The scenario a command line asks for: ``scenario`` (name or .toml path) or a
    ``seats`` list on ``map_name`` (default: battlefield for 2 seats, arena4 up to 4,
    arena8 beyond; ScenarioError with ``scenario``); ``game`` overrides either's [game]
    table."""
    game = dict(game or {})
    if scenario and seats:
        raise ScenarioError("give either --scenario or --seats, not both")
    if scenario and map_name:
        raise ScenarioError("--map picks the map for --seats; a --scenario plays on its own "
                            "map (give either --scenario or --map, not both)")
    if scenario:
        sc = load_scenario(scenario)
        if game:  # the maps as resolved from the file's folder, not its relative paths
            table = {**sc.game, **game}
            sc.game_config(f"{sc.source}: [game]", **table)
            sc = dataclasses.replace(sc, game=table)
        return sc
    seats = seats or default_seats
    n = len([s for s in seats.split(",") if s.strip()])
    default_map = "battlefield" if n <= 2 else "arena4" if n <= 4 else "arena8"
    return seats_scenario(seats, map_name or default_map, game)

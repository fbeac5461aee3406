"""Scenarios: who plays where. A scenario names the map, the preset, the observation and
each seat (team + controller), and is stored as a TOML file.

Format (see docs/environments.md)::

    name = "vs_smart"
    description = "1v1: one learner against the smart bot"
    map = "battlefield"          # shipped map, a .txt path, or a folder of maps
    preset = "paper"             # or "long_range"
    observation = "paper"        # or any of OBS_KINDS (alphatank.game.observe)
    [game]                       # optional GameConfig overrides
    max_steps = 1500
    [rewards]                    # optional RewardConfig overrides
    bullet_close = 0.0
    [[seats]]
    team = "A"
    controller = "learner"
    [[seats]]
    team = "B"
    controller = "bot"
    bot = "smart"
    weakness = 1.0               # optional, 0..1
    options = { ricochet = false }   # optional bot options

Controllers (kinds, see :mod:`alphatank.game.seats`): ``learner`` (the env's caller acts),
``bot`` (``bot`` + ``weakness`` + ``options``), ``human`` (``keys`` = wasd | arrows | ijkl;
idle unless a keyboard is attached), ``checkpoint`` (``path`` = checkpoint folder),
``agent`` (``agent`` = a shipped agent's name). Relative map paths are resolved against
the scenario file's folder. Every error names the file and the field.
"""

from __future__ import annotations

import tomllib
from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from alphatank.errors import InputError
from alphatank.files import decode_text, read_text
from alphatank.game.observe import OBS_KINDS
from alphatank.game.rewards import check_team_outcome
from alphatank.game.seats import (
    Seat,
    SeatError,
    parse_seat_list,
    parse_seat_table,
    resolve,
)
from alphatank.sim.config import (
    PRESETS,
    ConfigError,
    GameConfig,
    RewardConfig,
    from_dict,
    game_config,
    printable_problem,
)
from alphatank.sim.mapspec import (
    MapError,
    MapSpec,
    is_shipped_map,
    load_map,
    parse_map,
    shipped_map_folders,
    shipped_maps,
)
from alphatank.sim.policy import NoopPolicy

__all__ = ["NoopPolicy", "Scenario", "ScenarioError", "Seat", "bot_names", "load_scenario",
           "parse_scenario", "seats_scenario", "shipped_scenarios"]
_TOP_KEYS = ("name", "description", "map", "map_texts", "preset", "observation", "game",
             "rewards", "seats")
TEXT = "text:"  # a map source holding the map itself: "text:NAME\nTEXT" (map_texts)


class ScenarioError(InputError, ValueError):
    """A scenario file or value is invalid; the message names the file and the field."""


@dataclass(frozen=True)
class Scenario:
    """A validated scenario. ``maps`` holds one or more map sources: names, paths, or the
    maps' text (``map_texts``: a scenario stored in a checkpoint carries its own maps)."""

    name: str
    map: str
    maps: tuple[str, ...]
    seats: tuple[Seat, ...]
    description: str = ""
    preset: str = "paper"
    observation: str = "paper"
    game: dict[str, Any] = field(default_factory=dict)
    rewards: dict[str, Any] = field(default_factory=dict)
    source: str = "<dict>"

    @property
    def teams(self) -> list[str]:
        return [s.team for s in self.seats]

    @property
    def learner_seats(self) -> list[int]:
        return [i for i, s in enumerate(self.seats) if s.controller == "learner"]

    @property
    def team_mode(self) -> bool:
        """True when some team has more than one tank (observations get team flags)."""
        return len(set(self.teams)) < len(self.seats)

    def game_config(self, where: str = "game_overrides", **overrides: Any) -> GameConfig:
        """The preset plus the scenario's [game] table plus ``overrides``; an error names
        the scenario's file, or ``where`` once the overrides are in."""
        try:
            cfg = game_config(self.preset, where=f"{self.source}: [game]", **self.game)
            return game_config(self.preset, where=where, **{**self.game, **overrides}) \
                if overrides else cfg
        except ConfigError as exc:
            raise ScenarioError(str(exc)) from None

    def reward_config(self, where: str = "reward_overrides", **overrides: Any) -> RewardConfig:
        """The scenario's [rewards] table plus ``overrides`` (errors as for game_config)."""
        try:
            cfg = _rewards(self.rewards, f"{self.source}: [rewards]")
            return _rewards({**self.rewards, **overrides}, where) if overrides else cfg
        except ConfigError as exc:
            raise ScenarioError(str(exc)) from None

    def to_dict(self) -> dict[str, Any]:
        """A mapping :func:`parse_scenario` rebuilds this scenario from."""
        out = {"name": self.name, "description": self.description, "map": self.map,
               "preset": self.preset, "observation": self.observation, "game": dict(self.game),
               "rewards": dict(self.rewards), "seats": [s.to_dict() for s in self.seats]}
        if self.maps[0].startswith(TEXT):
            out["map_texts"] = [m[len(TEXT):].split("\n", 1) for m in self.maps]
        return out

    def map_specs(self) -> list[MapSpec]:
        """Parsed maps, in ``maps`` order (an episode's map is drawn from these)."""
        return [_load_map_cached(m) for m in self.maps]


def _rewards(table: dict[str, Any], where: str) -> RewardConfig:
    """A RewardConfig from a [rewards] table, its team-outcome rules checked too; errors
    name ``where`` and the field."""
    cfg = from_dict(RewardConfig, table, where=where)
    check_team_outcome(cfg, where)
    return cfg


_MAP_CACHE: dict[str, MapSpec] = {}


def team_shape(teams: Sequence[str], seat: int) -> tuple[int, tuple[int, ...]]:
    """Where ``seat`` of a match of ``teams`` plays: its team's size and the sizes of the
    other teams, smallest first (what a team observation's layout means)."""
    sizes = Counter(teams)
    own = teams[seat]
    return sizes[own], tuple(sorted(n for t, n in sizes.items() if t != own))


def _shape_text(shape: tuple[int, tuple[int, ...]]) -> str:
    own, others = shape
    them = (f"a team of {others[0]}" if len(others) == 1 else
            "teams of " + ", ".join(map(str, others[:-1])) + f" and {others[-1]}")
    return f"{'alone' if own == 1 else f'in a team of {own}'} against {them}"


def team_misfit(trained: Sequence[str], trained_seats: Iterable[int], teams: Sequence[str],
                seat: int) -> str | None:
    """Why ``seat`` of a match of ``teams`` is not a place that a policy trained in
    ``trained_seats`` of a match of ``trained`` (teams per seat) played, or None when it
    is (or ``trained`` is unknown)."""
    if not trained:
        return None
    fits = {team_shape(trained, s) for s in trained_seats}
    shape = team_shape(teams, seat)
    if shape in fits:
        return None
    return (f"seat {seat} of this match (teams {list(teams)}) plays {_shape_text(shape)}; "
            f"it trained {' or '.join(sorted(map(_shape_text, fits)))}")


def _load_map_cached(source: str) -> MapSpec:
    spec = _MAP_CACHE.get(source)
    if spec is None:
        if source.startswith(TEXT):
            name, _, text = source[len(TEXT):].partition("\n")
            spec = parse_map(text, f"<map {name!r} of map_texts>", name=name)
        elif source.startswith("pkg:"):
            res = resources.files("alphatank.maps").joinpath(source[4:])
            spec = parse_map(decode_text(res.read_bytes(), f"maps/{source[4:]}"),
                             f"maps/{source[4:]}", name=Path(source[4:]).stem)
        else:
            spec = load_map(source)
        _MAP_CACHE[source] = spec
    return spec


def shipped_scenarios() -> list[str]:
    """Names of the scenarios shipped with the package."""
    root = resources.files("alphatank").joinpath("data", "scenarios")
    return sorted(p.name[:-5] for p in root.iterdir() if p.name.endswith(".toml"))


def load_scenario(name_or_path: str | Path | Scenario) -> Scenario:
    """A shipped scenario by name (``"vs_smart"``; a file or folder of that name in the
    working folder does not hide it) or any scenario TOML file by path."""
    if isinstance(name_or_path, Scenario):
        return name_or_path
    if not isinstance(name_or_path, str | Path):
        raise ScenarioError(f"scenario: a shipped scenario's name, a .toml path or a Scenario, "
                            f"got {type(name_or_path).__name__} {name_or_path!r}")
    path = Path(name_or_path)
    named = isinstance(name_or_path, str) and name_or_path in shipped_scenarios()
    if not named and (path.suffix == ".toml" or path.exists()):
        if not path.is_file():
            hint = (f" (the shipped scenario is {path.stem!r}, without .toml)"
                    if str(path) == path.name and path.stem in shipped_scenarios() else "")
            raise ScenarioError(f"{path}: " + ("a folder, not a scenario file" if path.is_dir()
                                               else "no such scenario file") + hint)
        try:
            text = read_text(path)
        except ValueError as exc:
            raise ScenarioError(str(exc)) from None
        source, base = str(path), path.parent
    else:
        res = resources.files("alphatank").joinpath("data", "scenarios", f"{name_or_path}.toml")
        if not res.is_file():
            raise ScenarioError(f"unknown scenario {str(name_or_path)!r}; shipped scenarios: "
                                f"{shipped_scenarios()} (or give a path to a .toml file)")
        text, source, base = (res.read_text(encoding="utf-8"),
                              f"scenarios/{name_or_path}.toml", None)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{source}: invalid TOML: {exc}") from None
    return parse_scenario(data, source, base)


def parse_scenario(data: dict[str, Any], source: str = "<dict>",
                   base: Path | None = None, check_paths: bool = True,
                   map_label: str | None = None) -> Scenario:
    """Validate a scenario mapping (as read from TOML); errors name ``source`` and field.
    Each seat gets its kind's check (bot names, options and their types, checkpoint
    folders, ...); checkpoint seat paths are resolved against ``base`` first, like maps,
    and not checked when ``check_paths`` is False (a scenario stored in a checkpoint, whose
    opponents' folders may since have moved). ``map_label`` names the map in its errors
    (``--map`` for a scenario made from command-line flags; default ``SOURCE: map``)."""
    if not isinstance(data, dict):
        raise ScenarioError(f"{source}: a scenario must be a table, got {type(data).__name__}")

    def fail(where: str, msg: str) -> ScenarioError:
        if where == "map" and map_label is not None:
            return ScenarioError(f"{map_label}: {msg}")
        return ScenarioError(f"{source}: {where}: {msg}")

    unknown = sorted(set(data) - set(_TOP_KEYS))
    if unknown:
        raise fail(str(unknown[0]), f"unknown key; valid keys: {list(_TOP_KEYS)}")
    for key in ("name", "map"):
        if not isinstance(data.get(key), str) or not data[key]:
            raise fail(key, "required, a non-empty string")
    if why := printable_problem(data["name"]):  # printed, drawn and kept in replays
        raise fail("name", why)
    description = data.get("description", "")
    if not isinstance(description, str):
        raise fail("description", "must be a string")
    if why := printable_problem(description):
        raise fail("description", why)
    preset = data.get("preset", "paper")
    if not isinstance(preset, str) or preset not in PRESETS:
        raise fail("preset", f"unknown preset {preset!r}; valid: {sorted(PRESETS)}")
    observation = data.get("observation", "paper")
    if observation not in OBS_KINDS:
        raise fail("observation", f"unknown observation {observation!r}; valid: "
                   f"{list(OBS_KINDS)}")
    tables = {}
    for key in ("game", "rewards"):
        table = data.get(key, {})
        if not isinstance(table, dict):
            raise fail(f"[{key}]", "must be a table")
        tables[key] = dict(table)
    try:
        game_config(preset, where=f"{source}: [game]", **tables["game"])
        _rewards(tables["rewards"], f"{source}: [rewards]")
    except ConfigError as exc:
        raise ScenarioError(str(exc)) from None

    maps = _text_maps(data["map_texts"], fail) if "map_texts" in data else \
        _resolve_maps(data["map"], base, fail)
    seats_data = data.get("seats")
    if not isinstance(seats_data, list) or len(seats_data) < 2:
        raise fail("seats", "need at least 2 [[seats]] entries")
    try:
        seats = tuple(parse_seat_table(_seat_paths(s, base), f"seats[{i}]",
                                       check=check_paths or not _is_checkpoint_seat(s))
                      for i, s in enumerate(seats_data))
    except SeatError as exc:
        raise ScenarioError(f"{source}: {exc}") from None
    if len({s.team for s in seats}) < 2:
        raise fail("seats", f"need at least 2 teams, got {sorted({s.team for s in seats})}")
    for m in maps:
        spec = _load_map_cached(m)
        room = spec.tank_room(len(seats))
        if room < len(seats):
            raise fail("map", f"map {spec.name!r} has room for {room} tank(s) (free floor "
                       f"reachable from its spawns), the scenario has {len(seats)} seats")
    return Scenario(name=data["name"], map=data["map"], maps=maps, seats=seats,
                    description=description, preset=preset, observation=observation,
                    game=tables["game"], rewards=tables["rewards"], source=source)


def _text_maps(value: Any, fail: Any) -> tuple[str, ...]:
    """Map sources for a ``map_texts`` value: [name, map text] pairs (``map`` then only
    says where they came from)."""
    if not isinstance(value, list) or not value or not all(
            isinstance(p, list) and len(p) == 2 and all(isinstance(x, str) and x for x in p)
            and "\n" not in p[0] for p in value):
        raise fail("map_texts", "must be a list of [name, map text] pairs (a name is one "
                                "line)")
    return _checked(tuple(f"{TEXT}{name}\n{text}" for name, text in value), fail,
                    "map_texts")


def _resolve_maps(value: str, base: Path | None, fail: Any) -> tuple[str, ...]:
    """Map sources for a ``map`` value: a file or folder path in the scenario file's folder
    (``base``), a shipped map or folder, or a file or folder path from the working folder
    (which does not hide a shipped name: ``./arena4`` names a folder there)."""
    path = Path(value)
    if base is not None and not path.is_absolute() and (found := _maps_at(base / path, fail)):
        return found
    if _is_shipped_map(value):
        root = resources.files("alphatank.maps")
        if root.joinpath(f"{value}.txt").is_file():
            return _checked((f"pkg:{value}.txt",), fail)
        return _checked(tuple(f"pkg:{value}/{p.name}" for p in sorted(
            root.joinpath(value).iterdir(), key=lambda p: p.name) if p.name.endswith(".txt")),
            fail)
    if found := _maps_at(path, fail):
        return found
    raise fail("map", f"unknown map {value!r}; shipped maps: {shipped_maps()} "
               "(or a path to a .txt map or a folder of maps)")


def _maps_at(cand: Path, fail: Any) -> tuple[str, ...] | None:
    """The map sources of a file or folder ``cand``, or None when there is none."""
    if cand.is_dir():
        found = tuple(str(p) for p in sorted(cand.glob("*.txt")))
        if not found:
            raise fail("map", f"folder {str(cand)!r} holds no .txt maps")
        return _checked(found, fail)
    if cand.is_file():
        return _checked((str(cand),), fail)
    return None


def _is_shipped_map(value: str) -> bool:
    """Whether ``value`` names a shipped map (``maze``, ``train/maze_0000``) or a shipped
    folder of maps (``train``)."""
    return value in shipped_map_folders() or is_shipped_map(value)


def _checked(sources: tuple[str, ...], fail: Any, key: str = "map") -> tuple[str, ...]:
    for s in sources:
        try:
            _load_map_cached(s)
        except MapError as exc:
            raise fail(key, str(exc)) from None
    return sources


def seats_scenario(seats: str, map_name: str, game: dict[str, Any] | None = None,
                   preset: str = "paper", name: str = "custom") -> Scenario:
    """A scenario from a ``--seats`` list (see :mod:`alphatank.game.seats`) on
    ``map_name``; errors name the seat (or ``--map``) and the allowed values."""
    try:
        tables = parse_seat_list(seats)
    except SeatError as exc:
        raise ScenarioError(str(exc)) from None
    data = {"name": name, "map": map_name, "preset": preset, "seats": tables,
            "game": dict(game or {})}
    return parse_scenario(data, source="--seats", map_label="--map")


def _is_checkpoint_seat(data: Any) -> bool:
    return isinstance(data, dict) and data.get("controller") == "checkpoint"


def _seat_paths(data: Any, base: Path | None) -> Any:
    """A ``checkpoint`` seat table with a relative ``path`` found under ``base`` (the
    scenario file's folder) pointing there, like relative map paths; else as given."""
    path = data.get("path") if _is_checkpoint_seat(data) else None
    if base is None or not isinstance(path, str) or not path or Path(path).is_absolute():
        return data
    cand = base / path
    return {**data, "path": str(cand)} if cand.exists() else data


def bot_names() -> tuple[str, ...]:
    """Bot types that ``bot`` seats may name (``alphatank.bots``, resolved late)."""
    return tuple(resolve("alphatank.bots.registry:BOT_NAMES"))

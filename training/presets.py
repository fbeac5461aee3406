"""Training runs as data: :class:`TrainConfig` (the scenario, the learners with their
algorithms and hyperparameters, the opponent schedule, the run settings), its TOML form,
and the named presets shipped as ``alphatank/data/presets/<name>.toml`` (every experiment
of the paper's sections 4.1-4.5 with Tables 7/8/9 as the defaults).

``alphatank train --preset NAME`` or ``--config FILE.toml`` starts one; flags override its
settings. Every load error names the file and the field.
"""

from __future__ import annotations

import dataclasses
import math
import re
import tomllib
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

from alphatank.files import read_text
from alphatank.sim.config import ACTION_REPEAT_MAX, MATCHES_MAX, printable_problem
from alphatank.training.algorithms import ALGORITHMS, get_algorithm
from alphatank.training.fields import (
    FieldError,
    a_type,
    build,
    describe,
    did_you_mean,
    field_map,
    hp,
    parse_value,
)
from alphatank.training.fields import validate as validate_fields
from alphatank.training.stopping import TIME_LIMIT_MAX_S
from alphatank.training.tomlwriter import dumps

WANDB_MODES = ("offline", "online", "disabled")
WANDB_PROJECT_BANNED = "/\\#?%:"  # characters wandb refuses in a project name
BOT_POOL = ("random", "aggressive", "defensive", "dodge")  # the cycle of paper 4.3
CYCLE_INTERVAL = 100_000  # env steps per opponent when a cycle is set from the command line
DEFAULT_ROLLOUT_STEPS = 512  # vector steps per iteration when no learner asks for a length
REQUIRED: Any = dataclasses.MISSING
_NAME = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.-]*$")


@dataclass(frozen=True)
class LearnerSpec:
    """One independent learner: its name, algorithm, hyperparameters (``config``, that
    algorithm's config dataclass; None: its defaults) and the learner seats (indices
    into the scenario's learner seats, 0..L-1) it controls. Several seats share one
    network (parameter sharing); give each seat its own spec for independence."""

    name: str
    algo: str = "ppo"
    seats: tuple[int, ...] = (0,)
    config: Any = None

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not _NAME.match(self.name):
            raise ValueError(f"learner name must be letters, digits, '_', '.' or '-' (it "
                             f"names files and metrics), got {self.name!r}")
        try:
            algo = get_algorithm(self.algo)
        except ValueError as exc:
            raise ValueError(f"learner {self.name!r}: {exc}") from None
        cfg = algo.config() if self.config is None else self.config
        if not isinstance(cfg, algo.config):
            raise ValueError(f"learner {self.name!r}: config must be a {algo.config.__name__} "
                             f"for algo {self.algo!r}, got {type(cfg).__name__}")
        seats = tuple(self.seats)
        if not seats:
            raise ValueError(f"learner {self.name!r} controls no seats")
        if any(isinstance(s, bool) or not isinstance(s, int) or s < 0 for s in seats) or \
                len(set(seats)) != len(seats):
            raise ValueError(f"learner {self.name!r}: seats must be distinct learner-seat "
                             f"indices >= 0, got {list(seats)}")
        object.__setattr__(self, "config", cfg)
        object.__setattr__(self, "seats", seats)

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "algo": self.algo, "seats": list(self.seats),
                "config": dataclasses.asdict(self.config)}

    @classmethod
    def from_dict(cls, data: Any, prefix: str = "") -> LearnerSpec:
        """From ``{name, algo, seats, config}`` (a checkpoint's or a run file's learner);
        errors read ``{prefix}{field}: problem``."""
        if not isinstance(data, dict):
            raise ValueError(f"{prefix.rstrip('.: ')}: must be a table with name, algo, "
                             f"seats, config")
        valid = ("name", "algo", "seats", "config")
        for key in data:
            if key not in valid:
                raise ValueError(f"{prefix}{key}: unknown key; valid keys: {list(valid)}"
                                 f"{did_you_mean(key, valid)}")
        name = data.get("name")
        if not isinstance(name, str):
            raise ValueError(f"{prefix}name: required, a string")
        algo_name = data.get("algo", "ppo")
        try:
            algo = get_algorithm(algo_name)
        except ValueError as exc:
            raise ValueError(f"{prefix}algo: {exc}") from None
        seats = data.get("seats", [0])
        if not isinstance(seats, list | tuple):
            raise ValueError(f"{prefix}seats: must be a list of learner-seat indices, "
                             f"got {seats!r}")
        config = data.get("config", {})
        if not isinstance(config, dict):
            raise ValueError(f"{prefix}config: must be a table of {algo_name} "
                             f"hyperparameters")
        cfg = build(algo.config, config, f"{prefix}config.")
        try:
            return cls(name=name, algo=algo_name, seats=tuple(seats), config=cfg)
        except ValueError as exc:
            raise ValueError(f"{prefix.rstrip('.: ')}: {exc}") from None


def run_name_problem(name: str) -> str | None:
    """Why ``name`` cannot name a run's folder (None: it can); it names a folder, so no
    way out of the runs folder."""
    if _NAME.match(name):
        return None
    return (f"must be letters, digits, '_', '.' or '-', not starting with '.' (it names the "
            f"run's folder), got {name!r}")


# Most torch threads: more than any one machine has cores (torch made them all: at
# 100,000 its first matrix product crashed the process with a segmentation fault).
TORCH_THREADS_MAX = 1024


@dataclass(frozen=True)
class TrainConfig:
    """A training run. ``learners`` empty means one PPO learner per learner seat.
    Cadences (``checkpoint_every``, ``eval_every``, ``video_every``) count iterations of
    ``rollout_steps`` vector steps (one PPO update); 0 switches them off."""

    name: str = hp(REQUIRED, "run name; the run lives in <runs>/<name>")
    scenario: str = hp(REQUIRED, "shipped scenario name or path to a scenario .toml")
    description: str = hp("", "what the run is for (shown by alphatank train --list)")
    learners: tuple[LearnerSpec, ...] = hp((), "learners (name, algo, seats, config); "
                                           "none: one PPO learner per learner seat")
    total_steps: int = hp(2_000_000, "env steps summed over all envs (one match tick each), "
                          "rounded up to whole iterations (rollout_steps x num_envs)", gt=0)
    num_envs: int = hp(16, "matches stepped together (each holds about 0.5 MB)", gt=0,
                       le=MATCHES_MAX)
    num_workers: int = hp(1, "env worker processes", gt=0)
    seed: int = hp(0, "run seed (every random stream derives from it)", ge=0)
    observation: str | None = hp(None, "observation kind (none: the scenario's)")
    action_repeat: int = hp(1, "ticks each learner action is held for (the other seats act "
                            "every tick); an env step is that many ticks", ge=1,
                            le=ACTION_REPEAT_MAX)
    game: dict[str, Any] = hp({}, "GameConfig overrides on top of the scenario's")
    rewards: dict[str, Any] = hp({}, "RewardConfig overrides on top of the scenario's")
    schedule: dict[str, Any] = hp({}, "opponent schedule: kind = none | curriculum | cycle | "
                                  "winrate | lineup | league, and its parameters")
    selfplay: dict[str, Any] = hp({}, "self-play pool: the learner seats no learner drives "
                                  "are played by past snapshots of a learner (keys: learner, "
                                  "window, latest_share, every)")
    init_from: str = hp("", "warm start: every learner starts from the PPO learner of this "
                        "checkpoint (a run or checkpoint folder, or agent:NAME); empty: none")
    imitate: dict[str, Any] = hp({}, "behaviour-cloning warm start before RL: a bot plays "
                                 "the learner seats and the PPO and MAPPO learners copy it "
                                 "(keys: bot, steps, epochs, minibatch, learning_rate, "
                                 "dagger, dagger_steps, dagger_epochs); empty: none")
    rollout_steps: int = hp(0, "vector steps per iteration (0: the longest rollout any "
                            "learner wants, 512 if none)", ge=0)
    checkpoint_every: int = hp(10, "iterations per checkpoint (0: only at the end)", ge=0)
    keep_checkpoints: int = hp(3, "newest checkpoints kept (0: all)", ge=0)
    eval_every: int = hp(0, "iterations per evaluation (0: none)", ge=0)
    eval_games: int = hp(50, "games per evaluation", gt=0)
    video_every: int = hp(0, "iterations per match video (0: none)", ge=0)
    wandb: str = hp("offline", "wandb mode", choices=WANDB_MODES)
    project: str = hp("alphatank", "wandb project")
    tensorboard: bool = hp(False, "also write TensorBoard logs")
    torch_threads: int = hp(1, "torch threads", gt=0, le=TORCH_THREADS_MAX)
    time_limit_s: float = hp(0.0, "stop (and checkpoint) after this much wall time in "
                             "seconds of one invocation, at most a week; a resumed run gets "
                             "it again (0: none)", ge=0, le=TIME_LIMIT_MAX_S)
    map: str | None = hp(None, "map override: shipped map or folder name (e.g. train), "
                         "a .txt path or a folder of maps (none: the scenario's)")

    def __post_init__(self) -> None:
        object.__setattr__(self, "learners", tuple(self.learners))
        validate_fields(self)
        if why := run_name_problem(self.name):
            raise FieldError("TrainConfig", "name", why)
        for key, what in (("scenario", "a shipped scenario name or a path to a .toml"),
                          ("map", "a shipped map or folder name or a path, or leave it out")):
            if getattr(self, key) == "":  # read as the current folder
                raise FieldError("TrainConfig", key, f"is empty; give {what}")
        if why := printable_problem(self.description):  # one line of `train --list`
            raise FieldError("TrainConfig", "description", why)
        if self.wandb != "disabled" and (len(self.project) > 128 or any(
                c in self.project for c in WANDB_PROJECT_BANNED)):  # wandb would refuse it
            raise FieldError("TrainConfig", "project", f"must be a wandb project name: at most "
                             f"128 characters, none of {' '.join(WANDB_PROJECT_BANNED)}, got "
                             f"{self.project!r}")
        for spec in self.learners:
            if not isinstance(spec, LearnerSpec):
                raise FieldError("TrainConfig", "learners", f"must hold LearnerSpecs, got "
                                 f"{type(spec).__name__}")
        names = [spec.name for spec in self.learners]
        if len(set(names)) != len(names):
            raise FieldError("TrainConfig", "learners", f"names must be unique, got {names}")
        for spec in self.learners:  # anchor_kl pulls towards a warm start: one must exist
            kl = getattr(spec.config, "anchor_kl", 0.0)
            if kl and not (self.imitate or self.init_from):
                raise FieldError("TrainConfig", "learners", f"{spec.name!r}: anchor_kl = {kl} "
                                 f"needs a warm start to pull towards (an imitate table or "
                                 f"init_from); set anchor_kl = 0 or add one")

    def with_overrides(self, **changes: Any) -> TrainConfig:
        """A copy with run settings changed (None values are ignored)."""
        return dataclasses.replace(self, **{k: v for k, v in changes.items() if v is not None})

    def to_dict(self) -> dict[str, Any]:
        data = dataclasses.asdict(self)
        data["learners"] = [spec.to_dict() for spec in self.learners]
        return data

    @classmethod
    def from_dict(cls, data: dict[str, Any], prefix: str = "") -> TrainConfig:
        """From :meth:`to_dict` or a run file's mapping; errors read ``{prefix}field:
        problem`` and unknown keys list the valid ones."""
        data = dict(data)
        learners = data.pop("learners", [])
        if not isinstance(learners, list | tuple):
            raise ValueError(f"{prefix}learners: must be a list of learner tables")
        specs = tuple(LearnerSpec.from_dict(d, f"{prefix}learners[{i}].")
                      for i, d in enumerate(learners))
        return build(cls, {**data, "learners": specs}, prefix)


# ---- learners for a scenario ---------------------------------------------------------------

def default_learners(num_learners: int, algo: str = "ppo", config: Any = None
                     ) -> tuple[LearnerSpec, ...]:
    """One independent learner of ``algo`` (Table 7 PPO by default) per learner seat."""
    if num_learners == 1:
        return (LearnerSpec(algo, algo, (0,), config),)
    return tuple(LearnerSpec(f"{algo}_{i}", algo, (i,), config) for i in range(num_learners))


def learners_fit(specs: Sequence[LearnerSpec], num_learners: int, selfplay: bool = False
                 ) -> bool:
    """True when ``specs`` drive each of ``num_learners`` learner seats exactly once (with
    ``selfplay``: at most once, leaving at least one seat to the snapshot pool)."""
    seats = sorted(s for spec in specs for s in spec.seats)
    if selfplay:
        return (len(set(seats)) == len(seats) < num_learners
                and all(0 <= s < num_learners for s in seats))
    return seats == list(range(num_learners))


TEAM_ALGOS = ("mappo",)  # one learner per team: its critic and credit are the team's
SELFPLAY_KEYS = ("learner", "window", "latest_share", "every")
# Most snapshots a self-play pool keeps, each a copy of the learner's networks (up to
# ~0.5 GiB at the widest): far more would not fit, and past 2**63 the window could not
# even be made (OverflowError as the run started).
SNAPSHOT_WINDOW_MAX = 10_000


def check_pool_args(window: int = 8, latest_share: float = 0.5, every: int = 200_000) -> None:
    """Raise ValueError unless these are valid :class:`SnapshotPool` settings."""
    if not 1 <= window <= SNAPSHOT_WINDOW_MAX:
        raise ValueError(f"snapshot pool needs window >= 1 and at most "
                         f"{SNAPSHOT_WINDOW_MAX:,} (snapshots kept), got {window!r}")
    if every < 1:
        raise ValueError(f"snapshot pool needs every >= 1 (env steps between snapshots), "
                         f"got {every!r}")
    if not 0.0 <= latest_share <= 1.0:
        raise ValueError(f"latest_share must be in [0, 1], got {latest_share}")


def selfplay_pool_args(cfg: TrainConfig) -> tuple[str, dict[str, Any]]:
    """(learner name, SnapshotPool keyword arguments) of a run's ``selfplay`` table; a
    bad key or value is a one-line ValueError naming it."""
    table = dict(cfg.selfplay)
    bad = sorted(set(table) - set(SELFPLAY_KEYS))
    if bad:
        raise ValueError(f"selfplay.{bad[0]}: unknown key; valid keys: {list(SELFPLAY_KEYS)}"
                         f"{did_you_mean(bad[0], SELFPLAY_KEYS)}")
    names = [s.name for s in cfg.learners]
    learner = table.pop("learner", names[0] if names else "")
    if learner not in names:
        raise ValueError(f"selfplay.learner: {learner!r} is not one of the run's learners "
                         f"{names} (self-play needs its learners listed)")
    kinds = {"window": int, "every": int, "latest_share": float}
    for key, kind in kinds.items():
        value = table.get(key)
        if value is not None and (isinstance(value, bool) or not isinstance(value, int | float)
                                  or not math.isfinite(value)
                                  or (kind is int and not float(value).is_integer())):
            what = "an integer" if kind is int else "a number"
            raise ValueError(f"selfplay.{key}: must be {what}, got {value!r}")
    try:
        check_pool_args(**table)
    except ValueError as exc:
        raise ValueError(f"selfplay: {exc}") from None
    return learner, {key: kind(table[key]) for key, kind in kinds.items() if key in table}


def run_learners(cfg: TrainConfig, num_learners: int) -> tuple[LearnerSpec, ...]:
    """The run's learners: its own, or one per learner seat when it names none."""
    return cfg.learners or default_learners(num_learners)


def iteration_steps(cfg: TrainConfig) -> int:
    """Env steps of one iteration of the run: ``rollout_steps`` vector steps (0: the
    longest fixed rollout, ``num_steps``, its learners want; DEFAULT_ROLLOUT_STEPS when
    none does, as for SAC) times ``num_envs``."""
    wants = [getattr(spec.config, "num_steps", 0) for spec in run_learners(cfg, 1)]
    return (cfg.rollout_steps or max(wants) or DEFAULT_ROLLOUT_STEPS) * cfg.num_envs


def planned_steps(cfg: TrainConfig) -> int:
    """The env steps the run trains unless a stop ends it sooner: ``total_steps`` rounded
    up to whole iterations (:func:`iteration_steps`; the step count is checked between
    iterations)."""
    per = iteration_steps(cfg)
    return -(-cfg.total_steps // per) * per


def run_scenario(cfg: TrainConfig) -> Any:
    """The :class:`Scenario` a run plays: ``cfg.scenario`` with ``cfg.map`` (if set) in
    place of its map."""
    from alphatank.game.scenarios import load_scenario, parse_scenario

    sc = load_scenario(cfg.scenario)
    if cfg.map is None:
        return sc
    return parse_scenario({**sc.to_dict(), "map": cfg.map}, f"{sc.source} (map {cfg.map!r})")


# ---- hyperparameter overrides (--hp ALGO.FIELD=VALUE) -------------------------------------

def parse_hp(items: Iterable[tuple[str, str]], flags: dict[str, list[str]] | None = None
             ) -> dict[str, dict[str, Any]]:
    """``[(flag, "ppo.clip_coef=0.1,sac.tau=0.01"), ...]`` -> typed values per algorithm.
    A flag named after an algorithm (``--ppo``) takes bare ``FIELD=VALUE`` items. Errors
    are one line naming the flag and the field as typed and what is allowed. ``flags``, if
    given, gets the flags that set each algorithm's values (for :func:`with_hp`). A
    hyperparameter given twice is refused: which one plays would be a guess."""
    out: dict[str, dict[str, Any]] = {}
    set_by: dict[tuple[str, str], str] = {}  # (algorithm, field) -> the item that set it
    for flag, text in items:
        fixed = flag.lstrip("-") if flag.lstrip("-") in ALGORITHMS else None
        for item in filter(None, (part.strip() for part in text.split(","))):
            key, sep, raw = item.partition("=")
            key = key.strip()
            algo_name, dot, name = key.partition(".") if fixed is None else (fixed, ".", key)
            if not sep or not dot or not name:
                form = "FIELD=VALUE" if fixed else "ALGO.FIELD=VALUE"
                raise ValueError(f"{flag}: expected {form}, got {item!r}")
            try:
                cfg_cls = get_algorithm(algo_name).config
            except ValueError as exc:
                raise ValueError(f"{flag} {key}: {exc}") from None
            fields = field_map(cfg_cls)
            if name not in fields:
                raise ValueError(f"{flag} {key}: unknown {algo_name} hyperparameter; valid: "
                                 f"{sorted(fields)}{did_you_mean(name, fields)}")
            try:
                value = parse_value(cfg_cls, name, raw)
                dataclasses.replace(cfg_cls(), **{name: value})  # range check now
            except FieldError as exc:
                raise ValueError(f"{flag} {key}: {exc.problem}") from None
            if (algo_name, name) in set_by:
                raise ValueError(f"{flag} {key}: {algo_name}.{name} is also set by "
                                 f"{set_by[algo_name, name]}; give it once")
            set_by[algo_name, name] = f"{flag} {key}"
            out.setdefault(algo_name, {})[name] = value
            if flags is not None and flag not in flags.setdefault(algo_name, []):
                flags[algo_name].append(flag)
    return out


def parse_game(flag: str, text: str) -> dict[str, Any]:
    """``"random_spawns=false,max_steps=600"`` -> typed GameConfig overrides, each in its
    range (rules across settings, such as bullets faster than tanks, are checked where the
    game is built). Errors are one line naming the flag, the key and what is allowed."""
    from alphatank.sim.config import ConfigError, GameConfig, check_field

    fields = field_map(GameConfig)
    out: dict[str, Any] = {}
    for item in filter(None, (part.strip() for part in text.split(","))):
        key, sep, raw = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise ValueError(f"{flag}: expected KEY=VALUE, got {item!r}")
        if key not in fields:
            raise ValueError(f"{flag} {key}: unknown game setting; valid: {sorted(fields)}"
                             f"{did_you_mean(key, fields)}")
        if key in out:  # which one plays would be a guess
            raise ValueError(f"{flag} {key}: given twice; give it once")
        try:
            out[key] = check_field(GameConfig, key, parse_value(GameConfig, key, raw))
        except FieldError as exc:
            raise ValueError(f"{flag} {key}: {exc.problem}") from None
        except ConfigError as exc:
            raise ValueError(f"{flag} {key}: {exc.reason}") from None
    return out


def with_hp(cfg: TrainConfig, overrides: dict[str, dict[str, Any]], num_learners: int,
            flags: dict[str, list[str]] | None = None) -> TrainConfig:
    """``cfg`` with hyperparameters changed for every learner of each algorithm named.
    Errors name the flags that set the values (``flags``, from :func:`parse_hp`; default
    ``--hp``)."""
    if not overrides:
        return cfg

    def given(algo: str) -> str:
        return ", ".join(f if f == f"--{algo}" else f"{f} {algo}.*"
                         for f in (flags or {}).get(algo, ["--hp"]))

    specs = run_learners(cfg, num_learners)
    present = sorted({s.algo for s in specs})
    for algo in overrides:
        if algo not in present:
            raise ValueError(f"{given(algo)}: this run has no {algo} learner (its learners "
                             f"use {', '.join(present)})")
    specs = tuple(dataclasses.replace(
        s, config=dataclasses.replace(s.config, **overrides.get(s.algo, {}))) for s in specs)
    try:
        return dataclasses.replace(cfg, learners=specs)
    except FieldError as exc:  # a rule across settings, e.g. anchor_kl without a warm start
        raise ValueError(f"{', '.join(map(given, overrides))}: {exc.problem}") from None


# ---- run files ----------------------------------------------------------------------------

def check_run_fields(cfg: TrainConfig, sc: Any, source: str, where: str | None = None
                     ) -> None:
    """The settings of a run file or preset that no flag replaces, checked before the run
    starts against the scenario ``sc`` it plays (its map override in place): its
    observation and imitate table, learner seats to train, learners that drive each of
    them once (self-play: at most once, leaving one to the snapshot pool), bot seats for
    its schedule, and the ranges of its [game] and [rewards] tables. Errors name
    ``source`` and the field; ``where`` says where the scenario was chosen (default:
    ``source``)."""
    from alphatank.game.observe import OBS_KINDS
    from alphatank.training.hparams import imitate_config

    if cfg.observation is not None and cfg.observation not in OBS_KINDS:
        raise ValueError(f"{source}: observation: {cfg.observation!r} is not one of "
                         f"{list(OBS_KINDS)}")
    try:
        imitate_config(cfg.imitate)
    except ValueError as exc:
        raise ValueError(f"{source}: {exc}") from None
    where = where or source
    n = len(sc.learner_seats)
    if not n:
        raise ValueError(f"{where}: scenario {sc.name!r} has no learner seats: nothing to "
                         "train (a scenario for training has controller = \"learner\" seats)")
    if not learners_fit(run_learners(cfg, n), n, selfplay=bool(cfg.selfplay)):
        drives = [(s.name, list(s.seats)) for s in cfg.learners]
        if cfg.selfplay:
            raise ValueError(f"{where}: self-play learners {drives} must drive each of the "
                             f"{n} learner seat(s) of scenario {sc.name!r} at most once and "
                             "leave at least one to the snapshot pool")
        raise ValueError(f"{source}: learners {drives} do not drive each of the {n} learner "
                         f"seat(s) of scenario {sc.name!r} exactly once")
    for spec in run_learners(cfg, n):
        teams = sorted({sc.teams[sc.learner_seats[s]] for s in spec.seats})
        if spec.algo in TEAM_ALGOS and len(teams) > 1:
            raise ValueError(f"{where}: learners: {spec.algo} learner {spec.name!r} drives "
                             f"seats {sorted(spec.seats)} of teams {teams} in scenario "
                             f"{sc.name!r}; a {spec.algo} learner drives the seats of one "
                             f"team (one learner per team)")
    kind = cfg.schedule.get("kind", "none")
    if kind != "none" and not any(s.controller == "bot" for s in sc.seats):
        raise ValueError(f"{source}: schedule: the {kind} schedule needs bot seats; scenario "
                         f"{sc.name!r} has none (drop the schedule)")
    sc.game_config(where=f"{source}: [game]", **cfg.game)
    sc.reward_config(where=f"{source}: [rewards]", **cfg.rewards)


def parse_run(data: dict[str, Any], source: str, base: Path | None = None,
              name: str | None = None) -> TrainConfig:
    """A :class:`TrainConfig` from a run file's mapping. ``name`` is the default run name
    (the file's stem); relative scenario and map paths resolve against ``base``."""
    data = dict(data)
    if "name" not in data:
        data["name"] = name or "run"
        if not _NAME.match(data["name"]):  # the file's name: say where it came from
            raise ValueError(f"{source}: name: the run is named after its file, "
                             f"{data['name']!r}, which cannot name its folder (letters, "
                             f"digits, '_', '.' or '-', not starting with '.'); add name = "
                             f"\"...\" to the file or give --name")
    if "scenario" not in data:
        raise ValueError(f"{source}: scenario: required (a shipped scenario name or a path "
                         f"to a scenario .toml)")
    if base is not None:  # as a scenario file's map: a path beside the file comes first
        for key in ("scenario", "map", "init_from"):
            value = data.get(key)
            if isinstance(value, str) and value and not Path(value).is_absolute() and (
                    (base / value).is_file() if key == "scenario" else (base / value).exists()):
                data[key] = str(base / value)
    cfg = TrainConfig.from_dict(data, f"{source}: ")
    if cfg.selfplay:
        try:
            selfplay_pool_args(cfg)
        except ValueError as exc:
            raise ValueError(f"{source}: {exc}") from None
    from alphatank.training.schedules import make_schedule
    try:
        make_schedule(cfg.schedule, cfg.total_steps)
    except ValueError as exc:
        raise ValueError(f"{source}: schedule: {exc}") from None
    for key in ("game", "rewards"):
        _check_overrides(getattr(cfg, key), key, f"{source}: ")
    return cfg


def _check_overrides(table: dict[str, Any], key: str, prefix: str) -> None:
    """Keys and value types of a [game] / [rewards] table (ranges: when the scenario's
    preset is applied at the start of the run)."""
    from alphatank.sim.config import GameConfig, RewardConfig

    cls = GameConfig if key == "game" else RewardConfig
    fields = field_map(cls)
    for name, value in table.items():
        if name not in fields:
            raise ValueError(f"{prefix}{key}.{name}: unknown {cls.__name__} key; valid keys: "
                             f"{sorted(fields)}{did_you_mean(name, fields)}")
        default = fields[name].default
        kind = type(default)
        ok = (isinstance(value, bool) if kind is bool else
              isinstance(value, int | float) and not isinstance(value, bool) if kind is float
              else isinstance(value, kind) and not isinstance(value, bool))
        if not ok:
            raise ValueError(f"{prefix}{key}.{name}: needs {a_type(kind)}, got {value!r}")


def load_run(path: str | Path, name: str | None = None) -> TrainConfig:
    """A run file (``--config FILE.toml``): TrainConfig fields as TOML keys, learners as
    ``[[learners]]`` tables with a ``[learners.config]`` sub-table. Without a ``name``
    key the run is named ``name`` (``--name``), else after the file."""
    p = Path(path)
    if not (p.is_file() or p.is_fifo()):  # a pipe: --config <(alphatank train --print-config)
        raise ValueError(f"{p}: " + ("a folder, not a run file" if p.is_dir() else
                                     "not a file, nor a pipe" if p.exists() else
                                     "no such run file"))
    return _parse_text(read_text(p), str(p), p.parent, name or p.stem)


def _parse_text(text: str, source: str, base: Path | None, name: str) -> TrainConfig:
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{source}: invalid TOML: {exc}") from None
    return parse_run(data, source, base, name)


def run_toml(cfg: TrainConfig) -> str:
    """TOML text of ``cfg`` that :func:`load_run` reads back to an equal TrainConfig
    (settings at their defaults are left out)."""
    defaults = {f.name: f.default for f in describe(TrainConfig)}
    out: dict[str, Any] = {}
    for f in dataclasses.fields(TrainConfig):
        value = getattr(cfg, f.name)
        required = f.default is REQUIRED and f.default_factory is REQUIRED
        if f.name != "learners" and (required or value != defaults[f.name]):
            out[f.name] = value
    learners = []
    for spec in cfg.learners:
        base = type(spec.config)()
        changed = {f.name: getattr(spec.config, f.name)
                   for f in dataclasses.fields(spec.config)
                   if getattr(spec.config, f.name) != getattr(base, f.name)}
        entry: dict[str, Any] = {"name": spec.name, "algo": spec.algo, "seats": list(spec.seats)}
        if changed:
            entry["config"] = {k: "none" if v is None else v for k, v in changed.items()}
        learners.append(entry)
    if learners:
        out["learners"] = learners
    return dumps(out)


# ---- presets (alphatank/data/presets/<name>.toml) -----------------------------------------

def _preset_dir() -> Any:
    return resources.files("alphatank").joinpath("data", "presets")


def preset_names() -> list[str]:
    """Names of the shipped training presets."""
    return sorted(p.name[:-5] for p in _preset_dir().iterdir() if p.name.endswith(".toml"))


def get_preset(name: str) -> TrainConfig:
    """A shipped preset by name."""
    res = _preset_dir().joinpath(f"{name}.toml")
    if not res.is_file():
        raise ValueError(f"unknown training preset {name!r}; valid: {preset_names()}"
                         f"{did_you_mean(name, preset_names())}")
    return _parse_text(res.read_text(encoding="utf-8"), f"presets/{name}.toml", None, name)


def hyperparameter_help() -> str:
    """Every hyperparameter of every registered algorithm: default, type, range, help."""
    lines = []
    width = max(len(f"{n}.{f.name}") for n, a in ALGORITHMS.items() for f in describe(a.config))
    for name, algo in sorted(ALGORITHMS.items()):
        lines.append(f"{name}: {algo.description} ({algo.config.__name__})")
        for f in describe(algo.config):
            kind = f"{f.type} {f.allowed}".strip()
            lines.append(f"  {name + '.' + f.name:{width}s} {_show(f.default):>9s}  "
                         f"{kind:22s} {f.help}")
    return "\n".join(lines)


def _show(value: Any) -> str:
    if value is None:
        return "none"
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)

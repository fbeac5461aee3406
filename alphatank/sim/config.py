"""Game and reward configuration dataclasses (defaults: the paper's Table 5).

Speeds are given per second and converted to per-tick values with ``tick_hz``.
Every field is checked once, when a config is built (:func:`check_fields`, run by
``__post_init__``): its type from the annotation (``bool`` must be true or false, ``int``
an integer and not a bool, ``float`` a finite number; ints are accepted for floats) and,
where declared next to the field with :func:`bounded`, its range. A field added later is
covered by its type automatically. Unknown keys are errors that list the valid ones (see
:func:`from_dict`); errors name the field (``[game].friendly_fire: must be true or false,
got 'no'``), and the callers that read files prefix the file.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
import types
import typing
import unicodedata
from dataclasses import dataclass, field, fields
from typing import Any, TypeVar

from alphatank.errors import InputError

T = TypeVar("T")


class ConfigError(InputError, ValueError):
    """A configuration value or key is not allowed. ``key`` is the offending field (None for
    errors about the whole config) and ``reason`` the message without a location."""

    def __init__(self, message: str, key: str | None = None, reason: str | None = None):
        super().__init__(message)
        self.key, self.reason = key, reason if reason is not None else message


def bounded(default: Any, lo: float | None = None, hi: float | None = None) -> Any:
    """A dataclass field with an allowed closed range ``[lo, hi]`` (None: unbounded)."""
    return field(default=default, metadata={"range": (lo, hi)})


def _fmt(v: Any) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v)


def _kinds(tp: Any) -> tuple[type, ...]:
    """The classes an annotation admits (``X | None`` -> (X, NoneType))."""
    if isinstance(tp, types.UnionType) or typing.get_origin(tp) is typing.Union:
        return tuple(k for arg in typing.get_args(tp) for k in _kinds(arg))
    return (tp,) if isinstance(tp, type) else ()


TEAM_NAME_MAX = 32  # characters of a team name (drawn in banners and panels)


def name_problem(value: Any, max_len: int = TEAM_NAME_MAX) -> str | None:
    """Why ``value`` cannot be a name shown on screen (a team, a seat's label), else None:
    a non-empty string of at most ``max_len`` printable characters."""
    if not isinstance(value, str) or not value:
        return f"must be a non-empty string, got {value!r}"
    if len(value) > max_len:
        return f"must be at most {max_len} characters, got {len(value):,}"
    return printable_problem(value)


_NOT_PRINTABLE = {"Cc": "a control character", "Zs": "a space other than ' '",
                  "Zl": "a line break", "Zp": "a line break"}


def printable_problem(value: str) -> str | None:
    """Why the string ``value`` cannot be one line of text (a name, a description): its
    first character that ``str.isprintable`` refuses (a control character such as a newline,
    a tab or a NUL, a space other than ' ', a line break, a format character), else None."""
    bad = next((c for c in value if not c.isprintable()), None)
    if bad is None:
        return None
    char = f"U+{ord(bad):04X} {unicodedata.name(bad, '')}".rstrip()
    what = _NOT_PRINTABLE.get(unicodedata.category(bad), "not printable")
    return f"must be printable, got {value!r}: {char} is {what}"


def check_value(kinds: tuple[type, ...], value: Any, rng: tuple[Any, Any] | None = None
                ) -> tuple[Any, str | None]:
    """(normalised value, None) if ``value`` fits the types ``kinds`` and the range
    ``rng``, else (value, reason)."""
    if value is None and type(None) in kinds:
        return value, None
    kind = next((k for k in kinds if k is not type(None)), None)
    if kind is bool:
        if isinstance(value, bool):
            return value, None
        return value, f"must be true or false, got {value!r}"
    if kind is int:
        if isinstance(value, bool) or not isinstance(value, numbers.Integral):
            return value, f"must be an integer, got {value!r}"
        value = int(value)
    elif kind is float:
        if isinstance(value, bool) or not isinstance(value, numbers.Real):
            return value, f"must be a number, got {value!r}"
        value = float(value)
        if not math.isfinite(value):
            return value, f"must be a finite number, got {value!r}"
    elif kind is str:
        if not isinstance(value, str):
            return value, f"must be a string, got {value!r}"
    elif kind is not None and not isinstance(value, kind):
        return value, f"must be a {kind.__name__}, got {value!r}"
    if rng is not None:
        lo, hi = rng
        if (lo is not None and value < lo) or (hi is not None and value > hi):
            lo_s = "-inf" if lo is None else _fmt(lo)
            hi_s = "inf" if hi is None else _fmt(hi)
            return value, f"must be in [{lo_s}, {hi_s}], got {value!r}"
    return value, None



def check_seed(seed: Any) -> int:
    """``seed`` as a Python int: an integer >= 0 (numpy's too), what SeedSequence takes."""
    value, why = check_value((int,), seed, (0, None))
    if why:
        raise ValueError(f"seed {why}")
    return value

_HINTS: dict[type, dict[str, Any]] = {}


def _hints(cls: type) -> dict[str, Any]:
    hints = _HINTS.get(cls)
    if hints is None:
        hints = _HINTS[cls] = typing.get_type_hints(cls)
    return hints


def _checked(cls: type, f: dataclasses.Field, value: Any) -> Any:
    value, reason = check_value(_kinds(_hints(cls)[f.name]), value, f.metadata.get("range"))
    if reason is not None:
        raise ConfigError(f"{cls.__name__}.{f.name}: {reason}", f.name, reason)
    return value


def check_field(cls: type, name: str, value: Any) -> Any:
    """``value`` normalised for field ``name`` of the config dataclass ``cls``, checked
    on its own (its type and declared range; rules across fields are checked when the
    config is built); ConfigError names the field."""
    return _checked(cls, next(f for f in fields(cls) if f.name == name), value)


def check_fields(obj: Any) -> None:
    """Check (and normalise: int -> float for float fields) every field of the frozen
    dataclass ``obj`` against its annotation and declared range; ConfigError names the
    first bad field."""
    for f in fields(obj):
        object.__setattr__(obj, f.name, _checked(type(obj), f, getattr(obj, f.name)))


# Most ticks an agent may hold one action for (action_repeat): one second at 30 Hz.
ACTION_REPEAT_MAX = 30
# Most matches one set steps together (num_envs): each holds a physics space, its bots'
# tables and its observation rows, about 0.5 MB, so 4,096 is about 2 GB.
MATCHES_MAX = 4096
MAX_STEPS_MAX = 10_000_000  # ticks an episode may be limited to (GameConfig.max_steps)


@dataclass(frozen=True)
class GameConfig:
    """Rules and physics settings of a match. Ranges (inclusive) keep every setting
    physical and every tick's work bounded: e.g. bullet speed <= 10,000 px/s keeps the
    physics substeps per tick in the tens on the smallest allowed cells."""

    tick_hz: int = bounded(30, 1, 240)
    tank_width: float = bounded(30.0, 1.0, 500.0)
    tank_height: float = bounded(24.0, 1.0, 500.0)
    tank_speed: float = bounded(120.0, 1.0, 2000.0)  # px/s
    rotation_speed: float = bounded(90.0, 1.0, 3600.0)  # deg/s (3 deg per tick at 30 Hz)
    bullet_speed: float = bounded(300.0, 1.0, 10000.0)  # px/s; 2.5x the tank speed
    bullet_radius: float = bounded(3.0, 0.5, 50.0)
    bullet_max_bounces: int = bounded(6, 0, 1000)
    bullet_max_distance: float = bounded(300.0, 1.0, 1e7)  # px
    max_bullets: int = bounded(6, 0, 64)
    bullet_cooldown_ms: float = bounded(300.0, 0.0, 60000.0)
    buff_cooldown_factor: float = bounded(0.5, 0.0, 10.0)  # cooldown multiplier in a buff zone
    buff_max_bullets: int = bounded(10, 0, 64)
    debuff_max_bullets: int = bounded(1, 0, 64)
    random_buff_zones: int = bounded(2, 0, 64)
    random_debuff_zones: int = bounded(2, 0, 64)
    friendly_fire: bool = True
    self_hit: bool = False
    self_hit_grace_ms: float = bounded(150.0, 0.0, 60000.0)
    immortal: bool = False  # the paper's TERMINATE_TIME training mode: hits score, nobody dies
    # every tank starts on a random free cell, the map's spawn slots unused (the paper's team env)
    random_spawns: bool = False
    max_steps: int = bounded(1200, 1, MAX_STEPS_MAX)

    def __post_init__(self) -> None:
        check_fields(self)
        if self.bullet_speed <= self.tank_speed:
            reason = (f"({_fmt(self.bullet_speed)}) must exceed tank_speed "
                      f"({_fmt(self.tank_speed)}): bullets are faster than tanks in every preset")
            raise ConfigError(f"GameConfig.bullet_speed {reason}", "bullet_speed", reason)

    @property
    def dt(self) -> float:
        """Seconds per tick."""
        return 1.0 / self.tick_hz

    @property
    def cooldown_ticks(self) -> int:
        return max(1, math.ceil(self.bullet_cooldown_ms / 1000.0 * self.tick_hz))

    @property
    def buff_cooldown_ticks(self) -> int:
        return max(1, math.ceil(self.cooldown_ticks * self.buff_cooldown_factor))

    @property
    def grace_ticks(self) -> int:
        return math.ceil(self.self_hit_grace_ms / 1000.0 * self.tick_hz)

    @property
    def bullet_capacity(self) -> int:
        """Most bullets one tank can ever have alive."""
        return max(self.max_bullets, self.buff_max_bullets, self.debuff_max_bullets)


@dataclass(frozen=True)
class RewardConfig:
    """Weights of every reward term; 0 switches a term off (Table 5 defaults). Weights
    may be any finite number; counts and distances have ranges."""

    victory: float = 200.0
    hit: float = 50.0  # to the shooter
    hit_penalty: float = -50.0  # to the victim
    team_hit_penalty: float = -5.0  # to a shooter who hits a teammate
    trajectory_hit: float = 40.0
    trajectory_distance: float = 10.0
    # D_thresh: a fired shot whose predicted path passes within this is rewarded
    trajectory_close_px: float = bounded(70.0, 1.0, 100000.0)
    bullet_close: float = 0.01
    bullet_away: float = -0.02
    wall_hit: float = 0.0  # escalating: weight, then wall_hit_high_factor x weight
    wall_hit_low_ticks: int = bounded(10, 0, 10_000_000)
    wall_hit_high_factor: float = bounded(5.0, 0.0, 1000.0)
    stationary: float = 0.0
    stationary_ticks: int = bounded(20, 1, 10_000_000)
    bfs_progress: float = 0.0  # per cell of BFS path distance gained to the nearest enemy
    aim_streak: float = 0.0
    aim_streak_ticks: int = bounded(5, 1, 10_000_000)
    control_change: float = 0.0
    control_change_ticks: int = bounded(5, 1, 10_000_000)
    rotation: float = 0.0
    rotation_limit_deg: float = bounded(360.0, 1.0, 1e9)
    rotation_reset_px: float = bounded(35.0, 0.0, 100000.0)
    # Not in the paper's Table 5 (issue 12); 0 keeps every paper result unchanged.
    team_win: float = 0.0  # to every seat of the winning team, dead or alive
    # share of team_win lost by max_steps (linear in time); its range [0, 1] and the rule
    # team_draw <= team_loss are checked with the reward terms (game.rewards.check_team_outcome)
    team_win_time_decay: float = 0.0
    team_loss: float = 0.0  # to every seat of a losing team (configure <= 0)
    team_draw: float = 0.0  # to every seat on a draw; must not exceed team_loss
    step_cost: float = 0.0  # per tick to every seat while the match runs (configure <= 0)
    engagement: float = 0.0  # potential-based: weight x (1 - BFS cells to nearest enemy / diameter)
    # the learner's discount (shaping gamma*phi(s') - phi(s))
    engagement_gamma: float = bounded(0.99, 0.0, 1.0)
    distance_progress: float = 0.0  # per px of Euclidean distance gained (paper eq. 14, 2nd half)
    trajectory_far: float = 0.0  # eq. 15 far penalty: weight x min(1, (d - far) / far)
    # D_far: beyond this a fired shot is penalised
    trajectory_far_px: float = bounded(140.0, 1.0, 100000.0)

    def __post_init__(self) -> None:
        check_fields(self)


PRESETS: dict[str, dict[str, Any]] = {
    "paper": {},
    # The paper's Table 2 setting for dodge/defensive training: 4x bullet speed, 800 px range.
    "long_range": {"bullet_speed": 1200.0, "bullet_max_distance": 800.0},
}


def hit_radius(game: GameConfig) -> float:
    """Closest approach at which a predicted path surely hits a tank."""
    return game.bullet_radius + 0.5 * min(game.tank_width, game.tank_height)


def from_dict(cls: type[T], data: dict[str, Any], where: str = "") -> T:
    """Build a config dataclass from a mapping, rejecting unknown keys by name. Errors
    read ``<where>.<field>: <reason>`` (``where`` defaults to the class name)."""
    if not isinstance(data, dict):
        raise ConfigError(f"{where or cls.__name__}: must be a table of settings, got "
                          f"{type(data).__name__}")
    valid = {f.name for f in fields(cls)}  # type: ignore[arg-type]
    unknown = sorted(set(data) - valid, key=str)
    if unknown:
        loc = f"{where}: " if where else ""
        raise ConfigError(
            f"{loc}unknown {cls.__name__} key(s) {unknown}; valid keys: {sorted(valid)}")
    try:
        return cls(**data)
    except ConfigError as exc:
        if not where or exc.key is None:
            raise
        raise ConfigError(f"{where}.{exc.key}: {exc.reason}", exc.key, exc.reason) from None


def game_config(preset: str = "paper", where: str = "", **overrides: Any) -> GameConfig:
    """GameConfig from a named preset plus overrides (errors prefixed with ``where``)."""
    if preset not in PRESETS:
        raise ConfigError(f"unknown preset {preset!r}; valid presets: {sorted(PRESETS)}")
    return from_dict(GameConfig, {**PRESETS[preset], **overrides}, where=where)


def replace(cfg: T, **changes: Any) -> T:
    """dataclasses.replace that names unknown fields clearly."""
    return from_dict(type(cfg), {**dataclasses.asdict(cfg), **changes})  # type: ignore[arg-type]

"""Game and reward configuration dataclasses (defaults: the paper's Table 5).

Speeds are given per second and converted to per-tick values with ``tick_hz``.
Unknown keys are errors that list the valid ones (see :func:`from_dict`).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, fields
from typing import Any, TypeVar

T = TypeVar("T")


class ConfigError(ValueError):
    """A configuration value or key is not allowed."""


@dataclass(frozen=True)
class GameConfig:
    """Rules and physics settings of a match."""

    tick_hz: int = 30
    tank_width: float = 30.0
    tank_height: float = 24.0
    tank_speed: float = 120.0  # px/s
    rotation_speed: float = 90.0  # deg/s (3 deg per tick at 30 Hz, Table 5)
    bullet_speed: float = 300.0  # px/s; 2.5x the tank speed
    bullet_radius: float = 3.0
    bullet_max_bounces: int = 6
    bullet_max_distance: float = 300.0  # px
    max_bullets: int = 6
    bullet_cooldown_ms: float = 300.0
    buff_cooldown_factor: float = 0.5  # cooldown multiplier inside a buff zone
    buff_max_bullets: int = 10
    debuff_max_bullets: int = 1
    random_buff_zones: int = 2
    random_debuff_zones: int = 2
    friendly_fire: bool = True
    self_hit: bool = False
    self_hit_grace_ms: float = 150.0
    immortal: bool = False  # the paper's TERMINATE_TIME training mode: hits score, nobody dies
    max_steps: int = 1200

    def __post_init__(self) -> None:
        positive = ("tick_hz", "tank_width", "tank_height", "tank_speed", "rotation_speed",
                    "bullet_speed", "bullet_radius", "bullet_max_distance", "max_steps")
        for name in positive:
            if not getattr(self, name) > 0:
                raise ConfigError(f"GameConfig.{name} must be > 0, got {getattr(self, name)!r}")
        for name in ("bullet_max_bounces", "max_bullets", "buff_max_bullets", "debuff_max_bullets",
                     "random_buff_zones", "random_debuff_zones"):
            if getattr(self, name) < 0:
                raise ConfigError(f"GameConfig.{name} must be >= 0, got {getattr(self, name)!r}")
        if self.bullet_speed <= self.tank_speed:
            raise ConfigError(
                f"GameConfig.bullet_speed ({self.bullet_speed}) must exceed tank_speed "
                f"({self.tank_speed}): bullets are faster than tanks in every preset")

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
    """Weights of every reward term; 0 switches a term off (Table 5 defaults)."""

    victory: float = 200.0
    hit: float = 50.0  # to the shooter
    hit_penalty: float = -50.0  # to the victim
    team_hit_penalty: float = -5.0  # to a shooter who hits a teammate
    trajectory_hit: float = 40.0
    trajectory_distance: float = 10.0
    trajectory_close_px: float = 70.0  # D_thresh: within this, a fired shot is rewarded
    bullet_close: float = 0.01
    bullet_away: float = -0.02
    wall_hit: float = 0.0  # escalating: weight, then wall_hit_high_factor x weight
    wall_hit_low_ticks: int = 10
    wall_hit_high_factor: float = 5.0
    stationary: float = 0.0
    stationary_ticks: int = 20
    bfs_progress: float = 0.0  # per cell of BFS path distance gained to the nearest enemy
    aim_streak: float = 0.0
    aim_streak_ticks: int = 5
    control_change: float = 0.0
    control_change_ticks: int = 5
    rotation: float = 0.0
    rotation_limit_deg: float = 360.0
    rotation_reset_px: float = 35.0
    # Not in the paper's Table 5 (issue 12); 0 keeps every paper result unchanged.
    team_win: float = 0.0  # to every seat of the winning team, dead or alive
    team_win_time_decay: float = 0.0  # share of team_win lost by max_steps (linear in time)
    team_loss: float = 0.0  # to every seat of a losing team (configure <= 0)
    team_draw: float = 0.0  # to every seat on a draw; must not exceed team_loss
    step_cost: float = 0.0  # per tick to every seat while the match runs (configure <= 0)
    engagement: float = 0.0  # potential-based: weight x (1 - BFS cells to nearest enemy / diameter)
    engagement_gamma: float = 0.99  # the learner's discount (shaping gamma*phi(s') - phi(s))
    distance_progress: float = 0.0  # per px of Euclidean distance gained (paper eq. 14, 2nd half)
    trajectory_far: float = 0.0  # eq. 15 far penalty: weight x min(1, (d - far) / far)
    trajectory_far_px: float = 140.0  # D_far: beyond this a fired shot is penalised


PRESETS: dict[str, dict[str, Any]] = {
    "paper": {},
    # The paper's Table 2 setting for dodge/defensive training: 4x bullet speed, 800 px range.
    "long_range": {"bullet_speed": 1200.0, "bullet_max_distance": 800.0},
}


def from_dict(cls: type[T], data: dict[str, Any], where: str = "") -> T:
    """Build a config dataclass from a mapping, rejecting unknown keys by name."""
    valid = {f.name for f in fields(cls)}  # type: ignore[arg-type]
    unknown = sorted(set(data) - valid)
    if unknown:
        loc = f"{where}: " if where else ""
        raise ConfigError(
            f"{loc}unknown {cls.__name__} key(s) {unknown}; valid keys: {sorted(valid)}")
    return cls(**data)


def game_config(preset: str = "paper", **overrides: Any) -> GameConfig:
    """GameConfig from a named preset plus overrides."""
    if preset not in PRESETS:
        raise ConfigError(f"unknown preset {preset!r}; valid presets: {sorted(PRESETS)}")
    return from_dict(GameConfig, {**PRESETS[preset], **overrides}, where=f"preset {preset!r}")


def replace(cfg: T, **changes: Any) -> T:
    """dataclasses.replace that names unknown fields clearly."""
    return from_dict(type(cfg), {**dataclasses.asdict(cfg), **changes})  # type: ignore[arg-type]

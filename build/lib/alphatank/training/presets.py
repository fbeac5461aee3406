"""Named training presets: every experiment of the paper's sections 4.1, 4.2, 4.4 and 4.5
(plus 4.3's cycle learning and a curriculum run), with Tables 7/8/9 as the defaults.

A preset is a :class:`TrainConfig`: the scenario, the learners (which learner seats each
one drives, its algorithm and hyperparameters), the opponent schedule and the run
settings. ``alphatank train --preset NAME`` starts one; flags override its run settings.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

from alphatank.training.hparams import PPOConfig, SACConfig

ALGOS = ("ppo", "sac")
WANDB_MODES = ("offline", "online", "disabled")

# Table 9: PPO's side of SAC vs PPO (SAC's side equals Table 8).
PPO_TABLE9 = PPOConfig(clip_coef=0.1, ent_coef=0.02, update_epochs=20)


@dataclass(frozen=True)
class LearnerSpec:
    """One independent learner: its name, algorithm, hyperparameters and the learner
    seats (indices into the scenario's learner seats, 0..L-1) it controls. Several seats
    share one network (parameter sharing); give each seat its own spec for independence."""

    name: str
    algo: str = "ppo"
    seats: tuple[int, ...] = (0,)
    ppo: PPOConfig = field(default_factory=PPOConfig)
    sac: SACConfig = field(default_factory=SACConfig)

    def __post_init__(self) -> None:
        if self.algo not in ALGOS:
            raise ValueError(f"learner {self.name!r}: algo must be one of {ALGOS}, "
                             f"got {self.algo!r}")
        if not self.seats:
            raise ValueError(f"learner {self.name!r} controls no seats")

    @property
    def config(self) -> PPOConfig | SACConfig:
        return self.ppo if self.algo == "ppo" else self.sac

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "algo": self.algo, "seats": list(self.seats),
                "config": dataclasses.asdict(self.config)}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> LearnerSpec:
        algo = data.get("algo", "ppo")
        cfg_cls = PPOConfig if algo == "ppo" else SACConfig
        cfg = _dataclass_from(cfg_cls, data.get("config", {}), f"learner {data.get('name')!r}")
        return cls(name=data["name"], algo=algo, seats=tuple(data.get("seats", (0,))),
                   **{algo: cfg})


@dataclass(frozen=True)
class TrainConfig:
    """A training run. ``learners`` empty means one PPO learner per learner seat.
    Cadences (``checkpoint_every``, ``eval_every``, ``video_every``) count iterations of
    ``rollout_steps`` vector steps (one PPO update); 0 switches them off."""

    name: str
    scenario: str
    description: str = ""
    learners: tuple[LearnerSpec, ...] = ()
    total_steps: int = 2_000_000  # env steps summed over all envs (one match tick each)
    num_envs: int = 16
    num_workers: int = 1
    seed: int = 0
    observation: str | None = None
    game: dict[str, Any] = field(default_factory=dict)
    rewards: dict[str, Any] = field(default_factory=dict)
    schedule: dict[str, Any] = field(default_factory=dict)
    rollout_steps: int = 0  # 0: the PPO learners' num_steps (512 for SAC-only runs)
    checkpoint_every: int = 10
    keep_checkpoints: int = 3
    eval_every: int = 0
    eval_games: int = 50
    video_every: int = 0
    wandb: str = "offline"
    project: str = "alphatank"
    tensorboard: bool = False
    torch_threads: int = 1
    time_limit_s: float = 0.0  # stop (and checkpoint) after this much wall time; 0: none

    def __post_init__(self) -> None:
        if self.wandb not in WANDB_MODES:
            raise ValueError(f"wandb mode must be one of {WANDB_MODES}, got {self.wandb!r}")
        for name in ("total_steps", "num_envs", "num_workers", "torch_threads"):
            if getattr(self, name) <= 0:
                raise ValueError(f"TrainConfig.{name} must be > 0, got {getattr(self, name)}")
        names = [spec.name for spec in self.learners]
        if len(set(names)) != len(names):
            raise ValueError(f"learner names must be unique, got {names}")

    def with_overrides(self, **changes: Any) -> TrainConfig:
        """A copy with run settings changed (None values are ignored)."""
        return dataclasses.replace(self, **{k: v for k, v in changes.items() if v is not None})

    def to_dict(self) -> dict[str, Any]:
        data = dataclasses.asdict(self)
        data["learners"] = [spec.to_dict() for spec in self.learners]
        return data

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> TrainConfig:
        data = dict(data)
        learners = tuple(LearnerSpec.from_dict(d) for d in data.pop("learners", []))
        return _dataclass_from(cls, {**data, "learners": learners}, "train config")


def default_learners(num_learners: int) -> tuple[LearnerSpec, ...]:
    """One independent PPO learner (Table 7) per learner seat."""
    if num_learners == 1:
        return (LearnerSpec("ppo", "ppo", (0,)),)
    return tuple(LearnerSpec(f"ppo_{i}", "ppo", (i,)) for i in range(num_learners))


def parse_assignments(text: str, cls: type, where: str) -> dict[str, Any]:
    """``"update_epochs=4,num_steps=128"`` -> typed field values of dataclass ``cls``."""
    fields = {f.name: f for f in dataclasses.fields(cls)}
    out: dict[str, Any] = {}
    for item in filter(None, (part.strip() for part in text.split(","))):
        key, sep, raw = item.partition("=")
        key = key.strip()
        if not sep or key not in fields:
            raise ValueError(f"{where}: expected KEY=VALUE with KEY one of {sorted(fields)}, "
                             f"got {item!r}")
        kind = str(fields[key].type)
        raw = raw.strip()
        try:
            if "bool" in kind:
                if raw.lower() not in ("true", "false", "1", "0"):
                    raise ValueError(raw)
                out[key] = raw.lower() in ("true", "1")
            elif raw.lower() == "none" and "None" in kind:
                out[key] = None
            elif "int" in kind and "float" not in kind:
                out[key] = int(raw)
            else:
                out[key] = float(raw)
        except ValueError:
            raise ValueError(f"{where}: {key} needs a {kind} value, got {raw!r}") from None
    return out


def with_algo_overrides(cfg: TrainConfig, num_learners: int, ppo: str = "", sac: str = ""
                        ) -> TrainConfig:
    """``cfg`` with hyperparameters changed for all its PPO / SAC learners."""
    p = parse_assignments(ppo, PPOConfig, "--ppo")
    s = parse_assignments(sac, SACConfig, "--sac")
    specs = cfg.learners or default_learners(num_learners)
    specs = tuple(dataclasses.replace(spec, ppo=dataclasses.replace(spec.ppo, **p),
                                      sac=dataclasses.replace(spec.sac, **s)) for spec in specs)
    return dataclasses.replace(cfg, learners=specs)


def _dataclass_from(cls: type, data: dict[str, Any], where: str) -> Any:
    valid = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - valid)
    if unknown:
        raise ValueError(f"{where}: unknown {cls.__name__} key(s) {unknown}; "
                         f"valid: {sorted(valid)}")
    return cls(**data)


def _ppo(name: str = "ppo", seats: tuple[int, ...] = (0,),
         cfg: PPOConfig | None = None) -> LearnerSpec:
    return LearnerSpec(name=name, algo="ppo", seats=seats, ppo=cfg or PPOConfig())


def _sac(name: str = "sac", seats: tuple[int, ...] = (0,),
         cfg: SACConfig | None = None) -> LearnerSpec:
    return LearnerSpec(name=name, algo="sac", seats=seats, sac=cfg or SACConfig())


# Faster PPO settings used by the demo and the time-to-skill run (Table 7 architecture,
# fewer update epochs so a 10-minute budget covers more env steps).
PPO_FAST = PPOConfig(num_steps=128, update_epochs=4, num_minibatches=4, anneal_lr=True)

BOT_POOL = ["random", "aggressive", "defensive", "dodge"]

PRESETS: dict[str, TrainConfig] = {p.name: p for p in (
    # 4.1 agent vs agent
    TrainConfig("ppo_vs_ppo", "pair", "4.1.1 PPO vs PPO (independent learners)",
                (_ppo("ppo_a", (0,)), _ppo("ppo_b", (1,)))),
    TrainConfig("sac_vs_sac", "pair", "4.1.2 SAC vs SAC (Table 8)",
                (_sac("sac_a", (0,)), _sac("sac_b", (1,))), total_steps=200_000),
    TrainConfig("sac_vs_ppo", "pair", "4.1.3 SAC vs PPO (Table 9)",
                (_sac("sac", (0,)), _ppo("ppo", (1,), PPO_TABLE9)), total_steps=200_000),
    # 4.2 agent vs bots
    TrainConfig("ppo_vs_smart", "vs_smart", "4.2.1 PPO vs smart bot", (_ppo(),)),
    TrainConfig("ppo_vs_aggressive", "vs_aggressive", "4.2.2 PPO vs aggressive bot",
                (_ppo(),)),
    TrainConfig("ppo_vs_dodge", "vs_dodge", "4.2.3 PPO vs dodge bot (long-range bullets)",
                (_ppo(),)),
    TrainConfig("ppo_vs_defensive", "vs_defensive",
                "4.2.4 PPO vs defensive bot (long-range bullets)", (_ppo(),)),
    TrainConfig("ppo_vs_random", "vs_random", "Table 4: PPO vs random bot", (_ppo(),)),
    TrainConfig("sac_vs_aggressive", "vs_aggressive", "SAC vs aggressive bot (Table 8)",
                (_sac(),), total_steps=200_000),
    # 4.3 cycle learning and the curriculum (3.4.5-3.4.6)
    TrainConfig("ppo_cycle", "vs_random", "4.3 cycle learning over four bots (adaptive)",
                (_ppo(),), schedule={"kind": "cycle", "pool": BOT_POOL, "mode": "adaptive",
                                     "interval": 100_000}),
    TrainConfig("ppo_curriculum_smart", "vs_smart",
                "3.4.6 curriculum: smart bot weakness 0.1 -> 0.8 (sigmoid)", (_ppo(),),
                schedule={"kind": "curriculum", "start": 0.1, "end": 0.8,
                          "shape": "sigmoid"}),
    # 4.4 team agents vs team bots
    TrainConfig("team_vs_2smart", "team_vs_bot", "4.4.1 2 PPO vs 2 smart bots",
                (_ppo("ppo_1", (0,)), _ppo("ppo_2", (1,)))),
    TrainConfig("team_vs_def", "team_vs_def_bot", "4.4.2 2 PPO vs 1 defensive bot",
                (_ppo("ppo_1", (0,)), _ppo("ppo_2", (1,)))),
    TrainConfig("team_vs_def_2smart", "team_vs_def_smart",
                "4.4.3 2 PPO vs 1 defensive + 2 smart bots",
                (_ppo("ppo_1", (0,)), _ppo("ppo_2", (1,)))),
    TrainConfig("team_vs_four_bots", "team_vs_four_bots",
                "4.4.4 2 PPO vs 1 defensive + 1 aggressive + 2 smart bots",
                (_ppo("ppo_1", (0,)), _ppo("ppo_2", (1,)))),
    # 4.5 team agents vs team agents
    TrainConfig("team_ppo_vs_ppo", "team", "4.5.1 2 PPO vs 2 PPO (four independent learners)",
                tuple(_ppo(f"ppo_{t}{k}", (i,)) for i, (t, k) in
                      enumerate((("a", 1), ("a", 2), ("b", 1), ("b", 2))))),
    # the make-demo job and the time-to-skill run
    TrainConfig("demo", "vs_aggressive", "make demo: PPO vs aggressive, short budget",
                (_ppo(cfg=PPO_FAST),), total_steps=2_000_000, num_envs=16, num_workers=2,
                checkpoint_every=50, time_limit_s=480.0),
)}


def get_preset(name: str) -> TrainConfig:
    try:
        return PRESETS[name]
    except KeyError:
        raise ValueError(f"unknown training preset {name!r}; valid: {sorted(PRESETS)}") from None

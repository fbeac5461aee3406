"""Hyperparameter dataclasses of the learners (no torch import: presets and the CLI
can list and validate them cheaply)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class PPOConfig:
    """PPO hyperparameters. Defaults: the paper's Table 7; the rest CleanRL's defaults."""

    learning_rate: float = 3e-4
    gamma: float = 0.99
    gae_lambda: float = 0.95
    clip_coef: float = 0.2
    ent_coef: float = 0.01
    vf_coef: float = 0.3
    max_grad_norm: float = 0.3
    num_steps: int = 512  # rollout length per stream
    update_epochs: int = 60
    # not in Table 7: CleanRL defaults
    num_minibatches: int = 4
    norm_adv: bool = True
    clip_vloss: bool = True
    anneal_lr: bool = False
    target_kl: float | None = None
    hidden: int = 128
    norm_obs: bool = True
    norm_reward: bool = True
    obs_clip: float = 10.0
    reward_clip: float = 10.0
    adam_eps: float = 1e-5

    def __post_init__(self) -> None:
        for name in ("learning_rate", "num_steps", "update_epochs", "num_minibatches", "hidden"):
            if not getattr(self, name) > 0:
                raise ValueError(f"PPOConfig.{name} must be > 0, got {getattr(self, name)!r}")
        for name in ("gamma", "gae_lambda"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"PPOConfig.{name} must be in [0, 1], got {getattr(self, name)}")


@dataclass(frozen=True)
class SACConfig:
    """SAC hyperparameters; defaults are the paper's Tables 8 and 9."""

    policy_lr: float = 3e-4
    q_lr: float = 3e-4
    alpha_lr: float = 3e-4
    gamma: float = 0.99
    tau: float = 0.005
    batch_size: int = 256
    buffer_size: int = 1_000_000
    start_steps: int = 1000  # uniform random actions before this many transitions
    update_after: int = 1000
    update_every: int = 50  # transitions between update rounds
    utd_ratio: float = 1.0  # gradient steps per collected transition (update_every per round)
    hidden: int = 256
    autotune: bool = True
    alpha: float = 0.2  # initial (or fixed, without autotune) entropy coefficient
    target_entropy: float | None = None  # None: -action_dim
    norm_obs: bool = True
    obs_clip: float = 10.0
    reward_scale: float = 1.0

    def __post_init__(self) -> None:
        for name in ("policy_lr", "q_lr", "alpha_lr", "batch_size", "buffer_size",
                     "update_every", "utd_ratio", "hidden", "alpha", "reward_scale"):
            if not getattr(self, name) > 0:
                raise ValueError(f"SACConfig.{name} must be > 0, got {getattr(self, name)!r}")
        if not 0 < self.tau <= 1:
            raise ValueError(f"SACConfig.tau must be in (0, 1], got {self.tau}")

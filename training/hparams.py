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


@dataclass(frozen=True)
class MAPPOConfig:
    """MAPPO hyperparameters (issue 12). Defaults: MAPPO's published ones (Yu et al.
    2022: clip 0.2, 10 epochs, 2 minibatches, lr 5e-4, entropy 0.01, grad norm 10, Huber
    value loss with delta 10, value normalisation); network as PPO's (two 128-unit tanh
    layers) so 1v1 PPO checkpoints can warm-start its actor."""

    learning_rate: float = 5e-4  # actor
    critic_learning_rate: float = 5e-4
    gamma: float = 0.99
    gae_lambda: float = 0.95
    clip_coef: float = 0.2
    ent_coef: float = 0.01
    vf_coef: float = 1.0
    max_grad_norm: float = 10.0  # per network (actor, critic)
    num_steps: int = 128  # rollout length per stream
    update_epochs: int = 10
    num_minibatches: int = 2
    value_norm: bool = True  # running mean/std of returns; the critic predicts normalised
    huber_delta: float = 10.0  # Huber value loss on normalised errors; 0: squared error
    clip_vloss: bool = True
    norm_adv: bool = True  # over the live rows of the whole rollout
    anneal_lr: bool = False
    target_kl: float | None = None
    hidden: int = 128
    norm_obs: bool = True
    norm_state: bool = True
    norm_reward: bool = False  # value normalisation makes reward scaling unnecessary
    obs_clip: float = 10.0
    reward_clip: float = 10.0
    adam_eps: float = 1e-5
    bootstrap_timeouts: bool = False  # False: max_steps ends the game (time is in the state)
    critic_warmup_updates: int = 0  # first updates train only the critic (warm starts)

    def __post_init__(self) -> None:
        for name in ("learning_rate", "critic_learning_rate", "num_steps", "update_epochs",
                     "num_minibatches", "hidden"):
            if not getattr(self, name) > 0:
                raise ValueError(f"MAPPOConfig.{name} must be > 0, got {getattr(self, name)!r}")
        for name in ("gamma", "gae_lambda"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"MAPPOConfig.{name} must be in [0, 1], got "
                                 f"{getattr(self, name)}")
        if self.huber_delta < 0 or self.critic_warmup_updates < 0:
            raise ValueError(f"MAPPOConfig.huber_delta and critic_warmup_updates must be >= 0, "
                             f"got {self.huber_delta}, {self.critic_warmup_updates}")

"""The learner interface the runner drives, and a factory from a :class:`LearnerSpec`."""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np

from alphatank.training.ppo import PPO
from alphatank.training.presets import LearnerSpec
from alphatank.training.sac import SAC


class Learner(Protocol):
    """What PPO and SAC both provide (see :class:`alphatank.training.ppo.PPO`)."""

    algo: str
    obs_dim: int
    num_streams: int
    updates: int
    total_updates: int

    def act(self, obs: np.ndarray, masks: np.ndarray | None = None) -> np.ndarray: ...

    def observe(self, next_obs: np.ndarray, rewards: np.ndarray, terminated: np.ndarray,
                truncated: np.ndarray, final_obs: np.ndarray | None = None,
                active: np.ndarray | None = None) -> None: ...

    @property
    def ready(self) -> bool: ...

    def update(self, next_obs: np.ndarray) -> dict[str, float]: ...

    def policy_actions(self, obs: np.ndarray, deterministic: bool = False,
                       generator: Any = None) -> np.ndarray: ...

    def state_dict(self) -> dict[str, Any]: ...

    def load_state_dict(self, state: dict[str, Any], weights_only: bool = False) -> None: ...


def make_learner(spec: LearnerSpec, obs_dim: int, num_streams: int, seed: int,
                 mask_dim: int = 0) -> PPO | SAC:
    """A fresh PPO or SAC learner for ``num_streams`` (env, seat) streams."""
    if spec.algo == "ppo":
        return PPO(obs_dim, num_streams, spec.ppo, seed=seed, mask_dim=mask_dim)
    return SAC(obs_dim, num_streams, spec.sac, seed=seed)

"""Running mean / variance (parallel Welford) for observation and return normalisation.

The statistics are part of a trained model: they are saved in every checkpoint and
restored with it, and evaluation uses them frozen (``update=False``).
"""

from __future__ import annotations

import numpy as np
import torch


class RunningMeanStd:
    """Mean and variance of a stream of batches, merged with Chan et al.'s parallel rule."""

    def __init__(self, shape: tuple[int, ...] = (), epsilon: float = 1e-4):
        self.mean = np.zeros(shape, dtype=np.float64)
        self.var = np.ones(shape, dtype=np.float64)
        self.count = float(epsilon)

    def update(self, batch: np.ndarray) -> None:
        """Fold in a batch whose first axis indexes samples."""
        batch = np.asarray(batch, dtype=np.float64)
        if batch.shape[0] == 0:
            return
        b_mean = batch.mean(axis=0)
        b_var = batch.var(axis=0)
        b_count = batch.shape[0]
        delta = b_mean - self.mean
        total = self.count + b_count
        self.mean = self.mean + delta * (b_count / total)
        m2 = self.var * self.count + b_var * b_count + delta**2 * (self.count * b_count / total)
        self.var = m2 / total
        self.count = total

    def state_dict(self) -> dict[str, torch.Tensor]:
        return {"mean": torch.from_numpy(np.array(self.mean, dtype=np.float64)),
                "var": torch.from_numpy(np.array(self.var, dtype=np.float64)),
                "count": torch.tensor(self.count, dtype=torch.float64)}

    def load_state_dict(self, state: dict[str, torch.Tensor]) -> None:
        mean = state["mean"].numpy().astype(np.float64)
        if mean.shape != np.shape(self.mean):
            raise ValueError(f"normaliser shape mismatch: saved {tuple(mean.shape)}, "
                             f"expected {np.shape(self.mean)}")
        self.mean = mean.copy()
        self.var = state["var"].numpy().astype(np.float64).copy()
        self.count = float(state["count"])


class ObsNormalizer:
    """``clip((x - mean) / sqrt(var + eps), -clip, clip)`` with running statistics.

    ``enabled=False`` makes it the identity (still saved, so checkpoints stay uniform).
    """

    def __init__(self, obs_dim: int, enabled: bool = True, clip: float = 10.0,
                 epsilon: float = 1e-8):
        self.rms = RunningMeanStd((obs_dim,))
        self.enabled, self.clip, self.epsilon = enabled, float(clip), epsilon
        self._refresh()

    def _refresh(self) -> None:
        self._mean = self.rms.mean.astype(np.float32)
        self._inv_std = (1.0 / np.sqrt(self.rms.var + self.epsilon)).astype(np.float32)

    def stats(self) -> tuple[np.ndarray, np.ndarray]:
        """The float32 mean and 1 / std in use (fresh arrays after every update)."""
        return self._mean, self._inv_std

    def __call__(self, obs: np.ndarray, update: bool = False) -> np.ndarray:
        """Normalised float32 copy of ``obs`` (..., obs_dim); ``update`` folds it in first."""
        obs = np.asarray(obs, dtype=np.float32)
        if not self.enabled:
            return obs.copy()
        if update:
            self.update(obs)
        out = (obs - self._mean) * self._inv_std
        np.clip(out, -self.clip, self.clip, out=out)
        return out

    def update(self, obs: np.ndarray) -> None:
        """Fold ``obs`` (..., obs_dim) into the statistics (not when disabled)."""
        if not self.enabled:
            return
        self.rms.update(np.asarray(obs, dtype=np.float32).reshape(-1, self.rms.mean.shape[0]))
        self._refresh()

    def state_dict(self) -> dict[str, torch.Tensor]:
        return {**self.rms.state_dict(), "enabled": torch.tensor(self.enabled),
                "clip": torch.tensor(self.clip, dtype=torch.float64)}

    def load_state_dict(self, state: dict[str, torch.Tensor]) -> None:
        self.rms.load_state_dict(state)
        self.enabled = bool(state["enabled"])
        self.clip = float(state["clip"])
        self._refresh()


class ReturnNormalizer:
    """Scales rewards by the running std of the discounted return (as Gymnasium's
    ``NormalizeReward``), per stream, resetting the return at episode ends."""

    def __init__(self, num_streams: int, gamma: float, enabled: bool = True,
                 clip: float = 10.0, epsilon: float = 1e-8):
        self.rms = RunningMeanStd(())
        self.returns = np.zeros(num_streams, dtype=np.float64)
        self.gamma, self.enabled, self.clip, self.epsilon = gamma, enabled, clip, epsilon

    def __call__(self, rewards: np.ndarray, done: np.ndarray) -> np.ndarray:
        """Scaled float32 rewards (num_streams,); ``done`` marks the last step of an episode."""
        rewards = np.asarray(rewards, dtype=np.float64)
        if not self.enabled:
            return rewards.astype(np.float32)
        self.returns = self.returns * self.gamma + rewards
        self.rms.update(self.returns)
        self.returns[done] = 0.0
        scaled = rewards / np.sqrt(self.rms.var + self.epsilon)
        return np.clip(scaled, -self.clip, self.clip).astype(np.float32)

    def state_dict(self) -> dict[str, torch.Tensor]:
        return {**self.rms.state_dict(), "returns": torch.from_numpy(self.returns.copy())}

    def load_state_dict(self, state: dict[str, torch.Tensor]) -> None:
        self.rms.load_state_dict(state)
        returns = state["returns"].numpy().astype(np.float64)
        if returns.shape != self.returns.shape:
            raise ValueError(f"return normaliser has {returns.shape[0]} streams, "
                             f"this run has {self.returns.shape[0]} (num_envs x seats changed)")
        self.returns = returns.copy()

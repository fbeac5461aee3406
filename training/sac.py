"""Soft Actor-Critic on the discrete tank actions through the paper's equation (33).

The actor outputs a Gaussian squashed by a sigmoid into ``[0, 1]^d`` (Table 8); each
dimension is mapped to a discrete choice with ``min(max(floor(a (n-1) + 0.5), 0), n-1)``.
Twin critics Q(s, a) on the continuous action, Polyak-averaged targets, automatic entropy
tuning, and a cyclic replay buffer per learner. Defaults: Tables 8 and 9.
"""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np
import torch
import torch.nn.functional as F  # noqa: N812
from torch import nn

from alphatank.training.buffers import ReplayBuffer
from alphatank.training.hparams import SACConfig
from alphatank.training.normalize import ObsNormalizer
from alphatank.training.ppo import NVEC

LOG_STD_MIN, LOG_STD_MAX = -5.0, 2.0
LOG_2PI = math.log(2 * math.pi)


def continuous_to_discrete(action: np.ndarray, nvec: tuple[int, ...] | np.ndarray = NVEC
                           ) -> np.ndarray:
    """Equation (33): ``a_disc = min(max(floor(a * (n - 1) + 0.5), 0), n - 1)`` per dim.

    ``action`` (..., d) in [0, 1] (values outside are clipped by the formula); returns int64.
    """
    n = np.asarray(nvec, dtype=np.int64)
    action = np.asarray(action, dtype=np.float64)
    if action.shape[-1] != n.shape[0]:
        raise ValueError(f"continuous action has {action.shape[-1]} dims, expected {n.shape[0]}")
    return np.minimum(np.maximum(np.floor(action * (n - 1) + 0.5), 0), n - 1).astype(np.int64)


class ContinuousToDiscreteWrapper(gym.ActionWrapper):
    """Exposes a ``MultiDiscrete`` env as ``Box([0, 1]^d)`` using equation (33)."""

    def __init__(self, env: gym.Env):
        super().__init__(env)
        space = env.action_space
        if not isinstance(space, gym.spaces.MultiDiscrete):
            raise TypeError(f"ContinuousToDiscreteWrapper needs a MultiDiscrete action space, "
                            f"got {space}")
        self.nvec = tuple(int(n) for n in np.asarray(space.nvec).ravel())
        self.action_space = gym.spaces.Box(0.0, 1.0, shape=(len(self.nvec),), dtype=np.float32)

    def action(self, action: np.ndarray) -> np.ndarray:
        return continuous_to_discrete(action, self.nvec)


class QNetwork(nn.Module):
    """Table 8: Linear(obs+act, 256) ReLU, Linear(256, 256) ReLU, Linear(256, 1)."""

    def __init__(self, obs_dim: int, act_dim: int, hidden: int):
        super().__init__()
        self.net = nn.Sequential(nn.Linear(obs_dim + act_dim, hidden), nn.ReLU(),
                                 nn.Linear(hidden, hidden), nn.ReLU(), nn.Linear(hidden, 1))

    def forward(self, obs: torch.Tensor, act: torch.Tensor) -> torch.Tensor:
        return self.net(torch.cat([obs, act], dim=-1)).squeeze(-1)


class SquashedGaussianActor(nn.Module):
    """Table 8: two 256-unit ReLU layers, mean and log-std heads, sigmoid squash."""

    def __init__(self, obs_dim: int, act_dim: int, hidden: int):
        super().__init__()
        self.trunk = nn.Sequential(nn.Linear(obs_dim, hidden), nn.ReLU(),
                                   nn.Linear(hidden, hidden), nn.ReLU())
        self.mean = nn.Linear(hidden, act_dim)
        self.log_std = nn.Linear(hidden, act_dim)
        # Start at std 1 before the squash: sigmoid(N(0, 1)) reaches every bin of eq. (33)
        # (the usual init gives std ~0.2, i.e. actions in [0.4, 0.6]: rotate and move
        # would never leave their middle bin).
        nn.init.constant_(self.log_std.bias, math.atanh(-1 - 2 * LOG_STD_MIN /
                                                        (LOG_STD_MAX - LOG_STD_MIN)))

    def forward(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        h = self.trunk(obs)
        log_std = torch.tanh(self.log_std(h))
        log_std = LOG_STD_MIN + 0.5 * (LOG_STD_MAX - LOG_STD_MIN) * (log_std + 1)
        return self.mean(h), log_std

    def sample(self, obs: torch.Tensor, generator: torch.Generator
               ) -> tuple[torch.Tensor, torch.Tensor]:
        """Reparameterised action in (0, 1)^d and its log-density (B,)."""
        mean, log_std = self(obs)
        eps = torch.randn(mean.shape, generator=generator)
        u = mean + log_std.exp() * eps
        action = torch.sigmoid(u)
        # log N(u) - log|d sigmoid/du|, with d sigmoid/du = exp(-softplus(-u) - softplus(u))
        log_prob = (-0.5 * eps**2 - log_std - 0.5 * LOG_2PI
                    + F.softplus(-u) + F.softplus(u)).sum(-1)
        return action, log_prob


class SAC:
    """One SAC learner over ``num_streams`` = num_envs x its seats (implements
    :class:`alphatank.training.learners.Learner`)."""

    algo = "sac"
    inputs: tuple[str, ...] = ()
    rollout_steps = None  # updates on its own replay schedule, any rollout length

    def __init__(self, obs_dim: int, num_streams: int, cfg: SACConfig | None = None,
                 seed: int = 0, mask_dim: int = 0, num_seats: int = 1):
        del mask_dim  # SAC acts in the continuous space; masks do not apply
        del num_seats  # independent streams
        self.cfg = cfg = cfg or SACConfig()
        self.obs_dim, self.num_streams = obs_dim, num_streams
        self.nvec = NVEC
        act_dim = len(NVEC)
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(seed)
            self.actor = SquashedGaussianActor(obs_dim, act_dim, cfg.hidden)
            self.q1 = QNetwork(obs_dim, act_dim, cfg.hidden)
            self.q2 = QNetwork(obs_dim, act_dim, cfg.hidden)
            self.q1_target = QNetwork(obs_dim, act_dim, cfg.hidden)
            self.q2_target = QNetwork(obs_dim, act_dim, cfg.hidden)
        self.q1_target.load_state_dict(self.q1.state_dict())
        self.q2_target.load_state_dict(self.q2.state_dict())
        self.q_optimizer = torch.optim.Adam(list(self.q1.parameters()) +
                                            list(self.q2.parameters()), lr=cfg.q_lr)
        self.actor_optimizer = torch.optim.Adam(self.actor.parameters(), lr=cfg.policy_lr)
        self.target_entropy = (-float(act_dim) if cfg.target_entropy is None
                               else cfg.target_entropy)
        self.log_alpha = torch.tensor(math.log(cfg.alpha), requires_grad=cfg.autotune)
        self.alpha_optimizer = (torch.optim.Adam([self.log_alpha], lr=cfg.alpha_lr)
                                if cfg.autotune else None)
        self.generator = torch.Generator().manual_seed(seed)
        self.rng = np.random.default_rng(seed)
        self.obs_norm = ObsNormalizer(obs_dim, cfg.norm_obs, cfg.obs_clip)
        self.replay = ReplayBuffer(min(cfg.buffer_size, 10**9), obs_dim, act_dim)
        self.transitions = 0
        self.since_update = 0
        self.updates = 0  # update rounds
        self.grad_steps = 0
        self._obs = np.zeros((num_streams, obs_dim), dtype=np.float32)
        self._act = np.zeros((num_streams, act_dim), dtype=np.float32)

    @property
    def alpha(self) -> float:
        return float(self.log_alpha.detach().exp())

    # ---- run plumbing (the Learner protocol) --------------------------------------------

    def plan(self, total_steps: int) -> None:
        """SAC's schedule does not depend on the run length."""

    def new_segment(self) -> None:
        """Nothing per episode to forget (transitions are stored whole)."""

    def arrays(self) -> dict[str, np.ndarray]:
        """The replay buffer, saved beside the checkpoint for an exact resume."""
        return self.replay.arrays()

    def load_arrays(self, arrays: dict[str, np.ndarray]) -> None:
        self.replay.load_arrays(arrays)

    # ---- acting -----------------------------------------------------------------------

    @torch.no_grad()
    def act(self, obs: np.ndarray, masks: np.ndarray | None = None) -> np.ndarray:
        """Discrete actions (num_streams, 3); uniform random until ``start_steps``."""
        del masks
        self._obs[:] = obs
        if self.transitions < self.cfg.start_steps:
            self._act[:] = self.rng.random(self._act.shape, dtype=np.float32)
            self.obs_norm(obs, update=True)
        else:
            x = torch.from_numpy(self.obs_norm(obs, update=True))
            self._act[:] = self.actor.sample(x, self.generator)[0].numpy()
        return continuous_to_discrete(self._act, self.nvec)

    def observe(self, next_obs: np.ndarray, rewards: np.ndarray, terminated: np.ndarray,
                truncated: np.ndarray, final_obs: np.ndarray | None = None,
                active: np.ndarray | None = None) -> None:
        """Store the transitions of the last :meth:`act` (truncations keep bootstrapping)."""
        del active  # dead seats' transitions are kept: their value still includes team reward
        ended = np.logical_or(terminated, truncated)
        real_next = next_obs
        if ended.any():
            if final_obs is None:
                raise ValueError("ended streams need final_obs for their last transition")
            real_next = np.where(ended[:, None], final_obs, next_obs)
        scaled = np.asarray(rewards, np.float32) * self.cfg.reward_scale
        self.replay.add(self._obs, self._act, scaled, real_next,
                        np.asarray(terminated, np.float32))
        self.transitions += self.num_streams
        if self.transitions >= self.cfg.update_after:
            self.since_update += self.num_streams

    @property
    def ready(self) -> bool:
        return (self.transitions >= self.cfg.update_after
                and self.since_update >= self.cfg.update_every)

    # ---- learning ---------------------------------------------------------------------

    def update(self, next_obs: np.ndarray | None = None) -> dict[str, float]:
        """One update round: ``since_update * utd_ratio`` gradient steps."""
        del next_obs
        steps = max(1, int(self.since_update * self.cfg.utd_ratio))
        self.since_update = 0
        sums = {"qf_loss": 0.0, "actor_loss": 0.0, "alpha_loss": 0.0, "q_value": 0.0,
                "entropy": 0.0}
        for _ in range(steps):
            for key, val in self._gradient_step().items():
                sums[key] += val
        self.updates += 1
        out = {f"losses/{k}": v / steps for k, v in sums.items()}
        out["losses/alpha"] = self.alpha
        out["losses/grad_steps"] = float(self.grad_steps)
        return out

    def _gradient_step(self) -> dict[str, float]:
        cfg = self.cfg
        obs, act, rew, nxt, done = self.replay.sample(cfg.batch_size, self.rng)
        obs_t = torch.from_numpy(self.obs_norm(obs))
        nxt_t = torch.from_numpy(self.obs_norm(nxt))
        act_t, rew_t, done_t = (torch.from_numpy(a) for a in (act, rew, done))
        alpha = self.log_alpha.exp().detach()
        with torch.no_grad():
            next_act, next_logp = self.actor.sample(nxt_t, self.generator)
            q_next = torch.min(self.q1_target(nxt_t, next_act), self.q2_target(nxt_t, next_act))
            target = rew_t + cfg.gamma * (1.0 - done_t) * (q_next - alpha * next_logp)
        q1, q2 = self.q1(obs_t, act_t), self.q2(obs_t, act_t)
        qf_loss = F.mse_loss(q1, target) + F.mse_loss(q2, target)
        self.q_optimizer.zero_grad(set_to_none=True)
        qf_loss.backward()
        self.q_optimizer.step()

        pi, logp = self.actor.sample(obs_t, self.generator)
        q_pi = torch.min(self.q1(obs_t, pi), self.q2(obs_t, pi))
        actor_loss = (alpha * logp - q_pi).mean()
        self.actor_optimizer.zero_grad(set_to_none=True)
        actor_loss.backward()
        self.actor_optimizer.step()

        alpha_loss = torch.zeros(())
        if self.alpha_optimizer is not None:
            alpha_loss = -(self.log_alpha.exp() * (logp.detach() + self.target_entropy)).mean()
            self.alpha_optimizer.zero_grad(set_to_none=True)
            alpha_loss.backward()
            self.alpha_optimizer.step()

        with torch.no_grad():
            for net, tgt in ((self.q1, self.q1_target), (self.q2, self.q2_target)):
                for p, tp in zip(net.parameters(), tgt.parameters(), strict=True):
                    tp.mul_(1.0 - cfg.tau).add_(p, alpha=cfg.tau)
        self.grad_steps += 1
        return {"qf_loss": float(qf_loss.detach()) / 2, "actor_loss": float(actor_loss.detach()),
                "alpha_loss": float(alpha_loss.detach()), "q_value": float(q1.detach().mean()),
                "entropy": float(-logp.detach().mean())}

    # ---- inference and persistence ------------------------------------------------------

    @torch.no_grad()
    def policy_actions(self, obs: np.ndarray, deterministic: bool = False,
                       rng: np.random.Generator | None = None) -> np.ndarray:
        """Discrete actions for raw observations (B, obs_dim), frozen statistics;
        ``deterministic`` uses the mean action, else noise from ``rng``."""
        x = torch.from_numpy(self.obs_norm(np.atleast_2d(obs)))
        mean, log_std = self.actor(x)
        if deterministic:
            u = mean
        else:
            eps = (rng or self.rng).standard_normal(mean.shape, dtype=np.float32)
            u = mean + log_std.exp() * torch.from_numpy(eps)
        return continuous_to_discrete(torch.sigmoid(u).numpy(), self.nvec)

    def state_dict(self) -> dict[str, Any]:
        state = {"actor": self.actor.state_dict(), "q1": self.q1.state_dict(),
                 "q2": self.q2.state_dict(), "q1_target": self.q1_target.state_dict(),
                 "q2_target": self.q2_target.state_dict(),
                 "q_optimizer": self.q_optimizer.state_dict(),
                 "actor_optimizer": self.actor_optimizer.state_dict(),
                 "log_alpha": self.log_alpha.detach().clone(),
                 "obs_norm": self.obs_norm.state_dict(), "generator": self.generator.get_state(),
                 "np_rng": self.rng.bit_generator.state,
                 "counters": torch.tensor([self.transitions, self.since_update, self.updates,
                                           self.grad_steps])}
        if self.alpha_optimizer is not None:
            state["alpha_optimizer"] = self.alpha_optimizer.state_dict()
        return state

    def load_state_dict(self, state: dict[str, Any], weights_only: bool = False) -> None:
        self.actor.load_state_dict(state["actor"])
        self.obs_norm.load_state_dict(state["obs_norm"])
        if weights_only:
            return
        for key in ("q1", "q2", "q1_target", "q2_target", "q_optimizer", "actor_optimizer"):
            getattr(self, key).load_state_dict(state[key])
        with torch.no_grad():
            self.log_alpha.copy_(state["log_alpha"])
        if self.alpha_optimizer is not None:
            self.alpha_optimizer.load_state_dict(state["alpha_optimizer"])
        self.generator.set_state(state["generator"])
        self.rng.bit_generator.state = state["np_rng"]
        self.transitions, self.since_update, self.updates, self.grad_steps = (
            int(v) for v in state["counters"])

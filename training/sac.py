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

from alphatank.training.buffers import ReplayBuffer, check_memory
from alphatank.training.hparams import SACConfig
from alphatank.training.normalize import ObsNormalizer
from alphatank.training.ppo import NVEC

LOG_STD_MIN, LOG_STD_MAX = -5.0, 2.0
LOG_2PI = math.log(2 * math.pi)
STAT_NAMES = ("qf_loss", "actor_loss", "alpha_loss", "q_value", "entropy")


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


class TwinQNetwork(nn.Module):
    """Table 8's twin critics, each Linear(obs+act, 256) ReLU, Linear(256, 256) ReLU,
    Linear(256, 1), stacked on a leading axis of 2 so that both run as one batched
    matrix product per layer (half the torch calls of two networks). Each layer starts as
    ``nn.Linear`` does: weights and biases uniform in +-1/sqrt(fan_in)."""

    LAYERS = ("1", "2", "3")

    def __init__(self, obs_dim: int, act_dim: int, hidden: int):
        super().__init__()
        sizes = ((obs_dim + act_dim, hidden), (hidden, hidden), (hidden, 1))
        for name, (fan_in, out) in zip(self.LAYERS, sizes, strict=True):
            bound = 1.0 / math.sqrt(fan_in)
            self.register_parameter(f"w{name}", nn.Parameter(
                torch.empty(2, fan_in, out).uniform_(-bound, bound)))
            self.register_parameter(f"b{name}", nn.Parameter(
                torch.empty(2, 1, out).uniform_(-bound, bound)))

    def forward(self, obs: torch.Tensor, act: torch.Tensor) -> torch.Tensor:
        """Q-values (2, B) of both critics."""
        x = torch.cat([obs, act], dim=-1).expand(2, -1, -1)
        x = torch.baddbmm(self.b1, x, self.w1).relu()
        x = torch.baddbmm(self.b2, x, self.w2).relu()
        return torch.baddbmm(self.b3, x, self.w3).squeeze(-1)

    @staticmethod
    def from_pair(q1: dict[str, torch.Tensor], q2: dict[str, torch.Tensor]
                  ) -> dict[str, torch.Tensor]:
        """The state of a twin from two ``nn.Sequential`` critics' states (checkpoints
        saved before the twin: ``net.0/2/4.weight`` (out, in) and ``.bias``)."""
        out = {}
        for name, index in zip(TwinQNetwork.LAYERS, ("0", "2", "4"), strict=True):
            out[f"w{name}"] = torch.stack([q[f"net.{index}.weight"].T for q in (q1, q2)])
            out[f"b{name}"] = torch.stack([q[f"net.{index}.bias"][None] for q in (q1, q2)])
        return out


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


class NumpyActor:
    """Float32 numpy copy of a :class:`SquashedGaussianActor` for acting: one pass of a few
    BLAS calls for every stream of a learner (the torch module costs more in per-call
    overhead than in arithmetic at these batch sizes). ``sync`` after updates."""

    def __init__(self, actor: SquashedGaussianActor):
        self.sync(actor)

    def sync(self, actor: SquashedGaussianActor) -> None:
        def wt(layer: nn.Linear) -> np.ndarray:
            return np.ascontiguousarray(layer.weight.detach().numpy().T, dtype=np.float32)

        self.w1, self.b1 = wt(actor.trunk[0]), actor.trunk[0].bias.detach().numpy().copy()
        self.w2, self.b2 = wt(actor.trunk[2]), actor.trunk[2].bias.detach().numpy().copy()
        self.act_dim = actor.mean.out_features
        self.wh = np.ascontiguousarray(np.concatenate([wt(actor.mean), wt(actor.log_std)], 1))
        self.bh = np.concatenate([actor.mean.bias.detach().numpy(),
                                  actor.log_std.bias.detach().numpy()])

    def forward(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Mean and log-std (B, act_dim) for normalised float32 observations."""
        h = np.maximum(x @ self.w1 + self.b1, 0.0)
        h = np.maximum(h @ self.w2 + self.b2, 0.0)
        out = h @ self.wh + self.bh
        log_std = np.tanh(out[:, self.act_dim:])
        log_std = LOG_STD_MIN + 0.5 * (LOG_STD_MAX - LOG_STD_MIN) * (log_std + 1)
        return out[:, :self.act_dim], log_std

    def sample(self, x: np.ndarray, rng: np.random.Generator,
               deterministic: bool = False) -> np.ndarray:
        """Actions in (0, 1)^d: sigmoid of the mean, or of a sample from ``rng``."""
        mean, log_std = self.forward(x)
        u = mean
        if not deterministic:
            u = mean + np.exp(log_std) * rng.standard_normal(mean.shape, dtype=np.float32)
        return (1.0 / (1.0 + np.exp(-u))).astype(np.float32)


class SAC:
    """One SAC learner over ``num_streams`` = num_envs x its seats (implements
    :class:`alphatank.training.learners.Learner`).

    Cost: one gradient step (Table 8: batch 256, 256-256 nets) is ~0.8 GFLOP, about 20 ms
    on one core of the development machine, so ``utd_ratio`` (gradient steps per
    collected transition) sets the speed of a run: env steps cost ~0.3 ms each, a run of
    N env steps at ratio r needs about N * r gradient steps. ``alphatank bench --sac``
    measures both on the machine at hand.
    """

    algo = "sac"
    inputs: tuple[str, ...] = ()
    inference_keys = ("actor", "obs_norm")
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
            self.q = TwinQNetwork(obs_dim, act_dim, cfg.hidden)
            self.q_target = TwinQNetwork(obs_dim, act_dim, cfg.hidden)
        self.q_target.load_state_dict(self.q.state_dict())
        self._q_params = list(self.q.parameters())
        self._target_params = list(self.q_target.parameters())
        self._actor_params = list(self.actor.parameters())
        # fused: one kernel per optimiser step instead of a dozen ops per parameter
        self.q_optimizer = torch.optim.Adam(self._q_params, lr=cfg.q_lr, fused=True)
        self.actor_optimizer = torch.optim.Adam(self._actor_params, lr=cfg.policy_lr,
                                                fused=True)
        self.target_entropy = (-float(act_dim) if cfg.target_entropy is None
                               else cfg.target_entropy)
        self.log_alpha = torch.tensor(math.log(cfg.alpha), requires_grad=cfg.autotune)
        self.alpha_optimizer = (torch.optim.Adam([self.log_alpha], lr=cfg.alpha_lr)
                                if cfg.autotune else None)
        self.generator = torch.Generator().manual_seed(seed)
        self.rng = np.random.default_rng(seed)
        self.obs_norm = ObsNormalizer(obs_dim, cfg.norm_obs, cfg.obs_clip)
        self._replay: ReplayBuffer | None = None  # made by plan() or when first needed
        self.mirror = NumpyActor(self.actor)
        self.transitions = 0
        self.since_update = 0
        self.owed = 0.0  # gradient steps due but not done (fractions, interrupted rounds)
        self.updates = 0  # update rounds
        self.grad_steps = 0
        self.interrupt: Any = None  # set by the runner: () -> bool, stop between steps
        self._obs = np.zeros((num_streams, obs_dim), dtype=np.float32)
        self._act = np.zeros((num_streams, act_dim), dtype=np.float32)

    @property
    def alpha(self) -> float:
        return float(self.log_alpha.detach().exp())

    # ---- run plumbing (the Learner protocol) --------------------------------------------

    def plan(self, total_steps: int) -> None:
        """SAC's schedule does not depend on the run length, but the run trains: the
        replay buffer is made now, inside the run's
        :func:`~alphatank.training.buffers.memory_budget`, so that one that does not fit
        is refused before training starts."""
        self._claim()

    @property
    def replay(self) -> ReplayBuffer:
        return self._claim()

    def _claim(self) -> ReplayBuffer:
        """The replay buffer, made when training first needs it (:meth:`plan`, collecting,
        a resume's :meth:`load_arrays`) after checking that it and a gradient step fit in
        memory: a learner loaded for inference needs neither, whatever its
        ``buffer_size``."""
        if self._replay is None:
            cfg, obs_dim = self.cfg, self.obs_dim
            replay = ReplayBuffer(cfg.buffer_size, obs_dim, len(self.nvec))
            # a gradient step's sampled observations and the networks' activations (about)
            check_memory(4 * cfg.batch_size * (2 * obs_dim + 16 * cfg.hidden),
                         f"a gradient step of batch_size = {cfg.batch_size:,} transitions x "
                         f"{obs_dim} inputs", "lower batch_size")
            self._replay = replay
        return self._replay

    def new_segment(self) -> None:
        """Nothing per episode to forget (transitions are stored whole)."""

    def anchor(self) -> None:
        """No anchor: SAC learns off-policy from its replay buffer."""

    def drop_rollout(self) -> None:
        """No rollout to drop: every observed transition is whole and kept."""

    def arrays(self) -> dict[str, np.ndarray]:
        """The replay buffer, saved beside the checkpoint for an exact resume."""
        return self.replay.arrays()

    def load_arrays(self, arrays: dict[str, np.ndarray]) -> None:
        self.replay.load_arrays(arrays)

    # ---- acting -----------------------------------------------------------------------

    def act(self, obs: np.ndarray, masks: np.ndarray | None = None) -> np.ndarray:
        """Discrete actions (num_streams, 3) for all streams in one pass of the numpy
        actor; uniform random until ``start_steps``."""
        del masks
        self._obs[:] = obs
        x = self.obs_norm(obs, update=True)
        if self.transitions < self.cfg.start_steps:
            self._act[:] = self.rng.random(self._act.shape, dtype=np.float32)
        else:
            self._act[:] = self.mirror.sample(x, self.rng)
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
        return self.transitions >= self.cfg.update_after and (
            self.since_update >= self.cfg.update_every or self.owed >= 1.0)

    # ---- learning ---------------------------------------------------------------------

    def update(self, next_obs: np.ndarray | None = None) -> dict[str, float]:
        """One update round: ``utd_ratio`` gradient steps per transition collected since
        the last round (fractions carry over). Between gradient steps it stops early when
        :attr:`interrupt` says so; the steps left are owed to the next round."""
        del next_obs
        self.owed += self.since_update * self.cfg.utd_ratio
        self.since_update = 0
        self._round_stats()
        sums, steps = torch.zeros(len(STAT_NAMES)), 0
        while self.owed >= 1.0 and not (self.interrupt is not None and self.interrupt()):
            sums += self._gradient_step(refresh=False)
            self.owed -= 1.0
            steps += 1
        self.updates += 1
        if steps:
            self.mirror.sync(self.actor)
        means = (sums / max(steps, 1)).tolist()
        out = {f"losses/{k}": v for k, v in zip(STAT_NAMES, means, strict=True)}
        out["losses/alpha"] = self.alpha
        out["losses/grad_steps"] = float(self.grad_steps)
        return out

    def _round_stats(self) -> None:
        """Torch views of the replay arrays and the normaliser's (frozen) statistics."""
        r = self.replay
        self._t = {k: torch.from_numpy(getattr(r, k)) for k in
                   ("obs", "next_obs", "actions", "rewards", "dones")}
        mean, inv_std = self.obs_norm.stats()
        self._norm = (torch.from_numpy(mean), torch.from_numpy(inv_std),
                      self.obs_norm.clip) if self.obs_norm.enabled else None

    def _batch(self) -> tuple[torch.Tensor, ...]:
        """A uniform sample (with replacement) of ``batch_size`` transitions, observations
        normalised: (obs, actions, rewards, next_obs, dones)."""
        idx = torch.from_numpy(self.rng.integers(0, len(self.replay), self.cfg.batch_size))
        t = self._t
        obs, nxt = t["obs"].index_select(0, idx), t["next_obs"].index_select(0, idx)
        if self._norm is not None:
            mean, inv_std, clip = self._norm
            for x in (obs, nxt):
                x.sub_(mean).mul_(inv_std).clamp_(-clip, clip)
        return (obs, t["actions"].index_select(0, idx), t["rewards"].index_select(0, idx),
                nxt, t["dones"].index_select(0, idx))

    def _gradient_step(self, refresh: bool = True) -> torch.Tensor:
        """One gradient step of critics, actor, entropy coefficient and targets; returns
        the step's statistics (:data:`STAT_NAMES`). ``refresh=False``: inside a round,
        whose :meth:`_round_stats` are current."""
        if refresh:
            self._round_stats()
        cfg = self.cfg
        obs, act, rew, nxt, done = self._batch()
        alpha = self.log_alpha.detach().exp()
        with torch.no_grad():
            next_act, next_logp = self.actor.sample(nxt, self.generator)
            q_next = self.q_target(nxt, next_act).amin(0)
            target = rew + cfg.gamma * (1.0 - done) * (q_next - alpha * next_logp)
        q = self.q(obs, act)
        qf_loss = 2.0 * F.mse_loss(q, target.expand(2, -1))  # the sum of the two critics'
        self.q_optimizer.zero_grad(set_to_none=True)
        qf_loss.backward()
        self.q_optimizer.step()

        pi, logp = self.actor.sample(obs, self.generator)
        q_pi = self.q(obs, pi).amin(0)
        actor_loss = (alpha * logp - q_pi).mean()
        # gradients for the actor only: the critics' weight gradients are not computed
        grads = torch.autograd.grad(actor_loss, self._actor_params)
        for param, grad in zip(self._actor_params, grads, strict=True):
            param.grad = grad
        self.actor_optimizer.step()

        logp = logp.detach()
        alpha_loss = torch.zeros(())
        if self.alpha_optimizer is not None:
            alpha_loss = -(self.log_alpha.exp() * (logp + self.target_entropy)).mean()
            self.alpha_optimizer.zero_grad(set_to_none=True)
            alpha_loss.backward()
            self.alpha_optimizer.step()

        with torch.no_grad():
            torch._foreach_lerp_(self._target_params, self._q_params, cfg.tau)
        self.grad_steps += 1
        return torch.stack([qf_loss.detach() / 2, actor_loss.detach(), alpha_loss.detach(),
                            q[0].detach().mean(), -logp.mean()])

    # ---- inference and persistence ------------------------------------------------------

    def policy_actions(self, obs: np.ndarray, deterministic: bool = False,
                       rng: np.random.Generator | None = None) -> np.ndarray:
        """Discrete actions for raw observations (B, obs_dim), frozen statistics;
        ``deterministic`` uses the mean action, else noise from ``rng``."""
        x = self.obs_norm(np.atleast_2d(obs))
        return continuous_to_discrete(self.mirror.sample(x, rng or self.rng, deterministic),
                                      self.nvec)

    def state_dict(self) -> dict[str, Any]:
        state = {"actor": self.actor.state_dict(), "q": self.q.state_dict(),
                 "q_target": self.q_target.state_dict(),
                 "q_optimizer": self.q_optimizer.state_dict(),
                 "actor_optimizer": self.actor_optimizer.state_dict(),
                 "log_alpha": self.log_alpha.detach().clone(),
                 "obs_norm": self.obs_norm.state_dict(), "generator": self.generator.get_state(),
                 "np_rng": self.rng.bit_generator.state,
                 "counters": torch.tensor([self.transitions, self.since_update, self.updates,
                                           self.grad_steps]),
                 "owed": torch.tensor(self.owed, dtype=torch.float64)}
        if self.alpha_optimizer is not None:
            state["alpha_optimizer"] = self.alpha_optimizer.state_dict()
        return state

    def load_state_dict(self, state: dict[str, Any], weights_only: bool = False) -> None:
        self.actor.load_state_dict(state["actor"])
        self.mirror.sync(self.actor)
        self.obs_norm.load_state_dict(state["obs_norm"])
        if weights_only:
            return
        if "q1" in state:  # saved with two critic networks: stack them into the twin
            state = {**state, "q": TwinQNetwork.from_pair(state["q1"], state["q2"]),
                     "q_target": TwinQNetwork.from_pair(state["q1_target"],
                                                        state["q2_target"]),
                     "q_optimizer": _twin_optimizer_state(state["q_optimizer"])}
        for key in ("q", "q_target", "q_optimizer", "actor_optimizer"):
            getattr(self, key).load_state_dict(state[key])
        with torch.no_grad():
            self.log_alpha.copy_(state["log_alpha"])
        if self.alpha_optimizer is not None:
            self.alpha_optimizer.load_state_dict(state["alpha_optimizer"])
        self.generator.set_state(state["generator"])
        self.rng.bit_generator.state = state["np_rng"]
        self.transitions, self.since_update, self.updates, self.grad_steps = (
            int(v) for v in state["counters"])
        self.owed = float(state.get("owed", 0.0))


def _twin_optimizer_state(old: dict[str, Any]) -> dict[str, Any]:
    """The critics' Adam state saved for two ``nn.Sequential`` critics (12 parameters:
    the first's 6 then the second's, weights (out, in)) as the twin's 6 parameters."""
    per = old["state"]
    state = {}
    for k in range(6) if per else ():  # empty before the first gradient step
        a, b = per[k], per[k + 6]
        state[k] = {"step": torch.tensor(float(a["step"]))}
        for key in ("exp_avg", "exp_avg_sq"):
            x, y = (a[key].T, b[key].T) if k % 2 == 0 else (a[key][None], b[key][None])
            state[k][key] = torch.stack([x, y])
    groups = [{**g, "params": list(range(6))} for g in old["param_groups"]]
    return {"state": state, "param_groups": groups}


"""Rollout storage with GAE for PPO, and the cyclic replay buffer for SAC.

Conventions (SAME_STEP autoreset vector envs): row ``t`` holds the observation an action
was chosen from, that action, and the reward / ``terminated`` / ``truncated`` flags the
env returned for it. When row ``t`` ended an episode the next row already belongs to the
new episode, so GAE never crosses it: a termination contributes no future value, a
truncation is bootstrapped with ``V(final_obs)`` stored in ``bootstrap[t]``.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from typing import Any

import numpy as np
import torch


def compute_gae(rewards: torch.Tensor, values: torch.Tensor, terminated: torch.Tensor,
                truncated: torch.Tensor, bootstrap: torch.Tensor, last_values: torch.Tensor,
                gamma: float, lam: float) -> tuple[torch.Tensor, torch.Tensor]:
    """Generalised advantage estimates and returns, shape (T, B) each.

    ``rewards``, ``values``, ``terminated``, ``truncated``, ``bootstrap``: (T, B);
    ``last_values``: (B,) = V of the observation after the last row. A row that is both
    terminated and truncated counts as terminated (no bootstrap).
    """
    every = torch.ones(rewards.shape, dtype=torch.bool)
    return compute_gae_masked(rewards, values, terminated, truncated, bootstrap, last_values,
                              every, gamma, lam)


def compute_gae_masked(rewards: torch.Tensor, values: torch.Tensor, terminated: torch.Tensor,
                       truncated: torch.Tensor, bootstrap: torch.Tensor,
                       last_values: torch.Tensor, active: torch.Tensor, gamma: float,
                       lam: float) -> tuple[torch.Tensor, torch.Tensor]:
    """GAE with death masking and posthumous credit (MAPPO), shapes as :func:`compute_gae`
    plus ``active`` (T, B): the stream's seat was alive when it acted on that row.

    An inactive row (a dead seat whose team plays on) is not an agent step: it gets no
    advantage. Its rewards (the team's outcome, a bullet still in flight, time costs) are
    credited to the seat's last active row as the discounted sum ``P`` of everything the
    seat receives until its episode ends (terminated: nothing after; truncated:
    ``bootstrap``; the rollout ends first: ``last_values``, which the learner fills with a
    living teammate's value). The last active row then ends its GAE chain:
    ``delta = r + gamma * P - V``. With every row active this equals :func:`compute_gae`.
    Returns (advantages, returns); inactive rows get advantage 0 and return ``P``.
    """
    # numpy: the float32 operations of a torch loop, in its order, at a fraction of the
    # per-step overhead (2.5 vs 16.6 ms for 128 x 64)
    r, v, alive = rewards.numpy(), values.numpy(), active.numpy()
    term = terminated.numpy().astype(np.float32)
    keep = np.float32(1.0) - np.minimum(term + truncated.numpy().astype(np.float32),
                                        np.float32(1.0))
    boot = bootstrap.numpy() * (np.float32(1.0) - term) * (np.float32(1.0) - keep)
    act = alive.astype(np.float32)
    advantages, returns = np.zeros_like(r), np.zeros_like(r)
    g, gl = np.float32(gamma), np.float32(gamma * lam)
    last_gae = np.zeros_like(r[0])
    post = last_values.numpy()  # P of the row after the current one (if inactive)
    following, nxt_active = post, np.ones_like(post)
    for t in range(r.shape[0] - 1, -1, -1):
        if t < r.shape[0] - 1:
            nxt_active = act[t + 1]
            following = v[t + 1] * nxt_active + post * (np.float32(1.0) - nxt_active)
        after = following * keep[t] + boot[t]
        delta = r[t] + g * after - v[t]
        gae = delta + gl * (keep[t] * nxt_active) * last_gae
        last_gae = gae * act[t]
        advantages[t] = last_gae
        post = r[t] + g * after  # P of this row, used if it is inactive
        returns[t] = np.where(alive[t], gae + v[t], post)
    return torch.from_numpy(advantages), torch.from_numpy(returns)


def available_memory() -> int | None:
    """Bytes of memory this machine can still give (Linux's MemAvailable), or None."""
    try:
        with open("/proc/meminfo", encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


_reserved: list[int] = []  # bytes promised to buffers checked in an open memory_budget()


@contextlib.contextmanager
def memory_budget() -> Iterator[None]:
    """Buffers checked inside (a run's learners) share the memory available: each check
    counts what the ones before it will take once filled."""
    _reserved.append(0)
    try:
        yield
    finally:
        _reserved.pop()


def check_memory(nbytes: int, what: str, fix: str) -> None:
    """ValueError (``what`` needs ..., then ``fix``) before allocating ``nbytes`` when the
    machine has less memory available (a buffer allocated lazily would fill it hours into
    the run), less what earlier buffers of the open :func:`memory_budget` take."""
    avail = available_memory()
    taken = _reserved[-1] if _reserved else 0
    if avail is not None and nbytes > avail - taken:
        besides = (f" besides the {taken / 2**30:,.1f} GiB of the learners' buffers before "
                   "it" if taken else "")
        raise ValueError(f"{what} needs {nbytes / 2**30:,.1f} GiB; this machine has "
                         f"{max(avail - taken, 0) / 2**30:,.1f} GiB available{besides}: {fix}")
    if _reserved:
        _reserved[-1] += nbytes


class RolloutBuffer:
    """Preallocated PPO rollout of ``num_steps`` rows for ``num_streams`` (env, seat) streams."""

    def __init__(self, num_steps: int, num_streams: int, obs_dim: int, mask_dim: int = 0,
                 logit_dim: int = 0, state_dim: int = 0):
        """``logit_dim`` > 0: also ``anchor_logits`` (the anchor policy's logits per row);
        ``state_dim`` > 0: also ``states`` (a centralised critic's inputs per row)."""
        t, b = num_steps, num_streams
        check_memory(t * b * (4 * (obs_dim + logit_dim + state_dim + 7) + 24 + 1 + mask_dim),
                     f"a rollout of num_steps = {t:,} x {b:,} streams x {obs_dim} inputs",
                     "lower num_steps or num_envs")
        self.num_steps, self.num_streams = t, b
        self.obs = torch.zeros((t, b, obs_dim), dtype=torch.float32)
        self.actions = torch.zeros((t, b, 3), dtype=torch.int64)
        self.logprobs = torch.zeros((t, b), dtype=torch.float32)
        self.values = torch.zeros((t, b), dtype=torch.float32)
        self.rewards = torch.zeros((t, b), dtype=torch.float32)
        self.terminated = torch.zeros((t, b), dtype=torch.float32)
        self.truncated = torch.zeros((t, b), dtype=torch.float32)
        self.bootstrap = torch.zeros((t, b), dtype=torch.float32)
        self.active = torch.ones((t, b), dtype=torch.bool)
        self.masks = torch.ones((t, b, mask_dim), dtype=torch.bool) if mask_dim else None
        self.anchor_logits = (torch.zeros((t, b, logit_dim), dtype=torch.float32)
                              if logit_dim else None)
        self.states = torch.zeros((t, b, state_dim), dtype=torch.float32) if state_dim else None
        self.step = 0
        # numpy views of the same memory: per-step writes through numpy cost a third
        self.np = {k: v.numpy() for k, v in vars(self).items() if isinstance(v, torch.Tensor)}

    @property
    def full(self) -> bool:
        return self.step >= self.num_steps

    def clear(self) -> None:
        self.step = 0
        self.bootstrap.zero_()


class OnPolicyPlumbing:
    """The Learner protocol's run plumbing shared by the fixed-rollout learners (PPO,
    MAPPO): they hold ``cfg.num_steps``, a return normaliser ``ret_norm``, an
    ``optimizer``, a torch ``generator`` and a numpy ``np_rng``, ``updates`` and
    ``total_updates``, make their :class:`RolloutBuffer` by ``make_buffer()``, and keep all
    their state in ``state_dict``."""

    _buffer: RolloutBuffer | None = None

    @property
    def buffer(self) -> RolloutBuffer:
        """The rollout, made when the learner first trains (:meth:`plan`, acting, taking
        in fragments): a learner loaded to play or kept as a self-play snapshot holds
        none, whatever its ``num_steps``."""
        if self._buffer is None:
            self._buffer = self.make_buffer()
        return self._buffer

    @property
    def rollout_steps(self) -> int:
        return self.cfg.num_steps

    def plan(self, total_steps: int) -> None:
        """Anneal the learning rate(s) (``anneal_lr``) over ``total_steps`` observe calls;
        make the rollout now, inside the run's :func:`memory_budget`, so that one that
        does not fit is refused before training starts."""
        self.total_updates = total_steps // self.cfg.num_steps
        self._buffer = self.buffer

    def new_segment(self) -> None:
        """Fresh episodes everywhere: restart the discounted returns of reward scaling."""
        self.ret_norm.returns[:] = 0.0

    @property
    def ready(self) -> bool:
        return self.buffer.full

    def anchor(self) -> None:
        """No anchor (MAPPO; PPO overrides this)."""

    def anneal_learning_rates(self, *base_rates: float) -> None:
        """With ``anneal_lr``, set the optimiser's param groups to their ``base_rates``
        scaled down linearly to 0 over the planned updates."""
        if self.cfg.anneal_lr and self.total_updates > 0:
            frac = max(0.0, 1.0 - self.updates / self.total_updates)
            for group, rate in zip(self.optimizer.param_groups, base_rates, strict=True):
                group["lr"] = frac * rate

    def record_outcome(self, rewards: np.ndarray, terminated: np.ndarray,
                       truncated: np.ndarray, active: Any) -> None:
        """Write what followed the last act into the rollout's current row (rewards
        scaled); the caller adds the bootstrap values and advances the row."""
        buf = self.buffer
        row, t = buf.np, buf.step
        row["rewards"][t] = self.ret_norm(rewards, np.logical_or(terminated, truncated))
        row["terminated"][t] = terminated
        row["truncated"][t] = truncated
        row["active"][t] = active

    def drop_rollout(self) -> None:
        """Forget the unfinished rollout (its matches were lost)."""
        self.buffer.clear()

    def record_acted(self, x: np.ndarray, actions: np.ndarray, logprobs: np.ndarray,
                     values: np.ndarray, rewards: np.ndarray, terminated: np.ndarray,
                     truncated: np.ndarray, bootstrap: np.ndarray, active: Any) -> None:
        """Append one row acted elsewhere (a fragment's step): the network input ``x``,
        what was sampled, and what followed, rewards scaled as :meth:`observe` scales
        them."""
        buf = self.buffer
        row, s = buf.np, buf.step
        row["obs"][s] = x
        row["actions"][s] = actions
        row["logprobs"][s] = logprobs
        row["values"][s] = values
        self.record_outcome(rewards, terminated, truncated, active)
        row["bootstrap"][s] = bootstrap
        buf.step += 1

    def training_state(self) -> dict[str, Any]:
        """The ``state_dict`` entries that only resuming needs (inference does not): the
        optimiser, reward scaling, both random generators and the update count."""
        return {"optimizer": self.optimizer.state_dict(), "ret_norm": self.ret_norm.state_dict(),
                "generator": self.generator.get_state(),
                "np_rng": self.np_rng.bit_generator.state,
                "updates": torch.tensor(self.updates)}

    def load_training_state(self, state: dict[str, Any]) -> None:
        """Restore what :meth:`training_state` wrote."""
        self.optimizer.load_state_dict(state["optimizer"])
        self.ret_norm.load_state_dict(state["ret_norm"])
        self.generator.set_state(state["generator"])
        self.np_rng.bit_generator.state = state["np_rng"]
        self.updates = int(state["updates"])

    def arrays(self) -> dict[str, np.ndarray]:
        return {}

    def load_arrays(self, arrays: dict[str, np.ndarray]) -> None:
        """Everything is in ``state_dict``: nothing to load."""


class ReplayBuffer:
    """Fixed-size cyclic buffer of (s, a, r, s', d); the newest transitions overwrite the
    oldest. Stores raw observations (normalised at sampling time with current statistics)."""

    def __init__(self, capacity: int, obs_dim: int, act_dim: int):
        if capacity <= 0:
            raise ValueError(f"replay capacity must be > 0, got {capacity}")
        check_memory(4 * capacity * (2 * obs_dim + act_dim + 2),
                     f"a replay buffer of buffer_size = {capacity:,} transitions x {obs_dim} "
                     "inputs", "lower buffer_size")
        self.capacity = int(capacity)
        self.obs = np.zeros((capacity, obs_dim), dtype=np.float32)
        self.next_obs = np.zeros((capacity, obs_dim), dtype=np.float32)
        self.actions = np.zeros((capacity, act_dim), dtype=np.float32)
        self.rewards = np.zeros(capacity, dtype=np.float32)
        self.dones = np.zeros(capacity, dtype=np.float32)
        self.pos = 0
        self.size = 0

    def __len__(self) -> int:
        return self.size

    def add(self, obs: np.ndarray, actions: np.ndarray, rewards: np.ndarray,
            next_obs: np.ndarray, dones: np.ndarray) -> None:
        """Append a batch of transitions (first axis = transitions), wrapping around."""
        n = obs.shape[0]
        if n > self.capacity:  # keep only the newest ``capacity``
            obs, actions, rewards, next_obs, dones = (
                a[-self.capacity:] for a in (obs, actions, rewards, next_obs, dones))
            n = self.capacity
        idx = (self.pos + np.arange(n)) % self.capacity
        self.obs[idx] = obs
        self.actions[idx] = actions
        self.rewards[idx] = rewards
        self.next_obs[idx] = next_obs
        self.dones[idx] = dones
        self.pos = int((self.pos + n) % self.capacity)
        self.size = min(self.size + n, self.capacity)

    def sample(self, batch_size: int, rng: np.random.Generator
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Uniform sample with replacement: (obs, actions, rewards, next_obs, dones)."""
        if self.size == 0:
            raise ValueError("cannot sample from an empty replay buffer")
        idx = rng.integers(0, self.size, size=batch_size)
        return (self.obs[idx], self.actions[idx], self.rewards[idx], self.next_obs[idx],
                self.dones[idx])

    def arrays(self) -> dict[str, np.ndarray]:
        """The filled part plus the write position, for saving with a checkpoint."""
        n = self.size
        return {"obs": self.obs[:n], "next_obs": self.next_obs[:n], "actions": self.actions[:n],
                "rewards": self.rewards[:n], "dones": self.dones[:n],
                "pos": np.array(self.pos), "capacity": np.array(self.capacity)}

    def load_arrays(self, data: dict[str, np.ndarray]) -> None:
        n = int(data["obs"].shape[0])
        if int(data["capacity"]) != self.capacity or n > self.capacity:
            raise ValueError(f"replay buffer capacity mismatch: saved {int(data['capacity'])}, "
                             f"configured {self.capacity}")
        if data["obs"].shape[1:] != self.obs.shape[1:]:
            raise ValueError(f"replay buffer observation shape mismatch: saved "
                             f"{data['obs'].shape[1:]}, expected {self.obs.shape[1:]}")
        for key in ("obs", "next_obs", "actions", "rewards", "dones"):
            getattr(self, key)[:n] = data[key]
        self.size, self.pos = n, int(data["pos"])

"""Rollout fragments: a shard of matches stepped for a whole rollout by a policy copy held
next to the matches (``alphatank train --fragments``), one call per rollout instead of
one per step.

A :class:`RolloutPolicy` is a frozen, picklable copy of the learners' acting side, sent
once per rollout; :func:`collect_fragment` steps a :class:`VectorMatchEnv` with it for
``steps`` vector steps and returns a :class:`Fragment` of arrays, (steps, n, ...) with n the
shard's envs. Sampling draws from the policy's generator for the shard, seeded by the
shard's first env id (:meth:`RolloutPolicy.start`), so for the same policy seed and the
same shards a fragment is the same in one process, in worker processes and in Ray env
runners. :func:`merge_fragments` joins the shards' fragments along the env axis.
:class:`SplitRollout` lets a caller start a rollout and collect it later.

A fragment also carries the env's extra learner inputs (``env.inputs``, e.g. MAPPO's
agent-specific states) of every step, and the policy reads them.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np


class RolloutPolicy(Protocol):
    """The learners' acting side, frozen for one rollout."""

    def start(self, env_ids: Sequence[int]) -> None:
        """Seed sampling for the shard of these env ids (called once per fragment)."""

    def act(self, obs: np.ndarray, inputs: dict[str, np.ndarray]
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Actions int64 (n, L, 3), their log-probabilities and value estimates float32
        (n, L) for raw observations (n, L, obs_dim) and the env's inputs (n, L, ...)."""

    def values(self, obs: np.ndarray, inputs: dict[str, np.ndarray]) -> np.ndarray:
        """Bootstrap values float32 (k, L) of the last observations (k, L, obs_dim) and
        inputs of episodes cut by the time limit."""


class ShardEnv(Protocol):
    """What a fragment steps: a :class:`~alphatank.envs.vector.VectorMatchEnv`."""

    num_envs: int
    num_learners: int
    obs_dim: int
    env_ids: list[int]
    inputs: dict[str, np.ndarray]

    def step_into(self, acts: np.ndarray, obs: np.ndarray, rewards: np.ndarray,
                  terminated: np.ndarray, truncated: np.ndarray, final_obs: np.ndarray,
                  final_inputs: dict[str, np.ndarray]) -> list[dict[str, Any]]: ...


@dataclass
class Fragment:
    """``steps`` vector steps of ``n`` envs: what each learner seat saw (``obs``, raw, and
    the env's ``inputs``), did and got, the value of the last observation of each episode
    cut by the time limit (``bootstrap``, 0 elsewhere), the observations and inputs after
    the last step (``next_obs``, ``next_inputs``) and the episode records, each with the
    ``step`` it ended in."""

    obs: np.ndarray  # (T, n, L, D) float32
    actions: np.ndarray  # (T, n, L, 3) int64
    logprobs: np.ndarray  # (T, n, L) float32
    values: np.ndarray  # (T, n, L) float32
    rewards: np.ndarray  # (T, n, L) float32
    terminated: np.ndarray  # (T, n) bool
    truncated: np.ndarray  # (T, n) bool
    bootstrap: np.ndarray  # (T, n, L) float32
    next_obs: np.ndarray  # (n, L, D) float32
    inputs: dict[str, np.ndarray] = field(default_factory=dict)  # (T, n, L, ...) each
    next_inputs: dict[str, np.ndarray] = field(default_factory=dict)  # (n, L, ...) each
    episodes: list[dict[str, Any]] = field(default_factory=list)

    @property
    def steps(self) -> int:
        return self.obs.shape[0]


def fragment_specs(steps: int, n: int, L: int, D: int,
                   input_shapes: Mapping[str, tuple[int, ...]]
                   ) -> dict[str, tuple[tuple[int, ...], str]]:
    """(shape, dtype) of each array of a fragment of ``steps`` steps of ``n`` envs x ``L``
    learner seats x ``D`` features, ``input_shapes`` the env's extra inputs per seat:
    ``obs`` and ``input:<name>`` carry one row more, the observations after the last step."""
    specs = {"obs": ((steps + 1, n, L, D), "float32"), "actions": ((steps, n, L, 3), "int64"),
             "terminated": ((steps, n), "bool"), "truncated": ((steps, n), "bool")}
    for key in ("logprobs", "values", "rewards", "bootstrap"):
        specs[key] = ((steps, n, L), "float32")
    for name, shape in input_shapes.items():
        specs[f"input:{name}"] = ((steps + 1, n, L, *shape), "float32")
    return specs


def fragment_of(arrays: Mapping[str, np.ndarray], steps: int,
                episodes: list[dict[str, Any]]) -> Fragment:
    """The :class:`Fragment` held by ``arrays`` (shaped as :func:`fragment_specs` says, or
    with room for more steps: the first ``steps`` are used)."""
    obs = arrays["obs"][:steps + 1]
    ins = {k[6:]: a[:steps + 1] for k, a in arrays.items() if k.startswith("input:")}
    return Fragment(obs=obs[:steps], next_obs=obs[steps],
                    inputs={k: a[:steps] for k, a in ins.items()},
                    next_inputs={k: a[steps] for k, a in ins.items()}, episodes=episodes,
                    **{k: arrays[k][:steps] for k in ("actions", "logprobs", "values",
                                                      "rewards", "terminated", "truncated",
                                                      "bootstrap")})


def collect_fragment(env: ShardEnv, policy: RolloutPolicy, obs: np.ndarray, steps: int,
                     out: Mapping[str, np.ndarray] | None = None) -> Fragment:
    """Step ``env`` (already reset; ``obs`` its current observations) ``steps`` times with
    ``policy``'s actions. ``out``: the arrays to write the fragment into (shaped as
    :func:`fragment_specs` says, e.g. views of shared memory); new ones by default."""
    if steps < 1:
        raise ValueError(f"a fragment needs steps >= 1, got {steps}")
    n, L, D = env.num_envs, env.num_learners, env.obs_dim
    obs = np.asarray(obs, dtype=np.float32)
    if obs.shape != (n, L, D):
        raise ValueError(f"observations of shape {obs.shape} for a shard of {n} envs x {L} "
                         f"learners x {D} features")
    if out is None:
        shapes = {name: a.shape[2:] for name, a in env.inputs.items()}
        out = {k: np.empty(shape, dtype) for k, (shape, dtype)
               in fragment_specs(steps, n, L, D, shapes).items()}
    frag = fragment_of(out, steps, [])
    frag.bootstrap.fill(0.0)
    seen = out["obs"]
    seen[0] = obs
    ins = {name: out[f"input:{name}"] for name in env.inputs}
    final_obs = np.zeros((n, L, D), np.float32)
    finals = {name: np.zeros(a.shape, np.float32) for name, a in env.inputs.items()}
    policy.start(env.env_ids)
    for t in range(steps):
        now = {}
        for name, a in ins.items():
            a[t] = env.inputs[name]
            now[name] = a[t]
        actions, frag.logprobs[t], frag.values[t] = policy.act(seen[t], now)
        frag.actions[t] = actions
        episodes = env.step_into(frag.actions[t], seen[t + 1], frag.rewards[t],
                                 frag.terminated[t], frag.truncated[t], final_obs, finals)
        if episodes:
            cut = np.flatnonzero(frag.truncated[t] & ~frag.terminated[t])
            if cut.size:
                frag.bootstrap[t, cut] = policy.values(
                    final_obs[cut], {name: a[cut] for name, a in finals.items()})
            final_obs.fill(0.0)
            for a in finals.values():
                a.fill(0.0)
            for ep in episodes:
                ep["step"] = t
            frag.episodes.extend(episodes)
    for name, a in ins.items():
        a[steps] = env.inputs[name]
    return frag


class SplitRollout:
    """``rollout`` as ``rollout_start`` then ``rollout_finish``: an env whose shards run
    apart from the caller plays the rollout in between, while the caller does other work
    (``alphatank train --overlap``: the learner's update)."""

    def rollout(self, policy: RolloutPolicy, obs: np.ndarray, steps: int) -> Fragment:
        """``steps`` vector steps acted by ``policy`` from the current observations
        ``obs``."""
        self.rollout_start(policy, obs, steps)
        return self.rollout_finish()

    def rollout_start(self, policy: RolloutPolicy, obs: np.ndarray, steps: int) -> None:
        raise NotImplementedError

    def rollout_finish(self) -> Fragment:
        raise NotImplementedError

    @property
    def rollout_in_flight(self) -> bool:
        """A rollout begun by :meth:`rollout_start` that :meth:`rollout_finish` has not
        collected yet."""
        raise NotImplementedError

    def check_idle(self, call: str) -> None:
        """RuntimeError naming ``call`` while a rollout is in flight: steps, resets and
        opponent settings would land in the middle of it (or, in worker processes, take
        its answer), so they wait for :meth:`rollout_finish`."""
        if self.rollout_in_flight:
            raise RuntimeError(f"{call}() while a rollout is in flight: call "
                               f"rollout_finish() first")


def merge_fragments(parts: Sequence[Fragment]) -> Fragment:
    """The shards' fragments (in env-id order) as one, envs concatenated; episode
    records in step order, shards in order within a step (as stepping them together
    lists them)."""
    if len(parts) == 1:
        return parts[0]
    arrays = {name: np.concatenate([getattr(p, name) for p in parts], axis=1)
              for name in ("obs", "actions", "logprobs", "values", "rewards", "terminated",
                           "truncated", "bootstrap")}
    return Fragment(**arrays, next_obs=np.concatenate([p.next_obs for p in parts]),
                    inputs={k: np.concatenate([p.inputs[k] for p in parts], axis=1)
                            for k in parts[0].inputs},
                    next_inputs={k: np.concatenate([p.next_inputs[k] for p in parts])
                                 for k in parts[0].next_inputs},
                    episodes=merge_episodes([p.episodes for p in parts]))


def merge_episodes(parts: Sequence[list[dict[str, Any]]]) -> list[dict[str, Any]]:
    """The shards' episode records (shards in env-id order) in step order, shards in order
    within a step (as stepping them together lists them)."""
    return sorted((ep for p in parts for ep in p), key=lambda ep: ep["step"])

"""The learners' side of rollout fragments (``alphatank train --fragments``): the acting
copy sent to the env shards, what runs may use fragments, and taking a fragment in.

Each iteration the :class:`~alphatank.training.runner.Trainer` sends one
:class:`FrozenLearners` (every PPO learner's numpy network and observation statistics as
they are at the iteration's start) to the env's shards, which act and step the whole
rollout (:mod:`alphatank.envs.fragments`); the learners then record it
(:meth:`~alphatank.training.ppo.PPO.ingest`) and update. Against acting step by step on
the learner: the same network and the same updates, but the samples come from a
generator per shard (seeded by the run seed, the iteration and the shard's first env),
and the observation statistics take the rollout in after it instead of step by step.
So a run with fragments is reproducible for the same seed and the same number of shards
(one process, worker processes or Ray env runners alike), not step-equal to one without.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from alphatank.envs.fragments import Fragment
from alphatank.training.normalize import ObsNormalizer
from alphatank.training.ppo import NumpyActorCritic, np_sample


class FrozenLearners:
    """A :class:`~alphatank.envs.fragments.RolloutPolicy` over the PPO learners of a run:
    each learner's columns of the (n, L, D) observations act with its copy."""

    def __init__(self, parts: Sequence[tuple[list[int], NumpyActorCritic, ObsNormalizer,
                                             tuple[int, ...]]], seed: int):
        self.parts = list(parts)
        self.seed = int(seed)
        self.rng = np.random.default_rng(self.seed)
        self._out: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    @classmethod
    def of(cls, learners: Mapping[str, Any], cols: Mapping[str, list[int]],
           seed: int) -> FrozenLearners:
        return cls([(cols[name], *lr.frozen(), lr.nvec) for name, lr in learners.items()],
                   seed)

    def start(self, env_ids: Sequence[int]) -> None:
        seq = np.random.SeedSequence(self.seed, spawn_key=(int(env_ids[0]),))
        self.rng = np.random.default_rng(seq)

    def _buffers(self, n: int, L: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if self._out is None or self._out[1].shape != (n, L):
            self._out = (np.empty((n, L, 3), np.int64), np.empty((n, L), np.float32),
                         np.empty((n, L), np.float32))
        return self._out

    def act(self, obs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        n, L, D = obs.shape
        actions, logprobs, values = self._buffers(n, L)
        for cols, net, norm, nvec in self.parts:
            logits, v = net.forward(norm(obs[:, cols].reshape(-1, D)))
            a, lp = np_sample(logits, nvec, self.rng)
            k = len(cols)
            actions[:, cols] = a.reshape(n, k, 3)
            logprobs[:, cols] = lp.reshape(n, k)
            values[:, cols] = v.reshape(n, k)
        return actions, logprobs, values

    def values(self, obs: np.ndarray) -> np.ndarray:
        n, L, D = obs.shape
        out = np.empty((n, L), np.float32)
        for cols, net, norm, _ in self.parts:
            out[:, cols] = net.forward(norm(obs[:, cols].reshape(-1, D)))[1].reshape(n, -1)
        return out


def fragment_problems(learners: Mapping[str, Any], rollout_steps: int, *, masks: bool,
                      selfplay: bool, env: Any) -> list[str]:
    """Why this run cannot act in fragments (empty: it can)."""
    out = []
    other = sorted(f"{n} ({lr.algo})" for n, lr in learners.items() if lr.algo != "ppo")
    if other:
        out.append(f"fragments are acted by PPO learners only; this run has {other} (MAPPO "
                   "and SAC act step by step)")
    lengths = {n: lr.rollout_steps for n, lr in learners.items()}
    if any(k != rollout_steps for k in lengths.values()):
        out.append(f"every learner's rollout must be the iteration ({rollout_steps} steps); "
                   f"they are {lengths}")
    if any(getattr(lr.cfg, "anchor_kl", 0.0) for lr in learners.values()):
        out.append("anchor_kl needs the anchor's logits at every step; fragments carry none")
    if masks:
        out.append("action masks are applied step by step; fragments carry none")
    if selfplay:
        out.append("self-play swaps opponents on episode ends inside a rollout")
    if not callable(getattr(env, "rollout", None)):
        out.append(f"the env ({type(env).__name__}) does not collect fragments")
    return out


def ingest_fragment(frag: Fragment, learners: Mapping[str, Any],
                    cols: Mapping[str, list[int]], alive_col: int | None) -> None:
    """Give each learner its columns of ``frag`` as (T, streams, ...) rows, streams in
    (env, seat) order as when acting step by step."""
    T, E, _, D = frag.obs.shape
    for name, learner in learners.items():
        c = cols[name]
        k = len(c)
        obs = frag.obs[:, :, c].reshape(T, E * k, D)
        active = obs[..., alive_col] > 0.5 if alive_col is not None else None
        learner.ingest(obs, frag.actions[:, :, c].reshape(T, E * k, 3),
                       frag.logprobs[:, :, c].reshape(T, -1),
                       frag.values[:, :, c].reshape(T, -1),
                       frag.rewards[:, :, c].reshape(T, -1),
                       np.repeat(frag.terminated, k, axis=1),
                       np.repeat(frag.truncated, k, axis=1),
                       frag.bootstrap[:, :, c].reshape(T, -1), active)

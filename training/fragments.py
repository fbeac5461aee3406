"""The learners' side of rollout fragments (``alphatank train --fragments``): the acting
copy sent to the env shards, what runs may use fragments, and taking a fragment in.

Each iteration the :class:`~alphatank.training.runner.Trainer` sends one
:class:`FrozenLearners` (every learner's numpy networks and normalisers as they are at
the iteration's start: :meth:`PPO.frozen <alphatank.training.ppo.PPO.frozen>`,
:meth:`MAPPO.frozen <alphatank.training.mappo.MAPPO.frozen>`) to the env's shards, which
act and step the whole rollout (:mod:`alphatank.envs.fragments`); the learners then
record it (``ingest``) and update. Against acting step by step on the learner: the same
networks and the same updates, but the samples come from a generator per shard (seeded
by the run seed, the iteration and the shard's first env), and the normalisers take the
rollout in after it instead of step by step.
So a run with fragments is reproducible for the same seed and the same number of shards
(one process, worker processes or Ray env runners alike), not step-equal to one without.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from alphatank.envs.fragments import Fragment

ALGOS = ("ppo", "mappo")  # learners with frozen() and ingest()


def stream_rows(arr: np.ndarray, cols: list[int]) -> np.ndarray:
    """(E, L, ...) env array -> (E * len(cols), ...) stream rows of learner columns."""
    return arr[:, cols].reshape(-1, *arr.shape[2:])


class FrozenLearners:
    """A :class:`~alphatank.envs.fragments.RolloutPolicy` over the learners of a run:
    each learner's columns of the (n, L, D) observations (and of the env's inputs it
    reads) act with its frozen copy."""

    def __init__(self, parts: Sequence[tuple[list[int], Any, tuple[str, ...]]], seed: int):
        self.parts = list(parts)
        self.seed = int(seed)
        self.rng = np.random.default_rng(self.seed)
        self._out: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    @classmethod
    def of(cls, learners: Mapping[str, Any], cols: Mapping[str, list[int]],
           seed: int) -> FrozenLearners:
        return cls([(cols[name], lr.frozen(), tuple(lr.inputs))
                    for name, lr in learners.items()], seed)

    def start(self, env_ids: Sequence[int]) -> None:
        seq = np.random.SeedSequence(self.seed, spawn_key=(int(env_ids[0]),))
        self.rng = np.random.default_rng(seq)

    def _buffers(self, n: int, L: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if self._out is None or self._out[1].shape != (n, L):
            self._out = (np.empty((n, L, 3), np.int64), np.empty((n, L), np.float32),
                         np.empty((n, L), np.float32))
        return self._out

    def act(self, obs: np.ndarray, inputs: dict[str, np.ndarray]
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        n, L, _ = obs.shape
        actions, logprobs, values = self._buffers(n, L)
        for cols, frozen, names in self.parts:
            ins = {x: stream_rows(inputs[x], cols) for x in names}
            a, lp, v = frozen.act(stream_rows(obs, cols), ins, self.rng)
            k = len(cols)
            actions[:, cols] = a.reshape(n, k, 3)
            logprobs[:, cols] = lp.reshape(n, k)
            values[:, cols] = v.reshape(n, k)
        return actions, logprobs, values

    def values(self, obs: np.ndarray, inputs: dict[str, np.ndarray]) -> np.ndarray:
        n, L, _ = obs.shape
        out = np.empty((n, L), np.float32)
        for cols, frozen, names in self.parts:
            ins = {x: stream_rows(inputs[x], cols) for x in names}
            v = frozen.values(stream_rows(obs, cols), ins)
            out[:, cols] = v.reshape(n, len(cols))
        return out


class FragmentsRefused(ValueError):
    """A run that cannot act in fragments; ``problems`` says why (``; ``-joined)."""

    def __init__(self, problems: list[str]):
        self.problems = "; ".join(problems)
        super().__init__(f"fragments: {self.problems}")


def fragment_problems(learners: Mapping[str, Any], rollout_steps: int, *, masks: bool,
                      selfplay: bool, env: Any) -> list[str]:
    """Why this run cannot act in fragments (empty: it can)."""
    out = []
    other = sorted(f"{n} ({lr.algo})" for n, lr in learners.items() if lr.algo not in ALGOS)
    if other:
        out.append(f"fragments are acted by PPO and MAPPO learners only; this run has "
                   f"{other} (SAC acts step by step)")
    lengths = {n: lr.rollout_steps for n, lr in learners.items() if lr.algo in ALGOS}
    if any(k != rollout_steps for k in lengths.values()):
        out.append(f"every learner's rollout must be the iteration ({rollout_steps} steps); "
                   f"they are {lengths}")
    if any(getattr(lr.cfg, "anchor_kl", 0.0) for lr in learners.values()):
        out.append("anchor_kl needs the anchor's logits at every step; fragments carry none")
    if masks:
        out.append("action masks are applied step by step; fragments carry none")
    if selfplay:
        out.append("self-play swaps opponents on episode ends inside a rollout")
    if not callable(getattr(env, "rollout_start", None)):
        out.append(f"the env ({type(env).__name__}) does not collect fragments")
    return out


def ingest_fragment(frag: Fragment, learners: Mapping[str, Any],
                    cols: Mapping[str, list[int]], alive_col: int | None) -> None:
    """Give each learner its columns of ``frag`` as (T, streams, ...) rows, streams in
    (env, seat) order as when acting step by step."""
    T = frag.steps

    def rows(arr: np.ndarray, c: list[int]) -> np.ndarray:  # (T, E, L, ...) -> (T, E*k, ...)
        return arr[:, :, c].reshape(T, -1, *arr.shape[3:])

    for name, learner in learners.items():
        c = cols[name]
        k = len(c)
        obs = rows(frag.obs, c)
        active = obs[..., alive_col] > 0.5 if alive_col is not None else None
        learner.ingest(obs, rows(frag.actions, c), rows(frag.logprobs, c),
                       rows(frag.values, c), rows(frag.rewards, c),
                       np.repeat(frag.terminated, k, axis=1),
                       np.repeat(frag.truncated, k, axis=1), rows(frag.bootstrap, c), active,
                       **{x: rows(frag.inputs[x], c) for x in learner.inputs})

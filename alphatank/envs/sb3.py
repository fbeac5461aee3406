"""Stable-Baselines3 ``VecEnv`` over the batched engine (needs the ``sb3`` extra).

    from alphatank.envs.sb3 import make_sb3_env
    env = make_sb3_env("vs_smart", num_envs=16, seed=0)     # or "team": 16 x 4 learners
    PPO("MlpPolicy", env).learn(100_000)

Every (match, learner seat) pair is one SB3 env: ``num_envs`` = matches x learner seats,
index ``e * L + l`` (match ``e``, learner ``l``). In a multi-learner scenario one SB3 policy
therefore drives every learner seat (parameter sharing, teammates and opponents alike);
all seats of a match end together (a dead learner keeps its slot until the match ends, as
in the engine). On an episode end SB3's conventions hold: the returned observation is the
next episode's first, ``infos[i]["terminal_observation"]`` the last one,
``infos[i]["TimeLimit.truncated"]`` marks time-limit ends, and ``infos[i]["episode"]``
(``r`` return, ``l`` length, ``t`` seconds since start) feeds SB3's episode statistics
without a ``VecMonitor``; ``winner`` and ``outcome`` come with it.
"""

from __future__ import annotations

import time
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from alphatank.extras import require

require("sb3", "alphatank.envs.sb3")

from stable_baselines3.common.vec_env import VecEnv  # noqa: E402

from alphatank.envs.core import check_actions, check_reset_options  # noqa: E402
from alphatank.envs.vector import (  # noqa: E402
    SubprocVectorMatchEnv,
    TankBattleVectorEnv,
    VectorMatchEnv,
    make_vector_env,
)

Engine = VectorMatchEnv | SubprocVectorMatchEnv


class SB3VecEnv(VecEnv):
    """A :class:`VectorMatchEnv` / :class:`SubprocVectorMatchEnv` (or the engine of a
    :class:`TankBattleVectorEnv`) as an SB3 VecEnv of ``num_envs * num_learners`` envs."""

    def __init__(self, env: Engine | TankBattleVectorEnv):
        if not isinstance(env, VectorMatchEnv | SubprocVectorMatchEnv | TankBattleVectorEnv):
            raise TypeError(
                "SB3VecEnv needs make_vector_env(...)'s engine or gymnasium.make_vec(id, "
                "num_envs=N)'s TankBattleVectorEnv (the default vectorization mode, "
                f"unwrapped), got {type(env).__name__}; a gymnasium.make(id) env goes into "
                "SB3 as it is (SB3 wraps it in a DummyVecEnv)")
        self.engine: Engine = env.engine if isinstance(env, TankBattleVectorEnv) else env
        eng = self.engine
        self.matches, self.learners = eng.num_envs, eng.num_learners
        self._actions: np.ndarray | None = None
        self._start = time.perf_counter()
        super().__init__(self.matches * self.learners, eng.observation_space, eng.action_space)

    def reset(self) -> np.ndarray:
        seed = self._seeds[0]  # set by seed(); None continues the engine's episode sequence
        obs = self.engine.reset(seed)
        self._reset_seeds()
        self._reset_options()
        return obs.reshape(self.num_envs, -1)

    def set_options(self, options: list[dict] | dict | None = None) -> None:
        """The engine's reset takes no options: refuse any rather than ignore them."""
        for opts in options if isinstance(options, list) else [options]:
            check_reset_options(opts, " for SB3VecEnv: the batched engine's reset has none")
        super().set_options(options)

    def step_async(self, actions: np.ndarray) -> None:
        """``actions``: (num_envs, 3), one row per SB3 env (errors name the env and the
        allowed values)."""
        rows = check_actions(actions, (self.num_envs, 3), self._name)
        self._actions = rows.reshape(self.matches, self.learners, 3)

    def _name(self, idx: tuple[int, ...]) -> str:
        e, slot = divmod(idx[0], self.learners)
        return f"SB3 env {idx[0]} (match {e}, learner {slot})"

    def step_wait(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[dict[str, Any]]]:
        if self._actions is None:
            raise RuntimeError("step_wait() without step_async()")
        obs, rew, term, trunc, info = self.engine.step(self._actions)
        self._actions = None
        L = self.learners
        dones = np.repeat(term | trunc, L)
        infos: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        elapsed = round(time.perf_counter() - self._start, 6)
        for ep in info["episodes"]:
            e = ep["env"]
            for slot in range(L):
                infos[e * L + slot] = {
                    "terminal_observation": info["final_obs"][e, slot],
                    "TimeLimit.truncated": bool(trunc[e] and not term[e]),
                    "episode": {"r": float(ep["return"][slot]), "l": ep["length"],
                                "t": elapsed},
                    "winner": ep["winner"], "outcome": ep["outcome"][slot]}
        return obs.reshape(self.num_envs, -1), rew.reshape(-1), dones, infos

    def close(self) -> None:
        self.engine.close()

    # ---- SB3's per-env calls: the engine's settings hold for every env -----------------

    def _all(self, indices: Any, what: str) -> int:
        idx = list(self._get_indices(indices))
        if sorted(idx) != list(range(self.num_envs)):
            raise ValueError(f"{what} applies to every env of the batched engine at once; "
                             f"got indices {idx}")
        return len(idx)

    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
        value = getattr(self.engine, attr_name)
        return [value] * len(list(self._get_indices(indices)))

    def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
        self._all(indices, f"set_attr({attr_name!r})")
        setattr(self.engine, attr_name, value)

    def env_method(self, method_name: str, *method_args: Any, indices: Any = None,
                   **method_kwargs: Any) -> list[Any]:
        n = self._all(indices, f"env_method({method_name!r})")
        result = getattr(self.engine, method_name)(*method_args, **method_kwargs)
        return [result] * n

    def env_is_wrapped(self, wrapper_class: type, indices: Iterable[int] | int | None = None
                       ) -> list[bool]:
        return [False] * len(list(self._get_indices(indices)))

    def get_images(self) -> Sequence[np.ndarray | None]:
        raise NotImplementedError("the batched engine draws nothing; record a match with "
                                  "alphatank record or render a TankBattleEnv")


def make_sb3_env(scenario: str, num_envs: int, seed: int = 0, num_workers: int = 1,
                 **kwargs: Any) -> SB3VecEnv:
    """An SB3 VecEnv over ``make_vector_env(scenario, num_envs, seed, num_workers,
    **kwargs)`` (``num_envs`` matches; SB3 sees matches x learner seats envs)."""
    return SB3VecEnv(make_vector_env(scenario, num_envs, seed, num_workers, **kwargs))

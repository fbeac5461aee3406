"""Several scenarios in one vector env, so one learner trains on each bot in its own
setting (map and game preset) at once.

:class:`MixedVectorEnv` splits ``num_envs`` matches into one block per scenario (sizes
differ by at most one, the first blocks take the remainder) and speaks the interface of
:class:`~alphatank.envs.vector.VectorMatchEnv` that the trainer and the opponent
schedules use: arrays are the blocks' arrays concatenated along the env axis; opponent
controls (bot type, weakness, named opponents) apply to every block, and
:meth:`set_env_opponents` takes one name per env across all blocks. Block ``b``'s envs
carry the global env ids ``offset_b .. offset_b + n_b - 1``, so their episode seeds are
those of a single env of ``num_envs`` matches.

The scenarios must give the same observation size and learner seats: use an observation
that does not depend on the map (``egocentric``), since the ``paper`` one sizes its wall
block by the map's wall count.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from alphatank.envs.vector import VectorMatchEnv
from alphatank.game.scenarios import Scenario, load_scenario
from alphatank.sim.policy import Policy


class MixedVectorEnv:
    """``num_envs`` matches split over ``scenarios`` (see the module docstring)."""

    render_mode = None

    def __init__(self, scenarios: Sequence[str | Scenario], num_envs: int, seed: int = 0,
                 observation: str | None = None, game_overrides: dict | None = None,
                 reward_overrides: dict | None = None, inputs: Sequence[str] = (),
                 action_repeat: int = 1):
        scs = [load_scenario(s) for s in scenarios]
        if not scs:
            raise ValueError("a mixed env needs at least one scenario")
        if num_envs < len(scs):
            raise ValueError(f"a mixed env of {len(scs)} scenarios needs num_envs >= "
                             f"{len(scs)}, got {num_envs}")
        k = len(scs)
        sizes = [num_envs // k + (1 if b < num_envs % k else 0) for b in range(k)]
        self.blocks: list[VectorMatchEnv] = []
        self.slices: list[slice] = []
        off = 0
        for sc, n in zip(scs, sizes, strict=True):
            self.blocks.append(VectorMatchEnv(
                sc, n, seed, observation, game_overrides, reward_overrides,
                env_ids=range(off, off + n), inputs=inputs, action_repeat=action_repeat))
            self.slices.append(slice(off, off + n))
            off += n
        first = self.blocks[0]
        for sc, blk in zip(scs[1:], self.blocks[1:], strict=True):
            if blk.obs_dim != first.obs_dim:
                raise ValueError(f"mixed env: scenario {sc.name!r} gives {blk.obs_dim} "
                                 f"observation features, {scs[0].name!r} gives "
                                 f"{first.obs_dim} (use the egocentric observation, whose "
                                 f"size does not depend on the map)")
            if blk.learner_teams != first.learner_teams:
                raise ValueError(f"mixed env: scenario {sc.name!r} has learner teams "
                                 f"{blk.learner_teams}, {scs[0].name!r} has "
                                 f"{first.learner_teams}")
        self.scenarios = scs
        self.scenario = scs[0]  # what checkpoints record (their observation fits them all)
        self.core = first.core  # reward settings (victory) for the trainer
        self.num_envs = num_envs
        self.action_repeat = first.action_repeat
        self.num_learners = first.num_learners
        self.learner_seats = first.learner_seats
        self.learner_teams = first.learner_teams
        self.obs_dim = first.obs_dim
        self.observation_space = first.observation_space
        self.action_space = first.action_space
        self.input_shapes = first.input_shapes
        self.seed = int(seed)

    @property
    def layout(self) -> Any:
        return self.blocks[0].layout

    @property
    def inputs(self) -> dict[str, np.ndarray]:
        names = self.blocks[0].inputs
        return {n: np.concatenate([b.inputs[n] for b in self.blocks]) for n in names}

    # ---- opponents (every block; from each env's next episode) -------------------------

    def set_bot_weakness(self, weakness: float) -> None:
        for b in self.blocks:
            b.set_bot_weakness(weakness)

    def set_opponents(self, bot_names: Sequence[str] | None,
                      weakness: float | None = None) -> None:
        for b in self.blocks:
            b.set_opponents(bot_names, weakness)

    def set_opponent_policy(self, policy: Policy | None) -> None:
        for b in self.blocks:
            b.set_opponent_policy(policy)

    def set_benched(self, seats: Sequence[int]) -> None:
        for b in self.blocks:
            b.set_benched(seats)

    def add_opponent(self, name: str, opponent: str | Policy) -> None:
        for b in self.blocks:
            b.add_opponent(name, opponent)

    def set_env_opponents(self, names: Sequence[str | None]) -> None:
        if len(names) != self.num_envs:
            raise ValueError(f"need one opponent name per env ({self.num_envs}), got "
                             f"{len(names)}")
        for b, sl in zip(self.blocks, self.slices, strict=True):
            b.set_env_opponents(list(names[sl]))

    # ---- episodes -------------------------------------------------------------------

    def reset(self, seed: int | None = None) -> np.ndarray:
        if seed is not None:
            self.seed = int(seed)
        return np.concatenate([b.reset(seed) for b in self.blocks])

    def step(self, actions: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                          dict[str, Any]]:
        acts = np.asarray(actions)
        if acts.shape[:1] != (self.num_envs,):
            raise ValueError(f"actions must have shape ({self.num_envs}, {self.num_learners}, "
                             f"3), got {acts.shape}")
        parts = [b.step(acts[sl]) for b, sl in zip(self.blocks, self.slices, strict=True)]
        obs, rew, term, trunc = (np.concatenate([p[k] for p in parts]) for k in range(4))
        infos = [p[4] for p in parts]
        info = {"final_obs": np.concatenate([i["final_obs"] for i in infos]),
                "episodes": [ep for i in infos for ep in i["episodes"]],
                "final_inputs": {n: np.concatenate([i["final_inputs"][n] for i in infos])
                                 for n in infos[0]["final_inputs"]}}
        return obs, rew, term, trunc, info

    def close(self) -> None:
        for b in self.blocks:
            b.close()

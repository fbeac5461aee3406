"""Gymnasium env: one learner seat of a scenario; the env plays every other seat.

``gymnasium.make("AlphaTank/TankBattle-v0", scenario="vs_smart")`` (ids in
:mod:`alphatank.envs`). Other learner seats of the scenario need a Policy
(``seat_policies={seat: policy}`` or ``opponent_policy=`` for every non-learner seat).
Observation: ``Box(-1, 1, (obs_dim,), float32)`` (index map: ``env.unwrapped.layout``);
action: ``MultiDiscrete([3, 3, 2])``. ``info["reward_terms"]`` breaks the step's reward
down by term; the last step's info adds ``winner`` and ``outcome``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np

from alphatank.envs.core import FirstMatchRenderer, MatchSet, action_space, check_actions
from alphatank.game.observe import ObsLayout
from alphatank.game.rewards import TERMS
from alphatank.game.scenarios import Scenario, ScenarioError, load_scenario
from alphatank.sim.match import Match
from alphatank.sim.policy import Policy
from alphatank.ui.modes import RENDER_MODES, check_render_mode


class TankBattleEnv(gym.Env):
    """One learner against (or beside) bots and frozen policies."""

    metadata = {"render_modes": RENDER_MODES, "render_fps": 30}

    def __init__(self, scenario: str | Scenario = "vs_smart", *, observation: str | None = None,
                 learner_seat: int | None = None, opponent_policy: Policy | None = None,
                 seat_policies: Mapping[int, Policy] | None = None,
                 game_overrides: Mapping[str, Any] | None = None,
                 reward_overrides: Mapping[str, Any] | None = None,
                 render_mode: str | None = None):
        sc = load_scenario(scenario)
        learners = sc.learner_seats
        if not learners:
            raise ScenarioError(f"{sc.source}: TankBattle needs a learner seat; this scenario "
                                "has none (watch it with the PettingZoo or vector env)")
        seat = learners[0] if learner_seat is None else learner_seat
        if seat not in learners:
            raise ScenarioError(f"{sc.source}: learner_seat {seat} is not a learner seat; "
                                f"learner seats: {learners}")
        check_render_mode(render_mode)
        self.core = MatchSet(sc, 1, observation=observation, game_overrides=game_overrides,
                             reward_overrides=reward_overrides, driven=[seat],
                             seat_policies=seat_policies)
        self.core.opponent_policy = opponent_policy
        if self.core.orphans and opponent_policy is None:
            raise ScenarioError(
                f"{sc.source}: learner seats {self.core.orphans} have no controller: pass "
                "seat_policies={seat: policy} or opponent_policy=policy, or use the "
                "PettingZoo env to drive them all")
        self.scenario, self.seat = sc, seat
        self.render_mode = render_mode
        self.observation_space = self.core.observation_space()
        self.action_space = action_space()
        self.metadata = {**self.metadata, "render_fps": self.core.game.tick_hz}
        self._drawer = (FirstMatchRenderer(self.core, render_mode, self.metadata["render_fps"])
                        if render_mode is not None else None)

    @property
    def layout(self) -> ObsLayout:
        """Index map of the observation vector (feature name -> slice)."""
        return self.core.obs.layout

    @property
    def match(self) -> Match:
        """The live match (read it, don't step it)."""
        return self.core.matches[0]

    def reset(self, *, seed: int | None = None, options: dict | None = None
              ) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        self.core.reset_env(0, int(self.np_random.integers(2**63 - 1)))
        obs = self.core.obs.build()[0, 0].copy()
        if self.render_mode == "human":
            self.render()
        return obs, {"map": self.core.map_name(0), "seat": self.seat}

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict]:
        if not self.core.matches:
            raise RuntimeError("step() before reset() (an unpickled env must be reset)")
        m = self.core.matches[0]
        if m.done:
            raise RuntimeError("step() after the episode ended; call reset()")
        a = check_actions(action, (3,), lambda _: f"seat {self.seat} ({self.scenario.name})")
        terms, obs = self.core.step(a.reshape(1, 1, 3))
        col = terms[0, :, self.seat]
        info: dict[str, Any] = {"reward_terms": dict(zip(TERMS, col.tolist(), strict=True)),
                                "map": self.core.map_name(0)}
        if m.done:
            info["winner"] = m.winner
            info["outcome"] = self.core.outcome(0)[0]
        if self.render_mode == "human":
            self.render()
        return obs[0, 0].copy(), float(col.sum()), m.terminated, m.truncated, info

    def render(self) -> np.ndarray | None:
        if self.render_mode is None:
            gym.logger.warn("render() called with render_mode=None; pass render_mode= to "
                            f"the constructor ({RENDER_MODES})")
            return None
        return self._drawer.render()

    def close(self) -> None:
        if self._drawer is not None:
            self._drawer.close()

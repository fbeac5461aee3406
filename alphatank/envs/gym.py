"""Gymnasium env: one learner seat of a scenario; the env plays every other seat.

``gymnasium.make("AlphaTank/TankBattle-v0", scenario="vs_smart")`` or a scenario's own id
(``AlphaTank/VsSmart-v0``; all ids in :mod:`alphatank.envs`). A tank in a walled arena
fights bots, frozen policies or both, with ricocheting bullets (docs/rules.md); the
scenario (a TOML file) names the map, the game preset and every seat.

Action space
    ``MultiDiscrete([3, 3, 2])``: rotate {0 counter-clockwise, 1 none, 2 clockwise}, move
    {0 back, 1 stop, 2 forward}, fire {0 no, 1 yes}. One action per tick.

Observation space
    ``Box(-1, 1, (obs_dim,), float32)``, ``obs_dim`` fixed per scenario: the ``paper`` kind
    (the paper's Table 1 in map coordinates) or ``egocentric`` (the tank's own frame and
    wall rays). Every feature has a name: ``env.unwrapped.layout["tank[0].dist"]`` is its
    slice; docs/environments.md tabulates both layouts.

Rewards
    The sum of the scenario's reward terms for the learner this step (``RewardConfig``;
    defaults: the paper's Table 5: victory, hits, predicted trajectory hits, bullets
    closing in, ...). ``info["reward_terms"]`` breaks it down by term.

Episode end
    Terminated when at most one team has a live tank (the learner's death ends its episode:
    the rest of the match is played out at once so the winner is real); truncated at
    ``max_steps`` (1200 ticks by default, 40 s at 30 Hz). The last step's info adds
    ``winner`` (team or None) and ``outcome`` ("win" / "loss" / "draw").

Arguments
    ``scenario`` (name or TOML path), ``observation`` (one of ``OBS_KINDS``: "paper",
    "egocentric", "egocentric_path", "egocentric_nearest", "egocentric_aim",
    "egocentric_aim_path", "egocentric_full", "egocentric_fire", "egocentric_advice";
    default: the scenario's),
    ``learner_seat`` (default: the first learner seat), ``opponent_policy`` (a Policy in
    every seat the env plays),
    ``seat_policies`` ({seat: Policy}; the scenario's other learner seats need one),
    ``game_overrides`` / ``reward_overrides`` (GameConfig / RewardConfig fields),
    ``action_repeat`` (ticks each step holds the action for, 1..30, rewards summed over
    them, as a run's ``action_repeat``; default 1), ``render_mode`` (None, "rgb_array",
    "human").

Version history (``ENV_VERSION`` in :mod:`alphatank.envs.ids`, shared by every AlphaTank
env and written into checkpoints)
    * v0: the initial release: paper and egocentric observations, Table 5 rewards; later
      the additive egocentric_path, egocentric_nearest, egocentric_aim,
      egocentric_aim_path, egocentric_full, egocentric_fire and egocentric_advice kinds
      (the other kinds unchanged, their digests pinned).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np

from alphatank.envs.core import (
    FirstMatchRenderer,
    MatchSet,
    action_space,
    check_actions,
    check_policy,
    check_reset_options,
    check_seat_policies,
)
from alphatank.game.observe import ObsLayout
from alphatank.game.rewards import TERMS
from alphatank.game.scenarios import Scenario, ScenarioError, load_scenario
from alphatank.sim.config import check_seed
from alphatank.sim.match import Match
from alphatank.sim.policy import Policy
from alphatank.ui.modes import RENDER_MODES, check_render_mode


def single_learner_seat(sc: Scenario, learner_seat: int | None,
                        seat_policies: Mapping[int, Policy] | None,
                        opponent_policy: Policy | None) -> int:
    """The learner seat a one-learner env drives (default: the scenario's first); the
    scenario's other learner seats need a Policy (``seat_policies`` or
    ``opponent_policy``, checked to be one). Errors name the scenario file or the
    argument, and what is allowed."""
    learners = sc.learner_seats
    if not learners:
        raise ScenarioError(f"{sc.source}: TankBattle needs a learner seat; this scenario "
                            "has none (watch it with the PettingZoo or vector env)")
    seat = learners[0] if learner_seat is None else learner_seat
    if isinstance(seat, bool) or not isinstance(seat, int | np.integer):
        raise TypeError(f"learner_seat must be an int (a seat index), got {seat!r}; "
                        f"learner seats: {learners}")
    seat = int(seat)
    if opponent_policy is not None:
        check_policy(opponent_policy, "opponent_policy")
    if seat not in learners:
        raise ScenarioError(f"{sc.source}: learner_seat {seat} is not a learner seat; "
                            f"learner seats: {learners}")
    policies = check_seat_policies(seat_policies)
    orphans = [s for s in learners if s != seat and s not in policies]
    if orphans and opponent_policy is None:
        raise ScenarioError(
            f"{sc.source}: learner seats {orphans} have no controller: pass "
            "seat_policies={seat: policy} or opponent_policy=policy, or use the "
            "PettingZoo env to drive them all")
    return seat


class TankBattleEnv(gym.Env):
    """One learner against (or beside) bots and frozen policies."""

    metadata = {"render_modes": RENDER_MODES, "render_fps": 30}

    def __init__(self, scenario: str | Scenario = "vs_smart", *, observation: str | None = None,
                 learner_seat: int | None = None, opponent_policy: Policy | None = None,
                 seat_policies: Mapping[int, Policy] | None = None,
                 game_overrides: Mapping[str, Any] | None = None,
                 reward_overrides: Mapping[str, Any] | None = None,
                 action_repeat: int = 1, render_mode: str | None = None):
        sc = load_scenario(scenario)
        seat = single_learner_seat(sc, learner_seat, seat_policies, opponent_policy)
        check_render_mode(render_mode)
        self.core = MatchSet(sc, 1, observation=observation, game_overrides=game_overrides,
                             reward_overrides=reward_overrides, driven=[seat],
                             seat_policies=seat_policies, action_repeat=action_repeat)
        self.core.opponent_policy = opponent_policy
        self.scenario, self.seat = sc, seat
        self.render_mode = render_mode
        self.observation_space = self.core.observation_space()
        self.action_space = action_space()
        self.metadata = {**self.metadata, "render_fps": self.core.game.tick_hz}
        self._map = ""  # name of the current episode's map (set at reset)
        self._drawer = (FirstMatchRenderer(self.core, render_mode, self.metadata["render_fps"])
                        if render_mode is not None else None)

    @property
    def layout(self) -> ObsLayout:
        """Index map of the observation vector (feature name -> slice)."""
        return self.core.obs.layout

    @property
    def match(self) -> Match:
        """The live match (read it, don't step it)."""
        return self.core.first_match("match")

    def reset(self, *, seed: int | None = None, options: dict | None = None
              ) -> tuple[np.ndarray, dict]:
        check_reset_options(options)
        if seed is not None:
            seed = check_seed(seed)  # a Python int, as Gymnasium's seeding takes
        super().reset(seed=seed)
        # reset(seed=S) plays episode S (the game `record --seed S` plays); later resets
        # without a seed draw theirs from np_random, seeded with S
        episode = int(self.np_random.integers(2**63 - 1)) if seed is None else seed
        self.core.reset_env(0, episode)
        obs = self.core.obs.build()[0, 0].copy()
        if self.render_mode == "human":
            self.render()
        self._map = self.core.map_name(0)
        return obs, {"map": self._map, "seat": self.seat}

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict]:
        m = self.core.first_match("step()")
        if m.done:
            raise RuntimeError("step() after the episode ended; call reset()")
        a = check_actions(action, (3,), self._name)
        terms, obs = self.core.step(a.reshape(1, 1, 3))
        col = terms[0, :, self.seat]
        info: dict[str, Any] = {"reward_terms": dict(zip(TERMS, col.tolist(), strict=True)),
                                "map": self._map}
        if m.terminated or m.truncated:
            info["winner"] = m.winner
            info["outcome"] = self.core.outcome(0)[0]
        if self.render_mode == "human":
            self.render()
        return obs[0, 0].copy(), float(np.add.reduce(col)), m.terminated, m.truncated, info

    def _name(self, _: tuple[int, ...]) -> str:
        return f"seat {self.seat} ({self.scenario.name})"

    def render(self) -> np.ndarray | None:
        if self.render_mode is None:
            gym.logger.warn("render() called with render_mode=None; pass render_mode= to "
                            f"the constructor ({RENDER_MODES})")
            return None
        return self._drawer.render()

    def close(self) -> None:
        if self._drawer is not None:
            self._drawer.close()

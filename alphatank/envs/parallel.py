"""PettingZoo env: every learner seat of a scenario is an agent; the env plays the rest.

``parallel_env(scenario="team")`` returns a ParallelEnv, ``env(...)`` its AEC form
(``pettingzoo.utils.parallel_to_aec``). Agents are named ``tank_<seat>``.

Action space
    Per agent ``MultiDiscrete([3, 3, 2])``: rotate, move, fire (as in
    :mod:`alphatank.envs.gym`); every live agent acts every step.

Observation space
    Per agent ``Box(-1, 1, (obs_dim,), float32)``, the same layout as the Gymnasium env
    (``env.layout``; team scenarios add ``team`` flags). ``state()`` is the global state
    for centralised critics (``state_space``, index map ``state_layout``).

Rewards
    Per agent per step, the sum of its reward terms; ``infos[agent]["reward_terms"]``
    breaks it down.

Episode end
    The match ends when at most one team has a live tank (all agents terminated) or at
    ``max_cycles`` ticks (truncated). A tank that dies is terminated and leaves ``agents``
    for good, unless ``keep_dead_agents=True``, which keeps it (alive flag 0, actions
    ignored) until the match ends so it still receives its team's victory. The last
    step's infos add ``winner`` and ``outcome``.

Arguments
    ``scenario``, ``observation``, ``seat_policies``, ``game_overrides``,
    ``reward_overrides``, ``max_cycles`` (GameConfig.max_steps: refused beside a different
    ``game_overrides["max_steps"]``), ``keep_dead_agents`` (a bool),
    ``render_mode`` (None, "rgb_array", "human").

Version history
    ``metadata["name"]`` is ``alphatank_v<ENV_VERSION>``; see :mod:`alphatank.envs.gym`.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from gymnasium import spaces
from pettingzoo import AECEnv, ParallelEnv
from pettingzoo.utils import parallel_to_aec

from alphatank.envs.core import (
    FirstMatchRenderer,
    MatchSet,
    action_space,
    check_actions,
    check_overrides,
    check_step_limit,
)
from alphatank.envs.ids import ENV_VERSION
from alphatank.game.observe import ObsLayout
from alphatank.game.rewards import TERMS
from alphatank.game.scenarios import Scenario, ScenarioError, load_scenario
from alphatank.sim.config import check_seed, check_value
from alphatank.sim.policy import Policy
from alphatank.ui.modes import RENDER_MODES, check_render_mode


class TankBattleParallelEnv(ParallelEnv):
    """All learner seats of a scenario as simultaneous agents."""

    metadata = {"name": f"alphatank_v{ENV_VERSION}", "render_modes": RENDER_MODES, "render_fps": 30,
                "is_parallelizable": True}

    def __init__(self, scenario: str | Scenario = "team", *, observation: str | None = None,
                 seat_policies: Mapping[int, Policy] | None = None,
                 game_overrides: Mapping[str, Any] | None = None,
                 reward_overrides: Mapping[str, Any] | None = None,
                 max_cycles: int | None = None, keep_dead_agents: bool = False,
                 render_mode: str | None = None):
        check_render_mode(render_mode)
        self.scenario = sc = load_scenario(scenario)
        if not sc.learner_seats:
            raise ScenarioError(f"{sc.source}: no learner seats, so no PettingZoo agents (the "
                                "agents are a scenario's controller = \"learner\" seats); "
                                "watch a bots-only scenario with VectorMatchEnv or "
                                "`alphatank record --scenario`")
        overrides = check_overrides(game_overrides, "game_overrides")
        if max_cycles is not None:
            max_cycles = check_step_limit(max_cycles, "max_cycles")
            if overrides.get("max_steps", max_cycles) != max_cycles:
                raise ScenarioError(f"max_cycles {max_cycles} and game_overrides.max_steps "
                                    f"{overrides['max_steps']!r} set the same setting "
                                    "(GameConfig.max_steps); give one of them")
            overrides["max_steps"] = max_cycles
        why = check_value((bool,), keep_dead_agents)[1]
        if why:
            raise ScenarioError(f"keep_dead_agents: {why}")
        self.core = MatchSet(sc, 1, observation=observation, game_overrides=overrides,
                             reward_overrides=reward_overrides, seat_policies=seat_policies)
        self.keep_dead_agents = keep_dead_agents
        self.render_mode = render_mode
        self.seats = list(self.core.driven)
        self.possible_agents = [f"tank_{s}" for s in self.seats]
        self.agents: list[str] = []
        self._slot = {a: k for k, a in enumerate(self.possible_agents)}
        obs_space, act_space = self.core.observation_space(), action_space()
        self._obs_spaces = {a: obs_space for a in self.possible_agents}
        self._act_spaces = {a: act_space for a in self.possible_agents}
        self.state_space = self.core.state_space()
        self.metadata = {**self.metadata, "render_fps": self.core.game.tick_hz}
        self._rng = np.random.default_rng()
        self._actions = np.ones((1, len(self.seats), 3), dtype=np.int64)
        self._drawer = (FirstMatchRenderer(self.core, render_mode, self.metadata["render_fps"])
                        if render_mode is not None else None)

    @property
    def layout(self) -> ObsLayout:
        """Index map of an agent's observation vector."""
        return self.core.obs.layout

    @property
    def state_layout(self) -> ObsLayout:
        return self.core.global_state.layout

    def observation_space(self, agent: str) -> spaces.Box:
        return self._obs_spaces[self._agent(agent)]

    def action_space(self, agent: str) -> spaces.MultiDiscrete:
        return self._act_spaces[self._agent(agent)]

    def _agent(self, agent: str) -> str:
        """``agent``; KeyError naming it and the env's agents unless one of them."""
        if agent not in self._slot:
            raise KeyError(f"{agent!r} is not an agent of this env; its agents: "
                           f"{self.possible_agents}")
        return agent

    def reset(self, seed: int | None = None, options: dict | None = None
              ) -> tuple[dict[str, np.ndarray], dict[str, dict]]:
        del options  # none: PettingZoo's api tests pass options any env must take
        if seed is not None:  # episode ``seed``, then episodes drawn from a generator of it
            seed = check_seed(seed)
            self._rng = np.random.default_rng(seed)
        episode = int(self._rng.integers(2**63 - 1)) if seed is None else seed
        self.core.reset_env(0, episode)
        self.agents = self.possible_agents[:]
        obs = self.core.obs.build()[0]
        info = {"map": self.core.map_name(0)}
        if self.render_mode == "human":
            self.render()
        return ({a: obs[k].copy() for k, a in enumerate(self.agents)},
                {a: dict(info) for a in self.agents})

    def step(self, actions: Mapping[str, Any]) -> tuple[dict, dict, dict, dict, dict]:
        if not self.agents:
            raise RuntimeError("step() with no live agents; call reset()")
        if not isinstance(actions, Mapping):
            raise TypeError(f"step() takes a dict agent -> action (MultiDiscrete([3, 3, 2])) "
                            f"for the live agents {self.agents}, got {type(actions).__name__}")
        unknown = [a for a in actions if a not in self.agents]
        if unknown:
            raise ValueError(f"actions for unknown or finished agent(s) {unknown}; live "
                             f"agents: {self.agents}")
        missing = [a for a in self.agents if a not in actions]
        if missing:
            raise ValueError(f"no action for live agent(s) {missing}; every live agent acts "
                             "each step (MultiDiscrete([3, 3, 2]))")
        for a, act in actions.items():
            self._actions[0, self._slot[a]] = check_actions(act, (3,), lambda _, a=a: a)
        terms, obs = self.core.step(self._actions)
        m = self.core.matches[0]
        live = self.agents
        obs_d, rew, term, trunc, infos = {}, {}, {}, {}, {}
        outcome = self.core.outcome(0) if m.done else None
        map_name = self.core.map_name(0)
        for a in live:
            k = self._slot[a]
            col = terms[0, :, self.seats[k]]
            obs_d[a] = obs[0, k].copy()
            rew[a] = float(col.sum())
            dead = not m.alive[self.seats[k]] and not self.keep_dead_agents
            term[a] = bool(m.terminated or dead)
            trunc[a] = bool(m.truncated and not term[a])
            info = {"reward_terms": dict(zip(TERMS, col.tolist(), strict=True)),
                    "map": map_name}
            if outcome is not None:
                info["winner"] = m.winner
                info["outcome"] = outcome[k]
            infos[a] = info
        self.agents = [a for a in live if not (term[a] or trunc[a])]
        if self.render_mode == "human":
            self.render()
        return obs_d, rew, term, trunc, infos

    def state(self) -> np.ndarray:
        """Global state vector (every tank, bullet, zone and the time) for critics."""
        self.core.first_match("state()")
        return self.core.global_state.build()[0].copy()

    def render(self) -> np.ndarray | None:
        if self.render_mode is None:
            return None
        return self._drawer.render()

    def __getstate__(self) -> dict[str, Any]:
        """Configuration, spaces and seed stream; the live match is not carried (see
        :meth:`MatchSet.__getstate__`): reset after unpickling."""
        state = self.__dict__.copy()
        state["agents"] = []
        return state

    def close(self) -> None:
        if self._drawer is not None:
            self._drawer.close()


def parallel_env(**kwargs: Any) -> TankBattleParallelEnv:
    """PettingZoo ParallelEnv (keyword arguments: see :class:`TankBattleParallelEnv`)."""
    return TankBattleParallelEnv(**kwargs)


def env(**kwargs: Any) -> AECEnv:
    """PettingZoo AEC env: :func:`parallel_env` through ``parallel_to_aec``."""
    return parallel_to_aec(parallel_env(**kwargs))

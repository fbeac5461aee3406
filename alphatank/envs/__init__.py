"""Environments over one match: Gymnasium (one learner), PettingZoo (all learners) and
a batched vector env for training. Importing this package registers the Gymnasium ids:

* ``AlphaTank/TankBattle-v0``: any scenario (``scenario="vs_smart"`` by default);
* ``AlphaTank/<Scenario>-v0`` for each shipped scenario with exactly one learner seat,
  e.g. ``AlphaTank/VsSmart-v0`` (others: ``TankBattle-v0`` with ``scenario=`` and
  ``seat_policies=`` / ``opponent_policy=`` for the extra learner seats).
"""

from __future__ import annotations

import gymnasium

from alphatank.envs.gym import TankBattleEnv
from alphatank.envs.parallel import TankBattleParallelEnv, env, parallel_env
from alphatank.envs.vector import SubprocVectorMatchEnv, VectorMatchEnv, make_vector_env
from alphatank.game.scenarios import load_scenario, shipped_scenarios

ENTRY_POINT = "alphatank.envs.gym:TankBattleEnv"


def gym_id(scenario: str) -> str:
    """Registered Gymnasium id of a shipped scenario: ``vs_smart`` -> ``AlphaTank/VsSmart-v0``."""
    return "AlphaTank/" + "".join(p.capitalize() for p in scenario.split("_")) + "-v0"


def register_envs() -> list[str]:
    """Register (idempotently) the Gymnasium ids; returns them."""
    ids = ["AlphaTank/TankBattle-v0"]
    if ids[0] not in gymnasium.registry:
        gymnasium.register(ids[0], entry_point=ENTRY_POINT, kwargs={"scenario": "vs_smart"})
    for name in shipped_scenarios():
        if len(load_scenario(name).learner_seats) != 1:
            continue
        gid = gym_id(name)
        if gid not in gymnasium.registry:
            gymnasium.register(gid, entry_point=ENTRY_POINT, kwargs={"scenario": name})
        ids.append(gid)
    return ids


GYM_IDS = register_envs()

__all__ = ["GYM_IDS", "SubprocVectorMatchEnv", "TankBattleEnv", "TankBattleParallelEnv",
           "VectorMatchEnv", "env", "gym_id", "make_vector_env", "parallel_env",
           "register_envs"]

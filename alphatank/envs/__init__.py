"""Environments over one match: Gymnasium (one learner), PettingZoo (all learners) and
batched vector envs. Importing this package registers the Gymnasium ids, each with an
entry point (``gymnasium.make``) and a vector entry point (``gymnasium.make_vec``: the
batched :class:`TankBattleVectorEnv`):

* ``AlphaTank/TankBattle-v0``: any scenario (``scenario="vs_smart"`` by default);
* ``AlphaTank/<Scenario>-v0`` for each shipped scenario with exactly one learner seat,
  e.g. ``AlphaTank/VsSmart-v0`` (others: ``TankBattle-v0`` with ``scenario=`` and
  ``seat_policies=`` / ``opponent_policy=`` for the extra learner seats).

The ``-v0`` is :data:`ENV_VERSION`, shared by every env here; it changes whenever
observations or rewards do.
"""

from __future__ import annotations

import gymnasium

from alphatank.envs.gym import TankBattleEnv
from alphatank.envs.ids import ENV_VERSION, TANK_BATTLE_ID, env_id, gym_id, single_learner_scenarios
from alphatank.envs.parallel import TankBattleParallelEnv, env, parallel_env
from alphatank.envs.vector import (
    SubprocVectorMatchEnv,
    TankBattleVectorEnv,
    VectorMatchEnv,
    make_vector_env,
)

ENTRY_POINT = "alphatank.envs.gym:TankBattleEnv"
VECTOR_ENTRY_POINT = "alphatank.envs.vector:TankBattleVectorEnv"


def register_envs() -> list[str]:
    """Register (idempotently) the Gymnasium ids; returns them."""
    ids = {TANK_BATTLE_ID: "vs_smart"}
    ids.update((gym_id(name), name) for name in single_learner_scenarios())
    for gid, scenario in ids.items():
        if gid not in gymnasium.registry:
            gymnasium.register(gid, entry_point=ENTRY_POINT,
                               vector_entry_point=VECTOR_ENTRY_POINT,
                               kwargs={"scenario": scenario})
    return list(ids)


GYM_IDS = register_envs()

__all__ = ["ENV_VERSION", "GYM_IDS", "SubprocVectorMatchEnv", "TankBattleEnv",
           "TankBattleParallelEnv", "TankBattleVectorEnv", "VectorMatchEnv", "env", "env_id",
           "gym_id", "make_vector_env", "parallel_env", "register_envs"]

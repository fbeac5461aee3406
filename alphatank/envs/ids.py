"""Env ids and their version.

``ENV_VERSION`` is the one version of every AlphaTank env (Gymnasium, PettingZoo, vector):
bump it whenever observations or rewards change, so ids such as ``AlphaTank/VsSmart-v0``
and the ``env`` field of a checkpoint name the env a policy was trained on. Version
history: see :mod:`alphatank.envs.gym`.
"""

from __future__ import annotations

from alphatank.game.scenarios import Scenario, load_scenario, shipped_scenarios

ENV_VERSION = 0
NAMESPACE = "AlphaTank"


def versioned(name: str) -> str:
    """``TankBattle`` -> ``AlphaTank/TankBattle-v0``."""
    return f"{NAMESPACE}/{name}-v{ENV_VERSION}"


TANK_BATTLE_ID = versioned("TankBattle")


def gym_id(scenario: str) -> str:
    """Registered Gymnasium id of a shipped scenario: ``vs_smart`` -> ``AlphaTank/VsSmart-v0``."""
    return versioned("".join(p.capitalize() for p in scenario.split("_")))


def single_learner_scenarios() -> list[str]:
    """Shipped scenarios with exactly one learner seat: each has its own id."""
    return [n for n in shipped_scenarios() if len(load_scenario(n).learner_seats) == 1]


def env_id(scenario: str | Scenario) -> str:
    """The id of the env a policy trained on ``scenario`` plays: the scenario's own id
    when it is an unchanged shipped single-learner scenario, else
    ``AlphaTank/TankBattle-v<N>`` (with that scenario as its ``scenario=`` argument)."""
    sc = load_scenario(scenario)
    if sc.name in single_learner_scenarios() and (
            sc.to_dict() == load_scenario(sc.name).to_dict()):
        return gym_id(sc.name)
    return TANK_BATTLE_ID

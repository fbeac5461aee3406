"""The algorithm table: name -> hyperparameter dataclass and learner class.

Adding an algorithm = its learner module (implementing the Learner protocol of
:mod:`alphatank.training.learners`), its config dataclass in a torch-free module (fields
made with :func:`alphatank.training.fields.hp`), and one :func:`register` line below.
Presets, ``--hp ALGO.FIELD=VALUE``, ``alphatank train --list``, checkpoints and the runner
all read this table. The learner class is named as ``"module:Class"`` and imported on
first use, so the command line and preset listing never import torch.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Any

from alphatank.training.fields import did_you_mean
from alphatank.training.hparams import MAPPOConfig, PPOConfig, SACConfig


@dataclass(frozen=True)
class Algorithm:
    """One registered algorithm."""

    name: str
    config: type  # frozen dataclass of hyperparameters (defaults = the algorithm's defaults)
    learner: str  # "package.module:Class" implementing the Learner protocol
    description: str = ""

    def learner_class(self) -> Any:
        """The learner class (imports its module on first use)."""
        module, _, attr = self.learner.partition(":")
        return getattr(importlib.import_module(module), attr)


ALGORITHMS: dict[str, Algorithm] = {}


def register(name: str, config: type, learner: str, description: str = "") -> Algorithm:
    """Add (or replace) algorithm ``name``; returns its table entry."""
    if ":" not in learner:
        raise ValueError(f"algorithm {name!r}: learner must be 'module:Class', got {learner!r}")
    algo = Algorithm(name, config, learner, description)
    ALGORITHMS[name] = algo
    return algo


def get_algorithm(name: str) -> Algorithm:
    """The registered algorithm ``name``; ValueError naming the registered ones."""
    if not isinstance(name, str) or name not in ALGORITHMS:  # a list from TOML: unhashable
        raise ValueError(f"unknown algorithm {name!r}; registered: {sorted(ALGORITHMS)}"
                         f"{did_you_mean(name, ALGORITHMS)}")
    return ALGORITHMS[name]


register("ppo", PPOConfig, "alphatank.training.ppo:PPO",
         "PPO, independent learners (the paper's Table 7)")
register("sac", SACConfig, "alphatank.training.sac:SAC",
         "SAC on discrete actions via equation (33) (Tables 8/9)")
register("mappo", MAPPOConfig, "alphatank.training.mappo:MAPPO",
         "MAPPO: one shared actor per team (seat id), centralised critic over the "
         "agent-specific state, death masking, team credit")

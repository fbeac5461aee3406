"""AlphaTank: a physics-backed tank battle simulator and multi-agent RL framework.

Subpackages, one per layer of DESIGN.md (imports point down the list):

``sim``       the simulation: config, maps, pymunk world, match rules, ballistics, navigation
``game``      the agent-facing layer: scenarios, seat line-ups, observations, rewards
``envs``      Gymnasium, PettingZoo and the batched vector env
``bots``      rule-based opponents (from ``bots/``)
``training``  learners, runner, schedules, checkpoints, evaluation (from ``training/``)
``ui``        presentation: pygame renderer, keyboard players, videos, replays
``mapgen``    map generation, lint and the map editor
``commands``  the ``alphatank`` command line, one module per verb

The flat module paths of earlier releases (``alphatank.match``, ``alphatank.config``, ...)
still import: they name the same module objects as their new homes.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import sys
from types import ModuleType

__version__ = "0.2.0"

_MOVED = {f"alphatank.{old}": f"alphatank.{new}" for old, new in (
    ("config", "sim.config"), ("mapspec", "sim.mapspec"), ("world", "sim.world"),
    ("match", "sim.match"), ("ballistics", "sim.ballistics"),
    ("navigation", "sim.navigation"), ("policy", "sim.policy"),
    ("scenarios", "game.scenarios"), ("observe", "game.observe"),
    ("rewards", "game.rewards"), ("render", "ui.render"), ("human", "ui.human"),
    ("video", "ui.video"), ("replay", "ui.replay"), ("mapeditor", "mapgen.editor"))}


class _MovedModuleFinder(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Resolves a pre-0.2 flat path to the module at its new home (same object)."""

    def find_spec(self, name: str, path: object = None, target: object = None
                  ) -> importlib.machinery.ModuleSpec | None:
        if name not in _MOVED:
            return None
        return importlib.machinery.ModuleSpec(name, self)

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType:
        return importlib.import_module(_MOVED[spec.name])

    def exec_module(self, module: ModuleType) -> None:
        """The module was executed at its new home."""


if not any(isinstance(f, _MovedModuleFinder) for f in sys.meta_path):
    sys.meta_path.append(_MovedModuleFinder())

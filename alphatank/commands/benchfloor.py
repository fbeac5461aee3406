"""The bare pymunk floor for ``alphatank bench`` and ``bench --env``: finding the shared
prototype (``shared/bench/proto``) and timing its tick as ``floor_ratio.py`` does."""

from __future__ import annotations

import importlib
import random
import sys
import time
from collections.abc import Callable
from pathlib import Path
from types import ModuleType

FLOOR_DIR = Path("shared", "bench", "proto")


def find_floor(given: str | None) -> Path | None:
    """The prototype folder: ``given``, else the nearest ``shared/bench/proto`` in the
    ancestors of this project's source tree or of the working folder, else None."""
    if given is not None:
        folder = Path(given)
        if not (folder / "sim_core.py").is_file() or not (folder / "maze_0.txt").is_file():
            raise FileNotFoundError(f"--floor {given}: no sim_core.py and maze_0.txt there "
                                    "(the bare pymunk prototype's folder)")
        return folder
    for top in (Path(__file__).resolve().parents[2], Path.cwd().resolve()):
        for folder in (top, *top.parents):
            if (folder / FLOOR_DIR / "sim_core.py").is_file():
                return folder / FLOOR_DIR
    return None


def load_floor(folder: Path) -> ModuleType:
    """Import the prototype's ``sim_core`` (it imports its sibling ``scene`` by name)."""
    sys.path.insert(0, str(folder))
    try:
        return importlib.import_module("sim_core")
    finally:
        sys.path.remove(str(folder))


def floor_us_per_tick(folder: Path, n: int, ticks: int, seed: int = 0,
                      clock: Callable[[], float] = time.perf_counter) -> float:
    """Microseconds per tick (on ``clock``) of the prototype with ``n`` tanks, set up and
    driven as ``floor_ratio.py`` does (2 substeps, paper bullet speed, a shot every 3 ticks
    that never expires; random actions, 100 ticks of warm-up)."""
    core = load_floor(folder)
    core.SUB, core.BULLET_SPEED, core.MAX_BOUNCES, core.COOLDOWN = 2, 300.0, 1000, 3
    sim = core.Sim((folder / "maze_0.txt").read_text(), n, "pivot")
    rng = random.Random(seed)
    acts = [[(rng.randrange(3), rng.randrange(3), 1) for _ in range(n)]
            for _ in range(ticks + 100)]
    for a in acts[:100]:
        sim.step(a)
    start = clock()
    for a in acts[100:]:
        sim.step(a)
    return (clock() - start) / ticks * 1e6

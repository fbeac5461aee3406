"""Decision cost of each bot: median microseconds per ``act()`` call."""

from __future__ import annotations

import time

import numpy as np

from alphatank.bots.registry import BOT_NAMES, make_bot
from alphatank.sim.config import GameConfig
from alphatank.sim.episode import start_episode
from alphatank.sim.mapspec import load_map


def bot_costs(map_name: str = "maze", ticks: int = 2000, seed: int = 0,
              names: tuple[str, ...] = BOT_NAMES, cfg: GameConfig | None = None
              ) -> dict[str, float]:
    """Median µs per ``act()`` for each bot, timed over ``ticks`` ticks of mirror matches
    (the bot against a copy of itself, both timed; a finished match restarts with the
    next seed), so every bot is measured in the situations it creates."""
    spec = load_map(map_name)
    cfg = cfg or GameConfig()
    out: dict[str, float] = {}
    clock = time.perf_counter_ns
    for name in names:
        bots = [make_bot(name, seed=seed), make_bot(name, seed=seed + 1)]
        samples = np.empty(2 * ticks, dtype=np.int64)
        actions = np.zeros((2, 3), dtype=np.int64)
        k, game = 0, seed
        match = None
        while k < 2 * ticks:
            if match is None or match.done:
                match = start_episode(cfg, [spec], ["A", "B"], bots, game, match=match).match
                game += 1
            for i in range(2):
                if match.alive[i] and k < 2 * ticks:
                    t0 = clock()
                    actions[i] = bots[i].act(match, i)
                    samples[k] = clock() - t0
                    k += 1
            match.step(actions)
        out[name] = float(np.median(samples)) / 1000.0
    return out


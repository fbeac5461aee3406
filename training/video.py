"""MP4 of one match with trained policies in their seats (wandb videos, the demo)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from alphatank.policy import Policy
from alphatank.scenarios import Scenario, load_scenario


def record_policy_match(scenario: str | Scenario, policy: Policy, path: str | Path,
                        seed: int = 0, game_overrides: dict | None = None,
                        every: int = 2, fps: int = 15, max_frames: int = 1500,
                        opponents: dict[int, Policy] | None = None) -> Path:
    """Play one match of ``scenario`` with ``policy`` in every learner seat (and bots as
    the scenario says, or ``opponents`` by seat), drawing every ``every``-th tick into an
    H.264 MP4 at ``path``. Returns the path."""
    import imageio.v2 as imageio

    from alphatank.envs.core import MatchSet
    from alphatank.render import Renderer

    sc = load_scenario(scenario)
    seats = {s: policy for s in sc.learner_seats}
    seats.update(opponents or {})
    core = MatchSet(sc, 1, game_overrides=game_overrides, driven=[], seat_policies=seats)
    core.reset_env(0, seed)
    match = core.matches[0]
    renderer = Renderer("rgb_array", labels=[_label(core, s) for s in range(core.n)])
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    idle = np.zeros((1, 0, 3), dtype=np.int64)
    frames = 0
    with imageio.get_writer(path, fps=fps, codec="libx264", quality=7,
                            macro_block_size=1, ffmpeg_log_level="error") as writer:
        writer.append_data(renderer.frame(match))
        while not match.done and frames < max_frames:
            core.step(idle)
            if match.tick % every == 0 or match.done:
                writer.append_data(renderer.frame(match))
                frames += 1
        for _ in range(fps):  # hold the last frame a second
            writer.append_data(renderer.frame(match))
    renderer.close()
    return path


def _label(core: Any, seat: int) -> str:
    spec = core.seat_controller_spec(0, seat)
    if hasattr(spec, "describe"):
        return spec.describe() if spec.controller != "learner" else "agent"
    return "agent"

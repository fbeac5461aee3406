"""MP4 of one match with trained policies in their seats (wandb videos, the demo)."""

from __future__ import annotations

from pathlib import Path

from alphatank.game.scenarios import Scenario, Seat, load_scenario
from alphatank.sim.policy import Policy


def record_policy_match(scenario: str | Scenario, policy: Policy, path: str | Path,
                        seed: int = 0, game_overrides: dict | None = None) -> Path:
    """Play one match of ``scenario`` with ``policy`` in every learner seat (bots as the
    scenario says) and write it as an H.264 MP4 at ``path`` (every second tick, real
    time, one second held at the end)."""
    from alphatank.envs.core import MatchSet
    from alphatank.ui.video import record_match

    sc = load_scenario(scenario)
    seats: dict[int, Policy] = dict.fromkeys(sc.learner_seats, policy)
    core = MatchSet(sc, 1, game_overrides=game_overrides, driven=[], seat_policies=seats)
    core.reset_env(0, seed)
    labels = []
    for seat in range(core.n):
        spec = core.seat_controller_spec(0, seat)
        labels.append(spec.describe() if isinstance(spec, Seat) else "agent")
    rec = record_match(core.matches[0], core.controllers[0], mp4=path, every=2,
                       hold_s=1.0, labels=labels)
    assert rec.mp4 is not None
    return rec.mp4

"""Agent-specific global state (MAPPO critic input): layout, hand-placed values, death
masking, independence of envs, pickling."""

from __future__ import annotations

import math
import pickle

import numpy as np
import pytest

from alphatank.envs.core import MatchSet
from alphatank.envs.vector import VectorMatchEnv
from alphatank.game.scenarios import parse_scenario
from alphatank.game.state import AgentState

W = H = 770.0
DIAG = math.hypot(W, H)


def team_set(num_envs: int = 1, seats=("A", "A", "B")) -> MatchSet:
    sc = parse_scenario({"name": "t", "map": "open",
                         "seats": [{"team": t, "controller": "learner"} for t in seats]})
    ms = MatchSet(sc, num_envs)
    for e in range(num_envs):
        ms.reset_env(e, 10 + e)
    return ms


def place(ms: MatchSet, poses, bullets=(), e: int = 0) -> None:
    """Tanks at (x, y, angle); bullets (owner, slot, x, y, vx, vy)."""
    m = ms.matches[e]
    w = m.world
    for i, (x, y, a) in enumerate(poses):
        body = w.tank_bodies[i]
        body.position, body.angle, body.velocity = (x, y), a, (0.0, 0.0)
        w.controls[i].position, w.controls[i].angle = (x, y), a
    w.bullet_active[:] = False
    for owner, slot, x, y, vx, vy in bullets:
        b = owner * w.capacity + slot
        w.bullet_active[b] = True
        w.bullet_bodies[b].position, w.bullet_bodies[b].velocity = (x, y), (vx, vy)
    w.read_state()
    ms.batch.gather(e, m)


def f(st: AgentState, out: np.ndarray, name: str, learner: int, e: int = 0) -> float:
    return float(out[e, learner, st.layout[name]][0])


def test_layout_is_complete_and_fixed_size_per_scenario():
    ms = team_set(seats=("A", "A", "B", "B"))
    st = AgentState(ms.batch, ms.teams, ms.driven)
    lay = st.layout
    assert st.size == lay.size == st.out.shape[-1]
    assert len(set(lay.fields)) == lay.size
    assert lay.blocks() == ["self", "mate", "enemy", "enemy_bullets", "team_bullets", "seat",
                            "time"]
    assert "mate[0].fwd" in lay and "enemy[1].facing" in lay and "mate[1].x" not in lay
    assert st.seat_ids.tolist() == [0, 1, 0, 1] and st.num_seats == 2
    out = st.build()
    assert out.dtype == np.float32 and out.shape == (1, 4, lay.size)
    assert out.min() >= -1.0 and out.max() <= 1.0


def test_hand_placed_tanks_and_bullets():
    ms = team_set()
    st = AgentState(ms.batch, ms.teams, ms.driven)
    # Seat 0 at (200, 385) facing +x; mate (seat 1) at (200, 585); enemy (seat 2) at
    # (500, 385) facing -x (straight at seat 0). An enemy bullet at (300, 385) flies -x.
    place(ms, [(200.0, 385.0, 0.0), (200.0, 585.0, 0.0), (500.0, 385.0, math.pi)],
          bullets=[(2, 0, 300.0, 385.0, -300.0, 0.0), (0, 1, 450.0, 385.0, 300.0, 0.0)])
    out = st.build()
    assert f(st, out, "self.x", 0) == pytest.approx(2 * 200 / W - 1)
    assert f(st, out, "enemy[0].rel_x", 0) == pytest.approx(300 / W)
    assert f(st, out, "enemy[0].fwd", 0) == pytest.approx(300 / W)
    assert f(st, out, "enemy[0].side", 0) == pytest.approx(0.0, abs=1e-7)
    assert f(st, out, "enemy[0].dist", 0) == pytest.approx(300 / DIAG)
    assert f(st, out, "enemy[0].facing", 0) == pytest.approx(1.0)  # aims straight at me
    assert f(st, out, "mate[0].rel_y", 0) == pytest.approx(200 / W)
    assert f(st, out, "mate[0].side", 0) == pytest.approx(200 / W)  # right of me on screen
    assert f(st, out, "mate[0].alive", 0) == 1.0
    # the mate sees the enemy off to its side, not facing it
    assert f(st, out, "enemy[0].facing", 1) < 0.9
    assert f(st, out, "enemy_bullets.mask", 0) == 1.0
    assert f(st, out, "enemy_bullets.count", 0) == pytest.approx(1 / ms.game.bullet_capacity)
    assert f(st, out, "enemy_bullets.rel_x", 0) == pytest.approx(100 / W)
    assert f(st, out, "enemy_bullets.closing", 0) == pytest.approx(1.0)  # straight at me
    assert f(st, out, "team_bullets.mask", 0) == 1.0
    assert f(st, out, "team_bullets.dist", 0) == pytest.approx(50 / DIAG)
    assert f(st, out, "team_bullets.dist", 1) == pytest.approx(50 / DIAG)  # the mate's view
    # the enemy (seat 2) has no mate: a padded, all-zero slot; its own bullet is the team's
    assert not out[0, 2, st.layout["mate[0]"]].any()
    assert f(st, out, "enemy_bullets.rel_x", 2) == pytest.approx(-50 / W)
    assert f(st, out, "team_bullets.dist", 2) == pytest.approx(100 / DIAG)  # seat 0 nearest
    assert out[0, :, st.layout["seat"]].tolist() == [[1.0, 0.0], [0.0, 1.0], [1.0, 0.0]]


def test_dead_seat_is_zeros_and_its_seat_id():
    ms = team_set()
    st = AgentState(ms.batch, ms.teams, ms.driven)
    m = ms.matches[0]
    for _ in range(5):
        ms.step(np.ones((1, 3, 3), dtype=np.int64))
    m.alive[1] = False
    ms.batch.gather(0, m)
    out = st.build()
    seat = st.layout["seat"]
    assert out[0, 1, seat].tolist() == [0.0, 1.0]
    rest = np.delete(out[0, 1], np.arange(seat.start, seat.stop))
    assert not rest.any()
    assert f(st, out, "mate[0].alive", 0) == 0.0 and f(st, out, "self.alive", 0) == 1.0
    assert f(st, out, "time.t", 0) == pytest.approx(5 / ms.game.max_steps)


def test_envs_are_independent_and_state_survives_pickling():
    rng = np.random.default_rng(0)
    env = VectorMatchEnv("team_vs_def_bot", 3, seed=2)
    env.reset()
    st = AgentState(env.core.batch, env.core.teams, env.core.driven)
    for _ in range(40):
        env.step(rng.integers(0, [3, 3, 2], size=(3, 2, 3)))
    many = st.build().copy()
    for e in range(3):
        one = VectorMatchEnv("team_vs_def_bot", 1, seed=2, env_ids=[e])
        one.reset()
        rng1 = np.random.default_rng(0)
        for _ in range(40):
            a = rng1.integers(0, [3, 3, 2], size=(3, 2, 3))
            one.step(a[e:e + 1])
        single = AgentState(one.core.batch, one.core.teams, one.core.driven).build()
        np.testing.assert_array_equal(single[0], many[e])
    clone = pickle.loads(pickle.dumps(st))
    assert clone.layout.fields == st.layout.fields and clone.out.shape == st.out.shape


def test_bad_observers_are_rejected():
    ms = team_set()
    with pytest.raises(ValueError, match="observer seats"):
        AgentState(ms.batch, ms.teams, [5])

"""Reward terms: pure functions, and each term firing in real matches with its weight."""

from __future__ import annotations

import math

import numpy as np
import pytest

from alphatank import rewards as R
from alphatank.envs.core import MatchSet
from alphatank.envs.vector import VectorMatchEnv
from alphatank.game.scenarios import parse_scenario
from alphatank.sim.config import RewardConfig, game_config
from alphatank.sim.match import Hit

T = R.T
NOOP = (1, 1, 0)
FIRE = (1, 1, 1)


# ---- pure functions -----------------------------------------------------------------

def test_victory_goes_to_the_whole_winning_team():
    team = np.array([0, 0, 1, 2])
    assert R.victory(team, 0, 200.0).tolist() == [200, 200, 0, 0]
    assert R.victory(team, None, 200.0).tolist() == [0, 0, 0, 0]


def test_hits_enemy_teammate_and_self():
    cfg = RewardConfig()
    events = [Hit(0, 0, 2, False), Hit(1, 0, 1, True), Hit(5, 3, 3, True)]
    hit, hurt, team = R.hits(events, 4, cfg)
    assert hit.tolist() == [50, 0, 0, 0]
    assert hurt.tolist() == [0, -50, -50, -50]
    assert team.tolist() == [-5, 0, 0, 0]


def test_trajectory_eq15():
    cfg = RewardConfig()
    assert R.trajectory(10.0, 15.0, cfg) == (40.0, 0.0)
    assert R.trajectory(35.0, 15.0, cfg) == (0.0, pytest.approx(10.0 * (1 - 35 / 70)))
    assert R.trajectory(70.0, 15.0, cfg) == (0.0, 0.0)
    assert R.trajectory(math.inf, 15.0, cfg) == (0.0, 0.0)


def test_path_min_distance_agrees_with_ballistics():
    from alphatank.sim.ballistics import path_min_distance

    rng = np.random.default_rng(0)
    for k in range(50):
        path = rng.uniform(0, 700, size=(int(rng.integers(2, 8)), 2))
        if k % 10 == 0:
            path[1] = path[0]  # a zero-length leg
        targets = rng.uniform(0, 700, size=(int(rng.integers(1, 6)), 2))
        assert R.path_min_distance(path, targets) == pytest.approx(
            path_min_distance(path, targets), abs=1e-9)


def test_stateful_term_functions():
    cfg = RewardConfig(wall_hit=-1.0, wall_hit_low_ticks=2, wall_hit_high_factor=5.0,
                       stationary=-0.5, stationary_ticks=3, bfs_progress=0.5, aim_streak=2.0,
                       aim_streak_ticks=2, control_change=-0.1, control_change_ticks=2,
                       rotation=-3.0, rotation_limit_deg=90.0)
    assert R.wall_hit(np.array([0, 1, 2, 3]), cfg).tolist() == [0, -1, -1, -5]
    assert R.stationary(np.array([2, 3, 9]), cfg).tolist() == [0, -0.5, -0.5]
    assert R.bfs_progress(np.array([5, 5, -1]), np.array([4, 6, 3]), cfg).tolist() == [
        0.5, -0.5, 0.0]
    assert R.aim_streak(np.array([1, 2]), cfg).tolist() == [0, 2.0]
    assert R.control_change(np.array([[2, 0, 3], [1, 1, 1]]), cfg).tolist() == [
        pytest.approx(-0.2), 0.0]
    assert R.rotation(np.array([89.9, 90.0]), cfg).tolist() == [0, -3.0]
    assert R.streak(np.array([0, 4, 2]), np.array([True, True, False])).tolist() == [1, 5, 0]
    closer, farther = R.bullet_progress(np.array([5.0, 5.0, np.nan, 5.0]),
                                        np.array([4.0, 6.0, 1.0, np.nan]))
    assert closer.tolist() == [True, False, False, False]
    assert farther.tolist() == [False, True, False, False]


# ---- in real matches ----------------------------------------------------------------

def match_set(teams=("A", "B"), map_name="open", **rewards) -> MatchSet:
    seats = [{"team": t, "controller": "learner"} for t in teams]
    sc = parse_scenario({"name": "r", "map": map_name, "seats": seats, "rewards": rewards})
    ms = MatchSet(sc, 1)
    ms.reset_env(0, 1)
    return ms


def place(ms: MatchSet, poses) -> None:
    m = ms.matches[0]
    w = m.world
    for i, (x, y, a) in enumerate(poses):
        w.tank_bodies[i].position, w.tank_bodies[i].angle = (x, y), a
        w.tank_bodies[i].velocity = (0.0, 0.0)
        w.controls[i].position, w.controls[i].angle = (x, y), a
    w.read_state()
    ms.batch.gather(0, m)
    ms.tracker.reset_env(0, m)


def step(ms: MatchSet, *actions) -> np.ndarray:
    terms, _ = ms.step(np.array([actions], dtype=np.int64))
    return terms[0].copy()  # (terms, n)


def only(terms: np.ndarray, allowed: set[str]) -> bool:
    """No term outside ``allowed`` is non-zero."""
    return all(not terms[T[n]].any() for n in R.TERMS if n not in allowed)


def test_shot_hit_kill_and_victory_in_1v1():
    ms = match_set()
    place(ms, [(200.0, 385.0, 0.0), (330.0, 385.0, math.pi)])
    t = step(ms, FIRE, NOOP)
    assert t[T["trajectory_hit"]].tolist() == [40.0, 0.0]
    assert t[T["trajectory_distance"]].tolist() == [0.0, 0.0]
    per_step = [t.sum(axis=0)]
    closes = 0
    for _ in range(40):
        t = step(ms, NOOP, NOOP)
        per_step.append(t.sum(axis=0))
        if ms.matches[0].done:
            break
        assert only(t, {"bullet_close"}) and t[T["bullet_close"]].tolist() == [0.01, 0.0]
        closes += 1
    m = ms.matches[0]
    assert m.terminated and m.winner == "A" and closes > 5
    assert t[T["hit"]].tolist() == [50.0, 0.0]
    assert t[T["hit_penalty"]].tolist() == [0.0, -50.0]
    assert t[T["victory"]].tolist() == [200.0, 0.0]
    assert ms.outcome(0) == ["win", "loss"]
    total = np.sum(per_step, axis=0)
    assert total == pytest.approx([40 + 0.01 * closes + 50 + 200, -50.0])


def test_near_miss_scores_trajectory_distance():
    ms = match_set()
    place(ms, [(200.0, 385.0, 0.0), (330.0, 425.0, math.pi / 2)])  # 40 px off the line
    t = step(ms, FIRE, NOOP)
    assert t[T["trajectory_hit"], 0] == 0.0
    assert t[T["trajectory_distance"], 0] == pytest.approx(10.0 * (1 - 40 / 70), abs=1e-6)


def test_bullet_moving_away_is_penalised():
    ms = match_set()
    place(ms, [(385.0, 385.0, math.pi), (600.0, 385.0, 0.0)])  # fires away from the enemy
    t = step(ms, FIRE, NOOP)
    assert t[T["trajectory_distance"]].sum() == t[T["trajectory_hit"]].sum() == 0.0
    t = step(ms, NOOP, NOOP)
    assert t[T["bullet_away"]].tolist() == [-0.02, 0.0] and t[T["bullet_close"], 0] == 0.0


def test_friendly_fire_and_dead_teammate_still_wins():
    ms = match_set(("A", "A", "B"))
    # Seat 0 shoots its teammate (seat 1), then seat 2 (B) is shot by seat 0.
    place(ms, [(200.0, 200.0, 0.0), (300.0, 200.0, 0.0), (200.0, 500.0, 0.0)])
    step(ms, FIRE, NOOP, NOOP)
    for _ in range(30):
        t = step(ms, NOOP, NOOP, NOOP)
        if t[T["team_hit_penalty"]].any():
            break
    assert t[T["team_hit_penalty"]].tolist() == [-5.0, 0.0, 0.0]
    assert t[T["hit_penalty"]].tolist() == [0.0, -50.0, 0.0]
    assert t[T["hit"]].tolist() == [0.0, 0.0, 0.0]
    m = ms.matches[0]
    assert not m.alive[1] and not m.done
    while m.cooldown[0]:
        step(ms, NOOP, NOOP, NOOP)
    # Now turn seat 0 towards seat 2 (a quarter turn clockwise) and shoot it.
    place(ms, [(200.0, 300.0, math.pi / 2), tuple(m.tank_xy[1]) + (0.0,), (200.0, 500.0, 0.0)])
    step(ms, FIRE, NOOP, NOOP)
    for _ in range(40):
        t = step(ms, NOOP, NOOP, NOOP)
        if m.done:
            break
    assert m.winner == "A"
    assert t[T["victory"]].tolist() == [200.0, 200.0, 0.0]  # the dead teammate too


def test_weights_scale_and_zero_switches_off():
    ms = match_set(trajectory_hit=0.0, hit=7.0, victory=3.0, bullet_close=0.0)
    place(ms, [(200.0, 385.0, 0.0), (330.0, 385.0, math.pi)])
    t = step(ms, FIRE, NOOP)
    assert not t[T["trajectory_hit"]].any()
    for _ in range(40):
        t = step(ms, NOOP, NOOP)
        assert not t[T["bullet_close"]].any()
        if ms.matches[0].done:
            break
    assert t[T["hit"], 0] == 7.0 and t[T["victory"], 0] == 3.0


def test_wall_hit_escalates_and_resets():
    ms = match_set(wall_hit=-1.0, wall_hit_low_ticks=3, wall_hit_high_factor=5.0)
    place(ms, [(110.0, 385.0, math.pi), (600.0, 385.0, 0.0)])  # facing the left wall
    seen = []
    for _ in range(12):
        t = step(ms, (1, 2, 0), NOOP)  # drive into the wall
        seen.append(t[T["wall_hit"], 0])
    first = next(k for k, v in enumerate(seen) if v != 0)
    assert seen[first:first + 3] == [-1.0, -1.0, -1.0] and set(seen[first + 3:]) == {-5.0}
    assert not any(seen[:first]) and not ms.tracker.wall_count[0, 1]
    for _ in range(5):
        t = step(ms, (1, 0, 0), NOOP)  # back off
    assert t[T["wall_hit"], 0] == 0.0


def test_stationary_after_n_ticks_in_one_cell():
    ms = match_set(stationary=-0.5, stationary_ticks=5)
    place(ms, [(385.0, 385.0, 0.0), (600.0, 600.0, 0.0)])
    vals = [step(ms, NOOP, NOOP)[T["stationary"], 0] for _ in range(7)]
    assert vals == [0, 0, 0, 0, -0.5, -0.5, -0.5]


def test_bfs_progress_per_cell_gained():
    ms = match_set(map_name="maze", bfs_progress=1.0)
    m = ms.matches[0]
    from alphatank.sim.navigation import nav_grid
    nav = nav_grid(m.spec)
    total, start = 0.0, None
    for _ in range(60):
        if start is None:
            start = ms.tracker.bfs_prev[0, 0]
        total += step(ms, (1, 2, 0), NOOP)[T["bfs_progress"], 0]
    end = ms.tracker.bfs_prev[0, 0]
    d = nav.dist_table[nav.nodes_of(m.tank_xy)[0], nav.nodes_of(m.tank_xy)[1]]
    assert end == d and total == pytest.approx(start - end)


def test_aim_streak_every_n_aimed_ticks():
    ms = match_set(aim_streak=2.0, aim_streak_ticks=3, trajectory_hit=0.0)
    place(ms, [(200.0, 385.0, 0.0), (400.0, 385.0, math.pi)])
    vals = [step(ms, NOOP, NOOP)[T["aim_streak"]].tolist() for _ in range(6)]
    assert [v[0] for v in vals] == [0, 0, 2.0, 0, 0, 2.0]
    assert [v[1] for v in vals] == [0, 0, 2.0, 0, 0, 2.0]  # seat 1 aims back at seat 0


def test_control_change_counts_consecutive_changes():
    ms = match_set(control_change=-0.1, control_change_ticks=2)
    vals = [step(ms, (k % 2 * 2, 1, 0), NOOP)[T["control_change"], 0] for k in range(5)]
    # The rotate part changes every tick from the second tick on (1 -> 0 is the first).
    assert vals == pytest.approx([0.0, -0.1, -0.1, -0.1, -0.1])


def test_rotation_penalty_after_turning_in_place():
    ms = match_set(rotation=-1.0, rotation_limit_deg=90.0)
    place(ms, [(385.0, 385.0, 0.0), (600.0, 600.0, 0.0)])
    m = ms.matches[0]
    turned, fired = 0.0, []
    last = m.tank_angle[0]
    for k in range(70):
        v = step(ms, (2, 1, 0), NOOP)[T["rotation"], 0]
        turned += math.degrees(abs(m.tank_angle[0] - last))
        last = m.tank_angle[0]
        if v:
            fired.append(k)
            assert v == -1.0 and turned >= 90.0
            turned = 0.0
    assert len(fired) == 2


def test_episode_return_is_the_sum_of_step_rewards():
    env = VectorMatchEnv("vs_random", 2, seed=4, game_overrides={"max_steps": 150})
    env.reset()
    rng = np.random.default_rng(1)
    acc = np.zeros((2, 1))
    done = []
    for _ in range(400):
        _, rew, term, trunc, info = env.step(rng.integers(0, [3, 3, 2], size=(2, 1, 3)))
        acc += rew
        for ep in info["episodes"]:
            e = ep["env"]
            assert ep["return"] == pytest.approx(acc[e], abs=1e-3)
            assert sum(ep["terms"].values()) == pytest.approx(ep["return"], abs=1e-9)
            done.append(ep)
            acc[e] = 0.0
    assert len(done) >= 4


def test_trajectory_uses_the_game_hit_radius():
    g = game_config()
    assert R.hit_radius(g) == g.bullet_radius + g.tank_height / 2

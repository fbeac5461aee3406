"""Self-play snapshot pool: window, opponent sampling, frozen copies, ratings, persistence."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from alphatank.training.hparams import MAPPOConfig
from alphatank.training.learners import inference_state
from alphatank.training.mappo import MAPPO
from alphatank.training.selfplay import SnapshotPool


def learner(seed: int = 0) -> MAPPO:
    return MAPPO(6, 4, MAPPOConfig(), seed=seed, num_seats=2, state_dim=5)


def test_window_keeps_the_newest_and_due_follows_the_cadence():
    pool = SnapshotPool(window=3, every=100)
    assert pool.due(0)
    ids = []
    for step in range(0, 500, 100):
        ids.append(pool.add(learner(step).state_dict(), step))
        assert not pool.due(step + 50) and pool.due(step + 100)
    assert [s.id for s in pool.snapshots] == ids[-3:] and pool.latest.id == ids[-1]
    with pytest.raises(KeyError, match="not in the pool's window"):
        pool.snapshot(ids[0])
    assert pool.latest.name == "snap4@400"


def test_half_the_games_against_the_latest_the_rest_uniform_and_reproducible():
    pool = SnapshotPool(window=5, latest_share=0.5, seed=3)
    for step in range(5):
        pool.add(learner().state_dict(), step)
    picks = np.array([pool.opponent_for(e, k) for e in range(16) for k in range(250)])
    share = np.bincount(picks, minlength=5) / picks.size
    assert share[4] == pytest.approx(0.5, abs=0.03)
    assert np.allclose(share[:4], 0.125, atol=0.02)
    other = SnapshotPool(window=5, latest_share=0.5, seed=3)
    for step in range(5):
        other.add(learner().state_dict(), step)
    assert [other.opponent_for(e, k) for e in reversed(range(16)) for k in range(250)] == (
        picks.reshape(16, 250)[::-1].reshape(-1).tolist())  # order of asking is irrelevant
    single = SnapshotPool()
    single.add(learner().state_dict(), 0)
    assert {single.opponent_for(e, 0) for e in range(20)} == {0}


def test_frozen_snapshots_do_not_follow_the_learner():
    lr = learner(1)
    pool = SnapshotPool()
    sid = pool.add(inference_state("mappo", lr.state_dict()), 0)
    obs = np.random.default_rng(0).normal(size=(4, 6)).astype(np.float32)
    before = lr.policy_actions(obs, True)
    with torch.no_grad():
        for p in lr.net.actor.parameters():
            p.mul_(-3.0)
    lr.actor_np.sync(lr.net.actor)
    opp = pool.frozen(sid, lambda: learner(99))
    assert opp is pool.frozen(sid, lambda: learner(99))  # cached
    assert np.array_equal(opp.policy_actions(obs, True), before)
    assert not np.array_equal(lr.policy_actions(obs, True), before)
    assert set(pool.snapshot(sid).state) == set(MAPPO.inference_keys)


def test_ratings_move_with_results_and_timeouts_are_not_rated():
    pool = SnapshotPool(window=2)
    a = pool.add(learner().state_dict(), 0)
    for _ in range(8):
        pool.record(a, "win")
    rows = {name: mu for name, mu, _, _ in pool.ratings()}
    assert rows["learner"] > 25.0 > rows["snap0@0"]
    b = pool.add(learner().state_dict(), 100)
    assert pool.league.ratings[pool.index[b]].mu == pytest.approx(rows["learner"])
    frozen = [(r.mu, r.sigma) for r in pool.league.ratings]
    pool.record(b, "draw", truncated=True)
    assert [(r.mu, r.sigma) for r in pool.league.ratings] == frozen
    assert pool.metrics()["selfplay/timeouts"] == 1.0 and pool.games["rated"] == 8
    pool.add(learner().state_dict(), 200)
    pool.add(learner().state_dict(), 300)  # a leaves the window; its results still count
    pool.record(a, "loss")
    with pytest.raises(ValueError, match="outcome must be"):
        pool.record(b, "won")


def test_state_dict_round_trip_through_a_weights_only_file(tmp_path):
    pool = SnapshotPool(window=2, every=10, seed=4)
    for step in (0, 10, 20):
        sid = pool.add(learner(step).state_dict(), step)
        pool.record(sid, "win")
    torch.save(pool.state_dict(), tmp_path / "pool.pt")
    state = torch.load(tmp_path / "pool.pt", weights_only=True)
    other = SnapshotPool(window=2, every=10, seed=4)
    other.load_state_dict(state)
    assert [s.name for s in other.snapshots] == [s.name for s in pool.snapshots]
    assert other.ratings() == pool.ratings() and other.games == pool.games
    assert other.next_id == 3 and not other.due(25) and other.due(30)
    assert [other.opponent_for(1, k) for k in range(30)] == [pool.opponent_for(1, k)
                                                            for k in range(30)]
    obs = np.ones((4, 6), np.float32)
    make = learner
    assert np.array_equal(other.frozen(2, make).policy_actions(obs, True),
                          pool.frozen(2, make).policy_actions(obs, True))

"""GAE against hand-computed values, with a termination and a truncation inside the rollout."""

import numpy as np
import pytest
import torch

from alphatank.training.buffers import ReplayBuffer, compute_gae, compute_gae_masked
from alphatank.training.normalize import ObsNormalizer, ReturnNormalizer, RunningMeanStd
from alphatank.training.ppo import PPO, PPOConfig


def _col(values):
    return torch.tensor(values, dtype=torch.float32)[:, None]


def test_gae_hand_computed_termination_and_truncation():
    # gamma 0.9, lambda 0.8; row 1 terminates, row 2 is truncated with V(final_obs) = 10.
    rewards = _col([1.0, 2.0, 3.0, 4.0])
    values = _col([0.5, 1.0, 1.5, 2.0])
    terminated = _col([0, 1, 0, 0])
    truncated = _col([0, 0, 1, 0])
    bootstrap = _col([99.0, 99.0, 10.0, 99.0])  # only the truncated row may be read
    last = torch.tensor([3.0])
    adv, ret = compute_gae(rewards, values, terminated, truncated, bootstrap, last, 0.9, 0.8)
    # t=3: 4 + .9*3 - 2 = 4.7            (bootstraps from the value after the rollout)
    # t=2: 3 + .9*10 - 1.5 = 10.5        (truncated: V(final_obs), no carry from t=3)
    # t=1: 2 + 0 - 1 = 1.0               (terminated: no future value, no carry)
    # t=0: (1 + .9*1 - .5) + .72*1.0 = 2.12
    expected = [2.12, 1.0, 10.5, 4.7]
    assert adv[:, 0].tolist() == pytest.approx(expected, abs=1e-6)
    assert ret[:, 0].tolist() == pytest.approx([2.62, 2.0, 12.0, 6.7], abs=1e-6)


def test_gae_terminated_and_truncated_together_does_not_bootstrap():
    adv, _ = compute_gae(_col([1.0]), _col([0.0]), _col([1]), _col([1]), _col([50.0]),
                         torch.tensor([7.0]), 0.99, 0.95)
    assert adv.item() == pytest.approx(1.0)


def test_gae_without_episode_ends_matches_the_discounted_sum_and_streams_are_independent():
    rng = np.random.default_rng(0)
    t, gamma, lam = 6, 0.97, 0.9
    r = torch.tensor(rng.normal(size=(t, 2)), dtype=torch.float32)
    v = torch.tensor(rng.normal(size=(t, 2)), dtype=torch.float32)
    zeros = torch.zeros((t, 2))
    last = torch.tensor([0.3, -0.7])
    adv, _ = compute_gae(r, v, zeros, zeros, zeros, last, gamma, lam)
    v_next = torch.cat([v[1:], last[None]], dim=0)
    deltas = r + gamma * v_next - v
    for s in range(2):
        for k in range(t):
            want = sum((gamma * lam) ** j * float(deltas[k + j, s]) for j in range(t - k))
            assert float(adv[k, s]) == pytest.approx(want, abs=1e-5)
    # an end in stream 1 leaves stream 0 untouched
    term = zeros.clone()
    term[2, 1] = 1
    adv2, _ = compute_gae(r, v, term, zeros, zeros, last, gamma, lam)
    assert torch.equal(adv2[:, 0], adv[:, 0])
    assert not torch.equal(adv2[:, 1], adv[:, 1])


def _masked(rewards, values, term, trunc, boot, last, active, gamma=0.9, lam=0.8):
    return compute_gae_masked(_col(rewards), _col(values), _col(term), _col(trunc), _col(boot),
                              torch.tensor([last]), _col(active).bool(), gamma, lam)


def test_masked_gae_credits_the_team_outcome_to_the_last_live_step():
    # The seat dies on row 1 (hit penalty -50); its team wins on row 4 (+100) after a
    # time cost of -1 on row 3. Rows 2-4 are inactive: their values (99) never count.
    adv, ret = _masked([1, -50, 0, -1, 100], [2, 3, 99, 99, 99], [0, 0, 0, 0, 1],
                       [0, 0, 0, 0, 0], [77] * 5, 55.0, [1, 1, 0, 0, 0])
    # P4 = 100, P3 = -1 + .9*100 = 89, P2 = .9*89 = 80.1 (the posthumous return)
    # t=1: -50 + .9*80.1 - 3 = 19.09     (chain ends here: P is a full return)
    # t=0: (1 + .9*3 - 2) + .72*19.09 = 15.4448
    assert adv[:, 0].tolist() == pytest.approx([15.4448, 19.09, 0, 0, 0], abs=1e-4)
    assert ret[:, 0].tolist() == pytest.approx([17.4448, 22.09, 80.1, 89, 100], abs=1e-4)


def test_masked_gae_bootstraps_a_dead_tail_that_outlives_the_rollout():
    # Dead from row 2 on and the episode goes on past the rollout: the tail is
    # bootstrapped from last_values (the learner passes a living teammate's value, 20).
    adv, _ = _masked([1, -50, 0, 0], [2, 3, 99, 99], [0] * 4, [0] * 4, [0] * 4, 20.0,
                     [1, 1, 0, 0])
    # P3 = .9*20 = 18, P2 = 16.2; t=1: -50 + .9*16.2 - 3 = -38.42; t=0: 1.7 + .72*-38.42
    assert adv[:, 0].tolist() == pytest.approx([-25.9624, -38.42, 0, 0], abs=1e-4)


def test_masked_gae_truncated_dead_tail_and_a_new_episode():
    # Dead on rows 1-2; row 2 truncates (V(final) = 10); row 3 starts a new episode.
    adv, ret = _masked([1, 0, -5, 2], [2, 9, 9, 4], [0] * 4, [0, 0, 1, 0], [0, 0, 10, 0],
                       6.0, [1, 0, 0, 1])
    # t=3: 2 + .9*6 - 4 = 3.4; P2 = -5 + .9*10 = 4; P1 = .9*4 = 3.6; t=0: 1 + .9*3.6 - 2
    assert adv[:, 0].tolist() == pytest.approx([2.24, 0, 0, 3.4], abs=1e-5)
    assert ret[:, 0].tolist() == pytest.approx([4.24, 3.6, 4.0, 7.4], abs=1e-5)


def test_masked_gae_with_every_row_active_is_plain_gae():
    rng = np.random.default_rng(2)
    t, b = 9, 3
    r, v = (torch.tensor(rng.normal(size=(t, b)), dtype=torch.float32) for _ in range(2))
    term = torch.tensor(rng.random((t, b)) < 0.15, dtype=torch.float32)
    trunc = torch.tensor(rng.random((t, b)) < 0.15, dtype=torch.float32)
    boot = torch.tensor(rng.normal(size=(t, b)), dtype=torch.float32)
    last = torch.tensor(rng.normal(size=b), dtype=torch.float32)
    want = compute_gae(r, v, term, trunc, boot, last, 0.97, 0.9)
    got = compute_gae_masked(r, v, term, trunc, boot, last, torch.ones((t, b), dtype=torch.bool),
                             0.97, 0.9)
    for w, g in zip(want, got, strict=True):
        assert torch.allclose(w, g, atol=1e-6)


def test_ppo_rollout_bootstraps_truncations_from_final_obs():
    cfg = PPOConfig(num_steps=3, update_epochs=1, norm_obs=False, norm_reward=False)
    ppo = PPO(obs_dim=4, num_streams=2, cfg=cfg, seed=1)
    rng = np.random.default_rng(1)
    obs = rng.normal(size=(2, 4)).astype(np.float32)
    final = rng.normal(size=(2, 4)).astype(np.float32) * 5
    flags = [(np.array([False, False]), np.array([False, False])),
             (np.array([False, True]), np.array([True, True])),  # s0 truncated, s1 terminated
             (np.array([False, False]), np.array([False, False]))]
    for term, trunc in flags:
        ppo.act(obs)
        ppo.observe(obs, np.ones(2, np.float32), term, trunc, final_obs=final)
    with torch.no_grad():
        want = ppo.net.value(torch.from_numpy(final[:1]))
    assert ppo.buffer.bootstrap[1, 0].item() == pytest.approx(want.item())
    assert ppo.buffer.bootstrap[1, 1].item() == 0.0  # terminated: nothing to bootstrap
    assert ppo.buffer.terminated[:, 1].tolist() == [0.0, 1.0, 0.0]
    assert ppo.ready
    metrics = ppo.update(obs)
    assert np.isfinite(metrics["losses/value_loss"])
    assert not ppo.ready and ppo.updates == 1


def test_running_mean_std_matches_numpy_over_batches():
    rng = np.random.default_rng(3)
    data = rng.normal(3.0, 2.0, size=(1000, 5))
    rms = RunningMeanStd((5,), epsilon=0.0)
    rms.count = 0.0
    for chunk in np.array_split(data, 7):
        rms.update(chunk)
    np.testing.assert_allclose(rms.mean, data.mean(0), rtol=1e-10)
    np.testing.assert_allclose(rms.var, data.var(0), rtol=1e-10)


def test_obs_normalizer_round_trip_and_clip():
    norm = ObsNormalizer(3, clip=2.0)
    x = np.random.default_rng(0).normal(10.0, 3.0, size=(500, 3)).astype(np.float32)
    y = norm(x, update=True)
    assert abs(float(y.mean())) < 0.05 and y.max() <= 2.0 and y.min() >= -2.0
    other = ObsNormalizer(3)
    other.load_state_dict(norm.state_dict())
    np.testing.assert_array_equal(other(x[:5]), norm(x[:5]))
    with pytest.raises(ValueError, match="shape mismatch"):
        ObsNormalizer(4).load_state_dict(norm.state_dict())


def test_obs_normalizer_update_folds_in_without_normalising():
    x = np.random.default_rng(1).normal(-4.0, 2.0, size=(200, 3)).astype(np.float32)
    called, updated = ObsNormalizer(3), ObsNormalizer(3)
    called(x, update=True)
    updated.update(x)
    np.testing.assert_array_equal(updated(x[:7]), called(x[:7]))
    assert updated.rms.count == called.rms.count > 200
    off = ObsNormalizer(3, enabled=False)
    off.update(x)  # disabled: the statistics stay as they are, like __call__(update=True)
    assert off.rms.count < 1 and off.rms.mean.tolist() == [0.0, 0.0, 0.0]


def test_return_normalizer_resets_at_episode_end():
    rn = ReturnNormalizer(2, gamma=0.5)
    rn(np.array([1.0, 1.0]), np.array([True, False]))
    assert rn.returns.tolist() == [0.0, 1.0]


def test_replay_buffer_is_cyclic():
    buf = ReplayBuffer(5, obs_dim=1, act_dim=1)
    for i in range(3):
        x = np.full((3, 1), i, np.float32)
        buf.add(x, x, np.full(3, i, np.float32), x, np.zeros(3, np.float32))
    assert len(buf) == 5 and buf.pos == 4
    # 9 transitions into 5 slots: the 4 oldest (i=0 x3, i=1 x1) were overwritten
    assert sorted(buf.rewards.tolist()) == [1.0, 1.0, 2.0, 2.0, 2.0]
    obs, *_ = buf.sample(64, np.random.default_rng(0))
    assert set(obs[:, 0].tolist()) <= {1.0, 2.0}

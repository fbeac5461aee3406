"""SAC: the paper's eq. (33) action mapping, twin critics, targets, entropy tuning, replay."""

import pickle

import numpy as np
import pytest
import torch
from torch import nn

from alphatank.envs.gym import TankBattleEnv
from alphatank.envs.vector import VectorMatchEnv
from alphatank.game.scenarios import parse_scenario
from alphatank.training.evaluate import evaluate_learners
from alphatank.training.learners import inference_state
from alphatank.training.presets import LearnerSpec, TrainConfig
from alphatank.training.runner import Trainer
from alphatank.training.sac import (
    SAC,
    ContinuousToDiscreteWrapper,
    SACConfig,
    continuous_to_discrete,
)

torch.set_num_threads(1)


def test_equation_33_bins():
    a = np.array([[0.0, 0.0, 0.0], [0.24, 0.24, 0.49], [0.25, 0.25, 0.5],
                  [0.74, 0.74, 0.99], [0.75, 0.75, 1.0], [-0.3, 1.7, 2.0]])
    got = continuous_to_discrete(a, (3, 3, 2))
    assert got.tolist() == [[0, 0, 0], [0, 0, 0], [1, 1, 1], [1, 1, 1], [2, 2, 1], [0, 2, 1]]
    assert got.dtype == np.int64
    # every bin of every dimension is reachable and the mapping is monotone
    grid = np.linspace(0, 1, 101)[:, None].repeat(3, axis=1)
    bins = continuous_to_discrete(grid)
    assert [sorted(set(bins[:, i])) for i in range(3)] == [[0, 1, 2], [0, 1, 2], [0, 1]]
    assert (np.diff(bins, axis=0) >= 0).all()
    with pytest.raises(ValueError, match="expected 3"):
        continuous_to_discrete(np.zeros(2))


def test_wrapper_turns_the_tank_env_continuous():
    env = ContinuousToDiscreteWrapper(TankBattleEnv("vs_aggressive"))
    assert env.action_space.shape == (3,) and env.action_space.low.min() == 0.0
    assert env.action([0.9, 0.1, 0.7]).tolist() == [2, 0, 1]
    env.reset(seed=0)
    obs, reward, term, trunc, info = env.step(np.array([0.9, 1.0, 1.0], dtype=np.float32))
    assert obs.shape == env.observation_space.shape and np.isfinite(reward)
    with pytest.raises(TypeError, match="MultiDiscrete"):
        ContinuousToDiscreteWrapper(ContinuousToDiscreteWrapper(TankBattleEnv("vs_random")))


class Bandit:
    """Each step a random target in {0,1,2} is shown one-hot; reward 1 for rotate ==
    target plus 1 for fire == (target == 0); episodes last 8 steps (truncated)."""

    def __init__(self, n: int, seed: int):
        self.n, self.rng = n, np.random.default_rng(seed)
        self.t = np.zeros(n, dtype=np.int64)
        self.target = self.rng.integers(0, 3, n)

    def obs(self):
        o = np.zeros((self.n, 4), dtype=np.float32)
        o[np.arange(self.n), self.target] = 1.0
        o[:, 3] = self.rng.normal(size=self.n)
        return o

    def step(self, a):
        r = (a[:, 0] == self.target).astype(np.float32) + (a[:, 2] == (self.target == 0))
        self.t += 1
        trunc = self.t >= 8
        final = self.obs()
        self.t[trunc] = 0
        self.target = self.rng.integers(0, 3, self.n)
        return self.obs(), r, np.zeros(self.n, bool), trunc, final


@pytest.mark.slow
def test_sac_learns_a_toy_task_within_bounded_updates():
    cfg = SACConfig(hidden=64, batch_size=64, start_steps=256, update_after=256,
                    update_every=32, utd_ratio=0.5, buffer_size=20000, policy_lr=1e-3,
                    q_lr=1e-3, alpha_lr=1e-3)
    env, sac = Bandit(16, 0), SAC(4, 16, cfg, seed=0)
    obs, rewards = env.obs(), []
    # seeds 0-5 end at 1.91-1.95 a step, greedy all correct (300 steps at lr 3e-4: 1.91-1.95)
    for _ in range(150):
        a = sac.act(obs)
        obs, r, term, trunc, final = env.step(a)
        sac.observe(obs, r, term, trunc, final)
        rewards.append(float(r.mean()))
        if sac.ready:
            sac.update()
    assert np.mean(rewards[:16]) < 1.2  # uniform random play earns ~0.83
    assert np.mean(rewards[-50:]) > 1.8, np.mean(rewards[-50:])
    assert sac.grad_steps <= 0.5 * 150 * 16  # bounded by utd_ratio
    greedy = sac.policy_actions(env.obs(), deterministic=True)
    assert (greedy[:, 0] == env.target).mean() > 0.9


def test_replay_stores_final_obs_and_terminations_only():
    sac = SAC(2, 3, SACConfig(buffer_size=10, start_steps=0, update_after=100), seed=1)
    obs = np.zeros((3, 2), np.float32)
    nxt = np.ones((3, 2), np.float32)
    final = np.full((3, 2), 7.0, np.float32)
    sac.act(obs)
    sac.observe(nxt, np.array([1.0, 2.0, 3.0]), np.array([True, False, False]),
                np.array([False, True, False]), final_obs=final)
    assert sac.replay.next_obs[:3, 0].tolist() == [7.0, 7.0, 1.0]  # ended: their last obs
    assert sac.replay.dones[:3].tolist() == [1.0, 0.0, 0.0]  # truncation keeps bootstrapping
    assert sac.replay.rewards[:3].tolist() == [1.0, 2.0, 3.0]


def test_twin_critics_targets_and_entropy_tuning():
    cfg = SACConfig(hidden=16, batch_size=8, start_steps=0, update_after=8, update_every=8,
                    buffer_size=100, tau=0.1)
    sac = SAC(3, 4, cfg, seed=2)
    rng = np.random.default_rng(0)
    for _ in range(4):
        sac.act(rng.normal(size=(4, 3)).astype(np.float32))
        sac.observe(rng.normal(size=(4, 3)).astype(np.float32), rng.normal(size=4),
                    np.zeros(4, bool), np.zeros(4, bool))
    assert not torch.equal(sac.q.w1[0], sac.q.w1[1])  # two critics
    q_before = [p.detach().clone() for p in sac.q.parameters()]
    t_before = [p.detach().clone() for p in sac.q_target.parameters()]
    assert all(torch.equal(a, b) for a, b in zip(q_before, t_before, strict=True))
    alpha0 = sac.alpha
    sac._gradient_step()
    for p, t_old, t_new in zip(sac.q.parameters(), t_before, sac.q_target.parameters(),
                               strict=True):
        assert torch.allclose(t_new, 0.9 * t_old + 0.1 * p, atol=1e-6)  # Polyak average
    # the initial policy's entropy (~0 for std 1 before the sigmoid) exceeds the target
    # (-3), so automatic tuning lowers alpha
    assert sac.alpha < alpha0


def test_the_twin_critics_are_two_networks_and_load_a_checkpoint_of_two(tmp_path):
    """A state saved with two ``nn.Sequential`` critics (before the twin) loads into the
    twin: the same Q-values, and the same weights after one more Adam step."""
    torch.manual_seed(0)
    obs_dim, hidden = 5, 8
    pair = [nn.Sequential(nn.Linear(obs_dim + 3, hidden), nn.ReLU(), nn.Linear(hidden, hidden),
                          nn.ReLU(), nn.Linear(hidden, 1)) for _ in range(2)]
    params = [p for net in pair for p in net.parameters()]
    opt = torch.optim.Adam(params, lr=0.01, fused=True)
    obs, act = torch.randn(16, obs_dim), torch.rand(16, 3)

    def loss_pair() -> torch.Tensor:
        x = torch.cat([obs, act], -1)
        return sum((net(x).squeeze(-1) ** 2).mean() for net in pair)

    for _ in range(3):  # moments that are not zero
        opt.zero_grad()
        loss_pair().backward()
        opt.step()
    sac = SAC(obs_dim, 2, SACConfig(hidden=hidden, q_lr=0.01), seed=1)
    state = {k: v for k, v in sac.state_dict().items() if k not in ("q", "q_target")}
    q1, q2 = ({f"net.{k}": v for k, v in net.state_dict().items()} for net in pair)
    old = {"q1": q1, "q2": q2, "q1_target": q1, "q2_target": q2,
           "q_optimizer": opt.state_dict()}
    sac.load_state_dict({**state, **old})
    x = torch.cat([obs, act], -1)
    with torch.no_grad():
        want = torch.stack([net(x).squeeze(-1) for net in pair])
        assert torch.allclose(sac.q(obs, act), want, atol=1e-6)
        assert torch.allclose(sac.q_target(obs, act), want, atol=1e-6)
    opt.zero_grad()
    loss_pair().backward()
    opt.step()
    sac.q_optimizer.zero_grad()
    (sac.q(obs, act) ** 2).mean(1).sum().backward()
    sac.q_optimizer.step()
    with torch.no_grad():
        want = torch.stack([net(x).squeeze(-1) for net in pair])
        assert torch.allclose(sac.q(obs, act), want, atol=1e-5)
        assert not torch.allclose(sac.q_target(obs, act), want, atol=1e-5)  # moved: Adam


def test_each_sac_learner_keeps_its_own_replay_buffer(tmp_path):
    sac_cfg = SACConfig(hidden=16, batch_size=16, start_steps=16, update_after=16,
                        update_every=16, buffer_size=1000)
    cfg = TrainConfig("s2", "pair", total_steps=4 * 32, num_envs=4, rollout_steps=8,
                      wandb="disabled", checkpoint_every=0, game={"max_steps": 20},
                      learners=(LearnerSpec("sac_a", "sac", (0,), config=sac_cfg),
                                LearnerSpec("sac_b", "sac", (1,), config=sac_cfg)))
    tr = Trainer(cfg, tmp_path / "s2", progress=False)
    tr.train()
    a, b = tr.learners["sac_a"], tr.learners["sac_b"]
    assert len(a.replay) == len(b.replay) == 128
    assert a.replay is not b.replay
    assert not np.array_equal(a.replay.rewards[:128], b.replay.rewards[:128])
    assert a.grad_steps > 0 and b.grad_steps > 0


def test_a_sac_learner_that_only_plays_holds_no_replay_buffer():
    """Every SAC learner built to play (a checkpoint loaded to play, a self-play or league
    snapshot) made a full replay buffer: 158 MiB of zeros at buffer_size 100,000 (1.6 GiB
    at the default) in the pickle that env runners receive per snapshot. Now the buffer is
    made only when training plans or fills it."""
    cfg = SACConfig(buffer_size=100_000)
    trained = SAC(201, 1, cfg)
    player = SAC(201, 1, cfg)
    player.load_state_dict(inference_state("sac", trained.state_dict()), weights_only=True)
    assert len(pickle.dumps(player)) < 8 * 2**20
    x = np.random.default_rng(0).standard_normal((3, 201), dtype=np.float32)
    assert np.array_equal(player.policy_actions(x, deterministic=True),
                          trained.policy_actions(x, deterministic=True))
    trained.plan(1000)
    assert trained.replay.capacity == 100_000 and len(trained.replay) == 0


RANGE = """name: range
description: 5x5 firing range for learning tests

#######
#.....#
#.1...#
#.....#
#...2.#
#.....#
#######
"""


@pytest.mark.slow
def test_sac_learns_to_shoot_a_helpless_bot(tmp_path):
    """The learner, 2 cells from an aggressive bot of weakness 0, with the paper's
    aiming-streak shaping term on (weight 5; off by default)."""
    (tmp_path / "range.txt").write_text(RANGE)
    sc = parse_scenario({"name": "range", "map": str(tmp_path / "range.txt"),
                         "game": {"max_steps": 120}, "rewards": {"aim_streak": 5.0},
                         "seats": [{"team": "A", "controller": "learner"},
                                   {"team": "B", "controller": "bot", "bot": "aggressive",
                                    "weakness": 0.0}]})
    # a quarter of a gradient step per transition (2816 steps, ~4x fewer than ratio 1 at
    # ~10 ms each); faster learning rates and target averaging, rewards weighed more
    # against the entropy bonus and a lower entropy target keep it learning in time
    sac_cfg = SACConfig(hidden=64, batch_size=128, update_every=64, utd_ratio=0.25,
                        reward_scale=0.2, gamma=0.99, tau=0.05, policy_lr=5e-3, q_lr=5e-3,
                        alpha_lr=5e-3, target_entropy=-9.0, buffer_size=50_000)
    cfg = TrainConfig("range", "vs_aggressive", total_steps=12 * 1024, num_envs=8,
                      rollout_steps=64, wandb="disabled", checkpoint_every=0,
                      learners=(LearnerSpec("sac", "sac", (0,), config=sac_cfg),))
    tr = Trainer(cfg, tmp_path / "run", env=VectorMatchEnv(sc, 8, seed=0), progress=False)
    tr.train()
    sac = tr.learners["sac"]
    # a round every update_every transitions from update_after on: 176 rounds take the
    # transitions 993-12256 (the last 32 wait for a round), utd_ratio steps per transition
    assert sac.updates == (12 * 1024 - 1024) // 64
    assert sac.grad_steps == sac_cfg.utd_ratio * (12 * 1024 - 1024) == 2816
    first = tr.history[2]["charts/win_rate"]  # random actions (start_steps) and early play
    res = evaluate_learners(tr.learners, tr.observation_meta, {"sac": "sac"}, sc, [None],
                            games=40, seed=5, num_envs=8, deterministic=True)[0]
    # run seeds (TrainConfig.seed) 0, 1, 2: 0.2 / 0.3 / 0.11 -> 0.625 / 0.85 / 0.725
    assert first < 0.35 and res.win_rate >= 0.5, (first, res)

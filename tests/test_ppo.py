"""PPO: learns a toy task fast, masks work, and learns to shoot a helpless bot in the tank env."""

import numpy as np
import pytest
import torch

from alphatank.envs.vector import VectorMatchEnv
from alphatank.game.scenarios import parse_scenario
from alphatank.training.evaluate import evaluate_learners
from alphatank.training.ppo import (
    PPO,
    ActorCritic,
    NumpyActorCritic,
    PPOConfig,
    Tanh,
    clipped_surrogate,
    evaluate_actions,
    fold_constant,
    mlp,
    np_sample,
    run_folded,
)
from alphatank.training.presets import LearnerSpec, TrainConfig
from alphatank.training.runner import Trainer

torch.set_num_threads(1)

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


def firing_range(tmp_path) -> object:
    """A learner 2 cells (diagonally) from an aggressive bot of weakness 0 (never acts)."""
    path = tmp_path / "range.txt"
    path.write_text(RANGE)
    return parse_scenario({"name": "range", "map": str(path), "game": {"max_steps": 120},
                           "seats": [{"team": "A", "controller": "learner"},
                                     {"team": "B", "controller": "bot", "bot": "aggressive",
                                      "weakness": 0.0}]})


class ToyTargetEnv:
    """Many streams; each step a random target in {0,1,2} is shown one-hot. Reward 1 for
    rotate == target plus 1 for fire == (target == 0). Episodes last 8 steps (truncated)."""

    def __init__(self, num_streams: int, seed: int):
        self.n = num_streams
        self.rng = np.random.default_rng(seed)
        self.t = np.zeros(num_streams, dtype=np.int64)
        self.target = self.rng.integers(0, 3, num_streams)

    def obs(self) -> np.ndarray:
        o = np.zeros((self.n, 5), dtype=np.float32)
        o[np.arange(self.n), self.target] = 1.0
        o[:, 3:] = self.rng.normal(size=(self.n, 2))  # distractors
        return o

    def step(self, actions: np.ndarray):
        reward = (actions[:, 0] == self.target).astype(np.float32)
        reward += (actions[:, 2] == (self.target == 0)).astype(np.float32)
        self.t += 1
        trunc = self.t >= 8
        final = self.obs()
        self.t[trunc] = 0
        self.target = self.rng.integers(0, 3, self.n)
        return self.obs(), reward, np.zeros(self.n, bool), trunc, final


def run_toy(cfg: PPOConfig, updates: int, seed: int = 0) -> tuple[PPO, list[float]]:
    env = ToyTargetEnv(16, seed)
    ppo = PPO(obs_dim=5, num_streams=16, cfg=cfg, seed=seed)
    obs = env.obs()
    means = []
    for _ in range(updates):
        total = 0.0
        for _ in range(cfg.num_steps):
            act = ppo.act(obs)
            obs, rew, term, trunc, final = env.step(act)
            ppo.observe(obs, rew, term, trunc, final_obs=final)
            total += float(rew.mean())
        means.append(total / cfg.num_steps)
        ppo.update(obs)
    return ppo, means


def test_ppo_learns_toy_task_within_bounded_updates():
    cfg = PPOConfig(num_steps=32, update_epochs=4, learning_rate=3e-3, max_grad_norm=0.5)
    _, means = run_toy(cfg, updates=25)
    assert means[0] < 1.3  # random play earns ~0.83 per step
    assert max(means[-3:]) > 1.8, means


def test_ppo_same_seed_same_run():
    cfg = PPOConfig(num_steps=16, update_epochs=2)
    a, _ = run_toy(cfg, 2, seed=5)
    b, _ = run_toy(cfg, 2, seed=5)
    for pa, pb in zip(a.net.parameters(), b.net.parameters(), strict=True):
        assert torch.equal(pa, pb)


def test_action_mask_forbids_masked_choices_and_keeps_losses_finite():
    net = ActorCritic(4)
    obs = torch.randn(256, 4)
    mask = torch.ones(256, 8, dtype=torch.bool)
    mask[:, 7] = False  # fire = 1 forbidden
    mask[:, 0] = False  # rotate ccw forbidden
    logits = net.logits(obs, mask).detach()
    actions, logprob = np_sample(logits.numpy(), net.nvec, np.random.default_rng(0))
    assert (actions[:, 2] == 0).all() and (actions[:, 0] != 0).all()
    lp, ent = evaluate_actions(logits, torch.from_numpy(actions), net.nvec)
    assert torch.isfinite(lp).all() and torch.isfinite(ent).all()
    assert torch.allclose(lp, torch.from_numpy(logprob), atol=1e-5)  # numpy == torch


def test_numpy_mirror_matches_the_torch_network():
    net = ActorCritic(7)
    mirror = NumpyActorCritic(net)
    x = torch.randn(32, 7)
    logits, values = mirror.forward(x.numpy())
    with torch.no_grad():
        assert np.allclose(logits, net.logits(x).numpy(), atol=1e-5)
        assert np.allclose(values, net.value(x).numpy(), atol=1e-5)


def test_numpy_tanh_matches_torch_tanh_values_and_gradients():
    x = torch.randn(64, 16, dtype=torch.float32, requires_grad=True)
    y = Tanh()(x)
    y.pow(2).sum().backward()
    ref_x = x.detach().clone().requires_grad_(True)
    ref = torch.tanh(ref_x)
    ref.pow(2).sum().backward()
    assert torch.allclose(y, ref, atol=1e-6)
    assert torch.allclose(x.grad, ref_x.grad, atol=1e-6)


def test_folded_constant_columns_give_the_full_input_values_and_gradients():
    torch.manual_seed(0)
    x = torch.randn(50, 9)
    x[:, [1, 4, 5]] = torch.tensor([0.0, 2.5, -1.0])  # constant over every row
    seqs = [mlp(9, 16, 3, 1.0, Tanh) for _ in range(2)]
    seqs[1].load_state_dict(seqs[0].state_dict())
    var, fold = fold_constant(x)
    assert var.shape == (50, 6) and fold is not None
    assert torch.equal(fold[1], torch.tensor([1, 4, 5]))
    outs = [run_folded(seqs[0], var, fold), seqs[1](x)]
    assert torch.allclose(outs[0], outs[1], atol=1e-5)
    for out in outs:
        out.square().sum().backward()
    for a, b in zip(seqs[0].parameters(), seqs[1].parameters(), strict=True):
        assert torch.allclose(a.grad, b.grad, atol=1e-5)
    same, none = fold_constant(torch.randn(5, 3))
    assert none is None and same.shape == (5, 3)


def test_evaluate_actions_matches_per_head_categoricals():
    torch.manual_seed(1)
    logits = torch.randn(40, 8)
    logits[:5, 6] = -1e8  # a masked choice
    actions = torch.stack([torch.randint(0, 3, (40,)), torch.randint(0, 3, (40,)),
                           torch.randint(0, 2, (40,))], dim=1)
    actions[:5, 2] = 1
    logprob, entropy = evaluate_actions(logits, actions, (3, 3, 2))
    dists = [torch.distributions.Categorical(logits=p)
             for p in torch.split(logits, (3, 3, 2), dim=1)]
    want_lp = sum(d.log_prob(actions[:, i]) for i, d in enumerate(dists))
    want_ent = sum(d.entropy() for d in dists)
    assert torch.allclose(logprob, want_lp, atol=1e-5)
    assert torch.allclose(entropy, want_ent, atol=1e-5)


def test_clipped_surrogate_clips_ratios_and_leaves_out_zero_weight_rows():
    old = torch.zeros(4)
    new = torch.log(torch.tensor([1.5, 0.5, 1.1, 3.0]))  # ratios 1.5, 0.5, 1.1, 3.0
    adv = torch.tensor([1.0, -1.0, 2.0, 5.0])
    w = torch.tensor([1.0, 1.0, 1.0, 0.0])  # the last row is a dead seat's
    loss, kl, clipfrac = clipped_surrogate(new, old, adv, w, w.sum(), 0.2)
    # per row max(-A r, -A clip(r)): -1.2 (clipped), 0.8 (clipped), -2.2 (inside the range)
    assert loss.item() == pytest.approx((-1.2 + 0.8 - 2.2) / 3)
    assert clipfrac.item() == pytest.approx(2 / 3)  # the dead row's ratio 3.0 not counted
    r = torch.tensor([1.5, 0.5, 1.1])
    assert kl.item() == pytest.approx(((r - 1) - torch.log(r)).mean().item())
    new.requires_grad_(True)
    loss, _, _ = clipped_surrogate(new, old, adv, w, w.sum(), 0.2)
    loss.backward()
    # only the unclipped live row moves the policy: d(-A r)/d(log r) = -A r
    assert new.grad.tolist() == pytest.approx([0.0, 0.0, -2.0 * 1.1 / 3, 0.0])


def test_sampling_matches_categorical_probabilities():
    logits = np.log(np.array([[0.7, 0.2, 0.1, 0.1, 0.1, 0.8, 0.5, 0.5]], dtype=np.float32))
    actions, logprob = np_sample(np.repeat(logits, 20000, axis=0), (3, 3, 2),
                                 np.random.default_rng(1))
    freq = np.bincount(actions[:, 0], minlength=3) / 20000
    assert np.allclose(freq, [0.7, 0.2, 0.1], atol=0.015)
    greedy, _ = np_sample(logits, (3, 3, 2), np.random.default_rng(1), deterministic=True)
    assert greedy.tolist() == [[0, 2, 0]]
    heads = [np.array([0.7, 0.2, 0.1]), np.array([0.1, 0.1, 0.8]), np.array([0.5, 0.5])]
    want = sum(np.log(h[actions[:, i]]) for i, h in enumerate(heads))
    assert np.allclose(logprob, want, atol=1e-5)


def test_bad_config_is_rejected_by_name():
    with pytest.raises(ValueError, match="PPOConfig.num_steps"):
        PPOConfig(num_steps=0)
    with pytest.raises(ValueError, match="gae_lambda"):
        PPOConfig(gae_lambda=1.5)


@pytest.mark.slow
def test_ppo_learns_to_shoot_a_helpless_bot(tmp_path):
    sc = firing_range(tmp_path)
    cfg = TrainConfig("range", "vs_aggressive", total_steps=28 * 1024, num_envs=8, seed=1,
                      wandb="disabled", checkpoint_every=0,
                      learners=(LearnerSpec("ppo", "ppo", (0,), config=PPOConfig(
                          num_steps=128, update_epochs=4, learning_rate=1e-3)),))
    tr = Trainer(cfg, tmp_path / "run", env=VectorMatchEnv(sc, 8, seed=1), progress=False)
    tr.train()
    assert tr.learners["ppo"].updates == 28
    first = tr.history[1]["charts/win_rate"]  # mostly random play
    assert first < 0.5
    res = evaluate_learners(tr.learners, tr.observation_meta, {"ppo": "ppo"}, sc, [None],
                            games=100, seed=5, num_envs=8)[0]
    # 0.74 here, 0.765 over 200 games. Before numpy tanh and folded inputs (float rounding
    # only: the first updates' losses agree to 6 digits, then trajectories drift) 0.775
    # over 200 games but the first 40 games of each give 0.775 and 0.675: 40 was too few.
    assert res.win_rate >= 0.7, (first, res)


def test_action_mask_hook_reaches_the_rollout(tmp_path):
    def no_fire_no_reverse(obs):
        mask = np.ones(obs.shape[:2] + (8,), dtype=bool)
        mask[..., 3] = False  # move: backward
        mask[..., 7] = False  # fire: yes
        return mask

    cfg = TrainConfig("mask", "vs_aggressive", total_steps=2 * 64, num_envs=4,
                      wandb="disabled", checkpoint_every=0,
                      learners=(LearnerSpec("ppo", "ppo", (0,),
                                            config=PPOConfig(num_steps=16, update_epochs=1)),))
    tr = Trainer(cfg, tmp_path / "mask", progress=False, action_mask=no_fire_no_reverse)
    ppo = tr.learners["ppo"]
    seen = []
    act = ppo.act
    ppo.act = lambda x, m=None: seen.append(act(x, m)) or seen[-1]
    tr.train()
    actions = np.concatenate(seen)
    assert actions.shape == (2 * 16 * 4, 3)
    assert (actions[:, 2] == 0).all() and (actions[:, 1] != 0).all()
    assert ppo.updates == 2

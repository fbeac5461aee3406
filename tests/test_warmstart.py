"""Warm start: a 1v1 PPO learner's policy carried into a team learner, feature by name."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from alphatank.envs.core import MatchSet
from alphatank.envs.vector import VectorMatchEnv
from alphatank.training.hparams import MAPPOConfig
from alphatank.training.mappo import MAPPO
from alphatank.training.ppo import PPO, PPOConfig
from alphatank.training.presets import LearnerSpec, TrainConfig
from alphatank.training.runner import Trainer
from alphatank.training.sac import SAC
from alphatank.training.warmstart import feature_map, warm_start, warm_start_from_checkpoint

torch.set_num_threads(1)


def layouts(kind: str):
    """(1v1 layout on battlefield, 2v1 layout on arena4, a real 2v1 observation batch)."""
    src = MatchSet("vs_defensive", 1, observation=kind).obs.layout
    env = VectorMatchEnv("team_vs_def_bot", 2, seed=3, observation=kind)
    env.reset()
    rng = np.random.default_rng(0)
    for _ in range(30):
        obs, *_ = env.step(rng.integers(0, [3, 3, 2], size=(2, 2, 3)))
    return src, env.layout, obs.reshape(-1, env.obs_dim)


def trained_ppo(dim: int, seed: int = 0) -> PPO:
    """A PPO learner with non-trivial weights and normaliser statistics."""
    ppo = PPO(dim, 4, PPOConfig(), seed=seed)
    rng = np.random.default_rng(seed)
    ppo.obs_norm(rng.normal(0.3, 0.5, size=(500, dim)).astype(np.float32), update=True)
    with torch.no_grad():
        for p in ppo.net.parameters():
            p.add_(torch.randn(p.shape, generator=torch.Generator().manual_seed(seed)) * 0.3)
    ppo.mirror.sync(ppo.net)
    return ppo


def test_feature_map_matches_tanks_by_role():
    src, dst, _ = layouts("paper")
    si, di, dropped = feature_map(src, dst, src_mates=0, dst_mates=1)
    pairs = {src.fields[s]: dst.fields[d] for s, d in zip(si, di, strict=True)}
    assert pairs["self.x"] == "self.x"
    assert pairs["tank[0].rel_x"] == "tank[1].rel_x"  # the enemy, after the teammate
    assert pairs["bullet[2].dist"] == "bullet[2].dist"
    assert pairs["wall[0].x0"] == "wall[0].x0"
    assert not any(dst.fields[d].startswith("tank[0].") for d in di)  # teammate slot: new
    # battlefield has more wall rectangles and zones than arena4: those slots are dropped
    assert {src.fields[k] for k in dropped} == {
        f for f in src.fields if f.startswith(("wall[", "buff[", "debuff[")) and f not in dst}
    assert dropped.size == 21
    assert len(set(di.tolist())) == len(di)


def test_a_1v1_egocentric_policy_seeds_a_nearest_first_team_policy():
    src = MatchSet("vs_defensive", 1, observation="egocentric").obs.layout
    env = VectorMatchEnv("team_vs_def_smart", 2, seed=3, observation="egocentric_nearest")
    dst = env.layout
    si, di, _ = feature_map(src, dst, src_mates=0, dst_mates=1)
    pairs = {src.fields[s]: dst.fields[d] for s, d in zip(si, di, strict=True)}
    assert pairs["tank[0].fwd"] == "tank[1].fwd"  # the enemy: the nearest enemy
    assert pairs["ray[0].dist"] == "ray[0].dist" and pairs["self.v_fwd"] == "self.v_fwd"
    ppo = trained_ppo(src.size)
    team = PPO(dst.size, 4, PPOConfig(), seed=1)
    warm_start(team, ppo.state_dict(), src, dst, dst_mates=1)
    env.reset()
    obs, *_ = env.step(np.zeros((2, 2, 3), np.int64))
    obs = obs.reshape(-1, dst.size)
    one = np.zeros((len(obs), src.size), dtype=np.float32)
    one[:, si] = obs[:, di]
    np.testing.assert_allclose(team.mirror.forward(team.obs_norm(obs))[0],
                               ppo.mirror.forward(ppo.obs_norm(one))[0], rtol=1e-4, atol=1e-4)
    # enemies in seat order do not map onto nearest-first slots, nor other kinds
    seat_order = MatchSet("team_vs_def_smart", 1, observation="egocentric").obs.layout
    with pytest.raises(ValueError, match="at most one teammate and one enemy"):
        feature_map(seat_order, dst, src_mates=1, dst_mates=1)
    paper = MatchSet("vs_defensive", 1, observation="paper").obs.layout
    with pytest.raises(ValueError, match="cannot map a 'paper' observation"):
        feature_map(paper, dst, src_mates=0, dst_mates=1)


def test_a_nearest_first_team_policy_seeds_the_aim_kind_with_its_shot_inputs_at_zero():
    src = MatchSet("team_vs_def_smart", 1, observation="egocentric_nearest").obs.layout
    env = VectorMatchEnv("team_vs_def_smart", 2, seed=5, observation="egocentric_aim")
    dst = env.layout
    si, di, dropped = feature_map(src, dst, src_mates=1, dst_mates=1)
    assert len(dropped) == 0 and len(si) == src.size == dst.size - 3  # all but the shot
    assert [dst.fields[d] for d in di] == src.fields
    ppo = trained_ppo(src.size)
    aim = PPO(dst.size, 4, PPOConfig(), seed=2)
    warm_start(aim, ppo.state_dict(), src, dst, src_mates=1, dst_mates=1)
    env.reset()
    obs, *_ = env.step(np.zeros((2, 2, 3), np.int64))
    obs = obs.reshape(-1, dst.size)
    np.testing.assert_allclose(aim.mirror.forward(aim.obs_norm(obs))[0],
                               ppo.mirror.forward(ppo.obs_norm(obs[:, di]))[0],
                               rtol=1e-4, atol=1e-4)
    # and back: the shot block is dropped, every other feature keeps its place
    back, _, gone = feature_map(dst, src, src_mates=1, dst_mates=1)
    assert [dst.fields[k] for k in gone] == ["shot.enemy", "shot.friend", "shot.miss"]
    assert len(back) == src.size
    # on to the aim kind with paths: every feature maps by name, the path fields are new
    both = MatchSet("team_vs_def_smart", 1, observation="egocentric_aim_path").obs.layout
    si, di, dropped = feature_map(dst, both, src_mates=1, dst_mates=1)
    assert len(dropped) == 0 and [both.fields[d] for d in di] == dst.fields
    assert sorted(set(both.fields) - set(dst.fields)) == sorted(
        f"tank[{k}].path_{f}" for k in range(4) for f in ("dist", "fwd", "side"))
    # egocentric_path lists the other tanks in seat order: it cannot seed nearest first
    seat_paths = MatchSet("team_vs_def_smart", 1, observation="egocentric_path").obs.layout
    with pytest.raises(ValueError, match="at most one teammate and one enemy"):
        feature_map(seat_paths, both, src_mates=1, dst_mates=1)


@pytest.mark.parametrize("kind", ["paper", "egocentric"])
def test_warm_started_mappo_acts_as_the_1v1_network(kind):
    src, dst, team_obs = layouts(kind)
    ppo = trained_ppo(src.size)
    m = MAPPO(dst.size, 4, MAPPOConfig(), seed=1, num_seats=2)
    info = warm_start(m, ppo.state_dict(), src, dst, dst_mates=1)
    assert info["critic"] == 0 and info["mapped"] + info["dropped"] == src.size
    si, di, _ = feature_map(src, dst, 0, 1)
    # The 1v1 observation holding the same features; what the team map lacks is an empty
    # slot (zeros). The team observation's extra features (teammate, team flags, seat)
    # are real values: their weights start at zero.
    one = np.zeros((len(team_obs), src.size), dtype=np.float32)
    one[:, si] = team_obs[:, di]
    want, _ = ppo.mirror.forward(ppo.obs_norm(one))
    assert np.abs(team_obs[:, [d for d in range(dst.size) if d not in set(di)]]).sum() > 0
    for seat in (0, 1):
        got = m.actor_np.forward(m._actor_input(team_obs, np.full(len(team_obs), seat)))
        np.testing.assert_allclose(got, want, rtol=1e-4, atol=1e-4)
    assert np.array_equal(m.policy_actions(team_obs, True), ppo.policy_actions(one, True))


def test_warm_started_ppo_copies_the_critic_too():
    src, dst, team_obs = layouts("paper")
    ppo = trained_ppo(src.size, seed=2)
    team = PPO(dst.size, 4, PPOConfig(), seed=5)
    assert warm_start(team, ppo.state_dict(), src, dst, dst_mates=1)["critic"] == 1
    si, di, _ = feature_map(src, dst, 0, 1)
    one = np.zeros((len(team_obs), src.size), dtype=np.float32)
    one[:, si] = team_obs[:, di]
    want = ppo.mirror.forward(ppo.obs_norm(one))
    got = team.mirror.forward(team.obs_norm(team_obs))
    for w, g in zip(want, got, strict=True):
        np.testing.assert_allclose(g, w, rtol=1e-4, atol=1e-4)


def test_warm_start_from_a_1v1_checkpoint(tmp_path):
    cfg = TrainConfig("duel", "vs_defensive", total_steps=2 * 32 * 2, num_envs=2,
                      wandb="disabled", checkpoint_every=1,
                      learners=(LearnerSpec("ppo", "ppo", (0,),
                                            config=PPOConfig(num_steps=32, update_epochs=1)),))
    tr = Trainer(cfg, tmp_path / "duel", progress=False)
    tr.train()
    env = VectorMatchEnv("team_vs_def_bot", 1)
    m = MAPPO(env.obs_dim, 2, num_seats=2, state_dim=8)
    info = warm_start_from_checkpoint(m, tmp_path / "duel", env.layout,
                                      dst_mates=int(env.core.obs.other_team[0].sum()))
    assert info["mapped"] > 100
    src_w = tr.learners["ppo"].net.actor[2].weight
    assert torch.equal(m.net.actor[2].weight, src_w)
    with pytest.raises(ValueError, match="same hidden size"):
        warm_start_from_checkpoint(MAPPO(env.obs_dim, 2, MAPPOConfig(hidden=64), num_seats=2),
                                   tmp_path / "duel", env.layout, 1)
    with pytest.raises(ValueError, match="warm start fills PPO and MAPPO learners, not sac"):
        warm_start_from_checkpoint(SAC(env.obs_dim, 2), tmp_path / "duel", env.layout, 1)
    # A run with a SAC and a PPO learner: the PPO one starts from the checkpoint, SAC fresh.
    mixed = TrainConfig("mixed", "selfplay_1v1", total_steps=2, num_envs=1, wandb="disabled",
                        checkpoint_every=0, init_from=str(tmp_path / "duel"),
                        learners=(LearnerSpec("sac", "sac", (0,)),
                                  LearnerSpec("ppo", "ppo", (1,), config=PPOConfig(num_steps=2))))
    tr2 = Trainer(mixed, tmp_path / "mixed", progress=False)
    assert set(tr2.warm_start) == {"ppo"}
    assert torch.equal(tr2.learners["ppo"].net.actor[2].weight, src_w)
    # Its checkpoint (SAC first) seeds a run from its PPO learner, the first PPO one.
    tr2.train()
    ppo = PPO(env.obs_dim, 2)
    warm_start_from_checkpoint(ppo, tmp_path / "mixed", env.layout, 1)
    assert torch.equal(ppo.net.actor[2].weight, tr2.learners["ppo"].net.actor[2].weight)
    sac_only = TrainConfig("sac_only", "vs_defensive", total_steps=2, num_envs=1,
                           wandb="disabled", checkpoint_every=0,
                           learners=(LearnerSpec("sac", "sac", (0,)),))
    Trainer(sac_only, tmp_path / "sac_only", progress=False).train()
    with pytest.raises(ValueError, match=r"no PPO learner to warm-start from; its learners: "
                                         r"\[\('sac', 'sac'\)\]"):
        warm_start_from_checkpoint(ppo, tmp_path / "sac_only", env.layout, 1)


"""The batched engine as a gymnasium.vector.VectorEnv (make_vec) and as an SB3 VecEnv."""

from __future__ import annotations

import copy
import pickle

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import (
    check_reset_options,
    check_reset_seed_determinism,
    check_returned_data_not_reused,
)
from gymnasium.vector import AutoresetMode

import alphatank.envs as envs
from alphatank.envs import TankBattleVectorEnv, VectorMatchEnv
from alphatank.envs.vector import episode_seed
from alphatank.game.scenarios import NoopPolicy, ScenarioError

SHORT = {"max_steps": 40}


def vec(gid: str = "AlphaTank/VsRandom-v0", num_envs: int = 3, **kwargs) -> TankBattleVectorEnv:
    return gym.make_vec(gid, num_envs=num_envs, vectorization_mode="vector_entry_point",
                        **kwargs)


@pytest.mark.parametrize("gid", envs.GYM_IDS)
def test_every_id_has_the_batched_vector_entry_point(gid):
    assert gym.spec(gid).vector_entry_point == envs.VECTOR_ENTRY_POINT
    v = gym.make_vec(gid, num_envs=2)  # the default mode picks the vector entry point
    single = gym.make(gid)
    try:
        assert isinstance(v, TankBattleVectorEnv) and v.num_envs == 2
        assert v.metadata["autoreset_mode"] == AutoresetMode.SAME_STEP
        assert v.single_observation_space == single.observation_space
        assert v.single_action_space == single.action_space
        assert v.observation_space.shape == (2, *single.observation_space.shape)
        obs, info = v.reset(seed=0)
        assert obs in v.observation_space and info == {}
        assert v.spec.id == gid and v.spec.kwargs["num_envs"] == 2
    finally:
        v.close()
        single.close()


def test_gymnasium_checks_that_apply_to_vector_envs():
    v = vec(num_envs=1)
    check_reset_seed_determinism(v)
    check_reset_options(v)
    check_returned_data_not_reused(v)
    v.close()


def test_cleanrl_style_loop_with_same_step_autoreset():
    """What a CleanRL PPO script does: batched actions, final obs from infos on SAME_STEP
    autoreset, episode statistics from RecordEpisodeStatistics."""
    envs_ = gym.wrappers.vector.RecordEpisodeStatistics(
        vec(num_envs=4, game_overrides=SHORT))
    n = envs_.num_envs
    envs_.reset(seed=1)
    envs_.single_action_space.seed(0)
    returns = np.zeros(n)
    ended = 0
    for _ in range(100):
        actions = np.stack([envs_.single_action_space.sample() for _ in range(n)])
        next_obs, rew, term, trunc, infos = envs_.step(actions)
        assert next_obs.shape == (n, envs_.single_observation_space.shape[0])
        assert rew.dtype == np.float32 and term.dtype == trunc.dtype == bool
        returns += rew
        done = term | trunc
        real_next_obs = next_obs.copy()
        if done.any():
            assert np.array_equal(infos["_final_obs"], done)
            assert np.array_equal(infos["_episode"], done)
            fin = infos["final_info"]
            for i in np.flatnonzero(done):
                real_next_obs[i] = infos["final_obs"][i]
                assert not np.array_equal(real_next_obs[i], next_obs[i])
                assert envs_.unwrapped.engine.core.matches[i].tick == 0  # reset this step
                assert fin["_outcome"][i] and fin["outcome"][i] in ("win", "loss", "draw")
                assert fin["length"][i] == infos["episode"]["l"][i] <= SHORT["max_steps"]
                assert fin["return"][i] == pytest.approx(returns[i], abs=1e-3)
                assert infos["episode"]["r"][i] == pytest.approx(returns[i], abs=1e-3)
                assert sum(fin["terms"][t][i] for t in fin["terms"] if not t.startswith("_")) \
                    == pytest.approx(returns[i], abs=1e-3)
                ended += 1
            returns[done] = 0.0
        else:
            assert "final_obs" not in infos and "episode" not in infos
    assert ended >= 8
    envs_.close()


def test_same_results_as_the_engine_and_its_worker_processes_and_closed_is_said():
    def rollout(env, steps=90):
        rng = np.random.default_rng(3)
        out = [env.reset(seed=7)[0]]
        for _ in range(steps):
            obs, rew, term, trunc, info = env.step(rng.integers(0, [3, 3, 2], size=(3, 3)))
            final = np.zeros_like(obs)
            for i in np.flatnonzero(info.get("_final_obs", np.zeros(3, bool))):
                final[i] = info["final_obs"][i]
            out += [obs, rew, term, trunc, final]
        return out

    local = rollout(vec(game_overrides=SHORT))
    workers = vec(game_overrides=SHORT, num_workers=2)
    try:
        remote = rollout(workers)
        with pytest.raises(ValueError, match=r"unknown bot name\(s\) \['smartt'\]"):
            workers.set_opponents(["smartt"])  # refused here: the workers live on
        workers.step(np.ones((3, 3), dtype=np.int64))
    finally:
        workers.close()
    with pytest.raises(RuntimeError, match=r"^step\(\): the env is closed"):
        workers.step(np.ones((3, 3), dtype=np.int64))
    engine = VectorMatchEnv("vs_random", 3, game_overrides=SHORT)
    engine.reset(7)
    rng = np.random.default_rng(3)
    for k in range(90):
        obs, rew, *_ = engine.step(rng.integers(0, [3, 3, 2], size=(3, 3))[:, None])
        assert np.array_equal(obs[:, 0], local[1 + 5 * k])
        assert np.array_equal(rew[:, 0], local[2 + 5 * k])
    assert all(np.array_equal(a, b) for a, b in zip(local, remote, strict=True))


def test_make_vec_takes_max_episode_steps_as_make_does():
    """``make_vec(id, max_episode_steps=N)`` (also what an id registered with a limit
    passes) truncates each sub-env as ``make(id, max_episode_steps=N)``'s TimeLimit."""
    v = vec(num_envs=2, max_episode_steps=30)
    single = gym.make("AlphaTank/VsRandom-v0", max_episode_steps=30)
    obs, _ = v.reset(seed=4)
    one, _ = single.reset(seed=episode_seed(4, 1, 0))
    for t in range(30):
        obs, rew, term, trunc, info = v.step(np.ones((2, 3), dtype=np.int64))
        one, r, te, tr, _ = single.step(np.ones(3, dtype=np.int64))
        ended = info["final_obs"][1] if t == 29 else obs[1]
        assert np.array_equal(ended, one) and rew[1] == np.float32(r)
        assert (term[1], trunc[1]) == (te, tr) == (False, t == 29)
    assert info["final_info"]["length"].tolist() == [30, 30]
    shorter = vec(num_envs=1, max_episode_steps=30, game_overrides={"max_steps": 20})
    assert shorter.engine.core.game.max_steps == 20  # the lower limit ends the episode
    with pytest.raises(ScenarioError, match=r"^max_episode_steps: must be in \[1, 10000000\], "
                                            r"got 0$"):
        vec(max_episode_steps=0)


def test_unseeded_resets_draw_fresh_episodes():
    v = vec(num_envs=2)
    a, _ = v.reset()
    b, _ = v.reset()
    c, _ = vec(num_envs=2).reset()
    assert not np.array_equal(a, b) and not np.array_equal(a, c)


def test_errors_name_the_env_and_what_is_allowed():
    v = vec(num_envs=2)
    with pytest.raises(RuntimeError, match="before reset"):
        v.step(np.ones((2, 3), dtype=np.int64))
    v.reset(seed=0)
    bad = np.ones((2, 3), dtype=np.int64)
    bad[1, 2] = 4
    with pytest.raises(ValueError, match=r"env 1 \(seat 0, vs_random\).*fire 0\.\.1"):
        v.step(bad)
    with pytest.raises(ValueError, match=r"shape \(2, 3\)"):
        v.step(np.ones((2, 1, 3), dtype=np.int64))
    with pytest.raises(ValueError, match=r"^actions must have shape \(2, 3\) .*got nested "
                                         r"sequences of different lengths$"):
        v.step([[1, 1, 1], [1, 1]])  # not numpy's 'inhomogeneous shape' error
    with pytest.raises(ValueError, match="no options"):
        v.reset(options={"reset_mask": np.ones(2, bool)})
    with pytest.raises(TypeError, match="seed must be an int"):
        v.reset(seed=[1, 2])
    with pytest.raises(ValueError, match="render_mode must be one of"):
        vec(render_mode="human")
    with pytest.raises(ValueError, match="num_workers=1"):
        vec(render_mode="rgb_array", num_workers=2)
    with pytest.raises(ScenarioError, match=r"learner seats \[1\] have no controller"):
        vec("AlphaTank/TankBattle-v0", scenario="team_vs_bot")


def test_seeds_and_seats_are_checked_by_name_when_the_env_is_made():
    v = vec(num_envs=2)
    first, _ = v.reset(seed=np.int64(3))  # numpy integers seed as Python ints do
    again, _ = v.reset(seed=3)
    assert first.tobytes() == again.tobytes()
    with pytest.raises(ValueError, match=r"seed must be in \[0, inf\], got -1"):
        v.reset(seed=-1)
    with pytest.raises(ValueError, match=r"seed must be in \[0, inf\], got -5"):
        envs.make_vector_env("vs_random", 2, seed=-5)
    engine = envs.make_vector_env("vs_random", 2)
    with pytest.raises(ValueError, match="seed must be an integer, got 1.5"):
        engine.reset(1.5)
    with pytest.raises(ScenarioError, match=r"learner_seats \[1\] are not learner seats; "
                                            r"its learner seats: \[0\]"):
        envs.make_vector_env("vs_random", 2, learner_seats=[1])
    with pytest.raises(TypeError, match="learner_seat must be an int .*got '0'"):
        gym.make("AlphaTank/VsRandom-v0", learner_seat="0")
    assert gym.make("AlphaTank/VsRandom-v0", learner_seat=np.int64(0)).unwrapped.seat == 0


def test_gymnasium_faces_refuse_reset_options_they_would_ignore():
    single = gym.make("AlphaTank/VsRandom-v0")
    single.reset(seed=0, options={})  # empty options are no options
    with pytest.raises(ValueError, match=r"reset takes no options \(got \['bogus'\]\)"):
        single.reset(options={"bogus": 1})
    par = envs.parallel_env(scenario="team")  # PettingZoo's api_test passes options
    par.reset(seed=0, options={"options": 1})  # that every env must take: ignored
    with pytest.raises(ValueError, match=r"seed must be in \[0, inf\], got -5"):
        par.reset(seed=-5)


def test_multi_learner_scenario_drives_one_seat_like_the_single_env():
    v = vec("AlphaTank/TankBattle-v0", num_envs=2, scenario="team_vs_bot", learner_seat=1,
            seat_policies={0: NoopPolicy()})
    single = gym.make("AlphaTank/TankBattle-v0", scenario="team_vs_bot", learner_seat=1,
                      seat_policies={0: NoopPolicy()})
    assert v.single_observation_space == single.observation_space
    assert v.unwrapped.engine.learner_seats == [1] and v.learner_seat == 1
    obs, _ = v.reset(seed=0)
    assert obs.shape == (2, single.observation_space.shape[0])
    v.step(np.ones((2, 3), dtype=np.int64))
    v.close()


def test_rgb_array_render_gives_one_frame_per_env():
    v = vec(num_envs=2, render_mode="rgb_array")
    assert v.render_mode == "rgb_array" and v.metadata["render_fps"] == 30
    with pytest.raises(RuntimeError, match=r"^render\(\) before reset\(\)"):
        v.render()  # not zip()'s ValueError over no matches
    v.reset(seed=0)
    frames = v.render()
    assert len(frames) == 2 and frames[0].shape == (770, 770, 3) and frames[0].dtype == np.uint8
    for copied in (pickle.loads(pickle.dumps(v)), copy.deepcopy(v)):  # renderers left out
        copied.reset(seed=0)
        assert all(np.array_equal(a, b) for a, b in zip(copied.render(), frames, strict=True))
        copied.close()
    v.close()


def test_make_vec_action_repeat_as_make():
    v = vec(num_envs=2, action_repeat=3, max_episode_steps=4)
    v.reset(seed=0)
    v.step(np.ones((2, 3), dtype=np.int64))
    assert [m.tick for m in v.engine.core.matches] == [3, 3]
    for _ in range(3):
        _, _, _, trunc, infos = v.step(np.ones((2, 3), dtype=np.int64))
    assert trunc.all() and infos["final_info"]["length"].tolist() == [4, 4]  # steps, not ticks
    v.close()
    with pytest.raises(ValueError, match=r"^action_repeat must be a whole number of ticks"):
        vec(num_envs=2, action_repeat=31)


def test_sb3_reset_options_are_refused_not_ignored():
    from alphatank.envs.sb3 import make_sb3_env

    env = make_sb3_env("vs_random", 2, seed=0, game_overrides=SHORT)
    env.set_options(None)
    env.set_options([{}, {}])  # SB3's "no options" forms pass
    first = env.reset()
    for options in ({"map": "maze"}, [{}, {"map": "maze"}]):
        with pytest.raises(ValueError, match=r"reset takes no options \(got \['map'\]\) for SB3"):
            env.set_options(options)
    env.seed(0)
    assert np.array_equal(env.reset(), first)
    env.close()


@pytest.mark.parametrize("make", [
    lambda: gym.make("AlphaTank/VsRandom-v0"),
    lambda: gym.make_vec("AlphaTank/VsRandom-v0", num_envs=2, vectorization_mode="sync"),
    lambda: gym.wrappers.vector.RecordEpisodeStatistics(vec(num_envs=2)),
], ids=["single", "sync", "wrapped"])
def test_sb3_adapter_refuses_what_it_cannot_batch(make):
    from alphatank.envs.sb3 import SB3VecEnv

    env = make()
    with pytest.raises(TypeError, match=r"^SB3VecEnv needs make_vector_env.*got "
                                        r"(OrderEnforcing|SyncVectorEnv|RecordEpisodeStatistics);"):
        SB3VecEnv(env)
    env.close()


def test_stable_baselines3_ppo_trains_on_the_batched_env():
    from stable_baselines3 import PPO

    from alphatank.envs.sb3 import SB3VecEnv, make_sb3_env

    env = make_sb3_env("vs_random", 8, seed=0, game_overrides={"max_steps": 100})
    model = PPO("MlpPolicy", env, n_steps=128, batch_size=256, n_epochs=2, seed=0,
                device="cpu", verbose=0)
    model.learn(total_timesteps=3072)
    assert model.num_timesteps >= 3072 and len(model.ep_info_buffer) >= 16
    obs = env.reset()
    action, _ = model.predict(obs, deterministic=True)
    assert action.shape == (8, 3) and env.action_space.contains(action[0])
    env.close()
    # A multi-learner scenario: (match, learner) pairs flatten into SB3's env axis.
    team = SB3VecEnv(vec("AlphaTank/TankBattle-v0", 2, scenario="team_vs_bot",
                         seat_policies={1: NoopPolicy()}))
    assert team.num_envs == 2 and team.env_method("set_bot_weakness", 0.5) == [None] * 2
    flat = SB3VecEnv(VectorMatchEnv("team", 2, game_overrides=SHORT))
    assert flat.num_envs == 8 and flat.reset().shape == (8, flat.observation_space.shape[0])
    for _ in range(SHORT["max_steps"]):
        obs, rew, dones, infos = flat.step(np.ones((8, 3), dtype=np.int64))
        if dones.any():
            break
    assert dones.reshape(2, 4).all(axis=1).any()  # all seats of a match end together
    i = int(np.flatnonzero(dones)[0])
    assert infos[i]["terminal_observation"].shape == obs[i].shape
    assert {"episode", "outcome", "TimeLimit.truncated"} <= set(infos[i])
    with pytest.raises(ValueError, match="every env"):
        flat.env_method("set_bot_weakness", 0.5, indices=[0])
    # actions are (num_envs, 3), checked as every face checks them
    flat.reset()
    with pytest.raises(ValueError, match=r"must have shape \(8, 3\).*got \(3, 8\)"):
        flat.step_async(np.ones((3, 8), dtype=np.int64))
    bad = np.ones((8, 3), dtype=np.int64)
    bad[5, 0] = 3
    with pytest.raises(ValueError, match=r"SB3 env 5 \(match 1, learner 1\): action"):
        flat.step_async(bad)

"""Gymnasium and PettingZoo envs: API checkers, seeding, errors, pickling, SB3."""

from __future__ import annotations

import os
import pickle
import subprocess
import sys

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from pettingzoo.test import max_cycles_test, parallel_api_test, parallel_seed_test, render_test

import alphatank.envs as envs
from alphatank.envs import TankBattleEnv, parallel
from alphatank.game.scenarios import NoopPolicy, ScenarioError
from alphatank.sim.policy import NOOP


@pytest.mark.parametrize("render_mode", [None, "rgb_array", "human"])
def test_gymnasium_check_env_every_render_mode(render_mode):
    env = gymnasium.make("AlphaTank/TankBattle-v0", render_mode=render_mode)
    check_env(env.unwrapped, skip_render_check=False)
    if render_mode == "rgb_array":
        env.reset(seed=0)
        frame = env.render()
        assert frame.dtype == np.uint8 and frame.shape == (770, 770, 3)
    env.close()


def test_no_render_mode_leaves_pygame_display_alone():
    import pygame

    env = gymnasium.make("AlphaTank/VsSmart-v0")
    env.reset(seed=0)
    env.step(env.action_space.sample())
    assert not pygame.display.get_init()


def test_registered_ids():
    assert "AlphaTank/TankBattle-v0" in envs.GYM_IDS
    assert envs.gym_id("vs_smart") == "AlphaTank/VsSmart-v0"
    for gid in ("AlphaTank/VsRandom-v0", "AlphaTank/VsAggressive-v0", "AlphaTank/VsDodge-v0",
                "AlphaTank/VsSmart-v0"):
        assert gid in gymnasium.registry
    env = gymnasium.make("alphatank.envs:AlphaTank/VsDefensive-v0")
    assert env.unwrapped.core.game.bullet_max_distance == 800.0
    assert "AlphaTank/BotTeams-v0" not in gymnasium.registry  # no learner seat
    team = gymnasium.make("AlphaTank/TankBattle-v0", scenario="team_vs_bot",
                          seat_policies={1: NoopPolicy()})
    assert team.reset(seed=0)[0].shape == team.observation_space.shape


def test_same_seed_same_trajectory():
    def rollout(seed):
        env = TankBattleEnv("vs_smart")
        env.action_space.seed(seed)
        obs, _ = env.reset(seed=seed)
        out = [obs]
        for _ in range(200):
            obs, r, term, trunc, info = env.step(env.action_space.sample())
            out.append(np.append(obs, r))
            if term or trunc:
                obs, _ = env.reset()
        return np.concatenate(out)
    assert np.array_equal(rollout(3), rollout(3))
    assert not np.array_equal(rollout(3), rollout(4))


TRAJECTORY_DIGEST = """
import hashlib, sys
import numpy as np
from alphatank.envs import TankBattleEnv
from alphatank.envs.vector import VectorMatchEnv

h = hashlib.sha256()
seed = int(sys.argv[1])
env = TankBattleEnv("vs_smart")
h.update(env.reset(seed=seed)[0].tobytes())
rng = np.random.default_rng(seed)
for a in rng.integers((3, 3, 2), size=(300, 3)):
    obs, r, term, trunc, info = env.step(a)
    h.update(obs.tobytes() + np.float64(r).tobytes() + repr(sorted(info.items())).encode())
    if term or trunc:
        h.update(env.reset()[0].tobytes())
team = VectorMatchEnv("team_vs_four_bots", 2, seed=seed, observation="egocentric_full",
                      action_repeat=2)
h.update(team.reset(seed=seed).tobytes())
for a in rng.integers((3, 3, 2), size=(150, 2, 2, 3)):
    for x in team.step(a)[:4]:
        h.update(np.ascontiguousarray(x).tobytes())
print(h.hexdigest())
"""


def test_trajectories_do_not_depend_on_the_hash_seed():
    """Same seed, same trajectory in another process too: nothing on the step path may
    follow the order of a set of strings, which Python's hash seed changes per process
    (one env vs the smart bot, and the team engine with the four bots)."""
    def digest(hash_seed: str, seed: int) -> str:
        env = {**os.environ, "PYTHONHASHSEED": hash_seed}
        proc = subprocess.run([sys.executable, "-c", TRAJECTORY_DIGEST, str(seed)],
                              capture_output=True, text=True, env=env, timeout=300)
        assert proc.returncode == 0, proc.stderr[-2000:]
        return proc.stdout.strip()

    first = digest("1", 5)
    assert digest("2", 5) == first
    assert digest("1", 6) != first  # the digest follows the trajectory


def test_make_vec_sync_async_and_wrappers():
    for mode in ("sync", "async"):
        vec = gymnasium.make_vec("AlphaTank/VsRandom-v0", num_envs=2, vectorization_mode=mode)
        obs, _ = vec.reset(seed=1)
        assert obs.shape == (2, vec.single_observation_space.shape[0])
        for _ in range(20):
            obs, rew, term, trunc, _ = vec.step(vec.action_space.sample())
        assert rew.shape == (2,) and obs.dtype == np.float32
        vec.close()
    env = gymnasium.wrappers.RecordEpisodeStatistics(
        gymnasium.wrappers.TimeLimit(gymnasium.make("AlphaTank/VsRandom-v0"), 50))
    env.reset(seed=0)
    for _ in range(60):
        *_, term, trunc, info = env.step(env.action_space.sample())
        if term or trunc:
            assert "episode" in info
            break
    else:
        pytest.fail("TimeLimit did not end the episode")


@pytest.mark.parametrize("bad,match", [
    (np.array([1, 1]), "shape"),
    (np.array([1, 3, 0]), "rotate 0..2"),
    (np.array([-1, 1, 0]), "out of range"),
    (np.array([1, -1, 0]), "out of range"),
    (np.array([1, 1, 2]), "out of range"),
    (np.array([1.0, 1.0, 0.0]), "integers"),
    ("fire", "integers"),
    ([1, [1], 0], r"shape \(3,\) .*got nested sequences of different lengths$"),
])
def test_wrong_gym_actions_name_the_seat(bad, match):
    env = TankBattleEnv("vs_random")
    env.reset(seed=0)
    with pytest.raises((ValueError, TypeError), match=match) as err:
        env.step(bad)
    assert str(err.value).startswith("seat 0 (vs_random): ")


def test_gym_learner_seat_validation():
    with pytest.raises(ScenarioError, match="seat_policies"):
        TankBattleEnv("team_vs_bot")
    with pytest.raises(ScenarioError, match="learner seats"):
        TankBattleEnv("vs_smart", learner_seat=1)
    with pytest.raises(ScenarioError, match="no learner|has none"):
        TankBattleEnv("bot_teams")
    env = TankBattleEnv("team_vs_bot", learner_seat=1, seat_policies={0: NoopPolicy()})
    obs, info = env.reset(seed=0)
    assert info["seat"] == 1 and obs.shape == env.observation_space.shape


@pytest.mark.parametrize("make, what", [
    (lambda: gymnasium.make("AlphaTank/VsSmart-v0", opponent_policy="smart"),
     "opponent_policy"),
    (lambda: TankBattleEnv("team_vs_bot", seat_policies={1: "smart"}), r"seat_policies\[1\]"),
    (lambda: parallel.parallel_env(scenario="mixed_teams", seat_policies={0: "smart"}),
     r"seat_policies\[0\]"),
])
def test_a_policy_argument_that_is_not_a_policy_is_refused_when_the_env_is_made(make, what):
    with pytest.raises(TypeError, match=f"{what} must be a Policy .*make_bot.*got str 'smart'"):
        make()


def test_the_match_before_the_first_reset_is_a_clear_error():
    env = TankBattleEnv("vs_random", render_mode="rgb_array")
    for call in (lambda: env.match, env.render, lambda: env.step([1, 1, 0])):
        with pytest.raises(RuntimeError, match=r"before reset\(\)"):
            call()
    par = parallel.parallel_env(scenario="team", render_mode="rgb_array")
    for call in (par.render, par.state):
        with pytest.raises(RuntimeError, match=r"before reset\(\)"):
            call()
    par.reset(seed=0)
    assert par.render().ndim == 3 and par.state().ndim == 1


def test_overrides_that_break_a_setting_are_named_as_overrides():
    with pytest.raises(ScenarioError, match=r"^game_overrides\.max_steps: must be an integer"):
        TankBattleEnv("vs_smart", game_overrides={"max_steps": "x"})
    with pytest.raises(ScenarioError, match=r"^reward_overrides\.victory: must be a number"):
        TankBattleEnv("vs_smart", reward_overrides={"victory": "x"})


@pytest.mark.parametrize("make, match", [
    (lambda: TankBattleEnv("vs_smart", game_overrides="max_steps=600"),
     r"^game_overrides must be a dict, e\.g\. \{'max_steps': 600\}, got str"),
    (lambda: TankBattleEnv("vs_smart", game_overrides={1: 2}),
     r"^game_overrides: keys must be setting names \(strings\).*got \[1\]"),
    (lambda: TankBattleEnv("vs_smart", reward_overrides=[("victory", 1)]),
     r"^reward_overrides must be a dict, e\.g\. \{'victory': 2\.0\}, got list"),
    (lambda: TankBattleEnv("team_vs_bot", seat_policies=[NoopPolicy()]),
     r"^seat_policies must be a dict, e\.g\. \{1: .*make_bot.*got list"),
    (lambda: TankBattleEnv("team_vs_bot", seat_policies={"0": NoopPolicy()}),
     r"^seat_policies: keys must be seat indices \(ints\).*got \['0'\]"),
    (lambda: TankBattleEnv("team_vs_bot", seat_policies={True: NoopPolicy()}),
     r"^seat_policies: keys must be seat indices \(ints\).*got \[True\]"),
    (lambda: parallel.parallel_env(scenario="team", game_overrides=["max_steps"]),
     r"^game_overrides must be a dict"),
])
def test_mapping_arguments_of_the_wrong_shape_are_named(make, match):
    with pytest.raises(TypeError, match=match):
        make()


def test_an_empty_observation_kind_is_refused_not_read_as_the_default():
    with pytest.raises(ScenarioError, match=r"^observation '' is not one of \['paper'"):
        TankBattleEnv("vs_smart", observation="")


@pytest.mark.parametrize("bad, why", [(1.7, "must be an integer"), ("abc", "must be an integer"),
                                      (0, r"must be in \[1, ")])
def test_max_cycles_is_checked_by_its_own_name(bad, why):
    with pytest.raises(ScenarioError, match=f"^max_cycles: {why}"):
        parallel.parallel_env(scenario="team", max_cycles=bad)


def test_max_cycles_and_a_different_max_steps_are_refused_together():
    with pytest.raises(ScenarioError, match=r"^max_cycles 5 and game_overrides\.max_steps 50 "):
        parallel.parallel_env(scenario="team", max_cycles=5, game_overrides={"max_steps": 50})
    env = parallel.parallel_env(scenario="team", max_cycles=5, game_overrides={"max_steps": 5})
    assert env.core.game.max_steps == 5


def test_the_spaces_of_an_unknown_agent_name_the_agents():
    env = parallel.parallel_env(scenario="team")
    agents = r"\['tank_0', 'tank_1', 'tank_2', 'tank_3'\]"
    for space in (env.observation_space, env.action_space):
        with pytest.raises(KeyError, match=rf"'nope' is not an agent of this env; its agents: "
                                           rf"{agents}"):
            space("nope")
    assert env.action_space("tank_0") == env.action_space("tank_3")


def test_keep_dead_agents_must_be_a_bool():
    with pytest.raises(ScenarioError, match="^keep_dead_agents: must be true or false, got 'no'"):
        parallel.parallel_env(scenario="team", keep_dead_agents="no")


def test_a_scenario_of_the_wrong_type_is_named():
    with pytest.raises(ScenarioError, match="scenario: a shipped scenario's name.*got int 3"):
        gymnasium.make("AlphaTank/TankBattle-v0", scenario=3)


def test_dead_learner_match_is_played_out_with_its_outcome():
    env = TankBattleEnv("mixed_teams", seat_policies={5: NoopPolicy()})
    env.reset(seed=2)
    m = env.match
    m.alive[2] = False  # the learner dies (the rest of the match goes on)
    m.world.remove_tank(2)
    _, r, term, trunc, info = env.step(NOOP)
    assert m.done and (term or trunc)
    assert info["outcome"] in ("win", "loss", "draw")
    assert info["winner"] == m.winner
    if info["outcome"] == "win":
        assert info["reward_terms"]["victory"] == 200.0


def test_pettingzoo_parallel_api_seed_and_max_cycles():
    parallel_api_test(parallel.parallel_env(scenario="team"), num_cycles=400)
    parallel_api_test(parallel.parallel_env(scenario="mixed_teams"), num_cycles=200)
    parallel_seed_test(lambda: parallel.parallel_env(scenario="team_vs_bot"), num_cycles=100)
    max_cycles_test(parallel)


def test_pettingzoo_render_test():
    render_test(lambda render_mode=None: parallel.env(scenario="pair", render_mode=render_mode))


def test_pettingzoo_spaces_state_and_dead_agents():
    env = parallel.parallel_env(scenario="team")
    obs, infos = env.reset(seed=0)
    assert env.agents == ["tank_0", "tank_1", "tank_2", "tank_3"]
    assert env.observation_space("tank_0") is env.observation_space("tank_0")
    assert env.state().shape == env.state_space.shape
    m = env.core.matches[0]
    m.alive[1] = False
    m.world.remove_tank(1)
    _, rew, term, trunc, info = env.step({a: NOOP for a in env.agents})
    assert term["tank_1"] and "tank_1" not in env.agents and not term["tank_0"]
    with pytest.raises(ValueError, match="tank_1"):
        env.step({a: NOOP for a in ["tank_0", "tank_1", "tank_2", "tank_3"]})
    with pytest.raises(ValueError, match="no action for live agent"):
        env.step({"tank_0": NOOP})
    with pytest.raises(ValueError, match="tank_3.*out of range"):
        env.step({"tank_0": NOOP, "tank_2": NOOP, "tank_3": np.array([1, 1, 2])})
    with pytest.raises(ValueError, match=r"^tank_2: actions must have shape \(3,\)"):
        env.step({"tank_0": NOOP, "tank_2": np.array([1, 1]), "tank_3": NOOP})
    with pytest.raises(TypeError, match="^tank_3: actions must be integers"):
        env.step({"tank_0": NOOP, "tank_2": NOOP, "tank_3": np.array([1.0, 1.0, 0.0])})
    kept = parallel.parallel_env(scenario="team", keep_dead_agents=True)
    kept.reset(seed=0)
    kept.core.matches[0].alive[1] = False
    _, _, term, _, _ = kept.step({a: NOOP for a in kept.agents})
    assert not term["tank_1"] and "tank_1" in kept.agents


def test_pickle_round_trip():
    env = parallel.parallel_env(scenario="team_vs_bot")
    env.reset(seed=3)
    for _ in range(10):
        env.step({a: env.action_space(a).sample() for a in env.agents})
    clone = pickle.loads(pickle.dumps(env))
    assert clone.possible_agents == env.possible_agents and clone.agents == []
    assert clone.observation_space("tank_0") == env.observation_space("tank_0")
    o1, _ = env.reset(seed=9)
    o2, _ = clone.reset(seed=9)
    for _ in range(50):
        assert all(np.array_equal(o1[a], o2[a]) for a in o1)
        acts = {a: env.action_space(a).sample() for a in env.agents}
        o1, r1, *_ = env.step(acts)
        o2, r2, *_ = clone.step(acts)
        assert r1 == r2
        if not env.agents:
            break
    genv = TankBattleEnv("vs_random")
    genv.reset(seed=1)
    gclone = pickle.loads(pickle.dumps(genv))
    with pytest.raises(RuntimeError, match="reset"):
        gclone.step(NOOP)
    assert np.array_equal(gclone.reset(seed=5)[0], genv.reset(seed=5)[0])


def test_stable_baselines3_ppo_trains():
    from stable_baselines3 import PPO

    env = gymnasium.make("AlphaTank/VsRandom-v0")
    model = PPO("MlpPolicy", env, n_steps=256, batch_size=128, n_epochs=2, seed=0,
                device="cpu", verbose=0)
    model.learn(total_timesteps=512)  # two rollouts, each followed by an update
    assert model.num_timesteps >= 512 and model._n_updates == 2 * 2
    action, _ = model.predict(env.reset(seed=0)[0], deterministic=True)
    assert env.action_space.contains(action)


def test_ids_carry_the_env_version_and_checkpoints_name_their_env():
    import dataclasses

    from alphatank.envs.ids import ENV_VERSION, env_id
    from alphatank.game.scenarios import load_scenario

    assert all(gid.endswith(f"-v{ENV_VERSION}") for gid in envs.GYM_IDS)
    assert parallel.TankBattleParallelEnv.metadata["name"] == f"alphatank_v{ENV_VERSION}"
    assert env_id("vs_smart") == envs.gym_id("vs_smart") == f"AlphaTank/VsSmart-v{ENV_VERSION}"
    assert env_id("team") == env_id("bot_teams") == f"AlphaTank/TankBattle-v{ENV_VERSION}"
    changed = dataclasses.replace(load_scenario("vs_smart"), preset="long_range")
    assert env_id(changed) == f"AlphaTank/TankBattle-v{ENV_VERSION}"


def test_action_repeat_holds_each_action_for_k_ticks():
    held = gymnasium.make("AlphaTank/VsSmart-v0", action_repeat=3)
    every = gymnasium.make("AlphaTank/VsSmart-v0")
    held.reset(seed=4)
    every.reset(seed=4)
    rng = np.random.default_rng(0)
    for _ in range(10):
        a = rng.integers([3, 3, 2])
        obs, rew, *_ = held.step(a)
        obs1, rew1 = None, 0.0
        for _ in range(3):
            obs1, r, *_ = every.step(a)
            rew1 += r
        assert np.array_equal(obs, obs1) and rew == pytest.approx(rew1)
    assert held.unwrapped.match.tick == 30
    check_env(held.unwrapped, skip_render_check=True)
    with pytest.raises(ValueError, match=r"^action_repeat must be a whole number of ticks in "
                                         r"1\.\.30, got 0$"):
        gymnasium.make("AlphaTank/VsSmart-v0", action_repeat=0)

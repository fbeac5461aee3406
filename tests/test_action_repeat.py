"""Action repeat: a learner's action held for k ticks while the bots act every tick."""

import json

import numpy as np
import pytest
import torch

from alphatank.envs.core import MatchSet
from alphatank.envs.vector import SubprocVectorMatchEnv, VectorMatchEnv
from alphatank.game.scenarios import parse_scenario
from alphatank.training.checkpoint import CheckpointError, load_checkpoint, load_policy
from alphatank.training.ppo import PPOConfig
from alphatank.training.presets import FieldError, LearnerSpec, TrainConfig
from alphatank.training.runner import Trainer

torch.set_num_threads(1)

GAME = {"max_steps": 100}  # not a multiple of 3: episodes that run out end mid-step


def test_a_step_is_k_ticks_with_the_action_held():
    """Each env of a repeat-3 set matches a repeat-1 copy of it stepped up to 3 times
    with the same action: ticks, observations, summed reward terms and episode ends,
    including steps cut short by the match ending (kills, the tick limit, the play-out
    after the learner dies)."""
    k, E, rng = 3, 2, np.random.default_rng(4)
    held = MatchSet("vs_aggressive", E, game_overrides=GAME, action_repeat=k)
    singles = [MatchSet("vs_aggressive", 1, game_overrides=GAME) for _ in range(E)]
    seeds = [11, 12]
    for e in range(E):
        held.reset_env(e, seeds[e])
        singles[e].reset_env(0, seeds[e])
    cut_short = 0
    for _ in range(150):
        acts = rng.integers((3, 3, 2), size=(E, 1, 3))
        terms, obs = held.step(acts)
        for e, one in enumerate(singles):
            total = None
            for _ in range(k):
                t, o = one.step(acts[e:e + 1])
                total = t[0].copy() if total is None else total + t[0]
                if one.matches[0].done:
                    break
            m = held.matches[e]
            assert m.tick == one.matches[0].tick
            assert np.array_equal(obs[e], o[0])
            assert np.array_equal(terms[e], total)
            assert held.terminated[e] == one.terminated[0]
            assert held.truncated[e] == one.truncated[0]
            if m.done:
                cut_short += m.tick % k != 0
                seeds[e] += 100
                held.reset_env(e, seeds[e])
                one.reset_env(0, seeds[e])
    assert cut_short  # the case above was met


def test_worker_processes_hold_actions_alike():
    kw = dict(observation="egocentric", action_repeat=2)
    rng = np.random.default_rng(0)
    acts = rng.integers((3, 3, 2), size=(40, 4, 1, 3))
    runs = []
    for env in (VectorMatchEnv("vs_smart", 4, seed=2, **kw),
                SubprocVectorMatchEnv("vs_smart", 4, seed=2, num_workers=2, **kw),
                VectorMatchEnv("vs_smart", 4, seed=2, observation="egocentric")):
        try:
            assert env.action_repeat == (2 if len(runs) < 2 else 1)
            env.reset(seed=2)
            runs.append([env.step(a)[0].copy() for a in acts])
        finally:
            env.close()
    assert all(np.array_equal(a, b) for a, b in zip(runs[0], runs[1], strict=True))
    assert not all(np.array_equal(a, b) for a, b in zip(runs[0], runs[2], strict=True))


@pytest.mark.parametrize("bad", [0, 31, 1.5, True])
def test_bad_repeat_is_refused_with_the_allowed_range(bad):
    with pytest.raises(ValueError, match=r"action_repeat must be a whole number of ticks in "
                                         r"1\.\.30"):
        MatchSet("vs_aggressive", 1, action_repeat=bad)
    with pytest.raises(FieldError, match="action_repeat"):
        TrainConfig(name="r", scenario="vs_aggressive", action_repeat=bad)


def _config(repeat: int) -> TrainConfig:
    return TrainConfig(name="held", scenario="vs_aggressive", total_steps=16 * 4, num_envs=4,
                       seed=1, wandb="disabled", game={"max_steps": 40}, action_repeat=repeat,
                       learners=(LearnerSpec("ppo", "ppo", (0,), PPOConfig(
                           num_steps=16, update_epochs=1, num_minibatches=2)),))


def test_a_checkpoint_plays_as_it_trained_and_older_ones_act_every_tick(tmp_path):
    run = tmp_path / "held"
    Trainer(_config(2), run, progress=False).train()
    assert load_checkpoint(run).meta["observation"]["action_repeat"] == 2
    sc = parse_scenario({"name": "t", "map": "open", "seats": [
        {"team": "A", "controller": "learner"},
        {"team": "B", "controller": "bot", "bot": "aggressive", "weakness": 0.0}]})

    def played(policy) -> np.ndarray:
        core = MatchSet(sc, 1, driven=[], seat_policies={0: policy})
        core.reset_env(0, 7)
        rows = []
        for _ in range(30):
            core.step(np.zeros((1, 0, 3), dtype=np.int64))
            rows.append(core.joint[0, 0].copy())
        return np.array(rows)

    rows = played(load_policy(run))
    assert np.array_equal(rows[0::2], rows[1::2])  # decided at even ticks, held at odd
    assert len({tuple(r) for r in rows[0::2]}) > 1  # and it does decide
    # a checkpoint from before the setting has no action_repeat: it acts every tick
    meta_file = load_checkpoint(run).path / "meta.json"
    meta = json.loads(meta_file.read_text())
    del meta["observation"]["action_repeat"]
    meta_file.write_text(json.dumps(meta))
    old = load_policy(run)
    assert old.repeat == 1
    rows = played(old)
    assert not np.array_equal(rows[0::2], rows[1::2])
    meta["observation"]["action_repeat"] = 0
    meta_file.write_text(json.dumps(meta))
    with pytest.raises(CheckpointError, match=r"observation\.action_repeat: must be in \[1, 30\]"):
        load_policy(run)


def test_a_run_refuses_an_env_that_holds_actions_otherwise(tmp_path):
    env = VectorMatchEnv("vs_aggressive", 4, seed=1, game_overrides={"max_steps": 40})
    with pytest.raises(ValueError, match="holds actions for 1 tick.*action_repeat is 2"):
        Trainer(_config(2), tmp_path / "x", env=env, progress=False)
    env.close()

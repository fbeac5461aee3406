"""``alphatank bench --train`` / ``--sac``: the learner-cost benchmarks report real,
consistent figures (tiny sizes; the figures themselves are benchmarks, not tests)."""

from __future__ import annotations

import json

import pytest

from alphatank.cli import main
from alphatank.commands.benchtrain import sac_step_bench


def test_sac_step_bench_times_the_update_against_its_floor():
    out = sac_step_bench(obs_dim=16, steps=2, repeats=1, verbose=False)
    assert out["floor_ms"] > 0 and out["update_ms"] > 0
    assert out["ratio"] == round(out["update_ms"] / out["floor_ms"], 3)


def test_bench_train_compares_training_with_raw_env_steps(tmp_path):
    assert main(["bench", "--ticks", "50", "--repeats", "1", "--train", "--train-preset",
                 "ppo_vs_aggressive", "--train-workers", "1", "--train-envs", "2",
                 "--train-threads", "2", "--json", str(tmp_path / "b.json")]) == 0
    out = json.loads((tmp_path / "b.json").read_text())["train"]
    assert out["raw_steps_per_s"] > 0 and out["train_steps_per_s"] > 0
    assert (out["preset"], out["workers"], out["num_envs"], out["torch_threads"]) == (
        "ppo_vs_aggressive", 1, 2, 2)


@pytest.mark.parametrize("flag", ["--train-fragments", "--train-overlap"])
@pytest.mark.slow
def test_bench_train_with_fragments_says_so(tmp_path, flag):
    assert main(["bench", "--ticks", "50", "--repeats", "1", "--train", "--train-preset",
                 "ppo_vs_aggressive", "--train-workers", "2", "--train-envs", "2",
                 flag, "--train-iterations", "2", "--json", str(tmp_path / "b.json")]) == 0
    out = json.loads((tmp_path / "b.json").read_text())["train"]
    assert out["fragments"] is True and out["train_steps_per_s"] > 0
    assert out["overlap"] is (flag == "--train-overlap") and out["iterations"] == 2


def test_fragment_scaling_steps_worker_processes_a_fragment_each():
    from alphatank.commands.benchenv import RandomRollout, fragment_scaling
    from alphatank.envs.vector import VectorMatchEnv

    env = VectorMatchEnv("team", 3, seed=0)
    frag = env.rollout(RandomRollout(), env.reset(0), 40)
    assert frag.actions.min() == 0 and (frag.actions.max(axis=(0, 1, 2)) == [2, 2, 1]).all()
    rate, ratio = fragment_scaling("vs_random", 2, num_envs=2, steps=20, repeats=1)
    assert rate > 0 and ratio > 0

"""``alphatank bench --train`` / ``--sac``: the learner-cost benchmarks report real,
consistent figures (tiny sizes; the figures themselves are benchmarks, not tests)."""

from __future__ import annotations

import json

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

"""``alphatank bench --train`` / ``--sac``: the learner-cost benchmarks report real,
consistent figures (tiny sizes; the figures themselves are benchmarks, not tests)."""

from __future__ import annotations

import json
import subprocess
import sys

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
                 "--train-threads", "2", "--train-iterations", "1",
                 "--json", str(tmp_path / "b.json")]) == 0
    out = json.loads((tmp_path / "b.json").read_text())["train"]
    assert out["raw_steps_per_s"] > 0 and out["train_steps_per_s"] > 0
    assert (out["preset"], out["workers"], out["num_envs"], out["torch_threads"],
            out["iterations"]) == ("ppo_vs_aggressive", 1, 2, 2, 1)


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


def test_lockstep_scaling_times_both_sides_and_counts_every_process():
    """Two workers stepping in lockstep against one process, alternating: wall-clock
    steps/s, steps per CPU-second of all three processes and the ratio of the two
    wall-clock rates."""
    from alphatank.commands.benchenv import lockstep_scaling

    wall, cpu, ratio = lockstep_scaling("vs_random", 2, num_envs=2, steps=20, repeats=2)
    assert wall > 0 and cpu > 0 and ratio > 0


@pytest.mark.parametrize(("argv", "want"), [
    (["--steps", "0"], "argument --steps: must be an integer >= 1, got '0'"),
    (["--num-envs", "0"], "argument --num-envs: must be an integer in [1, "),
    (["--workers", "0"], "argument --workers: must be an integer >= 1, got '0'"),
    (["--repeats", "0"], "argument --repeats: must be an integer >= 1, got '0'"),
    (["--scenarios", "nope"], "--scenarios: unknown scenario 'nope'"),
], ids=["steps", "num-envs", "workers", "repeats", "scenario"])
def test_benchenv_refuses_bad_settings_in_one_line(argv, want):
    """`python -m alphatank.commands.benchenv` (docs/environments.md) with a bad size or
    scenario: one line, exit 2, nothing measured (it ended in tracebacks)."""
    proc = subprocess.run([sys.executable, "-m", "alphatank.commands.benchenv", *argv],
                          capture_output=True, text=True, timeout=300)
    assert (proc.returncode, proc.stdout) == (2, "")
    assert proc.stderr.count("\n") == 1 and want in proc.stderr, proc.stderr


@pytest.mark.parametrize(("argv", "want"), [
    (["--workers", "0"], "argument --workers: must be an integer >= 1, got '0'"),
    (["--num-envs", "5000"], "argument --num-envs: must be an integer in [1, "),
    (["--rounds", "x"], "argument --rounds: must be an integer >= 1, got 'x'"),
    (["--torch-threads", "0"], "argument --torch-threads: must be an integer >= 1, got '0'"),
    (["--preset", "nope"], "--preset nope: unknown training preset 'nope'"),
], ids=["workers", "num-envs", "rounds", "torch-threads", "preset"])
def test_benchtrain_refuses_bad_settings_in_one_line(argv, want):
    """`python -m alphatank.commands.benchtrain --train` takes the flags' types of
    `alphatank bench --train`: a bad value is one line naming the flag, exit 2, nothing
    measured (0 workers or threads ended in tracebacks)."""
    proc = subprocess.run([sys.executable, "-m", "alphatank.commands.benchtrain", "--train",
                           *argv], capture_output=True, text=True, timeout=300)
    assert (proc.returncode, proc.stdout) == (2, "")
    assert proc.stderr.count("\n") == 1 and want in proc.stderr, proc.stderr


def test_benchtrain_asked_for_nothing_says_so_and_checks_settings_before_torch():
    """Neither --train nor --sac is one line, exit 2 (it measured nothing and exited 0);
    a bad preset is refused before torch and the runner load (it took seconds)."""
    proc = subprocess.run([sys.executable, "-m", "alphatank.commands.benchtrain"],
                          capture_output=True, text=True, timeout=300)
    assert (proc.returncode, proc.stdout) == (2, "")
    assert proc.stderr == "error: nothing to measure: give --train, --sac or both\n"
    code = ("import sys\nfrom alphatank.commands.benchtrain import TrainBench\n"
            "try:\n    TrainBench('nope')\nexcept ValueError as exc:\n    print(exc)\n"
            "print(sorted(m for m in ('torch', 'alphatank.training.runner') if m in sys.modules))")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=300, check=True)
    said = proc.stdout.splitlines()
    assert said[0].startswith("unknown training preset 'nope'") and said[1] == "[]", said


def test_benchenv_with_one_process_leaves_the_worker_columns_blank(capsys):
    """--workers 1 skips the worker variants: their columns read '-' (they read 0), and
    a run shorter than the warm-up's 10 steps works."""
    from alphatank.commands.benchenv import env_bench

    out = env_bench(["vs_random"], num_envs=1, steps=2, workers=1)
    assert "workers_steps_per_s" not in out["vs_random"]
    row = capsys.readouterr().out.splitlines()[-1].split()
    assert row[0] == "vs_random" and row[-5:] == ["-"] * 5

"""``alphatank train`` as data: --config, --scenario, --map, --schedule, --curriculum and
--hp build the run (checked through --print-config, which --config reads back), and every
bad value is a one-line error naming the flag and what is allowed."""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import re
import shutil
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from alphatank.cli import main
from alphatank.errors import InputError
from alphatank.training.checkpoint import load_checkpoint
from alphatank.training.hparams import PPOConfig
from alphatank.training.presets import get_preset, iteration_steps, load_run, planned_steps
from alphatank.training.runner import Trainer, resume_trainer


def printed_run(capsys, tmp_path, *argv: str):
    """The run that ``train --print-config ARGV`` prints, read back as a run file."""
    assert main(["train", "--print-config", *argv]) == 0
    out = capsys.readouterr().out
    path = tmp_path / "printed.toml"
    path.write_text(out)
    return load_run(path)


def test_map_schedule_and_hp_flags_build_the_run(capsys, tmp_path):
    cfg = printed_run(capsys, tmp_path, "--preset", "ppo_vs_smart", "--map", "train",
                      "--schedule", "cycle:random", "--hp", "ppo.update_epochs=4",
                      "--ppo", "num_steps=128", "--total-steps", "400000", "--name", "mine")
    assert (cfg.name, cfg.scenario, cfg.map, cfg.total_steps) == ("mine", "vs_smart", "train",
                                                                  400_000)
    assert cfg.schedule == {"kind": "cycle", "mode": "random", "interval": 50_000,
                            "pool": ["random", "aggressive", "defensive", "dodge"]}
    assert cfg.learners[0].config == PPOConfig(update_epochs=4, num_steps=128)
    # a preset's own cycle keeps its pool and interval; only the mode changes
    cyc = printed_run(capsys, tmp_path, "--preset", "ppo_cycle", "--schedule", "cycle:fixed")
    assert cyc.schedule == {**get_preset("ppo_cycle").schedule, "mode": "fixed"}
    none = printed_run(capsys, tmp_path, "--preset", "ppo_cycle", "--schedule", "none")
    assert none.schedule == {}


def test_ppo_and_sac_flags_repeat_as_hp_does(capsys, tmp_path):
    """A second --ppo replaced the first (its update_epochs=4 was dropped, silently)."""
    cfg = printed_run(capsys, tmp_path, "--preset", "sac_vs_ppo", "--ppo", "update_epochs=4",
                      "--ppo", "num_steps=64", "--sac", "tau=0.01", "--sac", "batch_size=64")
    sac, ppo = cfg.learners
    assert (ppo.config.update_epochs, ppo.config.num_steps) == (4, 64)
    assert (sac.config.tau, sac.config.batch_size) == (0.01, 64)


def test_a_run_file_whose_name_cannot_name_a_folder_takes_name_from_the_flag(capsys, tmp_path):
    """'my run.toml' was refused as the run's name even with --name given (the file's
    name was checked first), in words that did not say where the name came from."""
    path = tmp_path / "my run.toml"
    path.write_text("scenario = 'vs_smart'\n")
    assert main(["train", "--print-config", "--config", str(path)]) == 2
    assert capsys.readouterr().err == (
        f"alphatank train: error: {path}: name: the run is named after its file, 'my run', "
        "which cannot name its folder (letters, digits, '_', '.' or '-', not starting with "
        "'.'); add name = \"...\" to the file or give --name\n")
    assert printed_run(capsys, tmp_path, "--config", str(path), "--name", "mine").name == "mine"


def test_curriculum_flag(capsys, tmp_path):
    cfg = printed_run(capsys, tmp_path, "--preset", "ppo_vs_smart", "--curriculum")
    assert cfg.schedule == {"kind": "curriculum", "start": 0.1, "end": 0.8}
    cfg = printed_run(capsys, tmp_path, "--preset", "ppo_vs_smart", "--curriculum",
                      "0.2:0.9:sigmoid")
    assert cfg.schedule == {"kind": "curriculum", "start": 0.2, "end": 0.9, "shape": "sigmoid"}
    kept = printed_run(capsys, tmp_path, "--preset", "ppo_curriculum_smart", "--curriculum")
    assert kept.schedule == get_preset("ppo_curriculum_smart").schedule


def test_scenario_flag_refits_learners_of_the_first_kind(capsys, tmp_path):
    cfg = printed_run(capsys, tmp_path, "--preset", "demo", "--scenario", "team_vs_bot")
    assert capsys.readouterr().err == ""  # the note went out before the capture was read
    assert cfg.scenario == "team_vs_bot"
    fast = get_preset("demo").learners[0].config
    assert [(s.name, s.algo, s.seats, s.config) for s in cfg.learners] == [
        ("ppo_0", "ppo", (0,), fast), ("ppo_1", "ppo", (1,), fast)]
    same = printed_run(capsys, tmp_path, "--preset", "sac_vs_ppo", "--scenario", "selfplay_1v1")
    assert same.learners == get_preset("sac_vs_ppo").learners  # they fit: kept


@pytest.mark.parametrize("argv,error", [
    (["--schedule", "cycle:sometimes"],
     "--schedule: got 'cycle:sometimes'; allowed: none, cycle:fixed, cycle:random, "
     "cycle:adaptive"),
    (["--curriculum", "0.1"], "--curriculum: expected START:END[:SHAPE]"),
    (["--curriculum", "0.1:2"], "--curriculum: expected START:END[:SHAPE]"),
    (["--curriculum", "0.1:0.5:cubic"], "--curriculum: expected START:END[:SHAPE]"),
    (["--schedule", "cycle:fixed", "--curriculum"], "--schedule and --curriculum: give one"),
    (["--scenario", "pair", "--schedule", "cycle:fixed"],
     "--schedule: scenario 'pair' has no bot seats to schedule"),
    (["--map", "nowhere"], "--map: scenarios/vs_aggressive.toml (map 'nowhere'): map: "
                           "unknown map 'nowhere'"),
    (["--scenario", "nowhere"], "--scenario: unknown scenario 'nowhere'"),
    (["--hp", "ppo.gamma=2"], "--hp ppo.gamma: must be in [0, 1], got 2.0"),
    (["--hp", "sac.tau=0.1"], "--hp sac.*: this run has no sac learner"),
    (["--hp", "ppo.anchor_kl=0.5"], "--hp ppo.*: 'ppo': anchor_kl = 0.5 needs a warm "
                                    "start to pull towards (an imitate table or init_from)"),
    # --ppo and --sac errors name them as typed (they named the --hp spelling)
    (["--ppo", "gamma=2"], "--ppo gamma: must be in [0, 1], got 2.0"),
    (["--sac", "tau=0.1"], "--sac: this run has no sac learner (its learners use ppo)"),
    (["--ppo", "anchor_kl=0.5"], "--ppo: 'ppo': anchor_kl = 0.5 needs a warm start"),
    (["--ppo", "clip_coef=0.1", "--hp", "ppo.clip_coef=0.3"],
     "--ppo clip_coef: ppo.clip_coef is also set by --hp ppo.clip_coef; give it once"),
    (["--workers", "3", "--num-envs", "2"], "--workers: 3 worker processes for 2 matches; "
                                            "at most one per match"),
    (["--preset", "demo", "--num-envs", "1"], "presets/demo.toml: num_workers: 2 worker "
                                              "processes for 1 matches; at most one per match"),
    (["--preset", "nope"], "--preset: unknown training preset 'nope'"),
    (["--preset", "ppo_vs_agressive"], "--preset: unknown training preset 'ppo_vs_agressive'; "
                                       "valid: ['demo', "),
    (["--config", "missing.toml"], "missing.toml: no such run file"),
    (["--config", "x.toml", "--preset", "demo"], "--config and --preset: give one"),
])
def test_bad_flags_are_one_line_errors(capsys, argv, error):
    assert main(["train", "--print-config", *argv]) == 2
    cap = capsys.readouterr()  # notes (on stderr) may come first; the error is one line
    lines = cap.err.splitlines()
    assert cap.out == "" and lines[-1].startswith(f"alphatank train: error: {error}"), cap.err
    assert all(ln.startswith("note: ") for ln in lines[:-1]), cap.err


@pytest.mark.parametrize("flag,value,allowed", [
    ("--num-envs", "0", "an integer in [1, 4096]"),
    ("--num-envs", "5000", "an integer in [1, 4096]"),
    ("--total-steps", "0", "an integer >= 1"),
    ("--workers", "0", "an integer >= 1"),
    ("--eval-games", "0", "an integer >= 1"),
    ("--torch-threads", "x", "an integer in [1, 1024]"),
    ("--torch-threads", "100000", "an integer in [1, 1024]"),  # torch crashed (SIGSEGV)
    ("--env-runners", "0", "an integer >= 1"),
    ("--checkpoint-every", "-1", "an integer >= 0"),
    ("--keep-checkpoints", "-1", "an integer >= 0"),
    ("--eval-every", "-1", "an integer >= 0"),
    ("--video-every", "1.5", "an integer >= 0"),
    ("--action-repeat", "0", "an integer in [1, 30]"),
    ("--action-repeat", "31", "an integer in [1, 30]"),
    ("--time-limit", "-1", "a number in [0, 604800]"),
    ("--time-limit", "1e10", "a number in [0, 604800]"),
    ("--time-limit", "nan", "a number in [0, 604800]"),
    ("--env-runner-timeout", "0", "a finite number > 0"),
    ("--env-runner-timeout", "inf", "a finite number > 0"),
])
@pytest.mark.parametrize("resume", [False, True])
def test_bad_counts_are_usage_errors_before_anything_runs(capsys, tmp_path, flag, value, allowed,
                                                          resume):
    """The run's counts, --action-repeat, --time-limit and --env-runner-timeout take the
    project's argument types (as eval, bench and benchenv do): one usage line naming the
    flag and what is allowed, exit 2, before a preset, a checkpoint (--resume: it read the
    checkpoint first, and --num-envs 0 said the run plays 16 matches) or a folder (the
    last three were checked after parsing, --time-limit after the preset was read)."""
    where = ["--resume", str(tmp_path / "runs" / "old")] if resume else [
        "--runs", str(tmp_path / "runs")]
    with pytest.raises(SystemExit) as exited:
        main(["train", *where, "--wandb", "disabled", "--no-progress", flag, value])
    assert exited.value.code == 2
    cap = capsys.readouterr()
    assert cap.out == "" and cap.err == (f"alphatank train: error: argument {flag}: must be "
                                         f"{allowed}, got '{value}' (see alphatank train "
                                         "--help)\n")
    assert not any(tmp_path.iterdir())


def test_more_env_runners_than_envs_are_refused_before_ray_starts(capsys, tmp_path):
    """The count does not depend on the cluster: no Ray is joined (the address has none,
    which would be the error) or started, nor a run folder made."""
    assert main(["train", "--ray", "127.0.0.1:1", "--env-runners", "9", "--num-envs", "4",
                 "--runs", str(tmp_path), "--wandb", "disabled", "--no-progress"]) == 2
    cap = capsys.readouterr()
    assert cap.out == "" and cap.err == ("alphatank train: error: --env-runners: 9 runners "
                                         "for 4 envs; at most --num-envs\n")
    assert not any(tmp_path.iterdir())


def test_resume_refuses_new_run_flags(capsys, tmp_path):
    assert main(["train", "--resume", str(tmp_path), "--hp", "ppo.gamma=0.9", "--map",
                 "open"]) == 2
    assert capsys.readouterr().err == ("alphatank train: error: --map, --hp apply to new runs; "
                                       "a resumed run keeps its settings\n")


def test_resuming_with_more_steps_says_what_the_longer_span_stretches(capsys, tmp_path):
    """A curriculum ramps over total_steps and annealing decays over them: extending a run
    stretches both, so the weakness steps back. The resume says so."""
    common = ["--wandb", "disabled", "--no-progress"]
    assert main(["train", "--preset", "ppo_curriculum_smart", "--num-envs", "2",
                 "--total-steps", "128", "--runs", str(tmp_path), "--name", "c",
                 "--hp", "ppo.num_steps=32,ppo.update_epochs=1,ppo.anneal_lr=true",
                 *common]) == 0
    capsys.readouterr()
    assert main(["train", "--resume", str(tmp_path / "c"), "--total-steps", "256",
                 *common]) == 0
    note = [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("note:")]
    assert note == ["note: --total-steps 256 (the run was planned for 128): the curriculum's "
                    "weakness ramp and the learning-rate annealing are stretched over 256 "
                    "steps from the run's start, back to where step 128 falls in them"]
    assert main(["train", "--resume", str(tmp_path / "c"), *common]) == 0  # 256 again: quiet
    assert "note:" not in capsys.readouterr().err


def test_help_and_list_show_every_hyperparameter(capsys):
    with pytest.raises(SystemExit):
        main(["train", "--help"])
    text = capsys.readouterr().out
    for name in ("ppo.clip_coef", "ppo.update_epochs", "sac.utd_ratio", "sac.tau",
                 "--hp ALGO.FIELD=VALUE", "--schedule", "--curriculum", "--map", "--config"):
        assert name in text, name
    assert main(["train", "--list"]) == 0
    out = capsys.readouterr().out
    assert re.search(r"team_ppo_vs_ppo_ippo +team +ppo x4 +4\.5\.1", out)
    assert "sac + ppo" in out and "sac.buffer_size" in out


def test_a_run_file_trains_on_the_training_maps(capsys, tmp_path):
    run = tmp_path / "tiny.toml"
    run.write_text('scenario = "vs_random"\nmap = "train"\ntotal_steps = 32\nnum_envs = 2\n'
                   'wandb = "disabled"\n[[learners]]\nname = "p"\n[learners.config]\n'
                   'num_steps = 16\nupdate_epochs = 1\n')
    assert main(["train", "--config", str(run), "--runs", str(tmp_path), "--no-progress"]) == 0
    ck = load_checkpoint(tmp_path / "tiny")
    assert ck.train_config.map == "train" and len(ck.scenario.maps) == 16
    assert ck.learner_specs[0].config.num_steps == 16
    capsys.readouterr()
    saved = printed_run(capsys, tmp_path, "--resume", str(tmp_path / "tiny"), "--total-steps",
                        "64")
    assert saved == dataclasses.replace(ck.train_config, total_steps=64)
    assert main(["train", "--resume", str(tmp_path / "nope")]) == 2
    assert capsys.readouterr().err.startswith(
        f"alphatank train: error: {tmp_path / 'nope'}: no such checkpoint")


def test_a_scenario_seat_that_does_not_fit_is_refused_before_the_run_folder(capsys, tmp_path):
    """An agent seat trained for 2 tanks and 11 wall slots, in a 3-tank match or on a map
    with more walls: one line naming the seat before the run folder is made (it failed at
    the first reset, with worker processes as a traceback)."""
    seats = ('[[seats]]\nteam = "A"\ncontroller = "learner"\n[[seats]]\nteam = "B"\n'
             'controller = "agent"\nagent = "ppo_vs_smart"\n')
    third = '[[seats]]\nteam = "B"\ncontroller = "bot"\nbot = "smart"\n'
    for name, text, why in (
            ("three", f'name = "three"\nmap = "arena4"\n{seats}{third}',
             "expects 236 observation features (paper, 2 tanks); seat 1 of this match "
             "(3 tanks, teams ['A', 'B', 'B']) gives"),
            ("maze", f'name = "maze"\nmap = "maze"\n{seats}',
             "map 'maze' has 15 wall rectangles; its 'paper' observation has room for 11")):
        scenario = tmp_path / f"{name}.toml"
        scenario.write_text(text)
        runs = tmp_path / f"runs_{name}"
        assert main(["train", "--preset", "ppo_vs_smart", "--scenario", str(scenario),
                     "--runs", str(runs), "--num-envs", "2", "--workers", "2",
                     "--total-steps", "128", "--wandb", "disabled", "--no-progress"]) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"alphatank train: error: {scenario}: seats[1] "
                              "(agent:ppo_vs_smart) does not fit: "), err
        assert why in err and err.count("\n") == 1, err
        assert not runs.exists()  # the --runs folder the run made is removed again


def test_a_run_that_fails_to_start_removes_only_the_folders_it_made(capsys, tmp_path):
    """An error while the trainer is made, after it locked the run's folder (here SAC with
    --fragments, refused once its env is made): the --runs folders the run made are removed
    again (they were left behind, empty); a --runs folder that was there before stays."""
    argv = ["train", "--preset", "sac_vs_aggressive", "--fragments", "--num-envs", "2",
            "--workers", "1", "--total-steps", "512", "--wandb", "disabled", "--no-progress"]
    assert main([*argv, "--runs", str(tmp_path / "new" / "runs")]) == 2
    err = capsys.readouterr().err
    assert "fragments are acted by PPO and MAPPO learners only" in err and err.count("\n") == 1
    assert not any(tmp_path.iterdir())
    (tmp_path / "empty").mkdir()
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "notes.txt").write_text("mine")
    for runs in ("empty", "full"):
        assert main([*argv, "--runs", str(tmp_path / runs)]) == 2
    assert sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*")) == [
        "empty", "full", "full/notes.txt"]


def test_self_play_and_league_runs_skip_the_fit_of_seats_they_fill(capsys, tmp_path):
    """Self-play and a league put their own opponents in every seat no learner drives: an
    agent seat that does not fit (trained for 2 tanks, in a 4-tank match; trained in a
    team of 2, in a team of 3) never plays, so those runs start; a plain run of the same
    scenario, or a league run that evaluates against the scenario's own seats, is still
    refused naming the seat."""
    learner, bot = 'controller = "learner"\n', 'controller = "bot"\nbot = "smart"\n'
    for name, *seats in (("four", ("A", learner), ("A", bot), ("B", learner),
                          ("B", 'controller = "agent"\nagent = "ppo_vs_smart"\n')),
                         ("teams", ("A", learner), ("B", learner), ("B", bot),
                          ("B", 'controller = "agent"\nagent = "team_vs_2smart"\n'))):
        (tmp_path / f"{name}.toml").write_text(f'name = "{name}"\nmap = "arena4"\n' + "".join(
            f'[[seats]]\nteam = "{team}"\n{kind}' for team, kind in seats))
    run = ('scenario = "{scenario}"\nobservation = "egocentric"\nnum_envs = 2\n'
           'total_steps = 64\ncheckpoint_every = 0\nwandb = "disabled"\n'
           'game = {{ max_steps = 30 }}\n{extra}\n'
           '[[learners]]\nname = "ppo"\nseats = {seats}\n'
           '[learners.config]\nnum_steps = 32\nupdate_epochs = 1\n')
    league = '[schedule]\nkind = "league"\nbots = ["random"]\nweaknesses = [1.0]\nsnapshots = 0\n'
    for name, scenario, agent, extra, seats, rc in (
            ("selfplay", "four", "ppo_vs_smart", "[selfplay]\nwindow = 2\nevery = 64\n", "[0]", 0),
            ("league", "four", "ppo_vs_smart", league, "[0, 1]", 0),
            ("plain", "four", "ppo_vs_smart", "", "[0, 1]", 2),
            ("league_eval", "four", "ppo_vs_smart", "eval_every = 1\n" + league, "[0, 1]", 2),
            ("league_teams", "teams", "team_vs_2smart", league, "[0, 1]", 0),
            ("plain_teams", "teams", "team_vs_2smart", "", "[0, 1]", 2)):
        path = tmp_path / f"{name}.toml"
        sc_path = tmp_path / f"{scenario}.toml"
        path.write_text(run.format(scenario=sc_path, extra=extra, seats=seats))
        runs = tmp_path / f"runs_{name}"
        assert main(["train", "--config", str(path), "--runs", str(runs),
                     "--no-progress"]) == rc, name
        err = capsys.readouterr().err
        if rc:
            assert err.startswith(f"alphatank train: error: {sc_path}: seats[3] "
                                  f"(agent:{agent}) does not fit: "), err
            assert err.count("\n") == 1 and not any(runs.glob("*")), err
            if scenario == "teams":
                assert "plays in a team of 3 against a team of 1; it trained in a team of 2" \
                    in err, err
        else:
            assert load_checkpoint(runs / name).meta["progress"]["global_step"] >= 64, name


TINY_RUN = ('scenario = "vs_random"\ntotal_steps = 32\nnum_envs = 2\nwandb = "disabled"\n'
            '[[learners]]\nname = "p"\n[learners.config]\nnum_steps = 16\nupdate_epochs = 1\n')


def test_a_time_limit_beyond_a_week_is_refused_before_anything_runs(capsys, tmp_path):
    """A time limit of 1e10 s overflowed the SIGALRM timer once training began (a
    traceback, and an empty run folder left): a run file's time_limit_s is one line naming
    it, exit 2, before a folder is made or a run resumed (the flag is a usage error:
    test_bad_counts_are_usage_errors_before_anything_runs)."""
    runs = tmp_path / "runs"
    argv = ["train", "--runs", str(runs), "--wandb", "disabled", "--no-progress",
            "--num-envs", "2", "--total-steps", "32"]
    run = tmp_path / "tiny.toml"
    run.write_text("time_limit_s = 1e30\n" + TINY_RUN)
    assert main([*argv, "--config", str(run)]) == 2
    assert capsys.readouterr().err == (f"alphatank train: error: {run}: time_limit_s: must be "
                                       f"in [0, 604800], got 1e+30\n")
    assert not runs.exists()
    run.write_text("time_limit_s = 604800\n" + TINY_RUN)  # a week is allowed
    assert main([*argv, "--config", str(run)]) == 0
    capsys.readouterr()
    assert load_checkpoint(runs / "tiny").meta["progress"]["global_step"] == 32


def test_a_checkpoint_saved_with_a_time_limit_beyond_a_week_resumes(capsys, tmp_path):
    """Limits were not capped once (--time-limit 1e6 trained): such a checkpoint's saved
    limit reads as the cap, or as the resume's --time-limit; its settings did not load."""
    runs, run = tmp_path / "runs", tmp_path / "tiny.toml"
    run.write_text(TINY_RUN)
    common = ["--wandb", "disabled", "--no-progress"]
    assert main(["train", "--runs", str(runs), "--config", str(run), *common]) == 0
    meta_file = load_checkpoint(runs / "tiny").path / "meta.json"
    meta = json.loads(meta_file.read_text())
    meta["train_config"]["time_limit_s"] = 1e6
    meta_file.write_text(json.dumps(meta))
    assert load_checkpoint(runs / "tiny").train_config.time_limit_s == 604800
    assert main(["train", "--resume", str(runs / "tiny"), "--total-steps", "64",
                 *common]) == 0
    assert load_checkpoint(runs / "tiny").train_config.time_limit_s == 604800
    meta_file = load_checkpoint(runs / "tiny").path / "meta.json"
    meta = json.loads(meta_file.read_text())
    meta["train_config"]["time_limit_s"] = 1e6
    meta_file.write_text(json.dumps(meta))
    assert main(["train", "--resume", str(runs / "tiny"), "--total-steps", "96",
                 "--time-limit", "60", *common]) == 0
    ckpt = load_checkpoint(runs / "tiny")
    assert (ckpt.meta["progress"]["global_step"], ckpt.train_config.time_limit_s) == (96, 60)


@contextlib.contextmanager
def unwritable(folder: Path) -> Iterator[None]:
    """``folder`` cannot be written in while the block runs: read-only by its mode, or for
    root (whom the mode does not stop) immutable (``chattr +i``); skips the test where
    neither works."""
    mode = folder.stat().st_mode
    folder.chmod(0o555)
    immutable = False
    if os.access(folder, os.W_OK) and shutil.which("chattr"):
        immutable = subprocess.run(["chattr", "+i", str(folder)],
                                   capture_output=True).returncode == 0
    try:
        if os.access(folder, os.W_OK):
            pytest.skip("cannot make a folder unwritable here (root without chattr +i)")
        yield
    finally:
        if immutable:
            subprocess.run(["chattr", "-i", str(folder)], check=True)
        folder.chmod(mode)


def test_a_resume_into_folders_it_cannot_write_is_refused_before_training(capsys, tmp_path):
    """A resumed run whose checkpoints folder (or run folder, or the folder its lock goes
    in) cannot be written trained its whole budget, then failed at the save with a bare
    '[Errno 1] ... .tmp' line: it is one line naming the folder, before training, as a new
    run's --runs is. resume_trainer (a resume from Python) refuses them too: the check was
    the command's alone."""
    runs = tmp_path / "runs"
    run = tmp_path / "tiny.toml"
    run.write_text(TINY_RUN)
    assert main(["train", "--config", str(run), "--runs", str(runs), "--no-progress"]) == 0
    capsys.readouterr()
    run_dir = runs / "tiny"
    metrics = (run_dir / "metrics.jsonl").read_text()
    for folder in (run_dir / "checkpoints", run_dir, runs):
        with unwritable(folder):
            assert main(["train", "--resume", str(run_dir), "--total-steps", "64",
                         "--no-progress"]) == 2
            with pytest.raises(InputError, match=re.escape(
                    f"--resume: {folder}: {folder.absolute()} is not writable")):
                resume_trainer(run_dir, progress=False, total_steps=64)
        cap = capsys.readouterr()
        assert cap.out == "" and cap.err == (f"alphatank train: error: --resume: {folder}: "
                                             f"{folder.absolute()} is not writable\n")
        assert (run_dir / "metrics.jsonl").read_text() == metrics
        assert load_checkpoint(run_dir).meta["progress"]["global_step"] == 32
    assert main(["train", "--resume", str(run_dir), "--total-steps", "64",
                 "--no-progress"]) == 0
    assert load_checkpoint(run_dir).meta["progress"]["global_step"] == 64


def test_total_steps_are_rounded_up_to_whole_iterations_as_help_and_plan_say(capsys, tmp_path):
    """The step count is checked between iterations: --total-steps 1500 of SAC (512 vector
    steps x 2 matches an iteration) trains 2,048 steps, planned_steps' figure; --help says
    so (it said 'env steps to train in total'), and a note at the start (there was none);
    a whole number of iterations gets no note."""
    assert main(["train", "--preset", "sac_vs_aggressive", "--num-envs", "2",
                 "--total-steps", "1500", "--runs", str(tmp_path), "--wandb", "disabled",
                 "--no-progress", "--hp", "sac.hidden=16,sac.batch_size=16,sac.utd_ratio=0.05,"
                 "sac.buffer_size=4096"]) == 0
    ck = load_checkpoint(tmp_path / "sac_vs_aggressive")
    assert (iteration_steps(ck.train_config), planned_steps(ck.train_config)) == (1024, 2048)
    assert ck.meta["progress"]["global_step"] == 2048
    cap = capsys.readouterr()
    assert "run " + str(tmp_path / "sac_vs_aggressive") + ": 2,048 steps" in cap.out
    assert cap.err.splitlines() == ["note: --total-steps 1,500 rounded up to 2,048 (whole "
                                    "iterations of 1,024 env steps)"], cap.err
    assert main(["train", "--resume", str(tmp_path / "sac_vs_aggressive"), "--total-steps",
                 "3072", "--no-progress"]) == 0
    assert "rounded" not in capsys.readouterr().err
    assert load_checkpoint(tmp_path / "sac_vs_aggressive").meta["progress"][
        "global_step"] == 3072
    with pytest.raises(SystemExit):
        main(["train", "--help"])
    assert "rounded up to a whole iteration" in " ".join(capsys.readouterr().out.split())


@pytest.mark.parametrize("preset,changes", [
    ("ppo_vs_aggressive", {}), ("team_vs_def", {}), ("sac_vs_ppo", {}),
    ("sac_vs_aggressive", {"rollout_steps": 64, "checkpoint_every": 0})])
def test_iteration_steps_are_the_trainers(tmp_path, preset, changes):
    """iteration_steps (what --list plans with) is the trainer's iteration: PPO's and
    MAPPO's rollout, SAC's default, the longest of a mix, a run's own rollout_steps."""
    cfg = dataclasses.replace(get_preset(preset), num_envs=2, wandb="disabled", **changes)
    tr = Trainer(cfg, tmp_path / preset, progress=False)
    try:
        assert tr.rollout_steps * tr.E == iteration_steps(cfg)
        assert tr.total_iterations * iteration_steps(cfg) == planned_steps(cfg)
    finally:
        tr.env.close()
        tr.logger.close()
        tr.lock.release()


def test_a_resume_whose_metrics_are_not_text_is_one_line_naming_the_file(capsys, tmp_path):
    """A metrics.jsonl that is not UTF-8 (a damaged disk, a binary copied over it) stopped
    the resume with a bare "'utf-8' codec can't decode byte 0xff ..." naming no file: it is
    one line naming it, as `alphatank plot` says, the file and the checkpoint left as
    they were; once the file is text again the run resumes."""
    runs, run = tmp_path / "runs", tmp_path / "tiny.toml"
    run.write_text(TINY_RUN)
    assert main(["train", "--config", str(run), "--runs", str(runs), "--no-progress"]) == 0
    capsys.readouterr()
    metrics = runs / "tiny" / "metrics.jsonl"
    damaged = metrics.read_bytes() + b"\xff\xfe garbage\n"
    metrics.write_bytes(damaged)
    argv = ["train", "--resume", str(runs / "tiny"), "--total-steps", "64", "--no-progress"]
    assert main(argv) == 2
    cap = capsys.readouterr()
    assert cap.out == "" and cap.err.count("\n") == 1, cap.err
    assert cap.err.startswith(f"alphatank train: error: {metrics}: not a UTF-8 text file "), \
        cap.err
    assert metrics.read_bytes() == damaged
    assert load_checkpoint(runs / "tiny").meta["progress"]["global_step"] == 32
    metrics.write_bytes(damaged.replace(b"\xff\xfe", b""))  # one line of junk: dropped
    assert main(argv) == 0
    assert load_checkpoint(runs / "tiny").meta["progress"]["global_step"] == 64
    assert "garbage" not in metrics.read_text()


def test_a_resume_with_more_workers_than_matches_names_the_flag(capsys, tmp_path):
    """--workers above the run's matches read "num_workers must be a whole number in
    1..num_envs=2, got 3", naming no flag: it is one line naming --workers (the new-run
    form: test_bad_flags_are_one_line_errors), the run left as it was."""
    runs, run = tmp_path / "runs", tmp_path / "tiny.toml"
    run.write_text(TINY_RUN)
    assert main(["train", "--config", str(run), "--runs", str(runs), "--no-progress"]) == 0
    capsys.readouterr()
    metrics = (runs / "tiny" / "metrics.jsonl").read_text()
    assert main(["train", "--resume", str(runs / "tiny"), "--total-steps", "64",
                 "--workers", "3", "--no-progress"]) == 2
    assert capsys.readouterr().err == ("alphatank train: error: --workers: 3 worker processes "
                                       "for 2 matches; at most one per match (fewer --workers "
                                       "or more --num-envs)\n")
    assert (runs / "tiny" / "metrics.jsonl").read_text() == metrics
    assert load_checkpoint(runs / "tiny").meta["progress"]["global_step"] == 32


def test_a_rollout_that_is_not_whole_learner_rollouts_names_the_run_file(capsys, tmp_path):
    """rollout_steps that are not a multiple of a learner's num_steps were refused once the
    trainer was made, in a line naming neither the file nor num_steps: it is the run file's
    rollout_steps, with the learners' num_steps after --hp, before anything runs."""
    run = tmp_path / "r.toml"
    run.write_text('scenario = "vs_aggressive"\nrollout_steps = 100\n')
    argv = ["train", "--config", str(run), "--runs", str(tmp_path / "runs"), "--no-progress"]
    assert main([*argv, "--print-config"]) == 2
    assert capsys.readouterr().err == (
        f"alphatank train: error: {run}: rollout_steps: 100 must be a multiple of every "
        "learner's rollout length, num_steps ({'ppo': 512})\n")
    assert main([*argv, "--print-config", "--hp", "ppo.num_steps=50"]) == 0
    assert "rollout_steps = 100" in capsys.readouterr().out
    assert not (tmp_path / "runs").exists()


def test_the_learners_replay_buffers_must_fit_together(capsys, tmp_path):
    """Each SAC replay buffer was checked alone against the memory available (allocated
    lazily, the first takes none of it yet): two buffers of 60% each passed and would have
    filled the machine hours into the run. Now the second is refused before the run starts."""
    from alphatank.training.buffers import available_memory

    avail = available_memory()
    if avail is None:
        pytest.skip("no MemAvailable on this system")
    size = int(0.6 * avail / (4 * (2 * 201 + 3 + 2)))  # over half of it per buffer
    assert main(["train", "--preset", "sac_vs_sac", "--num-envs", "1", "--runs",
                 str(tmp_path), "--wandb", "disabled", "--no-progress", "--hp",
                 f"sac.buffer_size={size}"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"buffer_size = {size:,}" in err[0], err
    assert "besides the" in err[0] and "lower buffer_size" in err[0], err
    assert not (tmp_path / "sac_vs_sac").exists()



PROBE = ("import sys\nfrom alphatank.cli import main\ncode = main(sys.argv[1:])\n"
         "print('torch' in sys.modules, code)\n")


def test_a_run_in_use_is_refused_before_torch_is_loaded(tmp_path, held_elsewhere):
    """A second train on a run another process holds (a new run before its first save, or
    a resume) is refused at once: it went through its start-up first (torch, checkpoint,
    env workers: about 30 s on a loaded machine) before it was told."""
    new = ["--preset", "ppo_vs_aggressive", "--total-steps", "64", "--num-envs", "2",
           "--workers", "1", "--wandb", "disabled", "--no-progress", "--runs", str(tmp_path)]
    assert main(["train", *new, "--name", "done"]) == 0
    for args, folder in (([*new, "--name", "busy"], tmp_path / "busy"),
                         (["--resume", str(tmp_path / "done")], tmp_path / "done")):
        with held_elsewhere(folder) as pid:
            run = subprocess.run([sys.executable, "-c", PROBE, "train", *args],
                                 capture_output=True, text=True, timeout=120)
        assert run.stdout.split()[-2:] == ["False", "2"], (run.stdout, run.stderr)
        assert re.search(f"{re.escape(str(folder))}: pid {pid} on .* is using it",
                         run.stderr), run.stderr


@pytest.mark.parametrize(("scenario", "seats"), [("pair", "[0, 1]"), ("team", "[0, 2]")])
def test_a_mappo_learner_over_two_teams_is_refused_before_the_run_folder(capsys, tmp_path,
                                                                         scenario, seats):
    """A MAPPO learner is one team's (its critic's team values and a dead seat's credit are
    its teammates'): one driving both sides of a 1v1 or seats of both teams trained, its
    dead seats bootstrapped from enemies' values. It is refused, naming the file."""
    other = '\n[[learners]]\nname = "red"\nalgo = "mappo"\nseats = [1, 3]\n' \
        if scenario == "team" else ""
    run = tmp_path / "r.toml"
    run.write_text(f'scenario = "{scenario}"\n\n[[learners]]\nname = "blue"\nalgo = "mappo"\n'
                   f'seats = {seats}\n{other}')
    argv = ["train", "--config", str(run), "--runs", str(tmp_path / "runs"), "--no-progress",
            "--total-steps", "100", "--wandb", "disabled"]
    assert main(argv) == 2
    assert capsys.readouterr().err == (
        f"alphatank train: error: {run}: learners: mappo learner 'blue' drives seats {seats} "
        f"of teams ['A', 'B'] in scenario '{scenario}'; a mappo learner drives the seats of "
        "one team (one learner per team)\n")
    assert not (tmp_path / "runs").exists()


def test_learner_rollouts_that_do_not_divide_the_longest_name_the_run_file(capsys, tmp_path):
    """Without rollout_steps the iteration is the longest num_steps; learners whose num_steps
    do not divide it were refused only once the trainer was being made, in a line naming
    neither the file nor a setting the user gave ('rollout_steps 128'). Now the run file's
    rollout_steps is named, with a common multiple that works."""
    run = tmp_path / "r.toml"
    run.write_text('scenario = "pair"\n\n[[learners]]\nname = "a"\nalgo = "ppo"\nseats = [0]\n'
                   'config = {num_steps = 96}\n\n[[learners]]\nname = "b"\nalgo = "ppo"\n'
                   'seats = [1]\nconfig = {num_steps = 128}\n')
    argv = ["train", "--config", str(run), "--runs", str(tmp_path / "runs"), "--no-progress",
            "--print-config"]
    assert main(argv) == 2
    assert capsys.readouterr().err == (
        f"alphatank train: error: {run}: rollout_steps: 0 (the longest num_steps, 128) must be "
        "a multiple of every learner's rollout length, num_steps ({'a': 96, 'b': 128}); set "
        "rollout_steps to a common multiple, e.g. 384\n")
    run.write_text(run.read_text().replace('scenario = "pair"\n',
                                           'scenario = "pair"\nrollout_steps = 384\n'))
    assert main(argv) == 0


@pytest.mark.parametrize("flag", ["--fragments", "--overlap"])
def test_a_run_that_cannot_act_in_fragments_names_the_flag_given(capsys, tmp_path, flag):
    """SAC with --overlap was refused as 'fragments: ...', naming no flag the user gave; the
    line now starts with the flag given, and no run folder is left."""
    argv = ["train", "--preset", "sac_vs_aggressive", flag, "--num-envs", "2", "--workers",
            "1", "--total-steps", "100", "--wandb", "disabled", "--no-progress", "--runs",
            str(tmp_path / "runs")]
    assert main(argv) == 2
    assert capsys.readouterr().err == (
        f"alphatank train: error: {flag}: this run cannot act in fragments: fragments are "
        "acted by PPO and MAPPO learners only; this run has ['sac (sac)'] (SAC acts step by "
        "step)\n")
    assert not (tmp_path / "runs").exists()

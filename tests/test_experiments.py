"""``alphatank experiments`` end to end on a tiny table (two rows, a few hundred steps):
training, evaluation, md/csv/json, heatmap and curves; --resume redoes nothing finished;
a failing row is reported while the other finishes; the shipped tables all load."""

import argparse
import contextlib
import csv
import dataclasses
import io
import json
import os
import re
import shlex
import shutil
import signal
import threading
import time
from pathlib import Path

import pytest

from alphatank.cli import main
from alphatank.commands.experiments import add_arguments
from alphatank.game.seats import agent_path
from alphatank.training.aggregate import pool_runs
from alphatank.training.checkpoint import load_checkpoint
from alphatank.training.experiments import (
    EVAL_SEED_BASE,
    LATER_SETTINGS,
    RunInterrupted,
    execute,
    load_tables,
    make_plan,
    mixed_env,
    row_config,
    run_job,
    settings_digest,
    table_names,
)
from alphatank.training.presets import TrainConfig
from alphatank.training.report import RowResult, run_checks

RUN = """
[run]
scenario = "vs_random"
observation = "egocentric"
num_envs = 4
checkpoint_every = 0
game = {{ max_steps = 120 }}
{extra}
[[run.learners]]
name = "ppo"
[run.learners.config]
num_steps = 64
update_epochs = 1
"""

TABLE = """
title = "Tiny: two rows"
layout = "matrix"
average = true
heatmap = true
[[columns]]
name = "random"
label = "Random"
scenario = "vs_random"
[[columns]]
name = "dodge"
label = "Dodge"
scenario = "vs_dodge"
[[checks]]
kind = "beats_paper"
"""


def write_rows(root: Path, broken: bool = False) -> Path:
    table = root / "tiny"
    table.mkdir(parents=True)
    (table / "_table.toml").write_text(TABLE)
    (table / "a_random.toml").write_text('title = "Random Bot"\norder = 1\n'
                                         'paper = { random = 50, dodge = 10 }\n'
                                         'eval_game = { max_steps = 60 }\n'
                                         + RUN.format(extra=""))
    cycle = ('title = "Cycle"\norder = 2\nscenarios = ["vs_random", "vs_dodge"]\n'
             + RUN.format(extra='schedule = { kind = "cycle", pool = ["random", "dodge"], '
                                'mode = "fixed", scale_victory = false }')
             + '[budget_fractions]\n"schedule.interval" = 0.25\n')
    if broken:  # the paper observation of the open map is smaller: fails when training
        cycle = cycle.replace('observation = "egocentric"', 'observation = "paper"') \
                     .replace('"vs_dodge"]', '"vs_aggressive"]', 1)
    (table / "b_cycle.toml").write_text(cycle)
    return root


def cli(*args: str) -> int:
    return main(["experiments", *args])


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    root = write_rows(tmp_path_factory.mktemp("exp"))
    out = tmp_path_factory.mktemp("out")
    rc = cli("tiny", "--experiments-dir", str(root), "--out", str(out), "--steps", "512",
             "--games", "4", "--budget", "2", "--no-progress")
    return root, out, rc


def copy_of_made(made, tmp_path) -> tuple[Path, list[str]]:
    """A copy of the finished plan of :func:`made` to damage, and the arguments that
    plan it."""
    root, made_out, _ = made
    out = tmp_path / "out"
    shutil.copytree(made_out, out)
    return out, ["tiny", "--experiments-dir", str(root), "--out", str(out), "--steps", "512",
                 "--games", "4", "--budget", "2", "--no-progress"]


def test_two_rows_train_evaluate_and_report(made):
    root, out, rc = made
    assert rc == 0
    md = (out / "tiny.md").read_text()
    assert "| Random Bot |" in md and "| Cycle " in md and "(paper 50%)" in md
    assert "alphatank experiments tiny" in md and "1,000,000 + s" in md
    assert "openskill" in md and "Dodge Bot" in md  # agents and bots rated together
    assert (out / "figures" / "tiny_heatmap.png").stat().st_size > 0
    assert (out / "figures" / "tiny_curves.png").stat().st_size > 0
    data = json.loads((out / "tiny.json").read_text())
    assert [r["row"] for r in data["rows"]] == ["a_random", "b_cycle"]
    cell = data["rows"][0]["columns"]["random"]
    assert cell["paper"] == 50 and len(cell["per_seed"]) == 1 and cell["per_seed"][0]["games"] == 4
    assert data["checks"][0]["kind"] == "beats_paper" and not data["missing"]
    with open(out / "tiny.csv") as f:
        lines = list(csv.DictReader(f))
    assert [(x["row"], x["column"]) for x in lines] == [
        (r, c) for r in ("a_random", "b_cycle") for c in ("random", "dodge", "average")]
    runs = sorted((out / "runs").iterdir())
    assert len(runs) == 2 and all((r / "done.json").is_file() for r in runs)
    cycle = json.loads((runs[1] / "row.json").read_text())
    assert cycle["cfg"]["schedule"]["interval"] == 128  # 1/4 of 512 steps
    assert cycle["cfg"]["time_limit_s"] == 120.0 and cycle["scenarios"] == ["vs_random",
                                                                            "vs_dodge"]
    evals = [json.loads(p.read_text()) for p in (runs[0] / "eval").iterdir()]
    assert {e["spec"]["seed"] for e in evals} == {EVAL_SEED_BASE}
    assert {e["spec"]["scenario"] for e in evals} == {"vs_random", "vs_dodge"}
    # the row's eval_game plays over the run's own game (max_steps 120 in training)
    assert all(e["spec"]["game"] == {"max_steps": 60} for e in evals)
    assert max(max(e["lengths"]) for e in evals) <= 60
    assert data["rows"][0]["eval_game"] == {"max_steps": 60} and "max_steps = 60" in md
    cycle_evals = [json.loads(p.read_text()) for p in (runs[1] / "eval").iterdir()]
    assert all("game" not in e["spec"] or not e["spec"]["game"] for e in cycle_evals)
    assert max(max(e["lengths"]) for e in cycle_evals) > 60


def test_resume_redoes_nothing_finished(made, capsys):
    root, out, _ = made
    args = ["tiny", "--experiments-dir", str(root), "--out", str(out), "--steps", "512",
            "--games", "4", "--budget", "2", "--no-progress"]
    assert cli(*args) == 2  # results exist: --resume is needed
    assert "--resume" in capsys.readouterr().err
    done = {p: p.stat().st_mtime_ns for p in out.glob("runs/*/done.json")}
    evals = sorted(out.glob("runs/*/eval/*.json"))
    gone = evals[0]
    kept = {p: p.stat().st_mtime_ns for p in evals[1:]}
    gone.unlink()
    assert cli(*args, "--resume") == 0
    assert "2 runs, 1 to do" in capsys.readouterr().out
    assert {p: p.stat().st_mtime_ns for p in done} == done  # no run trained again
    assert {p: p.stat().st_mtime_ns for p in kept} == kept
    assert gone.is_file()  # only the missing evaluation was played


def test_a_report_never_drops_the_results_it_shows(made, tmp_path, capsys):
    """--rows makes a table of every row with results (same settings), not only those
    rows; a report that would lack rows with results (other settings) is refused."""
    root, made_out, _ = made
    out = tmp_path / "out"
    shutil.copytree(made_out, out)
    before = json.loads((out / "tiny.json").read_text())
    args = ["tiny", "--experiments-dir", str(root), "--out", str(out), "--steps", "512",
            "--budget", "2", "--no-progress", "--report-only"]
    assert cli(*args, "--games", "4", "--rows", "a_random") == 0
    data = json.loads((out / "tiny.json").read_text())
    assert [r["row"] for r in data["rows"]] == ["a_random", "b_cycle"] and not data["missing"]
    assert [r["columns"] for r in data["rows"]] == [r["columns"] for r in before["rows"]]
    assert "--rows a_random,b_cycle" in data["command"]
    capsys.readouterr()
    reports = {p.name: p.read_bytes() for p in out.glob("tiny.*")}
    assert cli(*args, "--games", "6", "--rows", "a_random") == 2  # other evaluations
    err = capsys.readouterr().err
    assert "tiny.json reports results of a_random seed 0, b_cycle seed 0 that" in err
    assert {p.name: p.read_bytes() for p in out.glob("tiny.*")} == reports


def test_the_command_a_report_records_makes_that_report(tmp_path, capsys):
    """`all --rows tiny/a_random`, a row name another table has too: the report recorded
    `--rows a_random`, which makes the other table's row and report as well."""
    root = write_rows(tmp_path / "exp")
    shutil.copytree(root / "tiny", root / "other")
    out = tmp_path / "out"
    assert cli("all", "--experiments-dir", str(root), "--out", str(out), "--rows",
               "tiny/a_random", "--report-only") == 0
    command = json.loads((out / "tiny.json").read_text())["command"]
    assert "--rows tiny/a_random " in command and not (out / "other.json").exists()
    (out / "tiny.json").unlink()
    assert cli(*shlex.split(command)[2:], "--report-only") == 0
    assert sorted(p.name for p in out.glob("*.json")) == ["tiny.json"]
    assert json.loads((out / "tiny.json").read_text())["command"] == command


def test_a_report_of_a_row_renamed_since_says_so(made, tmp_path, capsys):
    """b_cycle.toml renamed c_cycle.toml: the report showing b_cycle is kept and the line
    says why; it blamed other settings ('e.g. --seeds'), which no setting fixes."""
    out, args = copy_of_made(made, tmp_path)
    root = tmp_path / "exp"
    shutil.copytree(made[0], root)
    (root / "tiny" / "b_cycle.toml").rename(root / "tiny" / "c_cycle.toml")
    args[args.index("--experiments-dir") + 1] = str(root)
    before = (out / "tiny.json").read_bytes()
    assert cli(*args, "--report-only") == 2
    assert capsys.readouterr().err == (
        f"alphatank experiments: error: --out {out}: tiny.json reports results of row(s) "
        "b_cycle, which table tiny has no more (a row file renamed or removed?); restore it, "
        "or move that report away to write it anew\n")
    assert (out / "tiny.json").read_bytes() == before


def test_two_seeds_pool_their_games_in_the_report(made, tmp_path, capsys):
    root, one_seed, _ = made
    assert "## Seeds pooled" not in (one_seed / "tiny.md").read_text()
    assert json.loads((one_seed / "tiny.json").read_text())[
        "rows"][0]["columns"]["random"]["pooled"] is None
    assert cli("tiny", "--experiments-dir", str(root), "--out", str(tmp_path), "--rows",
               "a_random", "--seeds", "2", "--steps", "512", "--games", "6", "--budget", "2",
               "--no-progress") == 0
    cell = json.loads((tmp_path / "tiny.json").read_text())["rows"][0]["columns"]["random"]
    wins = [r["wins"] for r in cell["per_seed"]]
    pool = cell["pooled"]
    assert (pool["wins"], pool["games"]) == (sum(wins), 12) and 0 < pool["p_value"] <= 1
    assert pool["p_value"] == round(pool_runs(wins, [6, 6]).p_value, 4)
    md = (tmp_path / "tiny.md").read_text()
    section = md.split("## Seeds pooled")[1].split("\n## ")[0]
    assert "| Random Bot " in section and f"p {pool_runs(wins, [6, 6]).p_text}" in section
    # a report of fewer seeds would drop seed 1's results: refused, the report kept
    capsys.readouterr()
    assert cli("tiny", "--experiments-dir", str(root), "--out", str(tmp_path), "--rows",
               "a_random", "--seeds", "1", "--steps", "512", "--games", "6", "--budget", "2",
               "--no-progress", "--report-only") == 2
    assert "tiny.json reports results of a_random seed 1 that" in capsys.readouterr().err
    assert json.loads((tmp_path / "tiny.json").read_text())["rows"][0]["columns"][
        "random"]["pooled"] == pool


def test_a_failing_row_is_reported_and_the_other_finishes(tmp_path, capsys):
    root = write_rows(tmp_path / "exp", broken=True)
    out = tmp_path / "out"
    rc = cli("tiny", "--experiments-dir", str(root), "--out", str(out), "--steps", "256",
             "--games", "2", "--budget", "2", "--no-progress")
    err = capsys.readouterr().err
    assert rc == 1
    assert "tiny/b_cycle seed 0" in err and "egocentric" in err
    assert "--resume only plays" not in err  # a run that failed to train trains again
    broken = next(out.glob("runs/b_cycle-*"))
    assert "Traceback" in (broken / "error.txt").read_text()
    good = next(out.glob("runs/a_random-*"))
    assert (good / "done.json").is_file() and len(list((good / "eval").iterdir())) == 2
    data = json.loads((out / "tiny.json").read_text())
    assert data["rows"][0]["columns"]["random"]["per_seed"]
    assert data["missing"] and "b_cycle" in data["missing"][0]


def test_a_row_stopped_by_a_signal_is_not_finished_nor_evaluated(tmp_path):
    """SIGTERM (a killed driver's workers get one) or Ctrl-C cut a row short: it must not
    be marked done (``--resume`` trains it again) nor evaluated as if finished, and in this
    process the signal ends the command: the next row does not start."""
    plan = make_plan(load_tables(["tiny"], write_rows(tmp_path / "exp")), tmp_path / "out",
                     steps=10**7, games=2, budget_min=2, rows=["a_random", "b_cycle"])
    job, after = plan.jobs[0], plan.jobs[-1]
    assert after.rows != job.rows
    metrics = Path(job.run_dir) / "metrics.jsonl"
    over = threading.Event()

    def stop_once_training() -> None:  # after the first logged iteration: handlers are set
        while not over.wait(0.05):
            if metrics.is_file() and metrics.read_text().strip():
                os.kill(os.getpid(), signal.SIGTERM)
                return

    watcher = threading.Thread(target=stop_once_training, daemon=True)
    watcher.start()
    t0 = time.time()
    try:
        with pytest.raises(RunInterrupted, match="stopped by SIGTERM.*--resume") as info:
            execute(plan.jobs, workers=1, progress=False)
    finally:
        over.set()
        watcher.join()
    assert info.value.exit_code == 143 and time.time() - t0 < 60
    assert not Path(after.run_dir).exists()  # the next row never started
    run = Path(job.run_dir)
    assert (run / "latest").exists()  # it saved where it stopped
    assert not job.done_file.exists() and not (run / "eval").exists()


def test_a_row_another_command_is_training_is_left_alone(tmp_path, held_elsewhere):
    """Two commands on one --out: the second reports a run the first is training as busy
    and neither deletes nor writes anything of it (an unfinished run is otherwise started
    again from scratch); once it is free, the second trains and evaluates it."""
    plan = make_plan(load_tables(["tiny"], write_rows(tmp_path / "exp")), tmp_path / "out",
                     steps=256, games=2, budget_min=2, rows=["a_random"])
    job = plan.jobs[0]
    run = Path(job.run_dir)
    run.mkdir(parents=True)
    (run / "metrics.jsonl").write_text('{"step": 64}\n')  # the other command's progress
    with held_elsewhere(run) as pid:
        _, error, _ = run_job(job)
        assert error is not None and error.startswith("BusyError: ")
        assert f"pid {pid} on " in error
        assert (run / "metrics.jsonl").read_text() == '{"step": 64}\n'
        assert sorted(p.name for p in run.iterdir()) == ["metrics.jsonl"]  # no error.txt
        assert not job.done_file.exists()
    _, error, _ = run_job(job)
    assert error is None and job.complete()


def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys):
    root = write_rows(tmp_path / "exp")
    assert cli("nosuch", "--experiments-dir", str(root)) == 2
    assert "unknown table 'nosuch'; choose one of tiny, all" in capsys.readouterr().err
    (root / "new").mkdir()  # a table being written: its _table.toml not yet
    assert cli("new", "--experiments-dir", str(root)) == 2
    assert (f"unknown table 'new' ({root / 'new'} holds no _table.toml); choose one of tiny, "
            "all") in capsys.readouterr().err
    (root / "tiny" / "c_bad.toml").write_text('title = "x"\nprest = "ppo_vs_smart"\n')
    assert cli("tiny", "--experiments-dir", str(root), "--list") == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "c_bad.toml: prest: unknown key" in err
    (root / "tiny" / "c_bad.toml").write_text('preset = "ppo_vs_smart"\n'
                                              'eval_game = { max_stepz = 5 }\n')
    assert cli("tiny", "--experiments-dir", str(root), "--list") == 2
    err = capsys.readouterr().err
    assert "c_bad.toml: eval_game: unknown GameConfig key(s) ['max_stepz']" in err
    (root / "tiny" / "c_bad.toml").write_text('preset = "ppo_vs_smart"\n[run]\nnum_envs = 0\n')
    assert cli("tiny", "--experiments-dir", str(root), "--list") == 2
    assert "c_bad.toml" in capsys.readouterr().err
    (root / "tiny" / "c_bad.toml").unlink()
    table = (root / "tiny" / "_table.toml").read_text()
    for check, why in (('kind = "gap"\ncolumns = ["random"]',
                        "checks[1].columns: must be two column names, got ['random']"),
                       ('kind = "within"\nrow = "a_random"\npoints = "five"',
                        "checks[1].points: must be a number >= 0, got 'five'"),
                       ('kind = "gap"\ncolums = ["random", "dodge"]',
                        "checks[1].colums: unknown key for kind 'gap'")):
        # a check's values are checked with the files, not after the training
        (root / "tiny" / "_table.toml").write_text(f"{table}\n[[checks]]\n{check}\n")
        assert cli("tiny", "--experiments-dir", str(root), "--list") == 2
        assert why in capsys.readouterr().err
    # a column's map and a row's scenarios are checked with the files too
    (root / "tiny" / "_table.toml").write_text(
        table + '[[columns]]\nname = "far"\nlabel = "Far"\nmap = "no_such_map"\n')
    assert cli("tiny", "--experiments-dir", str(root), "--list") == 2
    assert "_table.toml: columns[2]: map: unknown map 'no_such_map'" in capsys.readouterr().err
    (root / "tiny" / "_table.toml").write_text(table)
    (root / "tiny" / "c_bad.toml").write_text('preset = "ppo_vs_smart"\n'
                                              'scenarios = ["vs_random", "nosuch"]\n')
    assert cli("tiny", "--experiments-dir", str(root), "--list") == 2
    assert "c_bad.toml: scenarios[1]: unknown scenario 'nosuch'" in capsys.readouterr().err
    shutil.rmtree(root / "tiny")
    for flags in (["--seeds", "0"], ["--workers", "0"], ["--games", "0"]):
        assert cli("table4", *flags, "--list") == 2
        assert capsys.readouterr().err.count("\n") == 1


def test_an_experiments_dir_without_tables_is_one_line(tmp_path, capsys):
    """A folder of no tables (empty, or a table's own folder given) is refused naming
    it: `all` did nothing with exit status 0, a table was 'unknown; choose one of all'."""
    root = write_rows(tmp_path / "exp")
    (tmp_path / "empty").mkdir()
    (tmp_path / "file").write_text("")
    for where, table, why in (
            (root / "tiny", "tiny", f"--experiments-dir {root / 'tiny'}: holds no table (a "
             "folder <table> with a _table.toml and its row files); it is the folder of "
             "table 'tiny': give the folder above it"),
            (tmp_path / "empty", "all", f"--experiments-dir {tmp_path / 'empty'}: holds no "
             "table (a folder <table> with a _table.toml and its row files)\n"),
            (tmp_path / "file", "all", f"--experiments-dir {tmp_path / 'file'}: is a file, "
             "not a folder")):
        assert cli(table, "--experiments-dir", str(where), "--out", str(tmp_path / "out"),
                   "--steps", "512") == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and why in err, err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("name", ["runs", "figures", "tiny.md"])
def test_a_file_or_folder_where_out_writes_is_one_line_before_training(tmp_path, capsys,
                                                                       name):
    """A file named like --out's runs/ or figures/ folder failed every run (each naming
    an error.txt it could not write) or the report after the training, and a folder named
    like a report the report after the training; one line naming it, exit 2, nothing
    trained."""
    root, out = write_rows(tmp_path / "exp"), tmp_path / "out"
    out.mkdir()
    if name.endswith(".md"):
        (out / name).mkdir()
    else:
        (out / name).write_text("")
    assert cli("tiny", "--experiments-dir", str(root), "--out", str(out), "--steps", "64",
               "--games", "1", "--no-progress") == 2
    cap = capsys.readouterr()
    assert cap.out == "" and cap.err.count("\n") == 1, cap.err
    assert f"{out / name}" in cap.err and ("is a file" in cap.err or "is a folder" in cap.err)
    assert [p.name for p in out.iterdir()] == [name]


@pytest.mark.parametrize(("check", "why"), [
    ('kind = "best_average"\nrows = ["b_cycle"]\nagainst = ["a_randm"]',
     "checks[1].against: no row 'a_randm' in the table; rows: ['a_random', 'b_cycle']"),
    ('kind = "within"\nrow = "b_cycl"\nspecialists = { random = "a_random" }',
     "checks[1].row: no row 'b_cycl'"),
    ('kind = "within"\nrow = "b_cycle"\nspecialists = { randm = "a_random" }',
     "checks[1].specialists: no column 'randm' in the table; columns: ['random', 'dodge', "
     "'average']"),
    ('kind = "gap"\ncolumns = ["random", "dodg"]', "checks[1].columns: no column 'dodg'"),
    ('kind = "beats_paper"\nrows = ["nosuch"]', "checks[1].rows: no row 'nosuch'")])
def test_a_check_naming_no_row_or_column_of_its_table_is_one_line(tmp_path, capsys, check,
                                                                  why):
    """A misspelt name left a check "not measurable" for ever (or, in best_average's
    against, dropped that specialist from the comparison)."""
    root = write_rows(tmp_path / "exp")
    with open(root / "tiny" / "_table.toml", "a") as f:
        f.write(f"\n[[checks]]\n{check}\n")
    assert cli("tiny", "--experiments-dir", str(root), "--list") == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"tiny/_table.toml: {why}" in err, err


def test_a_bad_row_outside_rows_is_one_line_when_the_report_is_planned(tmp_path, capsys):
    """--rows reports every row of its tables with results: those plans read every row, and
    a bad one raised a traceback (they were outside the error handler); one line, exit 2."""
    root = write_rows(tmp_path / "exp")
    (root / "tiny" / "c_bad.toml").write_text('preset = "ppo_vs_smart"\n[run]\nnum_envs = 0\n')
    assert cli("tiny", "--experiments-dir", str(root), "--out", str(tmp_path / "out"),
               "--rows", "a_random", "--report-only", "--no-progress") == 2
    cap = capsys.readouterr()
    assert cap.out == "" and cap.err.count("\n") == 1, cap.err
    assert cap.err.startswith("alphatank experiments: error: ") and \
        "c_bad.toml: num_envs: must be in (0, 4096], got 0" in cap.err, cap.err
    assert not (tmp_path / "out" / "tiny.md").exists()


def test_a_mix_trains_every_scenario_on_the_rows_map_as_the_plan_checks(tmp_path):
    """A row's map override with several scenarios: the plan checked every scenario on
    it, but the mix trained each on its own map (battlefield and open): it trains every
    scenario on the override too."""
    root = write_rows(tmp_path / "exp")
    row = root / "tiny" / "b_cycle.toml"
    row.write_text(row.read_text().replace('num_envs = 4', 'num_envs = 4\nmap = "maze"', 1)
                   .replace('"vs_dodge"]', '"vs_aggressive"]', 1))
    plan = make_plan(load_tables(["tiny"], root), tmp_path / "out", steps=256,
                     rows=["b_cycle"])
    job = plan.jobs[0]
    assert job.scenarios == ["vs_random", "vs_aggressive"]
    cfg = TrainConfig.from_dict(job.cfg)
    assert cfg.map == "maze"
    env = mixed_env(job, cfg)
    try:
        assert [(sc.name, sc.map) for sc in env.scenarios] == [("vs_random", "maze"),
                                                               ("vs_aggressive", "maze")]
    finally:
        env.close()
    assert mixed_env(make_plan(load_tables(["tiny"], root), tmp_path / "out", steps=256,
                               rows=["a_random"]).jobs[0], cfg) is None


def test_the_plan_lists_the_steps_each_run_trains(tmp_path, capsys):
    """Runs train whole iterations: --list shows the steps rounded up (it said 'steps<=' the
    asked figure, and a SAC run of --steps 1000 trained 8,192), with the figure asked."""
    root = write_rows(tmp_path / "exp")
    assert cli("tiny", "--experiments-dir", str(root), "--steps", "600", "--list") == 0
    out = capsys.readouterr().out
    assert "steps<=" not in out
    assert "  a_random           vs_random          steps       768  Random Bot  (600 asked; " \
           "iterations of 256)" in out  # 64 vector steps x 4 matches
    assert "steps: env steps per run, whole iterations (rollout_steps x num_envs), unless " \
           "the 15-minute budget ends it first" in out
    assert cli("sac", "--rows", "sac_vs_aggressive", "--steps", "1000", "--list") == 0
    assert "steps     8,192  SAC vs Aggressive Bot  (1,000 asked; iterations of 8,192)" in \
        capsys.readouterr().out


@pytest.mark.parametrize(("workers", "minutes"), [(1, 26), (2, 13), (100, 13)])
def test_the_estimate_is_at_least_the_longest_run(tmp_path, capsys, workers, minutes):
    """A run trains on one worker: the estimate spread the plan over more workers than it
    has runs (2 runs of a 10-minute budget and 3 minutes of games each: 'about 0 min with
    100 worker(s)')."""
    root = write_rows(tmp_path / "exp")
    assert cli("tiny", "--experiments-dir", str(root), "--out", str(tmp_path / "out"),
               "--budget", "10", "--workers", str(workers), "--list") == 0
    assert capsys.readouterr().out.splitlines()[-1] == (
        f"2 runs (1 seed(s)), 2 to do: about {minutes} min with {workers} worker(s)")


def test_an_estimate_under_a_minute_is_not_zero(tmp_path, capsys):
    """Budgets of a few seconds (2 runs of 6 s, 2 evaluations of 2 games each) were
    'about 0 min'."""
    root = write_rows(tmp_path / "exp")
    assert cli("tiny", "--experiments-dir", str(root), "--out", str(tmp_path / "out"),
               "--budget", "0.1", "--games", "2", "--list") == 0
    assert capsys.readouterr().out.splitlines()[-1] == (
        "2 runs (1 seed(s)), 2 to do: about 0.26 min with 1 worker(s)")


def test_list_with_ray_does_not_claim_one_worker(tmp_path, capsys):
    """--list --ray does not connect, so it cannot know the cluster's CPUs: it gives the
    one-CPU time and says the cluster shares it out (it said 'with 1 worker(s)')."""
    root = write_rows(tmp_path / "exp")
    assert cli("tiny", "--experiments-dir", str(root), "--out", str(tmp_path / "out"),
               "--budget", "10", "--ray", "--list") == 0
    assert capsys.readouterr().out.splitlines()[-1] == (
        "2 runs (1 seed(s)), 2 to do: about 26 min on one CPU, shared out over the Ray "
        "cluster's CPUs (the run says how many)")


def test_shipped_tables_load_and_plan(tmp_path):
    names = table_names()
    assert names == ["table3", "table4", "sac", "league", "heldout"]
    tables = load_tables(names)
    plan = make_plan(tables, tmp_path, seeds=2, budget_min=15)
    t3 = next(t for t in tables if t.name == "table3")
    assert [r.paper["own"] for r in t3.rows] == [60, 79, 47, 41, 58, 26, 40, 51]
    t4 = next(t for t in tables if t.name == "table4")
    assert t4.row("cycle_victory").paper["average"] == 47.75
    cyc = row_config(t4.row("cycle_fixed"), 0, 15)
    assert cyc.schedule["interval"] == cyc.total_steps // 16 and cyc.observation == "egocentric"
    assert cyc.schedule["mode"] == "fixed" and cyc.schedule["scale_victory"] is False
    assert cyc.time_limit_s == 900.0 and cyc.seed == 0
    full = row_config(t4.row("cycle_fixed_full"), 0, 15)
    assert full.observation == "egocentric_full" and full.imitate["bot"] == "smart"
    assert full.learners[0].config.learning_rate == 1e-4
    for bot in ("random", "aggressive", "defensive", "dodge"):  # like with like
        spec = row_config(t4.row(f"{bot}_full"), 0, 15)
        assert spec.scenario == f"vs_{bot}" and not spec.schedule and not spec.rewards
        assert (spec.learners[0].config, spec.imitate, spec.observation, spec.num_envs) == \
            (full.learners[0].config, full.imitate, full.observation, full.num_envs)
        # the same specialist on the cycle's four settings: only its one bot, every setting
        mix = t4.row(f"{bot}_mix")
        assert mix.scenarios == t4.row("cycle_fixed_full").scenarios
        mixed = row_config(mix, 0, 15)
        assert mixed.schedule["pool"] == [bot] and mixed.schedule["kind"] == "cycle"
        assert (mixed.learners[0].config, mixed.imitate, mixed.observation) == \
            (full.learners[0].config, full.imitate, full.observation)
        if bot != "random":  # the same, every tank's cell drawn at random in training
            spawns = row_config(t4.row(f"{bot}_mix_spawns"), 0, 15)
            assert spawns.game == {"random_spawns": True} and not mixed.game
            assert dataclasses.replace(spawns, game={}, name=mixed.name) == mixed
            assert t4.row(f"{bot}_mix_spawns").eval_game == {"random_spawns": False}
        for kind, weaknesses, power in (("still", [0.05, 1.0], 1.0),
                                        ("strengths", [0.05, 0.25, 1.0], 1.0),
                                        ("even", [0.05, 1.0], 0.0)):
            if bot not in ("defensive", "dodge") or (kind, bot) == ("even", "dodge"):
                continue  # the same, meeting its bot weakened too (PFSP over strengths)
            weak = row_config(t4.row(f"{bot}_mix_{kind}"), 0, 15)
            assert weak.schedule == {"kind": "league", "bots": [bot],
                                     "weaknesses": weaknesses, "snapshots": 0,
                                     "power": power, "floor": 0.1, "window": 50}
            assert dataclasses.replace(weak, schedule=mixed.schedule,
                                       name=mixed.name) == mixed
    sac = row_config(next(t for t in tables if t.name == "sac").row("sac_vs_ppo"), 1, 15)
    assert {s.name: s.config.utd_ratio for s in sac.learners if s.algo == "sac"} == \
        {"sac": 0.125} and sac.seed == 1
    ppo = next(s for s in sac.learners if s.algo == "ppo")
    assert ppo.config.clip_coef == 0.1  # the preset's Table 9 settings are kept
    # Table 4's specialists and adaptive cycle are shared with the league table
    shared = [j for j in plan.jobs if len(j.rows) > 1]
    assert len(shared) == 2 * 5 and all(len(j.rows) == 2 for j in shared)
    assert len(plan.jobs) == 2 * (8 + 35 + 3 + 9 + 6) - len(shared)


def test_every_seed_of_a_plan_is_the_run_its_row_makes_for_that_seed_alone(tmp_path):
    """A plan parses and checks each row once and derives its other seeds' runs from it:
    every seed's settings (teachers' runs included), digest and run folder are those of
    ``row_config`` for that seed alone; a run folder already there is found by its
    digest, whatever its name."""
    tables = load_tables(table_names())
    plan = make_plan(tables, tmp_path, seeds=2, budget_min=2)
    for row in (r for t in tables for r in t.rows):
        for s in range(2):
            job = plan.cells[(row.id, s)][0]
            cfg = row_config(row, s, 2, refs=lambda name, s=s, table=row.table:
                             plan.cells[(f"{table}/{name}", s)][0].run_dir)
            named = {} if job.rows[0] == row.id else {"name": job.cfg["name"]}  # shared
            assert job.cfg == {**cfg.to_dict(), **named}
            assert job.key == settings_digest(cfg.to_dict(), row.scenarios)
            assert job.seed == s and job.run_dir == str(
                tmp_path / "runs" / f"{job.rows[0].split('/')[1]}-s{s}-{job.key}")
    job = plan.cells[("table3/smart", 1)][0]
    (tmp_path / "runs" / f"renamed-{job.key}").mkdir(parents=True)
    again = make_plan(tables[:1], tmp_path, seeds=2, budget_min=2)
    assert again.cells[("table3/smart", 1)][0].run_dir == str(tmp_path / "runs" /
                                                            f"renamed-{job.key}")


def test_a_setting_added_later_keeps_the_digests_of_runs_made_before_it(tmp_path):
    # docs/results/table4_full.* was made before PPO had anchor_kl: its runs still match
    plan = make_plan(load_tables(["table4"]), tmp_path, seeds=3, budget_min=15,
                     steps=5_000_000)
    planned = {Path(j.run_dir).name for j in plan.jobs}
    shipped = json.loads((Path(__file__).parents[1] / "docs/results/table4_full.json")
                         .read_text(encoding="utf-8"))
    made = {Path(r["run_dir"]).name for row in shipped["rows"] for r in row["runs"]}
    assert "cycle_fixed_full-s0-d532ca16a5" in made and made <= planned
    # turned on, the setting is part of what the run does
    cfg = row_config(load_tables(["table4"])[0].row("cycle_fixed_full"), 0, 15, 5_000_000)
    spec = cfg.learners[0]
    on = cfg.with_overrides(learners=(type(spec)(spec.name, spec.algo, spec.seats, config=
                                                 type(spec.config)(anchor_kl=0.1)),))
    assert settings_digest(on.to_dict(), ()) != settings_digest(cfg.to_dict(), ())


STUDENT = 'title = "Student"\norder = 3\n' + RUN.format(
    extra='imitate = { steps = 32, epochs = 1, teachers = { vs_random = "TEACHER" } }')


def test_a_row_taught_by_another_row_trains_after_it_on_its_checkpoint(tmp_path, capsys):
    """``row:NAME`` teachers: the named row's run (same seed) trains first, even when
    only the student was asked for, and teaches from its checkpoint; a student whose
    teacher's run failed is reported and not trained; unknown and circular rows are
    refused when planning."""
    root = write_rows(tmp_path / "exp", broken=True)
    (root / "tiny" / "c_student.toml").write_text(STUDENT.replace("TEACHER", "row:a_random"))
    (root / "tiny" / "d_student.toml").write_text(STUDENT.replace("TEACHER", "row:b_cycle")
                                                  .replace("Student", "Student D"))
    tables = load_tables(["tiny"], root)
    plan = make_plan(tables, tmp_path / "out", steps=256, games=2, budget_min=2,
                     rows=["c_student", "d_student"])
    teacher, student = plan.jobs[0], plan.jobs[1]
    assert teacher.rows == ["tiny/a_random"] and not teacher.evals  # planned, not asked for
    assert student.needs == [teacher.key] and len(student.evals) == 2
    assert student.cfg["imitate"]["teachers"] == {"vs_random": f"checkpoint:{teacher.run_dir}"}
    assert cli("tiny", "--experiments-dir", str(root), "--rows", "c_student", "--list") == 0
    assert "(trains after tiny/a_random)" in capsys.readouterr().out
    assert cli("tiny", "--experiments-dir", str(root), "--out", str(tmp_path / "out"),
               "--rows", "c_student,d_student", "--steps", "256", "--games", "2",
               "--budget", "2", "--no-progress") == 1
    err = capsys.readouterr().err
    assert "tiny/d_student seed 0: not trained: it needs the run of tiny/b_cycle seed 0, " \
           "which did not finish" in err
    assert teacher.done_file.is_file() and student.complete()
    first = json.loads((Path(student.run_dir) / "metrics.jsonl").read_text().splitlines()[0])
    assert first["imitate/samples"] > 0
    for teacher_spec, message in (("row:nosuch", "no row 'nosuch' in table tiny"),
                                  ("row:e_student", "rows need each other: tiny/e_student "
                                                    "-> tiny/e_student")):
        (root / "tiny" / "e_student.toml").write_text(STUDENT.replace("TEACHER", teacher_spec)
                                                      .replace("Student", "Student E"))
        with pytest.raises(ValueError, match=message):
            make_plan(load_tables(["tiny"], root), tmp_path / "x", rows=["e_student"])


def test_a_worker_whose_command_has_ended_starts_no_job(tmp_path):
    """A pool worker keeps its queued jobs after the driver dies; once it knows it is
    orphaned (training.stopping.exit_with_parent) it starts none of them."""
    from alphatank.training import stopping

    plan = make_plan(load_tables(["tiny"], write_rows(tmp_path / "exp")), tmp_path / "out",
                     steps=256, games=2, budget_min=2, rows=["a_random"])
    stopping._orphaned.set()
    try:
        _, error, _ = run_job(plan.jobs[0])
    finally:
        stopping._orphaned.clear()
    assert error == "not started: the command that ran it has ended"
    assert not Path(plan.jobs[0].run_dir).exists()


def test_a_run_whose_budget_ends_while_it_clones_is_reported_as_cut(tmp_path, capsys):
    table = tmp_path / "exp" / "tiny"
    table.mkdir(parents=True)
    (table / "_table.toml").write_text(TABLE)
    (table / "a_random.toml").write_text(
        'title = "Random Bot"\norder = 1\npaper = { random = 50 }\n'
        + RUN.format(extra='imitate = { bot = "smart", steps = 100000, epochs = 50 }'))
    out = tmp_path / "out"
    rc = cli("tiny", "--experiments-dir", str(tmp_path / "exp"), "--out", str(out), "--games",
             "2", "--budget", "0.02", "--no-progress")  # 1.2 s: within the cloning
    said = capsys.readouterr().out
    assert rc == 0
    assert "a_random seed 0: done, but its budget ended while it cloned its bot" in said
    assert "cloning cut" in (out / "tiny.md").read_text()
    run = json.loads((out / "tiny.json").read_text())["rows"][0]["runs"][0]
    assert run["cloning_cut"] is True and run["steps"] == 0 and run["stopped_by"] == "time"


def test_steps_reported_are_those_of_the_evaluated_checkpoint():
    from alphatank.training.report import trained_steps

    # a time limit ended the run 2,048 steps after its last save, which was evaluated
    assert trained_steps({"global_step": 36_864, "saved_step": 34_816}) == 34_816
    assert trained_steps({"global_step": 512}) == 512  # a run from before saved_step


@pytest.mark.parametrize("rate", ["nan", "inf", "0"])
def test_a_row_planning_rate_must_be_a_finite_positive_number(tmp_path, rate):
    root = write_rows(tmp_path / "exp")
    row = root / "tiny" / "a_random.toml"
    row.write_text(f"steps_per_minute = {rate}\n" + row.read_text())
    with pytest.raises(ValueError, match=r"a_random\.toml: steps_per_minute: must be a finite "
                                         r"number > 0, got"):
        load_tables(["tiny"], root)


@pytest.mark.parametrize("value", ["nan", "inf", "-5", "150"])
def test_a_rows_paper_figure_must_be_a_percent(tmp_path, value):
    """A paper figure of nan or 150 was shown as 'paper nan%' and compared by the checks."""
    root = write_rows(tmp_path / "exp")
    row = root / "tiny" / "a_random.toml"
    row.write_text(row.read_text().replace("random = 50", f"random = {value}"))
    with pytest.raises(ValueError, match=r"a_random\.toml: paper\.random: needs a number in "
                                         r"\[0, 100\] \(percent\), got"):
        load_tables(["tiny"], root)


@pytest.mark.parametrize(("where", "setting"), [
    ("budget_fractions", '"seed" = 0.5'), ("budget_fractions", "total_steps = 0.5"),
    ("run", "seed = 3"), ("run", "eval_every = 4")])
def test_a_row_setting_what_the_command_sets_for_each_run_is_refused(tmp_path, where,
                                                                     setting):
    """A fraction of the steps as the seed made every seed index's run of the first seed
    train with one seed (the seed rule broken: past 1,000,000 with enough steps), and the
    other seeds with theirs; a [run] seed or eval_every was dropped without a word."""
    root = write_rows(tmp_path / "exp")
    row = root / "tiny" / "b_cycle.toml"
    text = row.read_text()
    row.write_text(text.replace("[budget_fractions]\n", f"[budget_fractions]\n{setting}\n")
                   if where == "budget_fractions" else
                   text.replace("[run]\n", f"[run]\n{setting}\n"))
    key = setting.split(" =")[0].strip('"')
    with pytest.raises(ValueError, match=rf"b_cycle\.toml: {where}\.{key}: set by alphatank "
                                         r"experiments for each run \(from --budget, "):
        load_tables(["tiny"], root)


def test_two_rows_of_a_table_with_one_title_are_refused(tmp_path):
    """A row file copied for a variant, its title kept: the tables showed two rows alike
    and the openskill table rated both rows' agents as one player ('Random Bot s0')."""
    root = write_rows(tmp_path / "exp")
    (root / "tiny" / "c_copy.toml").write_text((root / "tiny" / "a_random.toml").read_text())
    with pytest.raises(ValueError, match=r"c_copy\.toml: title: 'Random Bot' is the title of "
                                         r".*a_random\.toml too; give each row of a table its "
                                         r"own"):
        load_tables(["tiny"], root)
    (root / "tiny" / "c_copy.toml").write_text(  # without titles: the file names
        (root / "tiny" / "a_random.toml").read_text().replace('title = "Random Bot"\n', ""))
    assert [r.title for r in load_tables(["tiny"], root)[0].rows] == ["Random Bot", "c_copy",
                                                                     "Cycle"]


def test_a_rows_run_observation_and_imitate_are_checked_when_it_is_planned(tmp_path):
    """Before anything trains, not when the row's run starts after the others."""
    root = write_rows(tmp_path / "exp")
    row = root / "tiny" / "a_random.toml"
    good = row.read_text()
    for bad, message in (('observation = "egocentric"', r"run: observation: 'bad' is not one"),
                         ('num_envs = 4', r"run: imitate\.bot 'smrt'")):
        text = good.replace('observation = "egocentric"', 'observation = "bad"') \
            if "observation" in bad else good.replace(bad, bad + '\nimitate = { bot = "smrt" }')
        row.write_text(text)
        with pytest.raises(ValueError, match=r"a_random\.toml: " + message):
            make_plan(load_tables(["tiny"], root), tmp_path / "out", rows=["a_random"])


@pytest.mark.parametrize(("text", "message"), [
    ('[run.game]\nmax_steps = 0\n', "run: [game].max_steps: must be in [1, 10000000], got 0"),
    ('[[run.learners]]\nname = "a"\nseats = [3]\n',
     "run: learners [('a', [3])] do not drive each of the 1 learner seat(s) of scenario "
     "'vs_aggressive' exactly once"),
    ('[run.rewards]\nteam_draw = 3\n', "run: [rewards].team_draw: (3.0) must not exceed"),
    ('[run]\nmap = "nosuchmap"\n', "run: map: unknown map 'nosuchmap'"),
    ('[run]\nscenario = "nosuch"\n', "run: scenario: unknown scenario 'nosuch'"),
    ('scenarios = [1, 2]\n', "scenarios[0]: needs a scenario name or path (a string), got 1"),
    # every scenario of a mix, not only the first: learners, schedule and [game] ranges
    ('scenarios = ["vs_random", "pair"]\n',
     "scenarios[1]: run: learners [('ppo', [0])] do not drive each of the 2 learner seat(s) "
     "of scenario 'pair' exactly once"),
    ('scenarios = ["vs_random", "vs_smart", "vs_agent"]\n[run.schedule]\nkind = "curriculum"\n',
     "scenarios[2]: run: schedule: the curriculum schedule needs bot seats; scenario "
     "'vs_agent' has none"),
    ('scenarios = ["vs_dodge", "vs_random"]\n[run.game]\ntank_speed = 500.0\n',
     "scenarios[1]: run: [game].bullet_speed: (300) must exceed tank_speed (500)"),
    ('[run]\ninit_from = "agent:nobody"\n', "run: init_from: unknown agent 'nobody'"),
    ('[run]\ninit_from = "no_such_run"\n',
     "run: init_from: no_such_run: no such checkpoint or run directory"),
    ('[run]\ninit_from = "agent:ppo_vs_smart"\n[[run.learners]]\nname = "s"\nalgo = "sac"\n',
     "run: init_from: a warm start fills PPO and MAPPO learners; this run's [('s', 'sac')] "
     "take none"),
])
def test_a_rows_run_is_checked_as_train_checks_a_run_file_when_it_is_planned(
        tmp_path, capsys, text, message):
    """Before anything trains (--list too), naming the row's file: not when the row's run
    starts after the rows before it have trained."""
    root = write_rows(tmp_path / "exp")
    (root / "tiny" / "c_bad.toml").write_text(f'preset = "demo"\n{text}')
    assert cli("tiny", "--experiments-dir", str(root), "--list") == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{root}/tiny/c_bad.toml: {message}" in err, err


def test_a_schedule_on_a_scenario_without_bot_seats_is_refused_when_planned(tmp_path):
    root = write_rows(tmp_path / "exp")
    (root / "tiny" / "c_bad.toml").write_text('preset = "ppo_vs_ppo"\n[run.schedule]\n'
                                              'kind = "curriculum"\n')
    with pytest.raises(ValueError, match=r"c_bad\.toml: run: schedule: the curriculum "
                                         r"schedule needs bot seats; scenario 'pair' has none"):
        make_plan(load_tables(["tiny"], root), tmp_path / "out", rows=["c_bad"])


def test_the_wandb_mode_leaves_the_run_digests_alone(tmp_path):
    """A logging mode: finished runs still count when only --wandb differs."""
    tables = load_tables(["tiny"], write_rows(tmp_path / "exp"))
    plans = [make_plan(tables, tmp_path / "out", wandb=mode) for mode in ("disabled", "offline")]
    assert [j.key for j in plans[0].jobs] == [j.key for j in plans[1].jobs]
    assert plans[1].jobs[0].cfg["wandb"] == "offline"  # the run still logs in that mode


def test_the_wandb_project_and_tensorboard_leave_the_run_digests_alone(tmp_path):
    """Where a row's metrics are logged is not what its run does: a row that only logs
    elsewhere shares the finished run (shipped digests stay: the defaults are hashed)."""
    root = write_rows(tmp_path / "exp")
    row = root / "tiny" / "a_random.toml"
    plain = make_plan(load_tables(["tiny"], root), tmp_path / "out", rows=["a_random"])
    row.write_text(row.read_text().replace('num_envs = 4',
                                           'num_envs = 4\nproject = "elsewhere"\n'
                                           'tensorboard = true'))
    logged = make_plan(load_tables(["tiny"], root), tmp_path / "out", rows=["a_random"])
    assert [j.key for j in logged.jobs] == [j.key for j in plain.jobs]
    assert logged.jobs[0].cfg["project"] == "elsewhere" and logged.jobs[0].cfg["tensorboard"]


def test_a_rows_damaged_init_from_is_refused_when_planned(tmp_path, capsys):
    """A run folder whose ``latest`` points at no save: refused by --list, naming the row's
    file, not when the row starts training."""
    run = tmp_path / "warm"
    run.mkdir()
    (run / "latest").write_text("step_64\n")
    root = write_rows(tmp_path / "exp")
    (root / "tiny" / "c_bad.toml").write_text(f'preset = "demo"\n[run]\ninit_from = "{run}"\n')
    assert cli("tiny", "--experiments-dir", str(root), "--list") == 2
    err = capsys.readouterr().err
    assert f"{root}/tiny/c_bad.toml: run: init_from: {run / 'latest'}: points at " in err
    assert err.count("\n") == 1, err


def _children(pid: int) -> list[int]:
    found = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            found.append(int(stat.parent.name))
    return found


def _alive(pid: int) -> bool:
    try:
        return (Path("/proc") / str(pid) / "stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


@pytest.mark.slow
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGKILL])
def test_a_signal_to_the_command_alone_stops_its_workers_runs_at_once(tmp_path, signum):
    """SIGINT sent to the command's process alone (not its group, as a supervisor does)
    reaches its pool workers: their runs stop and save, the command prints its interrupted
    line and exits 130 (SIGTERM takes the same handler: 143); killed, its workers save and
    exit once their runs are saved. Nothing lingers."""
    import subprocess
    import sys

    root = write_rows(tmp_path / "exp")
    out = tmp_path / "out"
    proc = subprocess.Popen(
        [sys.executable, "-m", "alphatank.cli", "experiments", "tiny", "--experiments-dir",
         str(root), "--out", str(out), "--steps", "100000000", "--games", "2", "--budget",
         "1", "--workers", "2", "--no-progress"],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True)
    try:
        end = time.monotonic() + 180
        while len([m for m in out.glob("runs/*/metrics.jsonl") if m.stat().st_size]) < 2:
            assert proc.poll() is None, proc.communicate()[0]
            assert time.monotonic() < end, "timed out waiting for the runs"
            time.sleep(0.1)
        workers = _children(proc.pid)
        t0 = time.monotonic()
        proc.send_signal(signum)
        text = proc.communicate(timeout=30)[0]
        while any(map(_alive, workers)) and time.monotonic() < t0 + 20:
            time.sleep(0.1)
        assert not any(map(_alive, workers)), (workers, text)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    if signum != signal.SIGKILL:
        assert proc.returncode == 128 + signum, text
        assert "interrupted: finished runs and evaluations are kept" in text
    assert len(list(out.glob("runs/*/latest"))) == 2  # both runs saved
    assert not list(out.glob("runs/*/done.json"))


def test_a_finished_rows_init_from_is_not_checked_when_it_only_reports(tmp_path, capsys):
    """A row trained from a checkpoint that is gone since: --report-only and --resume still
    report its finished run; a run still to train is refused, naming the row's file."""

    warm = tmp_path / "warm"
    shutil.copytree(agent_path("ppo_vs_smart"), warm)
    root = write_rows(tmp_path / "exp")
    (root / "tiny" / "c_warm.toml").write_text(
        'title = "Warm"\norder = 3\n' + RUN.format(extra=f'init_from = "{warm}"')
        .replace('"egocentric"', '"paper"'))  # the shipped agent's observation
    args = ("tiny", "--experiments-dir", str(root), "--out", str(tmp_path / "out"),
            "--rows", "c_warm", "--steps", "256", "--games", "2", "--budget", "2",
            "--no-progress")
    assert cli(*args) == 0
    shutil.rmtree(warm)
    capsys.readouterr()
    assert cli(*args, "--report-only") == 0
    assert cli(*args, "--resume") == 0
    assert "Warm" in (tmp_path / "out" / "tiny.md").read_text()
    assert cli(*args[:3], "--out", str(tmp_path / "other"), "--rows", "c_warm", "--list") == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"c_warm.toml: run: init_from: {warm}: " in err, err


def test_a_damaged_results_file_is_named_and_resume_makes_it_again(made, tmp_path, capsys):
    """An evaluation or done.json cut short: --list names it and counts its run to do;
    --report-only names it in one line (exit 2, nothing written); --resume sets it aside,
    saying so, and plays that evaluation or trains that run again; nothing else is
    touched."""
    out, args = copy_of_made(made, tmp_path)
    a_run, b_run = sorted((out / "runs").iterdir())
    cut = sorted((a_run / "eval").iterdir())[0]
    cut.write_bytes(cut.read_bytes()[:100])
    (b_run / "done.json").write_text("")
    reports = {p.name: p.read_bytes() for p in out.glob("tiny.*")}
    assert cli(*args, "--list") == 0  # named, and counted to do
    listed = capsys.readouterr().out
    assert f"tiny/a_random seed 0: damaged: {cut}: not valid JSON (line " in listed, listed
    assert f"tiny/b_cycle seed 0: damaged: {b_run / 'done.json'}: empty; " in listed
    assert "2 runs (1 seed(s)), 2 to do (2 damaged): about " in listed
    assert cli(*args, "--report-only") == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{cut}: not valid JSON (line " in err, err
    assert "(and 1 more)" in err and "--resume" in err
    assert {p.name: p.read_bytes() for p in out.glob("tiny.*")} == reports
    kept = {p: p.stat().st_mtime_ns for p in [a_run / "done.json", *(a_run / "eval").iterdir()]
            if p != cut}
    assert cli(*args, "--resume") == 0
    err = capsys.readouterr().err
    assert f"{b_run / 'done.json'}: empty; " in err and f"set aside as {b_run}.damaged;" in err
    assert f"{cut}: not valid JSON" in err and f"set aside as {cut}.damaged;" in err
    assert json.loads(cut.read_text())["games"] == 4 and (a_run / "eval" / f"{cut.name}.damaged"
                                                           ).is_file()
    assert json.loads((b_run / "done.json").read_text())["summary"]
    assert (Path(f"{b_run}.damaged") / "latest").exists()  # its checkpoint kept aside
    assert {p: p.stat().st_mtime_ns for p in kept} == kept
    data = json.loads((out / "tiny.json").read_text())
    assert not data["missing"] and all(r["columns"]["random"]["per_seed"] for r in data["rows"])


def test_a_results_file_without_what_the_report_reads_is_damaged(made, tmp_path, capsys):
    """A done.json whose "summary" is not an object, an evaluation file without its
    "draws" count (JSON objects both; the report once ended in a KeyError/TypeError
    traceback): named by --list and --report-only (exit 2, nothing written) as a damaged
    file is, and made again by --resume."""
    out, args = copy_of_made(made, tmp_path)
    a_run, b_run = sorted((out / "runs").iterdir())
    done = a_run / "done.json"
    done.write_text(json.dumps({**json.loads(done.read_text()), "summary": []}))
    played = sorted((b_run / "eval").iterdir())[0]
    played.write_text(json.dumps({k: v for k, v in json.loads(played.read_text()).items()
                                  if k != "draws"}))
    reports = {p.name: p.read_bytes() for p in out.glob("tiny.*")}
    assert cli(*args, "--list") == 0
    listed = capsys.readouterr().out
    assert f"tiny/a_random seed 0: damaged: {done}: \"summary\" is not an object; the file " \
        "is damaged; --resume" in listed, listed
    assert f"tiny/b_cycle seed 0: damaged: {played}: no \"draws\" integer >= 0; " in listed
    assert cli(*args, "--report-only") == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f'{done}: "summary" is not an object; ' in err, err
    assert "(and 1 more)" in err
    assert {p.name: p.read_bytes() for p in out.glob("tiny.*")} == reports
    assert cli(*args, "--resume") == 0
    err = capsys.readouterr().err
    assert f"set aside as {a_run}.damaged; the run trains again" in err
    assert f"set aside as {played}.damaged; the evaluation is played again" in err
    assert isinstance(json.loads(done.read_text())["summary"], dict)
    assert "draws" in json.loads(played.read_text())
    assert not json.loads((out / "tiny.json").read_text())["missing"]


# a value of a_random's done.json or first evaluation the report reads (some only when
# there), damaged, and what names it
DAMAGES = {
    "league": ("done.json", lambda d: d.update(league="ratings"),
               '"league" is not a list of [name, mu, sigma, ordinal]'),
    "league_bool": ("done.json", lambda d: d.update(league=[["a", 25.0, True, 1.0]]),
                    '"league" is not a list of [name, mu, sigma, ordinal]'),
    "saved_step": ("done.json", lambda d: d["summary"].update(saved_step="512"),
                   '"saved_step" is not an integer in "summary"'),
    "stopped": ("done.json", lambda d: d["summary"].update(stopped="time"),
                '"stopped" is not an object in "summary"'),
    "no_games": ("eval", lambda d: d.update(games=0, wins=0, losses=0, draws=0),
                 '"games" is not an integer > 0'),
    "negative": ("eval", lambda d: d.update(wins=-1, draws=d["draws"] + 1),
                 '"wins" is not an integer >= 0'),
    "sum": ("eval", lambda d: d.update(wins=d["games"] + 1),
            '"wins" + "losses" + "draws" is not "games"'),
    "opponent_kind": ("eval", lambda d: d.update(opponent_kind=["bot"]),
                      '"opponent_kind" is not a string'),
    "outcomes": ("eval", lambda d: d.update(outcomes=["draw", "lost", "draw", "draw"]),
                 '"outcomes" is not a list of "win", "loss", "draw"'),
    "outcomes_count": ("eval", lambda d: d.update(outcomes=d["outcomes"][:-1]),
                       '"outcomes" do not match "wins", "losses", "draws"'),
    "bool_count": ("eval", lambda d: d.update(wins=bool(d["wins"]) or True,
                                              losses=d["games"] - 1, draws=0),
                   '"wins" is not an integer >= 0'),
}


@pytest.mark.parametrize("damage", DAMAGES)
def test_a_results_value_the_report_reads_of_the_wrong_kind_is_damaged(made, tmp_path, capsys,
                                                                       damage):
    """A value the report reads only when it is there (league, saved_step, stopped,
    opponent_kind) of the wrong kind, or counts that are no games (none, negative, not
    adding up, a JSON true), or outcomes that are none or do not match the counts: the
    report once ended in a traceback (TypeError, ZeroDivisionError, ValueError, KeyError;
    opponent_kind in a counts table) or read them. Named by --list and --report-only
    (exit 2, nothing written) as a damaged file is, with the key, and made again by
    --resume."""
    which, spoil, why = DAMAGES[damage]
    out, args = copy_of_made(made, tmp_path)
    a_run = sorted((out / "runs").iterdir())[0]
    path = a_run / "done.json" if which == "done.json" else sorted((a_run / "eval").iterdir())[0]
    data = json.loads(path.read_text())
    spoil(data)
    path.write_text(json.dumps(data))
    reports = {p.name: p.read_bytes() for p in out.glob("tiny.*")}
    assert cli(*args, "--list") == 0
    listed = capsys.readouterr().out
    assert f"tiny/a_random seed 0: damaged: {path}: {why}; the file is damaged; " in listed, \
        listed
    assert cli(*args, "--report-only") == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{path}: {why}; the file is damaged: --resume" in err, err
    assert {p.name: p.read_bytes() for p in out.glob("tiny.*")} == reports
    assert cli(*args, "--resume") == 0
    err = capsys.readouterr().err
    assert f"{path}: {why}; the file is damaged: set aside as " in err, err
    assert not json.loads((out / "tiny.json").read_text())["missing"]


def test_a_damaged_metrics_jsonl_is_named_and_resume_trains_its_run_again(made, tmp_path,
                                                                          capsys):
    """A finished run's metrics.jsonl (the learning curves) with a line that is not JSON:
    --list and --report-only name it (exit 2, nothing written; the curves once left that
    run out silently); --resume sets its run aside and trains it again. A damaged
    checkpoint meta.json is named by the evaluation that reads it (a failed run, exit 1);
    row.json is never read back."""
    out, args = copy_of_made(made, tmp_path)
    a_run, b_run = sorted((out / "runs").iterdir())
    metrics = a_run / "metrics.jsonl"
    metrics.write_text("not json\n" + metrics.read_text())
    (b_run / "row.json").write_text("")
    reports = {p.name: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    assert cli(*args, "--list") == 0
    listed = capsys.readouterr().out
    assert f"tiny/a_random seed 0: damaged: {metrics}, line 1: not a JSON row " in listed
    assert "2 runs (1 seed(s)), 1 to do (1 damaged)" in listed
    assert cli(*args, "--report-only") == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{metrics}, line 1: not a JSON row" in err, err
    assert {p.name: p.read_bytes() for p in out.rglob("*") if p.is_file()} == reports
    assert cli(*args, "--resume") == 0
    err = capsys.readouterr().err
    assert f"{metrics}, line 1: " in err and f"set aside as {a_run}.damaged; the run " \
        "trains again" in err
    assert Path(f"{a_run}.damaged", "metrics.jsonl").read_text().startswith("not json")
    assert json.loads(metrics.read_text().splitlines()[0])["step"] > 0
    assert (a_run / "done.json").is_file() and (b_run / "row.json").read_text() == ""
    meta = Path(load_checkpoint(b_run).path) / "meta.json"
    meta.write_text("[]")
    next((b_run / "eval").iterdir()).unlink()
    assert cli(*args, "--resume") == 1
    err = capsys.readouterr().err
    assert f"tiny/b_cycle seed 0: CheckpointError: {meta}: not an alphatank checkpoint" in err


def retrain_hint(run: Path) -> str:
    """What the summary, --list and the report add to the failure of ``run``, a finished
    run whose checkpoint did not load."""
    return (f"; --resume only plays its evaluations again (the run is finished: it has "
            f"done.json): if its checkpoint is damaged or missing, move {run} away (e.g. to "
            f"{run}.damaged), then --resume trains the run again")


@pytest.fixture(scope="module")
def checkpoint_failed(made, tmp_path_factory):
    """A copy of :func:`made` whose a_random run lost its evaluations and whose checkpoint
    was cut short, after a --resume that tried to evaluate it: (out, arguments, the
    checkpoint file, the run, what the command printed on stderr)."""
    out, args = copy_of_made(made, tmp_path_factory.mktemp("failed"))
    run = sorted((out / "runs").iterdir())[0]
    ppo = Path(load_checkpoint(run).path) / "ppo.pt"
    ppo.write_bytes(ppo.read_bytes()[:200])
    for p in (run / "eval").iterdir():
        p.unlink()
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        assert cli(*args, "--resume") == 1
    return out, args, ppo, run, err.getvalue()


def test_a_failure_several_evaluations_gave_is_said_once(checkpoint_failed):
    """Both evaluations of a run fail to load its damaged checkpoint: the summary, the
    last line of error.txt and the report give the failure once, with the number of
    evaluations (it was said once per evaluation, "X; X")."""
    out, _, ppo, run, err = checkpoint_failed
    why = (f"CheckpointError: {ppo}: corrupt or truncated (SHA-256 differs from the one "
           f"recorded in meta.json; size 200 bytes) (2 evaluations)")
    assert f"tiny/a_random seed 0: {why} ({run}/error.txt)" in err, err
    assert err.count("SHA-256 differs") == 1
    assert (run / "error.txt").read_text().splitlines()[-1] == why
    assert json.loads((out / "tiny.json").read_text())["missing"] == [
        f"tiny/a_random seed 0: {why}{retrain_hint(run)}"]


def test_the_plan_names_the_runs_whose_last_attempt_failed(checkpoint_failed, capsys):
    """--list names a run still to do whose last attempt failed, and why (it was only
    counted to do)."""
    _, args, ppo, _, _ = checkpoint_failed
    assert cli(*args, "--list") == 0
    listed = capsys.readouterr().out
    assert f"tiny/a_random seed 0: last attempt failed: CheckpointError: {ppo}: corrupt or " \
        "truncated (SHA-256 differs" in listed, listed
    assert "b_cycle seed 0: last" not in listed and "2 runs (1 seed(s)), 1 to do:" in listed


def test_a_finished_run_whose_checkpoint_fails_says_how_to_train_it_again(
        made, checkpoint_failed, tmp_path, capsys):
    """--resume only plays a finished run's evaluations again, from its damaged
    checkpoint: the summary, --list and the report's missing runs say so and how to train
    it again (move the run away, then --resume), which then trains it and plays its
    evaluations."""
    failed_out, args, _, run, err = checkpoint_failed
    hint = retrain_hint(run)
    assert f"({run}/error.txt){hint}\n" in err, err
    section = (failed_out / "tiny.md").read_text().split("## Missing or failed\n")[1]
    assert section.count(hint) == 1 and "- tiny/a_random seed 0: CheckpointError: " \
        in section, section
    assert cli(*args, "--list") == 0
    assert hint in capsys.readouterr().out
    out, args = copy_of_made((made[0], failed_out, None), tmp_path)
    run = out / "runs" / run.name
    run.rename(f"{run}.damaged")
    assert cli(*args, "--resume") == 0
    assert "2 runs, 1 to do" in capsys.readouterr().out
    assert (run / "done.json").is_file() and len(list((run / "eval").iterdir())) == 2
    assert not (run / "error.txt").exists()
    assert not json.loads((out / "tiny.json").read_text())["missing"]


def test_a_failure_of_a_row_shown_beside_rows_is_listed_not_a_traceback(made, tmp_path,
                                                                       capsys):
    """--rows a_random --resume plays again the damaged evaluation of b_cycle (a row its
    table shows), whose checkpoint is damaged too: the failure is listed as any other
    (exit 1); the list once ended in a KeyError traceback (b_cycle is not in the plan of
    --rows), and the start line counted b_cycle's run to do but not among the runs."""
    out, args = copy_of_made(made, tmp_path)
    run = sorted((out / "runs").iterdir())[1]
    cut = sorted((run / "eval").iterdir())[0]
    cut.write_text("{")
    ppo = Path(load_checkpoint(run).path) / "ppo.pt"
    ppo.write_bytes(ppo.read_bytes()[:200])
    assert cli(*args, "--rows", "a_random", "--resume") == 1
    out_text, err = capsys.readouterr()
    assert "experiments tiny: 2 runs, 1 to do" in out_text, out_text  # was '1 runs, 1 to do'
    assert f"set aside as {cut}.damaged; the evaluation is played again" in err, err
    assert f"  tiny/b_cycle seed 0: CheckpointError: {ppo}: corrupt or truncated" in err, err
    assert "Traceback" not in err and f"({run}/error.txt)" in err


@pytest.mark.parametrize("size", [0, 60])
def test_a_damaged_table_json_is_named_not_taken_for_no_report(made, tmp_path, capsys, size):
    """The report that says which results a new one must keep, cut short: one line naming
    it, exit 2, the report left as it is (it once let a report drop every result)."""
    root, made_out, _ = made
    out = tmp_path / "out"
    shutil.copytree(made_out, out)
    table = out / "tiny.json"
    table.write_bytes(table.read_bytes()[:size])
    reports = {p.name: p.read_bytes() for p in out.glob("tiny.*")}
    assert cli("tiny", "--experiments-dir", str(root), "--out", str(out), "--steps", "512",
               "--games", "6", "--budget", "2", "--no-progress", "--report-only") == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{table}: " in err and "move it away" in err, err
    assert {p.name: p.read_bytes() for p in out.glob("tiny.*")} == reports


def test_best_average_is_not_met_before_every_specialist_has_an_average(tmp_path):
    """A row above the specialists with results was reported "met" while another
    specialist had none yet (failed, or not run: --rows), and a row without results made
    the check "NOT met" though another row could still meet it."""
    root = write_rows(tmp_path / "exp")
    (root / "tiny" / "c_spec.toml").write_text(
        (root / "tiny" / "a_random.toml").read_text().replace("order = 1", "order = 3")
        .replace("Random Bot", "Specialist"))
    with open(root / "tiny" / "_table.toml", "a") as f:
        f.write('[[checks]]\nkind = "best_average"\nrows = ["b_cycle"]\n'
                'against = ["a_random", "c_spec"]\n[[checks]]\nkind = "best_average"\n'
                'rows = ["a_random", "b_cycle"]\nagainst = ["c_spec"]\n')
    table = load_tables(["tiny"], root)[0]

    def results(rates: dict[str, float]) -> list[RowResult]:
        return [RowResult(row, table.row_columns(row), evals={
            c.name: {0: {"wins": round(rates[row.name] * 10), "losses": 0,
                         "draws": 10 - round(rates[row.name] * 10), "games": 10}}
            for c in table.row_columns(row)} if row.name in rates else {})
            for row in table.rows]

    def best_average(rates: dict[str, float]) -> bool | None:
        return run_checks(table, results(rates))[1]["passed"]

    assert best_average({"a_random": 0.2, "b_cycle": 0.5}) is None
    assert best_average({"a_random": 0.2, "b_cycle": 0.5, "c_spec": 0.4}) is True
    assert best_average({"a_random": 0.2, "b_cycle": 0.5, "c_spec": 0.6}) is False
    assert best_average({"a_random": 0.6, "b_cycle": 0.5}) is False
    assert best_average({"a_random": 0.2, "c_spec": 0.3}) is None
    # a_random below c_spec, b_cycle not measured yet: it may still be above
    assert run_checks(table, results({"a_random": 0.2, "c_spec": 0.4}))[2]["passed"] is None
    assert run_checks(table, results({"a_random": 0.2, "b_cycle": 0.3, "c_spec": 0.4})
                      )[2]["passed"] is False
    check = run_checks(table, results({"a_random": 0.2, "b_cycle": 0.5}))[1]
    assert check["details"] == ["Cycle: average 50.0% vs best specialist 20.0% - so far (no "
                                "average yet of c_spec)"]


def test_a_check_is_not_judged_before_every_seed_has_its_figures(made, tmp_path, capsys):
    """Seed 0 of two finished (the command was interrupted, say): the report shows its
    results, and its check is not measurable yet; it was judged on seed 0 alone (NOT met,
    or met, and so printed and written), then could turn once seed 1 finished."""
    out, args = copy_of_made(made, tmp_path)
    assert cli(*args, "--report-only", "--seeds", "2") == 0
    assert "tiny.md  [beats_paper: not measurable]  (2 missing)" in capsys.readouterr().out
    data = json.loads((out / "tiny.json").read_text())
    assert data["checks"][0]["passed"] is None and data["checks"][0]["details"] == []
    assert data["rows"][0]["columns"]["random"]["rates"] == [0.0]  # seed 0 still shown
    assert "every cell with a paper figure is at or above it: **not measurable yet**" in (
        out / "tiny.md").read_text()


def test_a_cell_without_results_has_the_keys_of_one_with_them(made, tmp_path):
    """A missing cell of the JSON report holds the keys of a cell with results, its
    figures null ("pooled" in every cell, as the docs say); it held only "runs": [] and
    "paper" (cell["iqm"] was a KeyError)."""
    out, args = copy_of_made(made, tmp_path)
    for f in sorted((out / "runs").iterdir())[1].glob("eval/*.json"):
        f.unlink()
    (out / "tiny.json").unlink()
    assert cli(*args, "--report-only") == 0
    a, b = json.loads((out / "tiny.json").read_text())["rows"]
    assert b["columns"]["random"] == {"rates": [], "median": None, "iqm": None,
                                      "iqm_ci95": None, "pooled": None, "paper": None,
                                      "per_seed": []}
    assert a["columns"]["random"].keys() == b["columns"]["random"].keys()
    assert a["average"].keys() == b["average"].keys() and b["average"]["iqm"] is None


def test_a_report_without_results_leaves_no_figure_of_an_earlier_one(made, tmp_path):
    """The runs moved away (as the report's own hints say) and the report written anew:
    its figures showed the earlier results still (they were left, unlinked, in figures/)."""
    out, args = copy_of_made(made, tmp_path)
    assert sorted(p.name for p in (out / "figures").iterdir()) == ["tiny_curves.png",
                                                                    "tiny_heatmap.png"]
    (out / "runs").rename(tmp_path / "runs.old")
    (out / "tiny.json").rename(tmp_path / "tiny.json.old")
    assert cli(*args, "--report-only") == 0
    assert list((out / "figures").iterdir()) == []
    md = (out / "tiny.md").read_text()
    assert "## Figures" not in md and "- tiny/a_random seed 0" in md


def test_an_interrupted_command_writes_the_tables_of_what_finished(tmp_path, capsys):
    """SIGINT while a row trains: exit 130, and the tables show the rows that finished
    (the docs: the tables are rewritten after every command)."""
    root = write_rows(tmp_path / "exp")
    quick = root / "tiny" / "a_random.toml"  # 2 min x 256 = 512 steps; b_cycle: 72,000
    quick.write_text("steps_per_minute = 256\n" + quick.read_text())
    out = tmp_path / "out"
    over = threading.Event()

    def stop_once_b_trains() -> None:
        while not over.wait(0.05):
            if any(m.stat().st_size for m in out.glob("runs/b_cycle-*/metrics.jsonl")):
                os.kill(os.getpid(), signal.SIGINT)
                return

    watcher = threading.Thread(target=stop_once_b_trains, daemon=True)
    watcher.start()
    try:
        rc = cli("tiny", "--experiments-dir", str(root), "--out", str(out), "--games", "2",
                 "--budget", "2", "--no-progress")
    finally:
        over.set()
        watcher.join()
    assert rc == 130
    assert "interrupted: finished runs" in capsys.readouterr().err
    data = json.loads((out / "tiny.json").read_text())
    assert data["rows"][0]["columns"]["random"]["per_seed"]
    assert [m for m in data["missing"] if "b_cycle" in m] and (out / "tiny.md").is_file()


def test_errors_name_the_row_files_where_they_are(tmp_path, capsys):
    """--experiments-dir XP: a bad row or table file is named by its path in XP."""
    root = write_rows(tmp_path / "xp")
    row, table = root / "tiny" / "a_random.toml", root / "tiny" / "_table.toml"
    text = row.read_text()
    for bad, why in (("bogus = 1\n" + text, f"{row}: bogus: unknown key"),
                     ("steps_per_minute = 0\n" + text, f"{row}: steps_per_minute: must be"),
                     ("title = \n" + text, f"{row}: invalid TOML")):
        row.write_text(bad)
        assert cli("tiny", "--experiments-dir", str(root), "--list") == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and why in err, err
    row.write_text(text)
    table.write_text("bogus = 1\n" + table.read_text())
    assert cli("tiny", "--experiments-dir", str(root), "--list") == 2
    assert f"{table}: bogus: unknown key" in capsys.readouterr().err


def test_rows_without_a_name_and_seeds_past_the_limit_are_one_line(tmp_path, capsys):
    """--rows ',' or '' once meant every row; --seeds past the training seeds' limit
    planned for minutes before the first seed past it failed."""
    for rows in (",", "", " , "):
        assert cli("table3", "--rows", rows, "--list", "--out", str(tmp_path)) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "--rows: no row name in" in err, err
    t0 = time.time()
    assert cli("table3", "--seeds", "1000001", "--list", "--out", str(tmp_path)) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--seeds must be in [1, 1,000,000]" in err, err
    assert time.time() - t0 < 30


TABLE3_AGENTS = {"smart": "ppo_vs_smart", "aggressive": "ppo_vs_aggressive",
                 "dodge": "ppo_vs_dodge", "defensive": "ppo_vs_defensive",
                 "team_2smart": "team_vs_2smart", "team_def": "team_vs_def",
                 "team_def_2smart": "team_vs_def_2smart", "team_four_bots": "team_vs_four_bots"}
# what a run is called and where it logs, not what it trains
NOT_TRAINING = {"name", "description", "wandb", "project", "tensorboard", "keep_checkpoints"}


def _assert_plans_agent(cfg: dict, agent: str) -> None:
    """``cfg`` (a planned run) trains what shipped agent ``agent`` saved: only names and
    logging differ, settings added later count as absent when off, and teachers' run
    folders are compared by name (the output folder differs)."""
    saved = load_checkpoint(agent_path(agent)).meta["train_config"]
    defaults = {f.name: f.default_factory() if f.default_factory is not dataclasses.MISSING
                else f.default for f in dataclasses.fields(TrainConfig)}
    for spec in cfg["learners"] + saved["learners"]:  # added later; absent when off
        for key, off in LATER_SETTINGS.items():
            if spec["config"].get(key, off) == off:
                spec["config"].pop(key, None)
    for run in (cfg, saved):
        teachers = (run.get("imitate") or {}).get("teachers") or {}
        teachers.update({k: Path(v).name for k, v in teachers.items()})
    differ = {k for k in set(cfg) | set(saved) if cfg.get(k) != saved.get(k)
              and not (k not in saved and cfg[k] == defaults.get(k))}  # added later
    assert differ <= NOT_TRAINING, (agent, sorted(differ))


def _planned(command: str) -> tuple[argparse.Namespace, dict[tuple[str, int], dict]]:
    """The arguments of ``alphatank experiments ...`` and its plan's runs by (row, seed)."""
    parser = argparse.ArgumentParser()
    add_arguments(parser)
    args = parser.parse_args(shlex.split(command)[2:])
    plan = make_plan(load_tables([args.table]), args.out, args.seeds, args.budget,
                     args.games, args.steps, rows=args.rows.split(","))
    return args, {(j.rows[0].split("/")[1], j.seed): j.cfg for j in plan.jobs}


@pytest.mark.parametrize("doc", ["README.md", "docs/results/README.md", "docs/training.md"])
def test_the_docs_table3_commands_plan_the_runs_of_the_shipped_agents(doc):
    """Each doc's block of Table 3 commands names every row with the README's seed counts
    (3, four for the three-bot row, five for the four-bot row) and plans each shipped
    agent's own run: its seed, budget (8 min for 1v1), step cap and every training
    setting. (The README once gave `--budget 15` and no `--steps`.)"""
    text = (Path(__file__).parents[1] / doc).read_text(encoding="utf-8")
    blocks = [b.split("```")[0] for b in text.split("```bash\n")[1:]]
    block = next(b for b in blocks if "experiments table3 --rows team_four_bots " in b)
    seeds, planned = {}, {}
    for line in block.splitlines():
        if line.startswith("alphatank experiments table3 "):
            args, runs = _planned(line.split("#")[0])
            seeds.update(dict.fromkeys(args.rows.split(","), args.seeds))
            planned.update(runs)
    assert seeds == {**dict.fromkeys(TABLE3_AGENTS, 3), "team_def_2smart": 4,
                     "team_four_bots": 5}
    for row, agent in TABLE3_AGENTS.items():
        seed = load_checkpoint(agent_path(agent)).meta["train_config"]["seed"]
        _assert_plans_agent(planned[row, seed], agent)


def test_the_readme_table4_and_league_commands_plan_the_shipped_agents_runs():
    """The README's cycle (Table 4) and distilled league commands plan the runs of
    ``agent:ppo_cycle_full`` and ``agent:league`` (the cycle one once lacked `--steps
    5000000`, which sets its phase length too)."""
    text = (Path(__file__).parents[1] / "README.md").read_text(encoding="utf-8")
    agents = {"cycle_fixed_full": "ppo_cycle_full", "league_distill": "league"}
    found = re.findall(r"`(alphatank experiments (?:table4|league) --rows[^`]*)`", text)
    assert len(found) == 2
    for command in found:
        args, runs = _planned(" ".join(command.split()))
        seed = load_checkpoint(agent_path(agents[args.rows])).meta["train_config"]["seed"]
        _assert_plans_agent(runs[args.rows, seed], agents[args.rows])

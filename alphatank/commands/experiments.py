"""``alphatank experiments``: the paper's tables in one command. Every row of a table
(``alphatank/data/experiments/<table>/<row>.toml``) is trained within a time budget,
evaluated over ``--games`` games per column at full bot strength with seeds disjoint
from training seeds, and reported as ``<out>/<table>.md``, ``.csv``, ``.json`` with the
paper's figures beside ours, plus learning curves (and a heatmap for cross tables).
"""

from __future__ import annotations

import argparse
import functools
import shlex
import sys
from collections import Counter
from pathlib import Path
from typing import TYPE_CHECKING

from alphatank.commands.argtypes import budget_minutes, given
from alphatank.files import check_folder

if TYPE_CHECKING:
    from alphatank.training.experiments import Plan

CHOICES = ("table3", "table4", "sac", "league", "heldout", "all")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("table", metavar="|".join(CHOICES),
                   help="the table to make (all: every table, in this order)")
    p.add_argument("--budget", type=budget_minutes, default=15.0, metavar="MINUTES",
                   help="training time per run in minutes, at most a week (default: "
                        "%(default)s)")
    p.add_argument("--seeds", type=int, default=1, metavar="N",
                   help="training seeds per row, 0..N-1 (default: %(default)s)")
    p.add_argument("--workers", type=int, default=1, metavar="W",
                   help="runs trained at once, one process each (default: %(default)s; "
                        "2 fills a 2-core machine)")
    p.add_argument("--out", type=given, default="results", metavar="DIR",
                   help="where runs, tables and figures go (default: %(default)s)")
    p.add_argument("--resume", action="store_true",
                   help="reuse what DIR already holds and finish only the missing runs and "
                        "evaluations (failed ones are tried again)")
    p.add_argument("--games", type=int, default=200,
                   help="evaluation games per cell (default: %(default)s)")
    p.add_argument("--rows", metavar="ROW,...",
                   help="only these rows (names or TABLE/ROW ids); their tables also show "
                        "every other row with results in DIR (made with the same settings)")
    p.add_argument("--steps", type=int, metavar="N",
                   help="env steps per run instead of budget x each row's planning rate, "
                        "rounded up to a whole iteration (rollout_steps x num_envs env "
                        "steps; --list shows each run's figure); the budget still caps the "
                        "time")
    p.add_argument("--list", action="store_true",
                   help="print the plan (rows, runs, estimated time) and exit")
    p.add_argument("--report-only", action="store_true",
                   help="write the tables from what DIR holds, training nothing (refused "
                        "where a table in DIR shows results this one would lack: rows made "
                        "with other settings)")
    p.add_argument("--experiments-dir", type=given, metavar="DIR",
                   help="read tables and rows from this folder instead of the shipped ones")
    p.add_argument("--wandb", default="disabled", choices=("disabled", "offline", "online"),
                   help="wandb mode of the runs (default: %(default)s; metrics.jsonl is "
                        "always written)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--ray", nargs="?", const="", metavar="ADDRESS",
                   help="run every training run and evaluation as a Ray task: join the "
                        "cluster at HOST:PORT, or without ADDRESS start a local Ray "
                        "instance (the ray extra; --out must be on a file system every node "
                        "sees: docs/distributed.md)")


def _error(msg: str) -> int:
    print(f"alphatank experiments: error: {msg}", file=sys.stderr)
    return 2


def run(args: argparse.Namespace) -> int:
    from alphatank.training.experiments import (
        BUSY,
        ExperimentError,
        Job,
        RunInterrupted,
        clone_cut,
        damaged_results,
        estimate_minutes,
        execute,
        load_tables,
        make_plan,
        read_json,
        retrain_hint,
        set_aside,
        table_names,
    )
    from alphatank.training.stopping import StopFlag, StopRequested, stop_on_signals

    if args.workers < 1:
        return _error(f"--workers must be >= 1, got {args.workers}")
    if args.ray is not None and args.workers != 1:
        return _error("--workers and --ray: give one (with --ray the cluster's CPUs decide "
                      "how many runs train at once)")
    rows = [r.strip() for r in (args.rows or "").split(",") if r.strip()]
    if args.rows is not None and not rows:
        return _error(f"--rows: no row name in {args.rows!r}; give ROW,... (row names or "
                      "TABLE/ROW ids), or leave --rows out for every row")
    for folder in ("", "runs", "figures"):  # a file where a folder goes fails every run
        check_folder(Path(args.out, folder), "--out")
    try:
        names = table_names(args.experiments_dir)
        if args.table == "all":
            wanted = names
        elif args.table in names:
            wanted = [args.table]
        else:
            folder = Path(args.experiments_dir or "", args.table)
            why = (f" ({folder} holds no _table.toml)"
                   if args.experiments_dir and folder.is_dir() else "")
            return _error(f"unknown table {args.table!r}{why}; choose one of "
                          f"{', '.join([*names, 'all'])}")
        tables = load_tables(wanted, args.experiments_dir)
        planned = functools.partial(make_plan, tables, args.out, seeds=args.seeds,
                                    budget_min=args.budget, games=args.games,
                                    steps=args.steps, wandb=args.wandb)
        plan = planned(rows=rows, report_only=args.report_only)
    except (ExperimentError, ValueError) as exc:
        return _error(str(exc))
    started = [j for j in plan.jobs if j.started()]
    if args.list:
        _print_plan(plan, None if args.ray is not None else args.workers)
        return 0
    if started and not (args.resume or args.report_only):
        return _error(f"{args.out} already holds {len(started)} of this plan's runs (e.g. "
                      f"{started[0].run_dir}); pass --resume to keep finished ones and "
                      f"finish the rest, or choose another --out")
    from alphatank.extras import require

    require("train", "alphatank experiments")
    from alphatank.training.report import evaluated_rows, reported_runs

    report = plan  # the reports: --rows, and every other row of their tables with results
    if rows:
        try:  # every row of their tables is planned: a bad one is refused here
            full, shown = planned(report_only=True), {t.name for t in plan.tables}
            rows += [r.id for t in full.tables if t.name in shown
                     for r in evaluated_rows(full, t)]
            report = planned(rows=rows, report_only=True)
        except (ExperimentError, ValueError) as exc:
            return _error(str(exc))
        # the command: each row by name, or TABLE/ROW where another table has that name
        named = Counter(r.name for t in tables for r in t.rows)
        args.rows = ",".join(r.name if named[r.name] == 1 else r.id
                             for t in report.tables for r in t.rows)
    damaged = damaged_results(report.jobs)  # a results file cut short: made again
    if damaged and (args.report_only or not args.resume):
        more = f" (and {len(damaged) - 1} more)" if len(damaged) > 1 else ""
        return _error(f"{damaged[0][2]}{more}: --resume (without --report-only) sets such "
                      "files aside and makes them again")
    for t in report.tables:  # a report never loses results it shows (made otherwise)
        folder = next((p for p in (report.out / f"{t.name}.{x}" for x in ("md", "csv"))
                       if p.is_dir()), None)
        if folder is not None:
            return _error(f"--out {args.out}: {folder} is a folder; the {t.name} report is "
                          "written there: move it away")
        coming = evaluated_rows(report, t) if args.report_only else t.rows
        try:
            shown = reported_runs(report.out / f"{t.name}.json")
        except ValueError as exc:
            return _error(f"--out {args.out}: {exc}; it says which results the new report "
                          "must keep: restore it, or move it away to write it anew from "
                          f"{report.out / 'runs'}")
        lost = sorted(shown - {(r.name, s) for r in coming for s in range(report.seeds)})
        rows_now = {r.name for r in next(x for x in tables if x.name == t.name).rows}
        gone = sorted({row for row, _ in lost} - rows_now)
        if gone:  # its row file removed or renamed since: no settings bring it back
            return _error(f"--out {args.out}: {t.name}.json reports results of row(s) "
                          f"{', '.join(gone)}, which table {t.name} has no more (a row file "
                          "renamed or removed?); restore it, or move that report away to "
                          "write it anew")
        if lost:
            runs = ", ".join(f"{row} seed {seed}" for row, seed in lost)
            return _error(f"--out {args.out}: {t.name}.json reports results of {runs} that "
                          "this report would lack (made with other settings, e.g. --seeds: "
                          "see the command in it); give those settings, or another --out")
    redo: dict[str, Job] = {}
    for job, path, why in damaged:  # --resume: training or evaluating it again
        if job.key in redo and not Path(job.run_dir).exists():
            continue  # its run folder went aside with its damaged done.json or metrics
        moved = set_aside(job, path)
        print(f"{why}: set aside as {moved}; "
              + ("the run trains again" if job.retrains(path) else
                 "the evaluation is played again"), file=sys.stderr)
        redo[job.key] = job
    planned_keys = {j.key for j in plan.jobs}
    todo = [j for j in plan.jobs if not j.complete()] + [
        j for k, j in redo.items() if k not in planned_keys]  # rows shown beside --rows
    command = _command(args)
    failed: dict[str, str] = {}
    if not args.report_only and todo:
        connection = runner = None
        workers, where = args.workers, f"{args.workers} worker(s)"
        if args.ray is not None:
            from alphatank.cluster import connect

            connection = connect(args.ray or None, feature="alphatank experiments --ray")
            print(connection.describe(), flush=True)
            workers, where = max(1, int(connection.cpus)), f"Ray ({connection.cpus:g} CPUs)"
            from alphatank.training.ray_jobs import run_on_ray as runner
        eta = estimate_minutes(plan, todo, workers)
        runs = len(planned_keys | {j.key for j in todo})  # with rows shown beside --rows
        print(f"experiments {', '.join(t.name for t in plan.tables)}: {runs} runs, "
              f"{len(todo)} to do, about {_minutes(eta)} with {where} -> "
              f"{args.out}", flush=True)

        def on_done(job, error, seconds):  # noqa: ANN001, ANN202
            status = "FAILED " + error if error else "done"
            if not error and clone_cut(read_json(job.done_file)["summary"]):
                status += (", but its budget ended while it cloned its bot: evaluated "
                           "untrained (give it a larger --budget)")
            from tqdm import tqdm
            tqdm.write(f"  {', '.join(job.rows)} seed {job.seed}: {status} "
                       f"({seconds / 60:.1f} min)")

        stop = StopFlag()  # SIGINT / SIGTERM to this process alone stop it as Ctrl-C does
        try:
            with stop_on_signals(stop), stop.interruptible():
                failed = execute(todo, args.workers, progress=not args.no_progress,
                                 on_done=on_done, runner=runner)
        except (KeyboardInterrupt, RunInterrupted, StopRequested) as exc:  # Ctrl-C, SIGTERM
            code = getattr(exc, "exit_code", stop.exit_code or 130)
            print("interrupted: finished runs and evaluations are kept (the tables show "
                  "them); --resume finishes the rest", file=sys.stderr)
            try:  # what finished before the signal; another Ctrl-C ends it here
                return _write_reports(report, command, args.out) or code
            except KeyboardInterrupt:
                return code
        finally:
            if connection is not None:
                connection.close()
    error = _write_reports(report, command, args.out)
    if error:
        return error
    if failed:
        print(f"{len(failed)} run(s) failed (their error.txt holds the traceback) or "
              f"busy (another command is training them):", file=sys.stderr)
        by_key = {j.key: j for j in todo}  # also a row shown beside --rows made again
        for key, err in failed.items():
            job = by_key[key]
            where = "busy" if err.startswith(BUSY) else f"{job.run_dir}/error.txt"
            print(f"  {', '.join(job.rows)} seed {job.seed}: {err} ({where})"
                  + retrain_hint(job, err), file=sys.stderr)
        return 1
    return 0


def _write_reports(report: Plan, command: str, out: str) -> int | None:
    """Write every table of ``report`` from what its folder holds, a line each; the exit
    status of a write that failed, else None."""
    from alphatank.training.report import write_report

    for table in report.tables:
        try:
            data = write_report(report, table, command)
        except OSError as exc:
            return _error(f"cannot write the {table.name} report in {out}: {exc}")
        status = ", ".join(f"{c['kind']}: " + {True: "met", False: "not met",
                                               None: "not measurable"}[c["passed"]]
                           for c in data["checks"])
        print(f"{report.out / (table.name + '.md')}" + (f"  [{status}]" if status else "")
              + (f"  ({len(data['missing'])} missing)" if data["missing"] else ""))
    return None


# flags that change what is made, in the order a command line shows them
RECORDED = (("--budget", "budget", 15.0), ("--seeds", "seeds", 1), ("--workers", "workers", 1),
            ("--games", "games", 200), ("--steps", "steps", None), ("--rows", "rows", None),
            ("--experiments-dir", "experiments_dir", None), ("--wandb", "wandb", "disabled"),
            ("--out", "out", "results"))


def _command(args: argparse.Namespace) -> str:
    """The command line that makes these tables (options at their defaults left out)."""
    parts = ["alphatank", "experiments", args.table]
    for flag, attr, default in RECORDED:
        value = getattr(args, attr)
        if value != default:
            parts += [flag, f"{value:g}" if isinstance(value, float) else str(value)]
    return " ".join(shlex.quote(p) for p in parts)


def _minutes(m: float) -> str:
    """An estimate in minutes: whole ones, two digits under one (a few seconds' budget
    is not 'about 0 min')."""
    return f"{m:.0f} min" if m >= 1 else f"{m:.2g} min"


def _print_plan(plan: Plan, workers: int | None) -> None:
    """Rows, runs and the time the missing ones take on ``workers`` (None: a Ray cluster,
    whose CPUs --list does not connect to count); a run whose results file is damaged
    (:func:`~alphatank.training.experiments.damaged_results`) is named and counted to do,
    one still to do whose last attempt failed is named with its failure."""
    from alphatank.training.experiments import (
        damaged_results,
        estimate_minutes,
        last_failure,
        retrain_hint,
    )
    from alphatank.training.presets import TrainConfig, iteration_steps, planned_steps

    by_key = {j.key: j for j in plan.jobs}
    for table in plan.tables:
        print(f"{table.name}: {table.title}")
        for row in table.rows:
            job = plan.cells[(row.id, 0)][0]
            cfg = TrainConfig.from_dict(job.cfg)
            steps = planned_steps(cfg)
            shared = [r for r in job.rows if r != row.id]
            where = (f"mix of {len(job.scenarios)}" if job.scenarios else cfg.scenario)
            after = [r for k in job.needs for r in by_key[k].rows[:1]]
            print(f"  {row.name:18s} {where:18s} steps {steps:>9,}  {row.title}"
                  + (f"  ({cfg.total_steps:,} asked; iterations of {iteration_steps(cfg):,})"
                     if steps != cfg.total_steps else "")
                  + (f"  (run shared with {', '.join(shared)})" if shared else "")
                  + (f"  (trains after {', '.join(after)})" if after else ""))
    print(f"steps: env steps per run, whole iterations (rollout_steps x num_envs), unless "
          f"the {plan.budget_min:g}-minute budget ends it first")
    damaged = damaged_results(plan.jobs)
    for job, _, why in damaged:
        print(f"  {', '.join(job.rows)} seed {job.seed}: damaged: {why}; --resume sets it "
              "aside and makes it again")
    redo = {j.key for j, _, _ in damaged}
    todo = [j for j in plan.jobs if not j.complete() or j.key in redo]
    for job in todo:
        failure = last_failure(job)
        if failure is not None:
            print(f"  {', '.join(job.rows)} seed {job.seed}: last attempt failed: {failure}"
                  + retrain_hint(job, failure))
    minutes = estimate_minutes(plan, todo, workers or 1, [p for _, p, _ in damaged])
    print(f"{len(plan.jobs)} runs ({plan.seeds} seed(s)), {len(todo)} to do"
          + (f" ({len(redo)} damaged)" if redo else "") + f": about {_minutes(minutes)} "
          + (f"with {workers} worker(s)" if workers else
             "on one CPU, shared out over the Ray cluster's CPUs (the run says how many)"))

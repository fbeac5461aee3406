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

from alphatank.commands.argtypes import budget_minutes
from alphatank.files import check_folder

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
    p.add_argument("--out", default="results", metavar="DIR",
                   help="where runs, tables and figures go (default: %(default)s)")
    p.add_argument("--resume", action="store_true",
                   help="reuse what DIR already holds and finish only the missing runs and "
                        "evaluations (failed ones are tried again)")
    p.add_argument("--games", type=int, default=200,
                   help="evaluation games per cell (default: %(default)s)")
    p.add_argument("--rows", default="", metavar="ROW,...",
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
    p.add_argument("--experiments-dir", metavar="DIR",
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
        RunInterrupted,
        clone_cut,
        estimate_minutes,
        execute,
        load_tables,
        make_plan,
        read_json,
        table_names,
    )
    from alphatank.training.stopping import StopFlag, StopRequested, stop_on_signals

    if args.workers < 1:
        return _error(f"--workers must be >= 1, got {args.workers}")
    if args.ray is not None and args.workers != 1:
        return _error("--workers and --ray: give one (with --ray the cluster's CPUs decide "
                      "how many runs train at once)")
    check_folder(args.out, "--out")
    try:
        names = table_names(args.experiments_dir)
        if args.table == "all":
            wanted = names
        elif args.table in names:
            wanted = [args.table]
        else:
            return _error(f"unknown table {args.table!r}; choose one of "
                          f"{', '.join([*names, 'all'])}")
        tables = load_tables(wanted, args.experiments_dir)
        rows = [r.strip() for r in args.rows.split(",") if r.strip()]
        planned = functools.partial(make_plan, tables, args.out, seeds=args.seeds,
                                    budget_min=args.budget, games=args.games,
                                    steps=args.steps, wandb=args.wandb)
        plan = planned(rows=rows, report_only=args.report_only)
    except (ExperimentError, ValueError) as exc:
        return _error(str(exc))
    todo = [j for j in plan.jobs if not j.complete()]
    started = [j for j in plan.jobs if j.started()]
    if args.list:
        _print_plan(plan, todo, args.workers, estimate_minutes)
        return 0
    if started and not (args.resume or args.report_only):
        return _error(f"{args.out} already holds {len(started)} of this plan's runs (e.g. "
                      f"{started[0].run_dir}); pass --resume to keep finished ones and "
                      f"finish the rest, or choose another --out")
    from alphatank.extras import require

    require("train", "alphatank experiments")
    from alphatank.training.report import evaluated_rows, reported_runs, write_report

    report = plan  # the reports: --rows, and every other row of their tables with results
    if rows:
        try:  # every row of their tables is planned: a bad one is refused here
            full, shown = planned(report_only=True), {t.name for t in plan.tables}
            rows += [r.id for t in full.tables if t.name in shown
                     for r in evaluated_rows(full, t)]
            report = planned(rows=rows, report_only=True)
        except (ExperimentError, ValueError) as exc:
            return _error(str(exc))
        args.rows = ",".join(r.name for t in report.tables for r in t.rows)  # the command
    for t in report.tables:  # a report never loses results it shows (made otherwise)
        coming = evaluated_rows(report, t) if args.report_only else t.rows
        lost = sorted(reported_runs(report.out / f"{t.name}.json")
                      - {(r.name, s) for r in coming for s in range(report.seeds)})
        if lost:
            runs = ", ".join(f"{row} seed {seed}" for row, seed in lost)
            return _error(f"--out {args.out}: {t.name}.json reports results of {runs} that "
                          "this report would lack (made with other settings, e.g. --seeds: "
                          "see the command in it); give those settings, or another --out")
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
        print(f"experiments {', '.join(t.name for t in plan.tables)}: {len(plan.jobs)} runs, "
              f"{len(todo)} to do, about {eta:.0f} min with {where} -> "
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
            print("interrupted: finished runs and evaluations are kept; --resume finishes "
                  "the rest", file=sys.stderr)
            return getattr(exc, "exit_code", stop.exit_code or 130)
        finally:
            if connection is not None:
                connection.close()
    for table in report.tables:
        try:
            data = write_report(report, table, command)
        except OSError as exc:
            return _error(f"cannot write the {table.name} report in {args.out}: {exc}")
        status = ", ".join(f"{c['kind']}: " + {True: "met", False: "not met",
                                               None: "not measurable"}[c["passed"]]
                           for c in data["checks"])
        print(f"{report.out / (table.name + '.md')}" + (f"  [{status}]" if status else "")
              + (f"  ({len(data['missing'])} missing)" if data["missing"] else ""))
    if failed:
        print(f"{len(failed)} run(s) failed (their error.txt holds the traceback) or "
              f"busy (another command is training them):", file=sys.stderr)
        by_key = {j.key: j for j in plan.jobs}
        for key, err in failed.items():
            where = "busy" if err.startswith(BUSY) else f"{by_key[key].run_dir}/error.txt"
            print(f"  {', '.join(by_key[key].rows)} seed {by_key[key].seed}: {err} "
                  f"({where})", file=sys.stderr)
        return 1
    return 0


# flags that change what is made, in the order a command line shows them
RECORDED = (("--budget", "budget", 15.0), ("--seeds", "seeds", 1), ("--workers", "workers", 1),
            ("--games", "games", 200), ("--steps", "steps", None), ("--rows", "rows", ""),
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


def _print_plan(plan, todo, workers, estimate) -> None:  # noqa: ANN001
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
    print(f"{len(plan.jobs)} runs ({plan.seeds} seed(s)), {len(todo)} to do: about "
          f"{estimate(plan, todo, workers):.0f} min with {workers} worker(s)")

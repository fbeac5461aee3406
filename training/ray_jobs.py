"""``alphatank experiments --ray``: the plan's training runs and evaluations as Ray tasks.

Each job's training run is one task asking for the run's CPUs (``num_workers``: a run
with W env workers asks for W); each of its missing evaluations is one task (one CPU)
that Ray starts once the training task has finished (the training result is its
argument), so the evaluations of a run spread over the cluster. Ray retries a task
whose worker process or node died (``max_retries``); an error inside a run is not
retried (it would fail again): it is written to the run's ``error.txt``, as without Ray.

Where results land: every task writes its files itself, at the absolute path the driver
resolved ``--out`` to, after moving to the driver's working directory (so relative paths
in run settings mean the same). On a cluster of several hosts that path must be on a
file system every node mounts at the same place (NFS, a cluster file system); on one
host nothing is needed. A row is finished when its ``done.json`` and evaluation files
exist, as without Ray: the driver submits only what is missing (``--resume``), and a
retried task skips what an earlier attempt finished, so finished rows are never redone.

Ray is imported only in :func:`run_on_ray`, which ``alphatank experiments --ray`` hands
to :func:`alphatank.training.experiments.execute`.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from alphatank.training.experiments import (
    EvalSpec,
    Failure,
    Job,
    eval_step,
    record_failures,
    train_step,
)

MAX_RETRIES = 3  # attempts after the first when a task's worker process or node dies


def _enter(cwd: str) -> None:
    """Work in the driver's folder where this node has it (a shared file system)."""
    if os.path.isdir(cwd):
        os.chdir(cwd)


def train_task(job: Job, cwd: str) -> tuple[Failure | None, float]:
    """Train ``job`` (a Ray task): its failure or None, and the seconds it took."""
    _enter(cwd)
    t0 = time.time()
    return train_step(job), time.time() - t0


def eval_task(job: Job, spec: EvalSpec, cwd: str,
              trained: tuple[Failure | None, float] | None) -> tuple[Failure | None, float]:
    """Evaluate ``job`` on ``spec`` (a Ray task) once its training (``trained``: the
    training task's result, None when it was finished before) succeeded."""
    if trained is not None and trained[0] is not None:
        return None, 0.0  # the training failure is reported by the training task
    _enter(cwd)
    t0 = time.time()
    return eval_step(job, spec), time.time() - t0


WAIT_S = 0.5  # how long one ray.wait blocks: Ray runs signal handlers only as it returns


def _wait(ray: Any, refs: list[Any]) -> list[Any]:
    """The refs of ``refs`` that are ready, at least one. Waits ``WAIT_S`` at a time so
    that Ctrl-C and SIGTERM act at once (a wait for a task of a 15-minute row ran the
    handler when the task ended), and raises what a handler raised (Ray 2.60 returns
    from ``wait`` with it set, as a SystemError caused by it)."""
    while True:
        try:
            ready, _ = ray.wait(refs, num_returns=1, timeout=WAIT_S)
        except SystemError as exc:
            if exc.__cause__ is None:
                raise
            raise exc.__cause__ from None
        if ready:
            return ready


def run_on_ray(jobs: Sequence[Job], finish: Callable[[Job, str | None, float], None],
               max_retries: int = MAX_RETRIES) -> None:
    """Submit every missing training run and evaluation of ``jobs`` to the connected
    Ray cluster and call ``finish(job, error or None, seconds)`` as each job's last task
    ends (in the order they end). Ctrl-C cancels the tasks not yet finished."""
    import ray

    cwd = os.getcwd()
    train = ray.remote(train_task)
    evaluate = ray.remote(eval_task).options(num_cpus=1, max_retries=max_retries)
    by_key: dict[str, Job] = {}
    pending: dict[Any, str] = {}  # task ref -> job key
    open_refs: dict[str, set[Any]] = {}
    failures: dict[str, list[Failure]] = {}
    seconds: dict[str, float] = {}
    for job in jobs:
        job = dataclasses.replace(job, run_dir=str(Path(job.run_dir).resolve()))
        by_key[job.key] = job
        trained = None
        if not job.done_file.is_file():
            cpus = max(1, int(job.cfg.get("num_workers", 1)))
            trained = train.options(num_cpus=cpus, max_retries=max_retries).remote(job, cwd)
        refs = [trained] if trained is not None else []
        refs += [evaluate.remote(job, spec, cwd, trained) for spec in job.evals
                 if not job.eval_file(spec).is_file()]
        if not refs:  # nothing missing
            finish(job, None, 0.0)
            continue
        open_refs[job.key] = set(refs)
        failures[job.key], seconds[job.key] = [], 0.0
        pending.update(dict.fromkeys(refs, job.key))
    try:
        while pending:
            ready = _wait(ray, list(pending))
            for ref in ready:
                key = pending.pop(ref)
                try:
                    failure, took = ray.get(ref)
                except ray.exceptions.RayError as exc:  # retries used up, or cancelled
                    lines = [x.strip() for x in str(exc).strip().splitlines() if x.strip()]
                    failure = (f"Ray task failed ({type(exc).__name__}"
                               f"{': ' + lines[0] if lines else ''}; max_retries="
                               f"{max_retries})", str(exc))
                    took = 0.0
                if failure is not None and failure not in failures[key]:
                    failures[key].append(failure)
                seconds[key] += took
                open_refs[key].discard(ref)
                if not open_refs[key]:
                    job = by_key[key]
                    finish(job, record_failures(job, failures[key]), seconds[key])
    finally:
        for ref in pending:  # interrupted: stop what was not finished
            with contextlib.suppress(Exception):  # already finished or gone
                ray.cancel(ref, force=True)

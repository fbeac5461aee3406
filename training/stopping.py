"""Stopping a training run cleanly: a flag set by SIGINT / SIGTERM or a time budget and
polled by the loop every vector step (and by learners between gradient steps).

:class:`StopFlag` is the flag; :func:`stop_on_signals` installs the signal handlers for
the duration of a run (main thread only; previous handlers are restored afterwards) and,
when the flag has a deadline, a ``SIGALRM`` timer so that the budget also ends long
stretches that do not poll (evaluation, videos) inside :meth:`StopFlag.interruptible`.
A SIGINT while a signal's stop is under way (or a second SIGINT) aborts at once
(``KeyboardInterrupt``; the previous checkpoint stays intact), unless a checkpoint is being
written (:meth:`StopFlag.shielded`): then the save is finished first and the abort comes
right after it. :meth:`StopFlag.deferred` keeps a stop from cutting short the making of
what could not be undone halfway (worker processes). :func:`exit_with_parent` makes a
pool worker stop its job the same way when the process that started it dies or ends the
pool early (:func:`running_job`).
"""

from __future__ import annotations

import math
import os
import signal
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

SIGNALS = (signal.SIGINT, signal.SIGTERM)
# the longest time limit a run takes, in seconds: a week (as ``experiments --budget``);
# far larger ones overflow the SIGALRM timer (``signal.setitimer``)
TIME_LIMIT_MAX_S = 7 * 24 * 3600


class StopRequested(Exception):  # noqa: N818 (a request, not an error)
    """Raised inside :meth:`StopFlag.interruptible` blocks when a stop arrives."""


def check_interrupt(interrupt: Any) -> None:
    """For fixed-rollout learners, between gradient steps: raise :class:`StopRequested`
    if ``interrupt`` (a learner's ``interrupt`` attribute: None or a callable) says so."""
    if interrupt is not None and interrupt():
        raise StopRequested("update interrupted")


class StopFlag:
    """Why (and whether) a run should stop. Calling it polls: True once a stop was
    requested or ``time_limit_s`` (> 0) seconds have passed since it was made."""

    def __init__(self, time_limit_s: float = 0.0):
        self.reason: str | None = None
        self.signum: int | None = None
        self.limit(time_limit_s)
        self._interruptible = 0
        self._shielded = 0
        self.aborted = False  # an abort came inside a shielded block (raised after it)

    def __call__(self) -> bool:
        if self.reason is None and time.monotonic() >= self.deadline:
            self.reason = "time limit"
        return self.reason is not None

    def limit(self, time_limit_s: float) -> None:
        """Stop ``time_limit_s`` seconds from now (0: no time limit); for a flag made
        before the work it times (a command's, watching its start-up too)."""
        self.deadline = (time.monotonic() + time_limit_s if time_limit_s > 0
                         else math.inf)

    def request(self, reason: str, signum: int | None = None) -> None:
        """Ask the run to stop (the first reason given is kept)."""
        if self.reason is None:
            self.reason, self.signum = reason, signum
        if self._interruptible:
            raise StopRequested(reason)

    @property
    def exit_code(self) -> int:
        """128 + the signal's number for a signal (130 for SIGINT, 143 for SIGTERM), else 0
        (a time limit is a normal end)."""
        return 128 + self.signum if self.signum is not None else 0

    def abort(self) -> None:
        """Abort the run (a second Ctrl-C): ``KeyboardInterrupt`` now, or at the end of the
        :meth:`shielded` block under way."""
        if self._shielded:
            self.aborted = True
        else:
            raise KeyboardInterrupt

    @contextmanager
    def shielded(self) -> Iterator[None]:
        """A block that :meth:`abort` does not cut short (writing a checkpoint): an abort
        asked for inside it raises ``KeyboardInterrupt`` once it has ended."""
        self._shielded += 1
        try:
            yield
        finally:
            self._shielded -= 1
        if self.aborted and not self._shielded:
            raise KeyboardInterrupt

    @contextmanager
    def interruptible(self) -> Iterator[None]:
        """A block that a stop ends at once by raising :class:`StopRequested` (work whose
        result the checkpoint does not need, e.g. evaluation). Skipped entirely when a
        stop is already pending."""
        if self():
            raise StopRequested(self.reason)
        self._interruptible += 1
        try:
            yield
        finally:
            self._interruptible -= 1

    @contextmanager
    def deferred(self) -> Iterator[None]:
        """A part of an :meth:`interruptible` block that a stop does not cut short (making
        what cannot be undone halfway, such as worker processes): a stop that comes
        meanwhile raises :class:`StopRequested` once it has ended."""
        outer, self._interruptible = self._interruptible, 0
        try:
            yield
        finally:
            self._interruptible = outer
        if outer and self():
            raise StopRequested(self.reason)


@contextmanager
def stop_on_signals(flag: StopFlag) -> Iterator[StopFlag]:
    """SIGINT and SIGTERM (and the deadline, through SIGALRM) set ``flag`` while the block
    runs; previous handlers and timers are restored on exit. Outside the main thread
    (where Python cannot handle signals) the flag is only polled."""
    if threading.current_thread() is not threading.main_thread():
        yield flag
        return

    interrupts = 0

    def on_signal(signum: int, frame: Any) -> None:
        nonlocal interrupts
        if signum == signal.SIGINT:
            interrupts += 1
            if interrupts > 1 or flag.signum is not None:
                flag.abort()  # Ctrl-C while stopping: abort (once a save under way is done)
                return
        flag.request(signal.Signals(signum).name, signum)

    def on_alarm(signum: int, frame: Any) -> None:
        flag.request("time limit")

    previous = {s: signal.signal(s, on_signal) for s in SIGNALS}
    timed = math.isfinite(flag.deadline)
    if timed:
        previous[signal.SIGALRM] = signal.signal(signal.SIGALRM, on_alarm)
        began = time.monotonic()
        timer = signal.setitimer(signal.ITIMER_REAL, max(1e-3, flag.deadline - began))
    try:
        yield flag
    finally:
        if timed:
            signal.setitimer(signal.ITIMER_REAL, 0)
        for s, handler in previous.items():
            signal.signal(s, handler)
        if timed and timer[0] > 0:  # someone else's timer was running: re-arm what is left
            left = timer[0] - (time.monotonic() - began)
            signal.setitimer(signal.ITIMER_REAL, max(1e-3, left), timer[1])


_orphaned = threading.Event()  # the command has ended, or ended the pool early
_parent_died = threading.Event()
_busy = threading.Event()  # a job is under way (running_job)


def orphaned() -> bool:
    """True once :func:`exit_with_parent` has seen this process's parent die or end the
    pool: a pool worker then starts no further job."""
    return _orphaned.is_set()


@contextmanager
def running_job() -> Iterator[None]:
    """One job of a pool worker: :func:`exit_with_parent` sends SIGTERM to a worker only
    inside one (an idle worker needs none), and a worker whose parent has died exits once
    its job is over (its results have no reader, and no further job can come)."""
    _busy.set()
    try:
        yield
    finally:
        _busy.clear()
        if _parent_died.is_set():
            os._exit(128 + signal.SIGTERM)


def exit_with_parent(ended: Any = None, poll_s: float = 1.0, grace_s: float = 60.0) -> None:
    """In a worker process (e.g. a process pool's initializer): once its parent dies or sets
    ``ended`` (a ``multiprocessing`` Event: the command is stopping), mark it
    :func:`orphaned` and, inside a :func:`running_job`, send it SIGTERM, so that a run in it
    stops and saves as on any SIGTERM. A worker whose parent died then exits: at once when
    idle, else when its job is over, and outright ``grace_s`` seconds later if it is still
    alive. A daemon thread polls the parent's pid every ``poll_s`` seconds."""
    if not poll_s > 0 or not grace_s >= 0:
        raise ValueError(f"exit_with_parent: need poll_s > 0 and grace_s >= 0, got "
                           f"poll_s={poll_s}, grace_s={grace_s}")
    parent = os.getppid()

    def watch() -> None:
        while os.getppid() == parent:
            if ended is None:
                time.sleep(poll_s)
            elif ended.wait(poll_s):
                break
        died = os.getppid() != parent
        if died:
            _parent_died.set()  # before looking at _busy: running_job exits after it
        _orphaned.set()
        if _busy.is_set():
            os.kill(os.getpid(), signal.SIGTERM)
        elif died:
            os._exit(128 + signal.SIGTERM)
        if died:
            time.sleep(grace_s)
            os._exit(128 + signal.SIGTERM)

    threading.Thread(target=watch, name="exit-with-parent", daemon=True).start()

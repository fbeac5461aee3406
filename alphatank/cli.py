"""``alphatank`` command line: one subcommand module per verb in ``alphatank.commands``.

Errors are handled here once for every verb: bad input (any
:class:`~alphatank.errors.InputError`: config, map, scenario, replay, checkpoint, ...) and
files that cannot be read or written (``OSError``) print one line,
``alphatank VERB: error: MESSAGE``, and exit with status 2; so do bad arguments, and a verb
whose install extra is missing (:class:`~alphatank.extras.MissingExtraError`: the line
names the ``pip install`` that fixes it). A reader
that closes the pipe early (``alphatank maps | head -n 1``) ends the command quietly with
status 141, as a program killed by SIGPIPE. ``ALPHATANK_TRACEBACK=1`` re-raises instead
(for debugging).
"""

from __future__ import annotations

import _thread
import argparse
import importlib
import os
import select
import signal
import sys
import threading
import time
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from typing import Any, NoReturn

from alphatank import __version__
from alphatank.errors import InputError, one_line
from alphatank.extras import MissingExtraError, install_hint

# verb -> module in alphatank.commands exposing add_arguments(parser) and run(args) -> int
COMMANDS = {
    "demo": "The main job: train PPO vs the aggressive bot, evaluate, record (runs/<name>/).",
    "train": "Train PPO, MAPPO or SAC learners from a preset or a run file (vs bots, "
             "self-play, teams).",
    "eval": "Evaluate a checkpoint against bots: Table-3 layout with Wilson 95% intervals.",
    "experiments": "The paper's tables in one command: train every row within a budget, "
                   "evaluate, report with the paper's figures.",
    "plot": "Learning curves of one or many runs (win rate, return vs steps and wall time).",
    "play": "Play interactively: humans, bots and checkpoints in any seat.",
    "record": "Record a headless match to MP4/GIF (and a replay file).",
    "replay": "Re-simulate, render or record a replay file.",
    "arena": "Play every pair of seats (bots, checkpoints, agents) on both sides; W/D/L "
             "matrix and league.",
    "bench": "Measure ticks/s of the match, env steps/s, bot and renderer cost; --soak.",
    "maps": "List shipped maps or validate and print some.",
    "agents": "List the trained agents shipped with the package (agent:NAME), or export one.",
}
EXIT_BAD_INPUT = 2
EXIT_BROKEN_PIPE = 141  # 128 + SIGPIPE, what a shell reports for a program killed by it
EXIT_INTERRUPTED = 130  # 128 + SIGINT: Ctrl-C before a verb installs its own stop handling


class Parser(argparse.ArgumentParser):
    """An ArgumentParser whose errors are one line: what is wrong and where to look."""

    verbs: dict[str, Parser]  # the top parser's subcommand parsers, by verb

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser(verbs: Iterable[str] = COMMANDS) -> Parser:
    """The command line's parser; only ``verbs`` get their options (and import their
    modules): the others are listed, for ``--help``, and refused if given."""
    verbs = set(verbs)
    parser = Parser(prog="alphatank", description=__doc__.split("\n\n")[0],
                    formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--version", action="version", version=f"alphatank {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="VERB",
                                parser_class=Parser)
    parser.verbs = {}
    for verb, help_text in COMMANDS.items():
        # help strings are %-formatted by argparse, descriptions are printed as they are
        p = parser.verbs[verb] = sub.add_parser(verb, help=help_text.replace("%", "%%"),
                                                description=help_text)
        if verb not in verbs:
            continue
        try:
            module = importlib.import_module(f"alphatank.commands.{verb}")
        except MissingExtraError as exc:  # the verb exists; running it says what to install
            p.set_defaults(_run=_unavailable(exc), _any_args=True)
            continue
        module.add_arguments(p)
        p.set_defaults(_run=module.run)
    return parser


def _unavailable(exc: MissingExtraError) -> Any:
    def run(args: argparse.Namespace) -> int:
        raise exc
    return run


def torch_importing() -> bool:
    """Whether this process is in the middle of importing torch."""
    spec = getattr(sys.modules.get("torch"), "__spec__", None)
    return bool(getattr(spec, "_initializing", False))


@contextmanager
def ctrl_c_kept() -> Iterator[None]:
    """Ctrl-C raises KeyboardInterrupt as Python's own handler does, but never where it
    would be lost. While torch is being imported it is raised once the import is done:
    inside, it could abort the process (torch's C++ side: ``terminate called after throwing
    an instance of 'pybind11::error_already_set'``, exit 134). One raised inside a C
    callback (pymunk's collision handlers and finalizers, through cffi), which swallows
    it, is raised again after it. Nothing changes where SIGINT is not Python's default
    handler (ignored, or a verb's own) or off the main thread."""
    if (threading.current_thread() is not threading.main_thread()
            or signal.getsignal(signal.SIGINT) is not signal.default_int_handler):
        yield
        return
    pending = threading.Event()  # a KeyboardInterrupt waits to be raised (one at a time)
    in_hook = threading.Event()

    def deliver() -> None:
        time.sleep(0.01)  # out of the hook or callback that deferred it
        while torch_importing():
            time.sleep(0.01)
        pending.clear()
        _thread.interrupt_main()  # the main thread's SIGINT handler once more

    def defer() -> None:
        if not pending.is_set():
            pending.set()
            threading.Thread(target=deliver, daemon=True).start()

    def on_sigint(signum: int, frame: Any) -> None:
        if torch_importing() or in_hook.is_set():
            defer()
            return
        raise KeyboardInterrupt

    hook = sys.unraisablehook

    def on_unraisable(unraisable: Any) -> None:
        if not issubclass(unraisable.exc_type, KeyboardInterrupt):
            hook(unraisable)
            return
        in_hook.set()  # swallowed by a callback: raised again after it
        try:
            defer()
        finally:
            in_hook.clear()

    signal.signal(signal.SIGINT, on_sigint)
    sys.unraisablehook = on_unraisable
    try:
        yield
    finally:
        sys.unraisablehook = hook
        signal.signal(signal.SIGINT, signal.default_int_handler)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    # The verb comes first (the top level has only --help and --version): build its
    # options alone, so `alphatank --help` or one verb imports no other verb's modules.
    parser = build_parser(argv[:1])
    args, unknown = parser.parse_known_args(argv)
    if unknown and not getattr(args, "_any_args", False):
        parser.verbs[args.command].error(f"unrecognized arguments: {' '.join(unknown)}")
    try:
        with ctrl_c_kept():
            return int(args._run(args) or 0)
    except BrokenPipeError as exc:
        if stdout_reader_gone():
            return broken_pipe_exit()
        if os.environ.get("ALPHATANK_TRACEBACK"):
            raise
        print(f"alphatank {args.command}: error: {one_line(exc)}", file=sys.stderr)
        return 1  # another pipe (a worker process's): said, not taken for SIGPIPE
    except KeyboardInterrupt as exc:  # its message, if any, says what was kept
        if os.environ.get("ALPHATANK_TRACEBACK"):
            raise
        print(f"alphatank {args.command}: interrupted{f' {exc}' if exc.args else ''}",
              file=sys.stderr)
        return EXIT_INTERRUPTED
    except MissingExtraError as exc:  # an ImportError, not bad input: its own message
        if os.environ.get("ALPHATANK_TRACEBACK"):
            raise
        who = f"alphatank {args.command}"  # or the option that needs it (--ray)
        who = exc.feature if exc.feature.startswith(who + " ") else who
        print(f"{who} needs the '{exc.extra}' extra: {install_hint(exc.extra)}",
              file=sys.stderr)
        return EXIT_BAD_INPUT
    except (InputError, OSError) as exc:
        if os.environ.get("ALPHATANK_TRACEBACK"):
            raise
        print(f"alphatank {args.command}: error: {one_line(exc)}", file=sys.stderr)
        return EXIT_BAD_INPUT


def stdout_reader_gone() -> bool:
    """Whether stdout is a pipe whose reader has closed it (poll reports an error on it),
    or not a real file (tests capture it): a BrokenPipeError is then stdout's."""
    try:
        fd = sys.stdout.fileno()
    except (OSError, ValueError, AttributeError):
        return True
    poller = select.poll()
    poller.register(fd, select.POLLOUT)
    return any(events & select.POLLERR for _, events in poller.poll(0))


def broken_pipe_exit() -> int:
    """The reader of stdout went away: point stdout at /dev/null so the interpreter's final
    flush does not raise again, and report SIGPIPE's status."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):  # stdout is not a real file (tests capture it)
        pass
    finally:
        os.close(devnull)
    return EXIT_BROKEN_PIPE


if __name__ == "__main__":
    sys.exit(main())

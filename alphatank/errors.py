"""The base of every error that reports bad input (a file, a flag, a value).

Each layer keeps its own error class (``ConfigError``, ``MapError``, ``ScenarioError``,
``ReplayError``, ``CheckpointError``, ...) and also derives it from :class:`InputError`, so
the command line catches them all in one place without importing every layer: it prints
the message on one line and exits with status 2 (``alphatank.cli.main``).
"""

from __future__ import annotations


class InputError(Exception):
    """Bad input; the message names the file, line or field and what is allowed."""


def as_input_error(exc: ValueError) -> InputError:
    """A ValueError that a layer raised for bad input (the training presets and fields,
    evaluation options) as an InputError with its message; InputErrors pass unchanged."""
    return exc if isinstance(exc, InputError) else InputError(str(exc))


def one_line(exc: BaseException) -> str:
    """An exception's message on one line (continuation lines joined with ' | ')."""
    text = " | ".join(part.strip() for part in str(exc).strip().splitlines() if part.strip())
    return text or type(exc).__name__


class BusyError(InputError, RuntimeError):
    """A file or folder that another process holds (a run another process is training)."""


class MissingPackageError(InputError, RuntimeError):
    """An optional package that a requested feature needs is not installed."""

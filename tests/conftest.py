"""Fixtures shared by several test files."""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

# No display here: SDL's dummy drivers, asked for by name (without them pygame falls back
# to its offscreen driver, which a human-mode window refuses: alphatank.ui.render).
os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
os.environ.setdefault("SDL_AUDIODRIVER", "dummy")

HOLD = ("import sys\nfrom alphatank.files import FolderLock\n"
        "lock = FolderLock(sys.argv[1]).acquire()\nprint('held', flush=True)\nsys.stdin.read()\n")


@contextmanager
def _held_elsewhere(folder: Path) -> Iterator[int]:
    """``FolderLock(folder)`` held by a second Python process while the block runs (it
    lets go when its standard input closes); yields that process's pid."""
    proc = subprocess.Popen([sys.executable, "-c", HOLD, str(folder)], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None and proc.stdout.readline().strip() == "held"
        yield proc.pid
    finally:
        assert proc.stdin is not None
        proc.stdin.close()
        proc.wait(timeout=60)


@pytest.fixture
def held_elsewhere():
    """A context manager factory: ``with held_elsewhere(folder) as pid: ...``."""
    return _held_elsewhere


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Files that hold a ``slow`` test run first. Under ``-n 2 --dist loadfile`` (with
    ``--no-loadscope-reorder``) the workers take whole files in collection order, so a
    minutes-long file collected late would end the run on one core while the other idles."""
    slow = {item.path for item in items if item.get_closest_marker("slow")}
    items.sort(key=lambda item: item.path not in slow)  # stable: the rest keep their order

"""argparse value types shared by the verbs: a bad value is an argparse error (one line,
exit 2) naming the flag and what is allowed."""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable

from alphatank.sim.config import ACTION_REPEAT_MAX, MATCHES_MAX, MAX_STEPS_MAX


def given(text: str) -> str:
    """A file or folder path, or a name (a map, a scenario, an agent): not empty (``""``
    read as none, or as the current folder)."""
    if not text:
        raise argparse.ArgumentTypeError("is empty; give a name or a path")
    return text


def positive_int(text: str) -> int:
    """An integer >= 1."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be an integer >= 1, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be an integer >= 1, got {text!r}")
    return value


def non_negative_int(text: str) -> int:
    """An integer >= 0 (a count or cadence where 0 means none or all)."""
    try:
        value = int(text)
    except ValueError:
        value = -1
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be an integer >= 0, got {text!r}")
    return value


def int_in_range(lo: int, hi: int) -> Callable[[str], int]:
    """An argparse type: an integer in [lo, hi]."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = lo - 1
        if not lo <= value <= hi:
            raise argparse.ArgumentTypeError(f"must be an integer in [{lo}, {hi}], got {text!r}")
        return value
    return parse


match_count = int_in_range(1, MATCHES_MAX)  # matches played at once
action_repeat = int_in_range(1, ACTION_REPEAT_MAX)  # ticks a learner's action is held
max_steps = int_in_range(1, MAX_STEPS_MAX)  # an episode's length limit in ticks


def positive_float(text: str) -> float:
    """A finite number > 0."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text!r}")
    return value


def seed(text: str) -> int:
    """A random seed: an integer in [0, 2^63)."""
    try:
        value = int(text)
    except ValueError:
        value = -1
    if not 0 <= value < 2**63:
        raise argparse.ArgumentTypeError(f"must be an integer in [0, 2^63), got {text!r}")
    return value


def in_range(lo: float, hi: float) -> Callable[[str], float]:
    """An argparse type: a number in [lo, hi] (bounds that keep a window, a video or a
    frame loop sane: a frame rate of 1e-9 sleeps for years)."""
    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not lo <= value <= hi:
            raise argparse.ArgumentTypeError(f"must be a number in [{lo:g}, {hi:g}], got "
                                             f"{text!r}")
        return value
    return parse


SCALE_RANGE = (0.1, 8.0)  # a 770 px map: 77 to 6160 px
scale = in_range(*SCALE_RANGE)  # a window or video scale (times the map's size in px)
window_fps = in_range(1.0, 1000.0)  # a window's frames per second (play)
video_fps = in_range(0.01, 1000.0)  # a video's frames per second (record)
replay_speed = in_range(0.05, 50.0)  # times real time (replay --render)
hold_seconds = in_range(0.0, 60.0)  # a video's still final frame (record --hold)


BUDGET_MAX_MIN = 7 * 24 * 60  # a week


def budget_minutes(text: str) -> float:
    """A time budget in minutes: a number in (0, BUDGET_MAX_MIN]."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not 0 < value <= BUDGET_MAX_MIN:
        raise argparse.ArgumentTypeError(f"must be a number of minutes in (0, {BUDGET_MAX_MIN}] "
                                         f"(a week), got {text!r}")
    return value

"""Opponent schedules (paper 3.4.5-3.4.6): curriculum by bot weakness (over steps, or
level by level as the win rate rises) or by line-up (bots left out, then added as the win
rate rises), cycle over a bot pool.

A schedule decides, between episodes, which bots fill the non-learner seats and how
strong they are. The runner calls :meth:`OpponentSchedule.record` for every finished
episode, :meth:`OpponentSchedule.apply` after every rollout (it pushes changes to the
vector env, which applies them from each env's next episode) and multiplies the victory
reward by :meth:`OpponentSchedule.victory_scale`.
"""

from __future__ import annotations

import inspect
import math
import re
import types
import typing
from collections import deque
from typing import Any, Protocol

import numpy as np

from alphatank.sim.config import check_value
from alphatank.training.fields import did_you_mean

SHAPES = ("linear", "sigmoid")
CYCLE_MODES = ("fixed", "random", "adaptive")
SCALARS = (int, float, bool, str, type(None))  # parameter types make_schedule checks
RANGES = {"start": (0, 1), "end": (0, 1), "weakness": (0, 1), "target": (0, 1),
          "threshold": (0, 1), "demote": (0, 1), "floor": (0, 1), "snapshot_share": (0, 1),
          "interval": (1, None), "window": (1, None), "steps": (1, None),
          "mastery_phase": (0, None), "min_episodes": (0, None), "snapshot_every": (0, None),
          "snapshots": (0, None), "seed": (0, None), "steepness": (0.01, 1000.0)}


class ScheduledEnv(Protocol):
    def set_bot_weakness(self, weakness: float) -> None: ...

    def set_opponents(self, bot_names: list[str], weakness: float | None = None) -> None: ...

    def set_benched(self, seats: tuple[int, ...]) -> None: ...


class OpponentSchedule:
    """No schedule: the scenario's opponents, unchanged. Base class of the others."""

    kind = "none"
    # names every env's opponent (set_env_opponents), which fills every seat no learner
    # drives: the scenario's own opponents never play in its games
    fills_seats = False

    def apply(self, env: ScheduledEnv, step: int) -> dict[str, float]:
        """Push the setting for env step ``step`` to ``env``; returns metrics to log."""
        return {}

    def record(self, opponent: str, outcome: str) -> None:
        """One finished episode against ``opponent``: ``win``, ``loss`` or ``draw``."""

    def victory_scale(self, step: int) -> float:
        return 1.0

    def check(self, scenario: Any, env: Any) -> None:
        """Refuse settings the run's ``scenario`` and ``env`` cannot play, before it
        starts (ValueError)."""

    def bind(self, trainer: Any) -> None:
        """Called once by the trainer after its set-up; schedules that need the learners
        (the league's snapshots, :mod:`alphatank.training.league`) keep it."""

    def state_dict(self) -> dict[str, Any]:
        return {}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore from :meth:`state_dict` (JSON-able)."""


class CurriculumSchedule(OpponentSchedule):
    """Bot weakness (probability of acting each tick) from ``start`` to ``end`` over
    ``steps`` env steps, linearly or along a sigmoid (paper 3.4.6: 0.1 -> 0.8)."""

    kind = "curriculum"

    def __init__(self, steps: int, start: float = 0.1, end: float = 0.8,
                 shape: str = "linear", steepness: float = 10.0):
        if shape not in SHAPES:
            raise ValueError(f"curriculum shape must be one of {SHAPES}, got {shape!r}")
        for name, w in (("start", start), ("end", end)):
            if not 0.0 <= w <= 1.0:
                raise ValueError(f"curriculum {name} weakness must be in [0, 1], got {w}")
        lo, hi = RANGES["steepness"]  # beyond: exp overflows, or the ends meet (0 / 0)
        if steps <= 0 or not lo <= steepness <= hi:
            raise ValueError(f"curriculum needs steps > 0 and steepness in [{lo:g}, {hi:g}], "
                             f"got {steps}, {steepness}")
        self.steps, self.start, self.end = int(steps), float(start), float(end)
        self.shape, self.steepness = shape, float(steepness)
        self._applied: float | None = None

    def weakness(self, step: int) -> float:
        p = min(max(step / self.steps, 0.0), 1.0)
        if self.shape == "sigmoid":
            k = self.steepness

            def sig(x: float) -> float:
                return 1.0 / (1.0 + math.exp(-x))

            lo, hi = sig(-k / 2), sig(k / 2)
            p = (sig(k * (p - 0.5)) - lo) / (hi - lo)
        return self.start + (self.end - self.start) * p

    def apply(self, env: ScheduledEnv, step: int) -> dict[str, float]:
        w = round(self.weakness(step), 4)
        if w != self._applied:
            env.set_bot_weakness(w)
            self._applied = w
        return {"schedule/weakness": w}

    def state_dict(self) -> dict[str, Any]:
        return {}  # a pure function of the step; re-applied on resume

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self._applied = None


class CycleSchedule(OpponentSchedule):
    """Rotate the opponent through a bot pool every ``interval`` env steps (paper 3.4.5).

    ``fixed`` cycles in order, ``random`` draws uniformly, ``adaptive`` draws with
    probability growing with (1 - rolling win rate) against each bot. Win rates use the
    last ``window`` episodes per bot; a bot is mastered at ``target`` win rate (with at
    least ``window // 2`` games). Victory reward scale: the mastered fraction during the
    first ``mastery_phase`` env steps, afterwards 1 only when every bot is mastered.
    ``scale_victory=False`` keeps the full victory reward.
    """

    kind = "cycle"

    def __init__(self, pool: list[str], mode: str = "fixed", interval: int = 50_000,
                 window: int = 50, target: float = 0.6, mastery_phase: int = 500_000,
                 scale_victory: bool = True, weakness: float | None = None, seed: int = 0):
        if not isinstance(pool, list | tuple) or not all(isinstance(b, str) for b in pool):
            raise ValueError(f"cycle pool must be a list of bot names, got {pool!r}")
        if not pool:
            raise ValueError("cycle schedule needs a non-empty bot pool")
        from alphatank.game.scenarios import bot_names

        unknown = [b for b in pool if b not in bot_names()]
        if unknown:
            raise ValueError(f"cycle pool: unknown bot {unknown[0]!r}; valid bots: "
                             f"{list(bot_names())}")
        if mode not in CYCLE_MODES:
            raise ValueError(f"cycle mode must be one of {CYCLE_MODES}, got {mode!r}")
        if interval <= 0 or window <= 0:
            raise ValueError(f"cycle interval and window must be > 0, got {interval}, {window}")
        self.pool, self.mode, self.interval = list(pool), mode, int(interval)
        self.window, self.target, self.mastery_phase = int(window), float(target), mastery_phase
        self.scale_victory, self.weakness = scale_victory, weakness
        self.rng = np.random.default_rng(seed)
        self.results: dict[str, deque[float]] = {b: deque(maxlen=self.window) for b in pool}
        self.current = self.pool[0]
        self.phase = -1  # index of the interval the current opponent was chosen for
        self.switches = 0
        self._pushed: str | None = None  # opponent last sent to the env

    def win_rate(self, bot: str) -> float:
        res = self.results[bot]
        return float(np.mean(res)) if res else 0.0

    def mastered(self, bot: str) -> bool:
        return (len(self.results[bot]) >= max(1, self.window // 2)
                and self.win_rate(bot) >= self.target)

    def _choose(self) -> str:
        if self.mode == "fixed":
            return self.pool[self.switches % len(self.pool)]
        if self.mode == "random":
            return self.pool[int(self.rng.integers(len(self.pool)))]
        need = np.array([1.0 - self.win_rate(b) + 0.05 for b in self.pool])
        return self.pool[int(self.rng.choice(len(self.pool), p=need / need.sum()))]

    def apply(self, env: ScheduledEnv, step: int) -> dict[str, float]:
        phase = step // self.interval
        if phase != self.phase:
            self.current = self._choose()
            self.phase = phase
            self.switches += 1
        if self._pushed != self.current:
            env.set_opponents([self.current], weakness=self.weakness)
            self._pushed = self.current
        metrics = {f"schedule/win_rate/{b}": self.win_rate(b) for b in self.pool}
        metrics["schedule/opponent_index"] = float(self.pool.index(self.current))
        metrics["schedule/victory_scale"] = self.victory_scale(step)
        return metrics

    def record(self, opponent: str, outcome: str) -> None:
        """``opponent``: a bot name or an env label such as ``B:dodge(w=1)``."""
        names = set(re.findall(r"([A-Za-z_]+)\(", opponent)) or {opponent}
        for bot in self.pool:
            if bot in names:
                self.results[bot].append(1.0 if outcome == "win" else 0.0)

    def victory_scale(self, step: int) -> float:
        if not self.scale_victory:
            return 1.0
        done = sum(self.mastered(b) for b in self.pool)
        if step < self.mastery_phase:
            return done / len(self.pool)
        return 1.0 if done == len(self.pool) else 0.0

    def state_dict(self) -> dict[str, Any]:
        return {"results": {b: list(r) for b, r in self.results.items()},
                "current": self.current, "phase": self.phase, "switches": self.switches,
                "rng": self.rng.bit_generator.state}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        for bot, res in state["results"].items():
            if bot in self.results:
                self.results[bot].extend(res)
        self.current, self.phase = state["current"], int(state["phase"])
        self.switches = int(state["switches"])
        self.rng.bit_generator.state = state["rng"]
        self._pushed = None  # a fresh env needs the current opponent again


class _LevelCurriculum(OpponentSchedule):
    """Levels of difficulty, one up each time the win rate over the last ``window``
    episodes played at the current level reaches ``threshold`` (with at least
    ``min_episodes`` of them). Only wins count; draws and losses do not. With ``demote``
    > 0 it also steps one level down when that win rate falls below ``demote`` (a team
    that stopped winning practises where it still wins). Subclasses say what a level
    pushes to the env and which episodes were played at the current one (an episode that
    started before the new level reached its env is not counted). Evaluation is not
    affected: the runner's evaluation plays the scenario's own line-up at full strength.
    """

    name = "curriculum"

    def __init__(self, count: int, threshold: float, window: int, min_episodes: int,
                 demote: float):
        if not 0.0 < threshold <= 1.0:
            raise ValueError(f"{self.name} threshold must be in (0, 1], got {threshold}")
        if window <= 0 or not 0 < min_episodes <= window:
            raise ValueError(f"{self.name} needs window > 0 and 0 < min_episodes <= "
                             f"window, got {window}, {min_episodes}")
        if not 0.0 <= demote < threshold:
            raise ValueError(f"{self.name} demote must be in [0, threshold), got {demote}")
        self.count, self.threshold, self.demote = count, float(threshold), float(demote)
        self.window, self.min_episodes = int(window), int(min_episodes)
        self.level = 0
        self.results: deque[float] = deque(maxlen=self.window)
        self._applied: int | None = None

    def win_rate(self) -> float:
        return float(np.mean(self.results)) if self.results else 0.0

    def _push(self, env: ScheduledEnv) -> None:
        """Send the current level's setting to ``env``."""
        raise NotImplementedError

    def _at_level(self, opponent: str) -> bool:
        """Whether an episode against ``opponent`` (its label) was played at this level."""
        raise NotImplementedError

    def _metrics(self) -> dict[str, float]:
        return {}

    def apply(self, env: ScheduledEnv, step: int) -> dict[str, float]:
        if self._applied != self.level:
            self._push(env)
            self._applied = self.level
        return {**self._metrics(), "schedule/level": float(self.level),
                "schedule/level_win_rate": self.win_rate()}

    def record(self, opponent: str, outcome: str) -> None:
        if not self._at_level(opponent):
            return
        self.results.append(1.0 if outcome == "win" else 0.0)
        if len(self.results) < self.min_episodes:
            return
        if self.level < self.count - 1 and self.win_rate() >= self.threshold:
            self.level += 1
            self.results.clear()
        elif self.level > 0 and self.win_rate() < self.demote:
            self.level -= 1
            self.results.clear()

    def state_dict(self) -> dict[str, Any]:
        return {"level": self.level, "results": list(self.results)}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        if state:
            self.level = min(int(state["level"]), self.count - 1)
            self.results.clear()
            self.results.extend(state["results"])
        self._applied = None  # a fresh env needs the current level again


class WinRateCurriculum(_LevelCurriculum):
    """Bot weakness in steps (``levels``), one level up as the win rate rises (see
    :class:`_LevelCurriculum`). Episodes whose opponent label names another weakness
    (``smart(w=0.1)``: finished before the new level reached the env) are not counted."""

    kind = "winrate"
    name = "winrate curriculum"

    def __init__(self, levels: tuple[float, ...] | list[float] = (0.1, 0.25, 0.5, 0.75, 1.0),
                 threshold: float = 0.6, window: int = 100, min_episodes: int = 50,
                 demote: float = 0.0):
        if not isinstance(levels, list | tuple) or any(
                isinstance(w, bool) or not isinstance(w, int | float) for w in levels):
            raise ValueError(f"winrate curriculum levels must be a list of weaknesses in "
                             f"[0, 1], got {levels!r}")
        levels = tuple(float(w) for w in levels)
        if not levels or any(not 0.0 <= w <= 1.0 for w in levels):
            raise ValueError(f"winrate curriculum levels must be weaknesses in [0, 1], "
                             f"got {list(levels)}")
        if list(levels) != sorted(levels):
            raise ValueError(f"winrate curriculum levels must rise, got {list(levels)}")
        super().__init__(len(levels), threshold, window, min_episodes, demote)
        self.levels = levels

    @property
    def weakness(self) -> float:
        return self.levels[self.level]

    def _push(self, env: ScheduledEnv) -> None:
        env.set_bot_weakness(self.weakness)

    def _at_level(self, opponent: str) -> bool:
        seen = {round(float(w), 4) for w in re.findall(r"\(w=([0-9.eE+-]+)", opponent)}
        return not seen or round(self.weakness, 4) in seen

    def _metrics(self) -> dict[str, float]:
        return {"schedule/weakness": self.weakness}


class LineupCurriculum(_LevelCurriculum):
    """The opponents' line-up in steps: ``levels`` lists, per level, the bot seats left
    out of the episodes (dead from the start), ending with the full line-up (``[]``); one
    level up as the win rate rises (see :class:`_LevelCurriculum`). E.g. two learners
    against a defensive and two smart bots (seats 2, 3, 4): ``[[2, 3], [2], []]`` plays
    one smart bot, then both, then all three. An episode counts at the level whose number
    of absent seats its label shows."""

    kind = "lineup"
    name = "lineup curriculum"

    def __init__(self, levels: list[list[int]] | tuple = ([],), threshold: float = 0.6,
                 window: int = 100, min_episodes: int = 50, demote: float = 0.0):
        ok = bool(levels) and all(isinstance(lv, list | tuple) and all(
            isinstance(k, int) and not isinstance(k, bool) for k in lv) for lv in levels)
        if not ok:
            raise ValueError(f"lineup curriculum levels must be lists of seat numbers, got "
                             f"{levels!r}")
        benched = tuple(tuple(sorted(set(lv))) for lv in levels)
        sizes = [len(b) for b in benched]
        if sizes[-1] or sizes != sorted(sizes, reverse=True) or len(set(sizes)) != len(sizes):
            raise ValueError(f"lineup curriculum levels must leave out fewer seats at each "
                             f"level and end with the full line-up ([]), got {list(levels)}")
        super().__init__(len(benched), threshold, window, min_episodes, demote)
        self.levels = benched

    @property
    def benched(self) -> tuple[int, ...]:
        return self.levels[self.level]

    def _push(self, env: ScheduledEnv) -> None:
        env.set_benched(self.benched)

    def check(self, scenario: Any, env: Any) -> None:
        from alphatank.envs.core import check_benched

        for seats in self.levels:
            try:
                check_benched(scenario, scenario.learner_seats, seats)
            except ValueError as exc:
                raise ValueError(f"schedule levels: {exc}") from None

    def _at_level(self, opponent: str) -> bool:
        return opponent.count(":absent") == len(self.benched)

    def _metrics(self) -> dict[str, float]:
        return {"schedule/absent": float(len(self.benched))}


def make_schedule(spec: dict[str, Any], total_steps: int, seed: int = 0) -> OpponentSchedule:
    """Build a schedule from a preset's ``schedule`` mapping (``kind`` + parameters); an
    unknown or missing key is a ValueError naming it and the kind's valid keys."""
    spec = dict(spec or {})
    kind = spec.pop("kind", "none")
    classes: dict[str, Any] = {s.kind: s for s in (OpponentSchedule, CurriculumSchedule,
                                                   CycleSchedule, WinRateCurriculum,
                                                   LineupCurriculum)}
    if kind == "league":  # resolved late: the league copies learners (checkpoint layer)
        from alphatank.game.seats import resolve
        classes[kind] = resolve("alphatank.training.league:LeagueSchedule")
    if not isinstance(kind, str) or kind not in classes:
        raise ValueError(f"unknown schedule kind {kind!r}; valid: none, curriculum, cycle, "
                         f"winrate, lineup, league{did_you_mean(kind, [*classes, 'league'])}")
    params = inspect.signature(classes[kind], eval_str=True).parameters
    given = {"steps": total_steps, "seed": seed}
    spec = {**{k: v for k, v in given.items() if k in params}, **spec}
    for key, value in spec.items():
        if key not in params:
            raise ValueError(f"{key}: unknown key for kind {kind!r}; valid keys: "
                             f"{['kind', *sorted(params)]}{did_you_mean(key, params)}")
        ann = params[key].annotation
        kinds = typing.get_args(ann) if isinstance(ann, types.UnionType) else (ann,)
        if all(k in SCALARS for k in kinds):  # numbers, flags and names: type and range
            _, why = check_value(kinds, value, RANGES.get(key))
            if why:
                raise ValueError(f"{key} {why}")
    for key, param in params.items():
        if key not in spec and param.default is param.empty:
            raise ValueError(f"{key}: required for kind {kind!r}")
    try:
        return classes[kind](**spec)
    except TypeError as exc:
        raise ValueError(f"schedule {kind!r}: {exc}") from None

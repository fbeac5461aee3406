"""The paper's experiments as data: tables of rows, each row a training run evaluated
against the table's columns, with the paper's figure beside ours.

Layout of ``alphatank/data/experiments/`` (or any folder given as ``experiments_dir``)::

    <table>/_table.toml   title, layout, the columns (evaluation targets), checks
    <table>/<row>.toml    one row: its run (a preset and/or inline run settings, the
                          run-file format), the paper's figures, budget fractions

Seeds: seed index ``s`` (0..N-1) trains with run seed ``s`` and is evaluated with
evaluation seed ``EVAL_SEED_BASE + s``: training seeds stay below ``EVAL_SEED_BASE``, so
no evaluation game reuses a training seed, and every row of a table meets the same
evaluation games for the same ``s`` (common random numbers across rows).

Budget: each run trains for at most ``budget`` minutes (``time_limit_s``) and
``budget x steps_per_minute`` env steps (the row's planning rate) rounded up to a whole
iteration (:func:`~alphatank.training.presets.planned_steps`); settings named in the
row's ``[budget_fractions]`` are set to that fraction of the run's steps (e.g. a cycle
interval of 1/16 visits each of four bots four times).

Teachers: a row's ``imitate.teachers`` may name another row of its table as
``row:NAME``; that row's run for the same seed is planned too, trained in an earlier wave
(:func:`stages`) and copied from its checkpoint.

Runs are keyed by their settings: a run dir is ``runs/<row>-s<seed>-<digest>`` where the
digest hashes the resolved run settings (not its name), so rows of different tables that
describe the same run train it once. A run is finished when its ``done.json`` exists;
each evaluation is one file ``eval/<column>-<digest>.json``. Everything is written as
soon as it exists, so an interrupted command resumes (``resume=True``) where it stopped.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import json
import math
import shutil
import time
import tomllib
import traceback
from collections import Counter
from collections.abc import Callable, Collection, Sequence
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from alphatank.errors import BusyError
from alphatank.files import FolderLock, read_text, write_text_atomic
from alphatank.sim.config import GameConfig, from_dict
from alphatank.training.presets import (
    TrainConfig,
    check_run_fields,
    get_preset,
    parse_hp,
    parse_run,
    run_learners,
    run_scenario,
    with_hp,
)
from alphatank.training.stopping import (
    StopFlag,
    StopRequested,
    exit_with_parent,
    orphaned,
    running_job,
    stop_on_signals,
)

TABLES = ("table3", "table4", "sac", "league", "heldout")
EVAL_SEED_BASE = 1_000_000
DEFAULT_GAMES = 200
DEFAULT_BUDGET_MIN = 15.0
DEFAULT_STEPS_PER_MINUTE = 36_000  # PPO 1v1 at Table 7 settings on one quiet core (~600/s)
LAYOUTS = ("counts", "matrix")
CHECKS = ("beats_paper", "best_average", "within", "gap")
# each check's keys besides kind and text: a test of its value, and what that test wants
_NAMES = (lambda v: isinstance(v, list) and all(isinstance(x, str) for x in v),
          "a list of row names")
_NUMBER = (lambda v: type(v) in (int, float) and math.isfinite(v) and v >= 0,
           "a number >= 0")
CHECK_KEYS: dict[str, dict[str, tuple[Callable[[Any], bool], str]]] = {
    "beats_paper": {"rows": _NAMES},
    "best_average": {"rows": _NAMES, "against": _NAMES, "above": _NUMBER},
    "within": {"row": (lambda v: isinstance(v, str), "a row name"), "points": _NUMBER,
               "specialists": (lambda v: isinstance(v, dict) and all(
                   isinstance(k, str) and isinstance(x, str) for k, x in v.items()),
                   "a table {column: row name}")},
    "gap": {"columns": (lambda v: isinstance(v, list) and len(v) == 2
                        and all(isinstance(x, str) for x in v), "two column names"),
            "points": _NUMBER},
}
EVAL_ENVS = 16


class ExperimentError(ValueError):
    """A bad experiment file, option or output folder (one line, naming the file)."""


# ---- the data -----------------------------------------------------------------------

@dataclass(frozen=True)
class Column:
    """An evaluation target: the row's agent against ``bot`` (or the scenario's own
    opponents) in ``scenario`` (default: the run's own) on ``map`` (default: the
    scenario's, or the run's map override for its own scenario), bots at ``weakness``."""

    name: str
    label: str
    scenario: str | None = None
    bot: str | None = None
    map: str | None = None
    weakness: float = 1.0
    note: str = ""

    def where(self) -> str:
        """Scenario, map and game preset in words (for table notes)."""
        from alphatank.game.scenarios import load_scenario

        if self.scenario is None:
            base = "the run's own scenario"
            return base + (f" on maps {self.map!r}" if self.map else "")
        sc = load_scenario(self.scenario)
        maps = self.map or sc.map
        return f"{self.scenario} (map {maps}, {sc.preset} preset)"


@dataclass(frozen=True)
class Row:
    """One row of a table: a run and what the paper reported for it."""

    table: str
    name: str
    title: str
    order: int
    run: dict[str, Any]  # run-file mapping (preset settings merged with [run])
    source: str
    hp: tuple[str, ...] = ()
    scenarios: tuple[str, ...] = ()
    paper: dict[str, float] = field(default_factory=dict)
    steps_per_minute: float = DEFAULT_STEPS_PER_MINUTE
    fractions: dict[str, float] = field(default_factory=dict)
    columns: tuple[str, ...] = ()  # subset of the table's columns ((): all)
    note: str = ""
    eval_game: dict[str, Any] = field(default_factory=dict)  # over the run's game, in evals

    @property
    def id(self) -> str:
        return f"{self.table}/{self.name}"


@dataclass(frozen=True)
class Table:
    name: str
    title: str
    description: str
    layout: str
    columns: tuple[Column, ...]
    rows: tuple[Row, ...]
    average: bool = False
    heatmap: bool = False
    checks: tuple[dict[str, Any], ...] = ()
    paper_average: bool = True

    def row(self, name: str) -> Row:
        for r in self.rows:
            if r.name == name:
                return r
        raise ExperimentError(f"table {self.name}: no row {name!r}; rows: "
                              f"{[r.name for r in self.rows]}")

    def row_columns(self, row: Row) -> list[Column]:
        return [c for c in self.columns if not row.columns or c.name in row.columns]


def _root(experiments_dir: str | Path | None) -> Any:
    if experiments_dir is not None:
        p = Path(experiments_dir)
        if not p.is_dir():
            raise ExperimentError(f"--experiments-dir {p}: "
                                  + ("is a file, not a folder" if p.exists() else
                                     "no such experiments folder"))
        return p
    return resources.files("alphatank").joinpath("data", "experiments")


def table_names(experiments_dir: str | Path | None = None) -> list[str]:
    """Tables in the experiments folder, the paper's order first; ExperimentError for a
    folder given that holds none (a table's own folder, say)."""
    root = _root(experiments_dir)
    found = sorted(p.name for p in root.iterdir()
                   if p.is_dir() and p.joinpath("_table.toml").is_file())
    if not found and experiments_dir is not None:
        own = root.joinpath("_table.toml").is_file()
        raise ExperimentError(f"--experiments-dir {root}: holds no table (a folder <table> "
                              "with a _table.toml and its row files)"
                              + (f"; it is the folder of table {root.absolute().name!r}: give "
                                 "the folder above it" if own else ""))
    return [t for t in TABLES if t in found] + [t for t in found if t not in TABLES]


def _read_toml(res: Any, source: str) -> dict[str, Any]:
    try:
        return tomllib.loads(res.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise ExperimentError(f"{source}: invalid TOML: {exc}") from None
    except UnicodeDecodeError:
        raise ExperimentError(f"{source}: not UTF-8 text") from None


def _keys(data: dict[str, Any], valid: Sequence[str], source: str) -> None:
    for key in data:
        if key not in valid:
            raise ExperimentError(f"{source}: {key}: unknown key; valid keys: {list(valid)}")


def _typed(data: dict[str, Any], key: str, kind: type | tuple[type, ...], source: str,
           default: Any = None) -> Any:
    value = data.get(key, default)
    ok = isinstance(value, kind) and not (isinstance(value, bool) and kind in (int, float,
                                                                                (int, float)))
    if value is not default and not ok:
        names = kind.__name__ if isinstance(kind, type) else " or ".join(k.__name__
                                                                         for k in kind)
        raise ExperimentError(f"{source}: {key}: needs {names}, got {value!r}")
    return value


def _column(data: Any, source: str) -> Column:
    if not isinstance(data, dict):
        raise ExperimentError(f"{source}: must be a table (name, label, scenario, bot, map, "
                              f"weakness, note)")
    _keys(data, [f.name for f in dataclasses.fields(Column)], source)
    name = _typed(data, "name", str, source)
    if not name:
        raise ExperimentError(f"{source}: name: required, a string")
    weakness = float(_typed(data, "weakness", (int, float), source, 1.0))
    if not 0.0 <= weakness <= 1.0:
        raise ExperimentError(f"{source}: weakness: must be in [0, 1], got {weakness}")
    col = Column(name, _typed(data, "label", str, source, name),
                 _typed(data, "scenario", str, source), _typed(data, "bot", str, source),
                 _typed(data, "map", str, source), weakness, _typed(data, "note", str, source, ""))
    if col.scenario is not None:
        from alphatank.game.scenarios import load_scenario
        try:
            load_scenario(col.scenario)
        except ValueError as exc:
            raise ExperimentError(f"{source}: scenario: {exc}") from None
    if col.map is not None:  # a map, a shipped folder or a path: one that loads
        from alphatank.game.scenarios import load_scenario
        from alphatank.training.evaluate import with_map
        try:
            with_map(load_scenario("vs_random"), col.map)
        except ValueError as exc:
            raise ExperimentError(f"{source}: map: {str(exc).removeprefix('--map: ')}") \
                from None
    if col.bot is not None:
        from alphatank.game.scenarios import bot_names
        if col.bot not in bot_names():
            raise ExperimentError(f"{source}: bot: unknown bot {col.bot!r}; valid: "
                                  f"{list(bot_names())}")
    return col


def _merge(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    """``over`` on top of ``base``; tables (schedule, game, rewards) merge key by key,
    except a table naming another ``kind`` (a schedule of another kind), which replaces
    the base's."""
    out = dict(base)
    for k, v in over.items():
        old = out.get(k)
        if isinstance(v, dict) and isinstance(old, dict) \
                and v.get("kind", old.get("kind")) == old.get("kind"):
            out[k] = {**old, **v}
        else:
            out[k] = v
    return out


# run settings the command gives each run (row_config): a row's [run] or
# [budget_fractions] setting one would be overwritten, or would override the seed rule
PER_RUN = ("name", "seed", "total_steps", "time_limit_s", "wandb", "num_workers",
           "keep_checkpoints", "eval_every", "video_every")
ROW_KEYS = ("title", "order", "preset", "same_as", "run", "hp", "scenarios", "paper",
            "steps_per_minute", "budget_fractions", "columns", "note", "eval_game")


def _row(table: str, name: str, data: dict[str, Any], source: str,
         raw: dict[str, dict[str, Any]]) -> Row:
    _keys(data, ROW_KEYS, source)
    same_as = _typed(data, "same_as", str, source)
    base: dict[str, Any] = {}
    if same_as is not None:
        other_table, _, other_row = same_as.partition("/")
        if (other_table, other_row) == (table, name) or not other_row:
            raise ExperimentError(f"{source}: same_as: needs TABLE/ROW of another row, got "
                                  f"{same_as!r}")
        other = raw.get(same_as)
        if other is None:
            raise ExperimentError(f"{source}: same_as: no row {same_as!r} in the experiments "
                                  f"folder")
        if "same_as" in other[0]:
            raise ExperimentError(f"{source}: same_as: {same_as!r} is itself a same_as row")
        own_run = data.get("run")
        data = {**{k: other[0][k] for k in ("preset", "run", "hp", "scenarios",
                                            "steps_per_minute", "budget_fractions",
                                            "eval_game")
                   if k in other[0]}, **data}
        if isinstance(own_run, dict) and isinstance(other[0].get("run"), dict):
            data["run"] = _merge(other[0]["run"], own_run)  # its own run, on top
    preset = _typed(data, "preset", str, source)
    run = _typed(data, "run", dict, source, {})
    if preset is None and not run:
        raise ExperimentError(f"{source}: needs preset = NAME and/or a [run] table (run-file "
                              f"settings)")
    if preset is not None:
        try:
            base = get_preset(preset).to_dict()
        except ValueError as exc:
            raise ExperimentError(f"{source}: preset: {exc}") from None
        base.pop("name", None)
    merged = _merge(base, run)
    hp_items = _typed(data, "hp", list, source, [])
    scenarios = _typed(data, "scenarios", list, source, [])
    paper = _typed(data, "paper", dict, source, {})
    for k, v in paper.items():
        if not isinstance(v, int | float) or isinstance(v, bool) or not 0 <= v <= 100:
            raise ExperimentError(f"{source}: paper.{k}: needs a number in [0, 100] (percent), "
                                  f"got {v!r}")
    fractions = _typed(data, "budget_fractions", dict, source, {})
    for k, v in fractions.items():
        if not isinstance(v, int | float) or isinstance(v, bool) or not 0 < v <= 1:
            raise ExperimentError(f"{source}: budget_fractions.{k}: needs a fraction in (0, 1], "
                                  f"got {v!r}")
    for where, keys in (("run", run), ("budget_fractions", fractions)):
        for k in keys:
            if k.split(".")[0] in PER_RUN:
                raise ExperimentError(f"{source}: {where}.{k}: set by alphatank experiments "
                                      "for each run (from --budget, --steps, the seed index, "
                                      "--wandb); leave it out")
    rate = _typed(data, "steps_per_minute", (int, float), source, DEFAULT_STEPS_PER_MINUTE)
    if not 0 < rate < math.inf:
        raise ExperimentError(f"{source}: steps_per_minute: must be a finite number > 0, "
                              f"got {rate}")
    from alphatank.game.scenarios import load_scenario
    for k, sc in enumerate(scenarios):
        if not isinstance(sc, str):
            raise ExperimentError(f"{source}: scenarios[{k}]: needs a scenario name or path (a "
                                  f"string), got {sc!r}")
        try:
            load_scenario(sc)
        except ValueError as exc:
            raise ExperimentError(f"{source}: scenarios[{k}]: {exc}") from None
    cols = _typed(data, "columns", list, source, [])
    eval_game = _typed(data, "eval_game", dict, source, {})
    try:
        from_dict(GameConfig, eval_game, where=f"{source}: eval_game")
    except ValueError as exc:
        raise ExperimentError(str(exc)) from None
    return Row(table, name, _typed(data, "title", str, source, name),
               int(_typed(data, "order", int, source, 0)), merged, source,
               tuple(str(h) for h in hp_items), tuple(str(s) for s in scenarios),
               {str(k): float(v) for k, v in paper.items()}, float(rate),
               {str(k): float(v) for k, v in fractions.items()}, tuple(str(c) for c in cols),
               _typed(data, "note", str, source, ""), dict(eval_game))


TABLE_KEYS = ("title", "description", "layout", "columns", "average", "heatmap", "checks",
              "paper_average")


def load_tables(names: Sequence[str], experiments_dir: str | Path | None = None
                ) -> list[Table]:
    """The named tables (with their rows, in ``order``), every file checked; errors name
    a file by its path in ``experiments_dir`` (``experiments/<table>/...`` when shipped)."""
    root = _root(experiments_dir)
    where = "experiments" if experiments_dir is None else str(Path(experiments_dir))
    valid = table_names(experiments_dir)
    bad = [n for n in names if n not in valid]
    if bad:
        raise ExperimentError(f"unknown table(s) {bad}; tables: {valid}")
    # every row of every table: same_as may point across tables
    raw: dict[str, tuple[dict[str, Any], str]] = {}
    for t in valid:
        for res in sorted(root.joinpath(t).iterdir(), key=lambda p: p.name):
            if res.name.endswith(".toml") and not res.name.startswith("_"):
                source = f"{where}/{t}/{res.name}"
                raw[f"{t}/{res.name[:-5]}"] = (_read_toml(res, source), source)
    tables = []
    for t in names:
        source = f"{where}/{t}/_table.toml"
        data = _read_toml(root.joinpath(t, "_table.toml"), source)
        _keys(data, TABLE_KEYS, source)
        layout = _typed(data, "layout", str, source, "matrix")
        if layout not in LAYOUTS:
            raise ExperimentError(f"{source}: layout: must be one of {list(LAYOUTS)}, got "
                                  f"{layout!r}")
        cols_data = _typed(data, "columns", list, source, [])
        if not cols_data:
            raise ExperimentError(f"{source}: columns: needs at least one [[columns]] table")
        columns = tuple(_column(c, f"{source}: columns[{i}]") for i, c in enumerate(cols_data))
        names_seen = [c.name for c in columns]
        if len(set(names_seen)) != len(names_seen):
            raise ExperimentError(f"{source}: columns: names must be unique, got {names_seen}")
        rows = []
        for key, (row_data, row_source) in raw.items():
            if key.startswith(f"{t}/"):
                row = _row(t, key.split("/", 1)[1], row_data, row_source, raw)
                unknown = [c for c in row.columns if c not in names_seen]
                unknown += [c for c in row.paper if c not in names_seen and c != "average"]
                if unknown:
                    raise ExperimentError(f"{row_source}: columns / paper name {unknown}; the "
                                          f"table's columns: {names_seen} (and 'average')")
                rows.append(row)
        if not rows:
            raise ExperimentError(f"{where}/{t}: no row files")
        titled: dict[str, Row] = {}
        for row in rows:  # the tables and the ratings name a row by its title
            other = titled.setdefault(row.title, row)
            if other is not row:
                raise ExperimentError(f"{row.source}: title: {row.title!r} is the title of "
                                      f"{other.source} too; give each row of a table its own")
        checks = tuple(_typed(data, "checks", list, source, []))
        for i, chk in enumerate(checks):
            if not isinstance(chk, dict) or chk.get("kind") not in CHECKS:
                raise ExperimentError(f"{source}: checks[{i}]: needs kind = one of "
                                      f"{list(CHECKS)}")
            keys = CHECK_KEYS[chk["kind"]]
            for key, value in chk.items():
                if key in ("kind", "text"):
                    if key == "text" and not isinstance(value, str):
                        raise ExperimentError(f"{source}: checks[{i}].text: must be a string")
                    continue
                if key not in keys:
                    raise ExperimentError(f"{source}: checks[{i}].{key}: unknown key for kind "
                                          f"{chk['kind']!r}; valid: "
                                          f"{['kind', 'text', *keys]}")
                test, wants = keys[key]
                if not test(value):
                    raise ExperimentError(f"{source}: checks[{i}].{key}: must be {wants}, "
                                          f"got {value!r}")
            _check_names(chk, f"{source}: checks[{i}]", [r.name for r in rows],
                         [*names_seen, "average"])
        tables.append(Table(t, _typed(data, "title", str, source, t),
                            _typed(data, "description", str, source, ""), layout, columns,
                            tuple(sorted(rows, key=lambda r: (r.order, r.name))),
                            bool(_typed(data, "average", bool, source, False)),
                            bool(_typed(data, "heatmap", bool, source, False)), checks,
                            bool(_typed(data, "paper_average", bool, source, True))))
    return tables


def _check_names(chk: dict[str, Any], where: str, rows: Sequence[str],
                 columns: Sequence[str]) -> None:
    """ExperimentError naming ``where`` unless the rows and columns ``chk`` names are the
    table's ``rows`` and ``columns`` (a check naming another stays unmeasurable)."""
    named = {"rows": chk.get("rows", []), "against": chk.get("against", []),
             "row": [chk["row"]] if "row" in chk else [],
             "specialists": list(chk.get("specialists", {}).values())}
    for key, names in named.items():
        for name in names:
            if name not in rows:
                raise ExperimentError(f"{where}.{key}: no row {name!r} in the table; rows: "
                                      f"{sorted(rows)}")
    for key, names in (("columns", chk.get("columns", [])),
                       ("specialists", list(chk.get("specialists", {})))):
        for name in names:
            if name not in columns:
                raise ExperimentError(f"{where}.{key}: no column {name!r} in the table; "
                                      f"columns: {list(columns)}")


# ---- a row's run for one seed and budget ---------------------------------------------

def _set_path(data: dict[str, Any], path: str, value: Any) -> None:
    """``data[a][b] = value`` for ``path`` ``"a.b"`` (copying the tables on the way; the
    run-file loader then rejects a setting that does not exist)."""
    keys = path.split(".")
    node = data
    for k in keys[:-1]:
        node[k] = dict(node[k]) if isinstance(node.get(k), dict) else {}
        node = node[k]
    node[keys[-1]] = value


ROW_REF = "row:"  # a teacher seat naming another row of the table: that row's run


def _row_ref(teacher: Any) -> str | None:
    """NAME of a teacher written ``row:NAME`` (a row of the same table), else None."""
    return teacher[len(ROW_REF):] if isinstance(teacher, str) and \
        teacher.startswith(ROW_REF) else None


def row_config(row: Row, seed: int, budget_min: float, steps: int | None = None,
               wandb: str = "disabled", refs: Callable[[str], str] | None = None
               ) -> TrainConfig:
    """The TrainConfig of ``row`` for seed index ``seed`` under ``budget_min`` minutes;
    ``refs(name)`` gives the run folder of row ``name`` for the same seed, for teachers
    written ``row:NAME``."""
    if not 0 <= seed < EVAL_SEED_BASE:
        raise ExperimentError(f"training seeds must be in [0, {EVAL_SEED_BASE}), got {seed}")
    total = int(steps) if steps else max(1, int(round(budget_min * row.steps_per_minute)))
    data = dict(row.run)
    teachers = _teachers(row, refs)
    if teachers is not None:
        data["imitate"] = {**data["imitate"], "teachers": teachers}
    data.update(name=_run_name(row, seed), seed=seed, total_steps=total,
                time_limit_s=float(budget_min) * 60.0, wandb=wandb, num_workers=1,
                keep_checkpoints=1, eval_every=0, video_every=0)  # PER_RUN
    for path, frac in row.fractions.items():
        _set_path(data, path, max(1, int(total * frac)))
    if row.scenarios:
        data["scenario"] = row.scenarios[0]
    try:
        cfg = parse_run(data, row.source)
        where = f"{row.source}: run"
        sc = _run_scenario(cfg, where)
        # teachers may be runs not trained yet (row:NAME): the plan checks those
        checked = dataclasses.replace(cfg, imitate={
            k: v for k, v in cfg.imitate.items() if k != "teachers"})
        check_run_fields(checked, sc, where)
        for k, name in enumerate(row.scenarios[1:], 1):  # the others of a mix, each in turn
            at = f"{row.source}: scenarios[{k}]"
            other = _run_scenario(dataclasses.replace(cfg, scenario=name), f"{at}: run")
            check_run_fields(checked, other, f"{at}: run", at)
        if row.hp:
            cfg = with_hp(cfg, parse_hp([("hp", ",".join(row.hp))]), len(sc.learner_seats))
    except ValueError as exc:
        msg = str(exc)
        raise ExperimentError(msg if msg.startswith(row.source) else
                              f"{row.source}: {msg}") from None
    return cfg


def _run_name(row: Row, seed: int) -> str:
    return f"{row.table}-{row.name}-s{seed}"


def _teachers(row: Row, refs: Callable[[str], str] | None) -> dict[str, Any] | None:
    """The row's ``imitate.teachers`` with each ``row:NAME`` as ``checkpoint:`` that row's
    run folder (``refs(NAME)``, which plans it); None when it names no row."""
    teachers = (row.run.get("imitate") or {}).get("teachers") or {}
    named = [n for v in teachers.values() if (n := _row_ref(v)) is not None]
    if not named:
        return None
    if refs is None:
        raise ExperimentError(f"{row.source}: imitate.teachers names rows "
                              f"({', '.join(named)}): plan it with them")
    return {k: v if (n := _row_ref(v)) is None else f"checkpoint:{refs(n)}"
            for k, v in teachers.items()}


def reseeded(data: dict[str, Any], row: Row, seed: int,
             refs: Callable[[str], str] | None = None) -> dict[str, Any]:
    """``row_config(row, seed, ..., refs).to_dict()`` from ``data``, that of the row for
    another seed under the same budget: only the name, the seed and the teachers' run
    folders differ, so a row is parsed and checked once, not for every seed. The tables
    ``data`` holds are shared, not copied."""
    out = {**data, "name": _run_name(row, seed), "seed": seed}
    teachers = _teachers(row, refs)
    if teachers is not None:
        out["imitate"] = {**data["imitate"], "teachers": teachers}
    return out


def check_row_init_from(row: Row, cfg: TrainConfig) -> None:
    """ExperimentError naming the row's file unless its run's ``init_from`` (if any) names
    a checkpoint it can warm-start from: checked for runs that will train, so a finished
    run still reports after its warm-start checkpoint is gone."""
    if not cfg.init_from:
        return
    from alphatank.training.warmstart import check_init_from

    try:
        check_init_from(cfg, f"{row.source}: run: init_from")
    except ValueError as exc:
        raise ExperimentError(str(exc)) from None


def _run_scenario(cfg: TrainConfig, where: str) -> Any:
    """The scenario a row's run plays, its map in place; errors name ``where`` and the
    field (scenario or map)."""
    from alphatank.game.scenarios import load_scenario

    try:
        load_scenario(cfg.scenario)
    except ValueError as exc:
        raise ExperimentError(f"{where}: scenario: {exc}") from None
    try:
        return run_scenario(cfg)
    except ValueError as exc:
        raise ExperimentError(f"{where}: map: {str(exc).rpartition(': map: ')[2]}") from None


def digest(obj: Any) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()[:10]


# settings added after runs were made: at these values (off) they leave a run's digest as
# it was, so result folders made before them still resume and report (learner, run)
LATER_SETTINGS = {"anchor_kl": 0.0}
LATER_RUN_SETTINGS = {"action_repeat": 1}
# how a run is watched, not what it does: hashed at the values runs were made with before
# (the --wandb default, the run-file defaults), so a finished run counts whatever mode,
# wandb project or TensorBoard setting the next command logs with
LOGGING_SETTINGS = {"wandb": "disabled", "project": "alphatank", "tensorboard": False}


def settings_digest(data: dict[str, Any], scenarios: Sequence[str]) -> str:
    """Hash of what a run does, from its settings as :meth:`TrainConfig.to_dict` gives
    them (left unchanged; the name and where its metrics are logged left out) and its
    scenario mix."""
    data = {**data, **LOGGING_SETTINGS}
    data.pop("name")
    for key, off in LATER_RUN_SETTINGS.items():
        if data.get(key, off) == off:
            data.pop(key, None)
    data["learners"] = [{**spec, "config": {k: v for k, v in spec["config"].items()
                                            if k not in LATER_SETTINGS or v != LATER_SETTINGS[k]}}
                        for spec in data["learners"]]
    return digest({"cfg": data, "scenarios": list(scenarios)})


# ---- the plan: runs (row x seed, shared when equal) and their evaluations ----------------

@dataclass
class EvalSpec:
    """One evaluation of a run: a column's target, resolved."""

    column: str
    scenario: str
    bot: str | None
    map: str | None
    weakness: float
    games: int
    seed: int
    game: dict[str, Any] = field(default_factory=dict)  # over the checkpoint's own game

    @property
    def key(self) -> str:
        data = dataclasses.asdict(self)
        if not self.game:  # the digests of evaluations from before this field
            del data["game"]
        return f"{self.column}-{digest(data)}"


@dataclass
class Job:
    """One training run and the evaluations its rows ask for."""

    key: str
    run_dir: str
    cfg: dict[str, Any]
    scenarios: list[str]
    evals: list[EvalSpec]
    rows: list[str]
    seed: int
    needs: list[str] = field(default_factory=list)  # keys of the jobs to train first

    @property
    def done_file(self) -> Path:
        return Path(self.run_dir) / "done.json"

    @property
    def metrics_file(self) -> Path:
        return Path(self.run_dir) / "metrics.jsonl"

    def retrains(self, path: Path) -> bool:
        """True for a file that only training the run again makes (done.json,
        metrics.jsonl), False for an evaluation file."""
        return path in (self.done_file, self.metrics_file)

    def eval_file(self, spec: EvalSpec) -> Path:
        return Path(self.run_dir) / "eval" / f"{spec.key}.json"

    def complete(self) -> bool:
        return self.done_file.is_file() and all(self.eval_file(s).is_file()
                                                for s in self.evals)

    def started(self) -> bool:
        return Path(self.run_dir).exists()


@dataclass
class Plan:
    tables: list[Table]
    jobs: list[Job]
    cells: dict[tuple[str, int], tuple[Job, dict[str, EvalSpec]]]  # (row id, seed)
    out: Path
    seeds: int
    budget_min: float
    games: int


def _eval_spec(col: Column, row: Row, cfg: TrainConfig, games: int, seed: int) -> EvalSpec:
    scenario = col.scenario or cfg.scenario
    map_name = col.map if col.map is not None else (cfg.map if col.scenario is None else None)
    return EvalSpec(col.name, scenario, col.bot, map_name, col.weakness, games,
                    EVAL_SEED_BASE + seed, dict(row.eval_game))


def make_plan(tables: Sequence[Table], out: str | Path, seeds: int = 1,
              budget_min: float = DEFAULT_BUDGET_MIN, games: int = DEFAULT_GAMES,
              steps: int | None = None, wandb: str = "disabled",
              rows: Sequence[str] | None = None, report_only: bool = False) -> Plan:
    """Every (row, seed) of ``tables`` as jobs in ``out``; rows with equal runs share one
    job. ``rows`` keeps only those row names (or ``table/row`` ids). The ``init_from`` of
    a run that will train is checked (not with ``report_only``, nor for finished runs)."""
    if not 1 <= seeds <= EVAL_SEED_BASE:  # the last training seed, seeds - 1, stays below
        raise ExperimentError(f"--seeds must be in [1, {EVAL_SEED_BASE:,}] (training seeds "
                              f"0..N-1 stay below the evaluation seeds), got {seeds}")
    if not budget_min > 0:
        raise ExperimentError(f"--budget must be > 0 minutes, got {budget_min}")
    if games < 1:
        raise ExperimentError(f"--games must be >= 1, got {games}")
    if steps is not None and steps < 1:
        raise ExperimentError(f"--steps must be >= 1, got {steps}")
    out = Path(out)
    every = {(t.name, r.name): r for t in tables for r in t.rows}  # before --rows
    if rows:
        known = {r.name for t in tables for r in t.rows} | {r.id for t in tables for r in t.rows}
        bad = [r for r in rows if r not in known]
        if bad:
            raise ExperimentError(f"--rows: unknown row(s) {bad}; rows: "
                                  f"{sorted(r.id for t in tables for r in t.rows)}")
        tables = [dataclasses.replace(t, rows=tuple(r for r in t.rows
                                                    if r.name in rows or r.id in rows))
                  for t in tables]
        tables = [t for t in tables if t.rows]
    jobs: dict[str, Job] = {}
    cells: dict[tuple[str, int], tuple[Job, dict[str, EvalSpec]]] = {}
    checked: dict[str, tuple[TrainConfig, dict[str, Any]]] = {}  # row id: its first seed's
    made: dict[str, Path] = {}  # digest: the first run folder in out/runs ending -<digest>
    if (out / "runs").is_dir():
        for p in sorted((out / "runs").iterdir()):
            if "-" in p.name:
                made.setdefault(p.name.rpartition("-")[2], p)

    def job_for(row: Row, s: int, path: tuple[str, ...] = ()) -> tuple[Job, TrainConfig]:
        """The job of ``row`` for seed ``s``, after the jobs of the rows it needs, and the
        row's config as checked for its first seed (what its seeds share)."""
        needs: list[str] = []

        def ref(name: str) -> str:
            other = every.get((row.table, name))
            if other is None:
                raise ExperimentError(f"{row.source}: imitate.teachers: no row {name!r} in "
                                      f"table {row.table}")
            if other.id in path:
                raise ExperimentError(f"{row.source}: imitate.teachers: rows need each "
                                      f"other: {' -> '.join([*path, other.id])}")
            job = job_for(other, s, (*path, other.id))[0]
            needs.append(job.key)
            return job.run_dir

        if row.id not in checked:  # a row is parsed and checked once, for its first seed
            cfg = row_config(row, s, budget_min, steps, wandb, ref)
            checked[row.id] = cfg, cfg.to_dict()
            data = checked[row.id][1]
        else:
            cfg, first = checked[row.id]
            data = reseeded(first, row, s, ref)
        d = settings_digest(data, row.scenarios)
        job = jobs.get(d)
        if job is None:
            found = made.get(d)
            run_dir = found or out / "runs" / f"{row.name}-s{s}-{d}"
            job = jobs[d] = Job(d, str(run_dir), data, list(row.scenarios), [], [], s, needs)
            if not report_only and not job.done_file.is_file():
                check_row_init_from(row, cfg)
        if row.id not in job.rows:
            job.rows.append(row.id)
        return job, cfg

    for table in tables:
        for row in table.rows:
            for s in range(seeds):
                job, cfg = job_for(row, s, (row.id,))
                specs = {}
                for col in table.row_columns(row):
                    spec = _eval_spec(col, row, cfg, games, s)
                    if all(e.key != spec.key for e in job.evals):
                        job.evals.append(spec)
                    specs[col.name] = spec
                cells[(row.id, s)] = (job, specs)
    return Plan(list(tables), list(jobs.values()), cells, out, seeds, budget_min, games)


# ---- running one job (in this process or a worker) -----------------------------------

def _write_json(path: Path, data: Any) -> None:
    write_text_atomic(path, json.dumps(data, indent=1, default=str) + "\n")


def read_json(path: Path) -> Any:
    """A JSON file's contents; ValueError naming the file for one that cannot be read or
    is not JSON (empty, or cut short)."""
    text = read_text(path)
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        why = "empty" if not text.strip() else (f"not valid JSON (line {exc.lineno}, column "
                                                f"{exc.colno}: {exc.msg})")
        raise ValueError(f"{path}: {why}; the file is cut short or damaged") from None


# What the reports (training/report.py) read from a run's done.json and its evaluation
# files: key -> (a test of its value, what the test wants), a dict for an object with
# these keys, a tuple of keys (checked after each of them) -> (a test of their values
# together, what is wrong when it fails). A file whose value fails its test is damaged;
# keys read with .get() or only when there pass when missing or null. (summary.global_step
# is read for a run that saved no checkpoint.)
KeyTest = tuple[Callable[..., bool], str]


def _value(kind: type | tuple[type, ...], noun: str, ok: Callable[[Any], bool] | None = None,
           optional: bool = False) -> KeyTest:
    """The test of a value of ``kind`` that ``ok`` accepts (``optional``: or none); JSON
    ``true``/``false`` are no numbers here."""
    kinds = kind if isinstance(kind, tuple) else (kind,)
    return (lambda v: (optional and v is None)
            or (isinstance(v, kind) and not (isinstance(v, bool) and bool not in kinds)
                and (ok is None or ok(v)))), noun


def _rated(rows: list[Any]) -> bool:
    """True for league rows ``[name, mu, sigma, ordinal]``."""
    return all(isinstance(r, list) and len(r) == 4 and isinstance(r[0], str)
               and all(isinstance(x, int | float) and not isinstance(x, bool) for x in r[1:])
               for r in rows)


_COUNT = _value(int, "integer >= 0", lambda v: v >= 0)
DONE_KEYS: dict[str, Any] = {
    "summary": {"global_step": _value(int, "integer"),
                "saved_step": _value(int, "integer", optional=True),
                "stopped": _value(dict, "object", optional=True)},
    "wall_s": _value((int, float), "number"), "stopped_by": _value(str, "string"),
    "league": _value(list, "list of [name, mu, sigma, ordinal]", _rated, optional=True)}
EVAL_KEYS: dict[str | tuple[str, ...], Any] = {
    **dict.fromkeys(("wins", "losses", "draws"), _COUNT),
    "games": _value(int, "integer > 0", lambda v: v > 0),
    ("wins", "losses", "draws", "games"): (lambda w, lost, d, g: w + lost + d == g,
                                           '"wins" + "losses" + "draws" is not "games"'),
    "win_rate": _value((int, float), "number"), "opponent": _value(str, "string"),
    "experiment": _value(str, "string"), "spec": _value(dict, "object"),
    # the words of evaluate.OUTCOME_SCORE, which the ratings read (importing it would
    # bring torch into --list)
    "outcomes": _value(list, 'list of "win", "loss", "draw"',
                       lambda v: all(o in ("win", "loss", "draw") for o in v)),
    ("outcomes", "wins", "losses", "draws"): (
        lambda o, w, lost, d: [o.count("win"), o.count("loss"), o.count("draw")] == [w, lost, d],
        '"outcomes" do not match "wins", "losses", "draws"'),
    "opponent_kind": _value(str, "string", optional=True)}


def _lacks(data: Any, keys: dict[Any, Any]) -> str | None:
    """What JSON ``data`` lacks of ``keys`` (:data:`DONE_KEYS`, :data:`EVAL_KEYS`) in
    words, e.g. ``no "summary" object``, ``"games" is not an integer > 0``; None when
    nothing."""
    if not isinstance(data, dict):
        return "not a JSON object"
    for key, kind in keys.items():
        if isinstance(key, tuple):  # each of them passed its own test
            test, wrong = kind
            if not test(*(data[k] for k in key)):
                return wrong
            continue
        value = data.get(key)
        test, noun = _value(dict, "object") if isinstance(kind, dict) else kind
        if not test(value):
            return (f'no "{key}" {noun}' if value is None else
                    f'"{key}" is not {"an" if noun[0] in "aeiou" else "a"} {noun}')
        if isinstance(kind, dict) and (inner := _lacks(value, kind)):
            return f'{inner} in "{key}"'
    return None


def damaged_results(jobs: Sequence[Job]) -> list[tuple[Job, Path, str]]:
    """The ``done.json`` and evaluation files of ``jobs`` that exist but hold no JSON
    object (emptied, cut short) or one without what the reports read, or with it of a
    kind they cannot read (:func:`_lacks`), and the ``metrics.jsonl`` of a finished run that
    :func:`~alphatank.training.logging.read_metrics` refuses (a line before the last that
    is not JSON or a row value that is not a number, not UTF-8): (job, file, why naming
    the file), each file once."""
    from alphatank.training.logging import read_metrics

    found: dict[Path, tuple[Job, Path, str]] = {}
    for job in jobs:
        for path in (job.done_file, *map(job.eval_file, job.evals)):
            if path in found or not path.is_file():
                continue
            try:
                data = read_json(path)
            except ValueError as exc:
                found[path] = (job, path, str(exc))
                continue
            why = _lacks(data, DONE_KEYS if path == job.done_file else EVAL_KEYS)
            if why:
                found[path] = (job, path, f"{path}: {why}; the file is damaged")
        if job.done_file.is_file() and job.done_file not in found \
                and job.metrics_file not in found:  # the learning curves read it
            try:
                read_metrics(job.run_dir)
            except ValueError as exc:
                found[job.metrics_file] = (job, job.metrics_file, str(exc))
    return list(found.values())


def set_aside(job: Job, path: Path) -> Path:
    """Move a damaged result of ``job`` out of the way so that it is made again: an
    evaluation file becomes ``<file>.damaged``, a damaged ``done.json`` or ``metrics.jsonl``
    takes its whole run folder to ``<run>.damaged`` (its checkpoint kept; the run trains
    again from scratch). Returns where it went (a free name: ``.damaged``, ``.damaged-2``,
    ...)."""
    src = Path(job.run_dir) if job.retrains(path) else path
    dest, n = src.with_name(f"{src.name}.damaged"), 1
    while dest.exists():
        n += 1
        dest = src.with_name(f"{src.name}.damaged-{n}")
    src.rename(dest)
    return dest


def clone_cut(summary: dict[str, Any]) -> bool:
    """True when a run's budget ended during its behaviour cloning (``Trainer.train``'s
    summary): its checkpoint holds the untrained learners."""
    return bool((summary.get("stopped") or {}).get("clone_pending"))


class RunInterrupted(RuntimeError):
    """A row's job was stopped by a signal: a run cut short has no done.json and no
    evaluation, an evaluation cut short no file. Run in this process, it ends
    :func:`execute` (the signal was meant for the command); ``exit_code`` is the job's
    (130 after SIGINT, 143 after SIGTERM)."""

    def __init__(self, message: str, exit_code: int = 130):
        super().__init__(message)
        self.exit_code = exit_code


def _train(job: Job) -> dict[str, Any]:
    cfg = TrainConfig.from_dict(job.cfg)
    run_dir = Path(job.run_dir)
    with FolderLock(run_dir):  # another command training this run: BusyError, nothing lost
        return _train_locked(job, cfg, run_dir)


def mixed_env(job: Job, cfg: TrainConfig) -> Any:
    """The env of a job whose row trains on a ``scenarios`` mix (None for one scenario):
    each scenario on the run's ``map`` override if it has one, as the plan checks them."""
    if not job.scenarios:
        return None
    from alphatank.training.learners import learner_class
    from alphatank.training.mixed import MixedVectorEnv

    inputs = sorted({x for spec in run_learners(cfg, 1) for x in learner_class(spec.algo).inputs})
    scenarios = [run_scenario(dataclasses.replace(cfg, scenario=name)) for name in job.scenarios]
    return MixedVectorEnv(scenarios, cfg.num_envs, cfg.seed, cfg.observation, cfg.game or None,
                          cfg.rewards or None, inputs=inputs, action_repeat=cfg.action_repeat)


def _train_locked(job: Job, cfg: TrainConfig, run_dir: Path) -> dict[str, Any]:
    from alphatank.training.runner import Trainer

    if job.done_file.is_file():  # finished by another command while this one waited
        return read_json(job.done_file)
    if run_dir.exists():  # an unfinished run: start it again from scratch
        shutil.rmtree(run_dir)
    run_dir.mkdir(parents=True)
    _write_json(run_dir / "row.json", {"rows": job.rows, "seed": job.seed, "cfg": job.cfg,
                                       "scenarios": job.scenarios, "digest": job.key})
    env = mixed_env(job, cfg)
    t0 = time.time()
    trainer = Trainer(cfg, run_dir, env=env, progress=False)
    summary = trainer.train()
    if summary["exit_code"]:  # SIGINT / SIGTERM: cut short, not finished
        raise RunInterrupted(f"stopped by {summary['stopped']['reason']} at step "
                             f"{summary['global_step']:,}; --resume trains it again",
                             summary["exit_code"])
    league = trainer.schedule.table() if hasattr(trainer.schedule, "table") else None
    done = {"summary": summary, "wall_s": time.time() - t0, "total_steps": cfg.total_steps,
            # the budget's time ran out unless the run trained its planned steps
            "stopped_by": ("steps" if summary["global_step"] >= trainer.planned_steps
                           else "time"),
            "league": league, "finished_at": time.strftime("%Y-%m-%d %H:%M:%S")}
    _write_json(job.done_file, done)
    return done


def _evaluate(job: Job, spec: EvalSpec) -> dict[str, Any]:
    from alphatank.training.evaluate import evaluate_checkpoint

    t0 = time.time()
    res = evaluate_checkpoint(job.run_dir, [spec.bot], games=spec.games, seed=spec.seed,
                              scenario=spec.scenario, weakness=spec.weakness,
                              map_name=spec.map, num_envs=min(EVAL_ENVS, spec.games),
                              label=Path(job.run_dir).name, game=spec.game or None)[0]
    data = {**res.as_dict(per_game=True), "spec": dataclasses.asdict(spec),
            "lengths": res.lengths, "wall_s": time.time() - t0}
    _write_json(job.eval_file(spec), data)
    return data


Failure = tuple[str, str]  # (one line: type and message, the traceback)
BUSY = f"{BusyError.__name__}: "  # a failure's line when another command holds the run


def train_step(job: Job) -> Failure | None:
    """Train ``job`` unless it is finished; a failure is returned, not raised (but for a
    signal's stop: :class:`RunInterrupted`)."""
    from alphatank.training.threads import limit_threads

    limit_threads()
    try:
        if not job.done_file.is_file():
            _train(job)
    except (RunInterrupted, StopRequested):
        raise
    except Exception as exc:  # a failed row is reported; the others go on
        return _failure(exc)
    return None


def eval_step(job: Job, spec: EvalSpec) -> Failure | None:
    """Evaluate ``job`` on ``spec`` unless that is on disk; a failure is returned."""
    from alphatank.training.threads import limit_threads

    limit_threads()
    try:
        if not job.eval_file(spec).is_file():
            _evaluate(job, spec)
    except StopRequested:
        raise
    except Exception as exc:
        return _failure(exc)
    return None


def _failure(exc: Exception) -> Failure:
    first = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
    return f"{type(exc).__name__}: {first}", traceback.format_exc()


def record_failures(job: Job, failures: Sequence[Failure]) -> str | None:
    """Write the tracebacks to ``<run_dir>/error.txt`` (removed when there are none),
    then the failures in one line, which is returned (None when there are none): each
    line once, one that several evaluations gave with their number, ``X (2
    evaluations)``."""
    err = Path(job.run_dir) / "error.txt"
    if not failures:
        if err.exists():
            err.unlink()
        return None
    counts = Counter(line for line, _ in failures)
    line = "; ".join(f"{x} ({n} evaluations)" if n > 1 else x for x, n in counts.items())
    with contextlib.suppress(OSError):  # the failure is still returned and reported
        write_text_atomic(err, "\n".join(tb for _, tb in failures) + f"\n{line}\n")
    return line


def last_failure(job: Job) -> str | None:
    """The one line of the failures of ``job``'s last attempt: the last line of its
    ``error.txt`` (:func:`record_failures`), or None when it has none."""
    try:
        text = (Path(job.run_dir) / "error.txt").read_text(encoding="utf-8", errors="replace")
    except OSError:  # none (or none to read)
        return None
    lines = [ln for ln in text.splitlines() if ln.strip()]
    return lines[-1] if lines else "failed"


CHECKPOINT = "CheckpointError: "  # a failure's line when a checkpoint did not load or fit
# (training.checkpoint.CheckpointError: importing it would bring torch into --list)


def retrain_hint(job: Job, failure: str) -> str:
    """What to do when ``failure`` (one line) says the checkpoint of ``job``, a finished
    run, did not load: ``--resume`` plays its evaluations again from that checkpoint, it
    does not train the run again; '' for other failures."""
    if CHECKPOINT not in failure or not job.done_file.is_file():
        return ""
    return (f"; --resume only plays its evaluations again (the run is finished: it has "
            f"done.json): if its checkpoint is damaged or missing, move {job.run_dir} away "
            f"(e.g. to {job.run_dir}.damaged), then --resume trains the run again")


def run_job(job: Job) -> tuple[str, str | None, float]:
    """Train (unless finished) and evaluate what is missing (each evaluation on its own: one
    that fails does not stop the others); returns (key, error or None, seconds). Failures
    are written to ``<run_dir>/error.txt`` and do not raise; a run another command is
    training is reported busy and nothing is written to its folder. A pool worker whose
    command has ended starts nothing (its queue may still hold jobs). SIGINT or SIGTERM
    stops the job (a run saves): :class:`RunInterrupted`."""
    t0 = time.time()
    with running_job():
        if orphaned():
            return job.key, "not started: the command that ran it has ended", 0.0
        stop = StopFlag()
        try:  # a run handles the signals itself, and the rest has nothing to save
            with stop_on_signals(stop), stop.interruptible():
                failure = train_step(job)
                if failure is not None and failure[0].startswith(BUSY):
                    return job.key, failure[0], time.time() - t0
                failures = [failure] if failure else [f for spec in job.evals
                                                      if (f := eval_step(job, spec))]
                return job.key, record_failures(job, failures), time.time() - t0
        except StopRequested:
            raise RunInterrupted(f"stopped by {stop.reason} before its run and evaluations "
                                 f"were done; --resume does the rest",
                                 stop.exit_code) from None


def stages(jobs: Sequence[Job]) -> list[list[Job]]:
    """``jobs`` in waves, each job after every job of ``jobs`` it needs (the others are
    trained already), in plan order within a wave."""
    by_key = {j.key: j for j in jobs}
    depth: dict[str, int] = {}

    def level(job: Job) -> int:
        if job.key not in depth:
            depth[job.key] = 1 + max((level(by_key[k]) for k in job.needs if k in by_key),
                                     default=-1)
        return depth[job.key]

    waves: list[list[Job]] = [[] for _ in range(1 + max(map(level, jobs), default=-1))]
    for job in jobs:
        waves[level(job)].append(job)
    return waves


def execute(jobs: Sequence[Job], workers: int = 1, progress: bool = True,
            on_done: Callable[[Job, str | None, float], None] | None = None,
            runner: Callable[[Sequence[Job], Callable[[Job, str | None, float], None]],
                             None] | None = None) -> dict[str, str]:
    """Run ``jobs`` (``workers`` processes; 1: in this process; or ``runner(jobs,
    finish)``, e.g. :func:`alphatank.training.ray_jobs.run_on_ray`, calling ``finish``
    as each job ends) with a progress bar over them, wave by wave (:func:`stages`: a
    row taught by other rows' runs trains after them; not at all if one of them did not
    finish); returns {job key: error} of the failed ones."""
    failed: dict[str, str] = {}
    if not jobs:
        return failed
    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=len(jobs), unit="run", dynamic_ncols=True, desc="experiments")

    def finish(job: Job, error: str | None, seconds: float) -> None:
        if error is not None:
            failed[job.key] = error
        if on_done is not None:
            on_done(job, error, seconds)
        if bar is not None:
            bar.update(1)

    def run(stage: Sequence[Job]) -> None:
        if runner is not None:
            runner(stage, finish)
        elif workers <= 1:
            for job in stage:
                if bar is not None:
                    bar.set_postfix_str(", ".join(job.rows), refresh=True)
                _, error, seconds = run_job(job)
                finish(job, error, seconds)
        else:
            import multiprocessing as mp
            from concurrent.futures import ProcessPoolExecutor, as_completed

            # a worker whose driver was killed or stopped (ended) stops its run (saving
            # it) instead of training on as an orphan, and starts no other job
            context = mp.get_context("spawn")
            ended = context.Event()
            with ProcessPoolExecutor(max_workers=workers, mp_context=context,
                                     initializer=exit_with_parent,
                                     initargs=(ended,)) as pool:
                futures = {pool.submit(run_job, job): job for job in stage}
                try:
                    for fut in as_completed(futures):
                        job = futures[fut]
                        try:
                            _, error, seconds = fut.result()
                        except RunInterrupted as exc:  # a signal stopped the worker's run
                            error, seconds = f"{type(exc).__name__}: {exc}", 0.0
                        except Exception as exc:  # the worker process died
                            error, seconds = f"worker died: {type(exc).__name__}: {exc}", 0.0
                        finish(job, error, seconds)
                except BaseException:  # Ctrl-C or SIGTERM of this process: stop the workers
                    ended.set()
                    pool.shutdown(cancel_futures=True)
                    raise

    by_key = {j.key: j for j in jobs}
    try:
        for stage in stages(jobs):
            ready = []
            for job in stage:
                lost = [by_key[k] for k in job.needs
                        if k in by_key and not by_key[k].done_file.is_file()]
                if lost:  # a teacher's run did not finish: nothing to learn from
                    finish(job, "not trained: it needs the run of " + ", ".join(
                        f"{', '.join(j.rows)} seed {j.seed}" for j in lost)
                        + ", which did not finish", 0.0)
                else:
                    ready.append(job)
            run(ready)
    finally:
        if bar is not None:
            bar.close()
    return failed


def estimate_minutes(plan: Plan, jobs: Sequence[Job], workers: int,
                     damaged: Collection[Path] = ()) -> float:
    """Rough wall time of ``jobs``: the budget per run still to train plus ~1.5 min per
    evaluation of 200 games still to play (200 games of up to 1,200 ticks took 1-3 min on
    a shared 2-core machine), spread over the workers, and at least the longest job (a
    job runs on one worker). Files in ``damaged`` are made again (a run whose done.json or
    metrics.jsonl is damaged trains and plays every evaluation again)."""
    minutes = []
    for j in jobs:
        trains = not j.done_file.is_file() or any(map(j.retrains, damaged))
        plays = sum(trains or not j.eval_file(s).is_file() or j.eval_file(s) in damaged
                    for s in j.evals)
        minutes.append(plan.budget_min * trains + 1.5 * plays * plan.games / DEFAULT_GAMES)
    return max(sum(minutes) / max(1, workers), max(minutes, default=0.0))

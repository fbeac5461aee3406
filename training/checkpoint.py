"""Checkpoints: one directory per save, written atomically, loadable as a Policy anywhere.

Layout of ``<run>/checkpoints/step_<N>/``::

    meta.json           format/version, train config, scenario, observation layout,
                        learners (algo, seats, hyperparameters), progress, RNG states,
                        schedule state, SHA-256 of every other file
    <learner>.pt        weights, optimiser state, normalisers, random generator states
                        (plain tensors and dicts: ``torch.load(weights_only=True)``)
    <learner>.replay.npz  SAC replay buffer (for exact resume; ``allow_pickle=False``)

A save writes everything into a temporary sibling directory and ``os.replace``-s it into
place, then updates ``<run>/latest`` (a one-line file, also replaced atomically), so a
process killed at any moment (even ``kill -9``) leaves the previous save intact and
``latest`` pointing at a complete one; leftovers of killed saves are removed by the next
save. Every load problem raises :class:`CheckpointError` naming the file and what is wrong.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import re
import shutil
import time
import weakref
import zipfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from alphatank.errors import InputError
from alphatank.files import check_folder, read_text, write_text_atomic
from alphatank.game.observe import OBS_KINDS
from alphatank.game.scenarios import Scenario, ScenarioError, parse_scenario, team_misfit
from alphatank.game.seats import agent_path
from alphatank.sim.config import ACTION_REPEAT_MAX, check_value
from alphatank.sim.mapspec import map_text
from alphatank.sim.policy import NOOP, Observe
from alphatank.training.learners import make_learner
from alphatank.training.presets import LearnerSpec, TrainConfig
from alphatank.training.stopping import TIME_LIMIT_MAX_S
from alphatank.training.streams import GameStreams

FORMAT = "alphatank-checkpoint"
VERSION = 1
# seconds a save sleeps after writing the learner files, before meta.json and the rename
# (crash tests kill the process there; never set in normal use)
DELAY_ENV = "ALPHATANK_TEST_SAVE_DELAY"


class CheckpointError(InputError, RuntimeError):
    """A checkpoint is missing, corrupt, truncated or does not fit; names file and cause."""


class SaveFailed(OSError):
    """A checkpoint could not be written (disk full, folder not writable): names the save
    and the cause; the run's earlier saves and ``latest`` are as they were."""


def scenario_to_dict(sc: Scenario) -> dict[str, Any]:
    """A mapping :func:`parse_scenario` rebuilds ``sc`` from. Maps not shipped with the
    package travel as text (``map_texts``), so the checkpoint needs no map file; ``map``
    then says where they were read from."""
    out = sc.to_dict()
    if all(m.startswith("pkg:") for m in sc.maps) or "map_texts" in out:
        return out
    where = Path(sc.maps[0]).resolve()
    return {**out, "map": str(where if len(sc.maps) == 1 else where.parent),
            "map_texts": [[spec.name, map_text(spec)] for spec in sc.map_specs()]}


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def save_checkpoint(run_dir: str | Path, tag: str, meta: dict[str, Any],
                    states: dict[str, dict[str, Any]],
                    arrays: dict[str, dict[str, np.ndarray]] | None = None,
                    keep: int = 0, extra: dict[str, dict[str, Any]] | None = None) -> Path:
    """Write ``<run_dir>/checkpoints/<tag>`` atomically and point ``<run_dir>/latest`` at
    it. ``states``: learner name -> torch state dict; ``arrays``: learner name -> arrays
    for ``<name>.replay.npz``; ``extra``: other run state (the self-play pool) -> torch
    state dict, saved as ``extra/<key>.pt`` (no learner name can clash with a folder).
    ``keep`` > 0 prunes all but the newest ``keep`` saves."""
    root = Path(run_dir) / "checkpoints"
    final = root / tag
    tmp = root / f".{tag}.tmp-{os.getpid()}"
    try:
        root.mkdir(parents=True, exist_ok=True)
        if tmp.exists():
            shutil.rmtree(tmp)
        tmp.mkdir()
        try:
            _write_save(tmp, meta, states, arrays or {}, extra or {})
        except BaseException:  # a failed or aborted write leaves nothing behind
            shutil.rmtree(tmp, ignore_errors=True)
            raise
        new = not final.exists()
        if not new:  # re-saving a tag: move the old one aside first (rename is atomic;
            old = root / f".{tag}.old-{os.getpid()}"  # resolve_checkpoint_dir finds it if
            os.replace(final, old)  # the process dies before the next rename)
            os.replace(tmp, final)
            shutil.rmtree(old)
        else:
            os.replace(tmp, final)
        try:
            write_text_atomic(Path(run_dir) / "latest", f"checkpoints/{tag}\n")
        except OSError:  # latest names the previous save: a save it does not name would
            if new:  # stop a resume of it ("the run has later saves")
                shutil.rmtree(final, ignore_errors=True)
            raise
    except OSError as exc:
        raise SaveFailed(f"{final}: the checkpoint cannot be written ({exc.strerror or exc});"
                         f" nothing of it is kept, and the run's earlier saves are as they "
                         f"were") from None
    if keep > 0:  # only the run's own saves: other folders a user put there stay
        for old in run_saves(root)[:-keep]:
            if old != final:
                shutil.rmtree(old, ignore_errors=True)
    _remove_leftovers(root)
    return final


def _write_save(tmp: Path, meta: dict[str, Any], states: dict[str, dict[str, Any]],
                arrays: dict[str, dict[str, np.ndarray]],
                extra: dict[str, dict[str, Any]]) -> None:
    """The files of a save (:func:`save_checkpoint`) in its temporary folder ``tmp``."""
    files: dict[str, str] = {}
    for name, state in states.items():
        _torch_save(state, tmp / f"{name}.pt")
        files[f"{name}.pt"] = _sha256(tmp / f"{name}.pt")
    for name, arrs in arrays.items():
        np.savez(tmp / f"{name}.replay.npz", **arrs)
        files[f"{name}.replay.npz"] = _sha256(tmp / f"{name}.replay.npz")
    for key, state in extra.items():
        (tmp / "extra").mkdir(exist_ok=True)
        _torch_save(state, tmp / "extra" / f"{key}.pt")
        files[f"extra/{key}.pt"] = _sha256(tmp / "extra" / f"{key}.pt")
    meta = {"format": FORMAT, "version": VERSION, "saved_at": time.time(), **meta,
            "files": files}
    if os.environ.get(DELAY_ENV):
        time.sleep(float(os.environ[DELAY_ENV]))
    (tmp / "meta.json").write_text(json.dumps(meta, indent=1), encoding="utf-8")


def _torch_save(state: dict[str, Any], file: Path) -> None:
    """``torch.save`` into ``file``; a write that fails (disk full) raises its OSError
    (torch's writer reports it as a RuntimeError about zip positions)."""
    try:
        with open(file, "wb") as f:
            torch.save(state, f)
    except RuntimeError as exc:
        if isinstance(exc.__context__, OSError):
            raise exc.__context__ from None
        raise


_SAVE = re.compile(r"step_(\d+)")  # the name of a save's folder (save_checkpoint's tag)
_MOVED_SAVE = re.compile(r"\.step_(\d+)\.old-\d+")  # one moved aside while re-saved


def run_saves(root: Path) -> list[Path]:
    """The save folders (``step_<N>``) in a run's ``checkpoints`` folder, oldest step first."""
    found = [(int(m.group(1)), p) for p in root.iterdir()
             if (m := _SAVE.fullmatch(p.name)) and p.is_dir()]
    return [p for _, p in sorted(found)]


def resume_dir(ckpt: Checkpoint) -> Path:
    """The run folder in which resuming ``ckpt`` continues: the run of a save at
    ``<run>/checkpoints/step_<N>`` (beside ``<run>/latest``) with no later save, that can
    be written in. Anything else is refused: a resumed run writes, and prunes saves, in
    that folder."""
    path = ckpt.path
    if isinstance(ckpt.meta.get("agent"), dict):
        raise CheckpointError(f"{path}: an agent folder (weights without their training "
                              f"state) cannot be resumed; train a new run from it with "
                              f"--init-from {path}")
    run = path.parent.parent
    m = _SAVE.fullmatch(path.name) or _MOVED_SAVE.fullmatch(path.name)
    if m is None or path.parent.name != "checkpoints" or not (run / "latest").is_file():
        raise CheckpointError(f"{path}: not a save in a run folder (RUN/checkpoints/step_N "
                              f"beside RUN/latest), and --resume continues a run in its own "
                              f"folder; resume the run folder, or train a new run from "
                              f"these weights with --init-from {path}")
    later = [p.name for p in run_saves(path.parent) if int(p.name[5:]) > int(m.group(1))]
    if later:
        raise CheckpointError(f"{path}: the run has later saves ({', '.join(later)}), and "
                              f"resuming an earlier one would write a second history into "
                              f"the same run; resume the run ({run}), or remove the later "
                              f"saves first")
    # its lock goes beside it, its saves and metrics in it: checked before training, not
    # when the first save fails
    for folder in (run.parent, run, run / "checkpoints"):
        check_folder(folder, "--resume")
    return run


def _remove_leftovers(root: Path) -> None:
    """Delete the temporary folders of saves whose process is gone (killed mid-save)."""
    for p in root.iterdir():
        name, _, pid = p.name.rpartition("-")
        if not (p.name.startswith(".") and (".tmp" in name or ".old" in name) and pid.isdigit()):
            continue
        try:
            os.kill(int(pid), 0)
            continue  # that process still runs (another save of this run?): leave it
        except ProcessLookupError:
            pass
        except PermissionError:
            continue
        shutil.rmtree(p, ignore_errors=True)


def resolve_checkpoint_dir(path: str | Path) -> Path:
    """A checkpoint directory from a checkpoint path or a run directory (its ``latest``)."""
    p = Path(path)
    if not p.exists():
        raise CheckpointError(f"{p}: no such checkpoint or run directory")
    if p.is_file():
        raise CheckpointError(f"{p}: expected a checkpoint directory (with meta.json), "
                              f"got a file")
    if (p / "meta.json").exists():
        return p
    latest = p / "latest"
    if latest.is_file():
        try:
            name = read_text(latest).strip()
        except ValueError as exc:
            raise CheckpointError(str(exc)) from None
        if not name:  # read as the run folder itself
            raise CheckpointError(f"{latest}: is empty; it names the run's latest save "
                                  "(checkpoints/step_N)")
        if "\n" in name:
            raise CheckpointError(f"{latest}: holds {len(name.splitlines())} lines; it names "
                                  f"one save, the run's latest (checkpoints/step_N)")
        target = p / name
        moved = sorted(target.parent.glob(f".{target.name}.old-*/meta.json"))
        if not target.exists() and moved:  # killed while re-saving this tag
            return moved[-1].parent
        if not target.exists():  # its save was removed
            saves = run_saves(p / "checkpoints") if (p / "checkpoints").is_dir() else []
            raise CheckpointError(
                f"{latest}: points at {target}, which does not exist" + (
                    f"; the run's saves: {', '.join(s.name for s in saves)} (give one, e.g. "
                    f"{saves[-1]}, or write checkpoints/{saves[-1].name} into {latest})"
                    if saves else "; the run has no saves"))
        if not (target / "meta.json").exists():
            raise CheckpointError(f"{latest}: points at {target}, which holds no meta.json")
        return target
    saves = run_saves(p / "checkpoints") if (p / "checkpoints").is_dir() else []
    if saves:  # latest removed
        raise CheckpointError(f"{p}: a run folder without its 'latest' file; the run's saves: "
                              f"{', '.join(s.name for s in saves)} (give one, e.g. "
                              f"{saves[-1]}, or write checkpoints/{saves[-1].name} into "
                              f"{latest})")
    if (p / "metrics.jsonl").is_file():
        raise CheckpointError(f"{p}: a run folder with no save yet (a run saves after every "
                              f"checkpoint_every iterations and when it stops)")
    raise CheckpointError(f"{p}: not a checkpoint (no meta.json) and not a run directory "
                          f"(no 'latest' file)")


def _torch_load(file: Path) -> Any:
    """``torch.load(weights_only=True)`` of ``file``; CheckpointError naming it and why not
    (for a file holding other Python objects, the one that the weights-only load refused,
    not torch's advice to load it with ``weights_only=False``)."""
    try:
        return torch.load(file, map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises many types for damaged files
        text = re.sub(r"\x1b\[[0-9;]*m", "", str(exc))  # torch bolds a phrase with escapes
        refused = re.search(r"WeightsUnpickler error: (.+?)(?: was not an allowed global|$)",
                            text, re.MULTILINE)
        if refused:
            raise CheckpointError(f"{file}: holds more than tensors and plain data, which "
                                  f"a checkpoint never does ({refused.group(1).rstrip('.')}); "
                                  f"it was not saved by alphatank or was altered") from None
        first = text.strip().splitlines()[0] if text.strip() else ""
        raise CheckpointError(f"{file}: cannot be loaded (corrupt or not a checkpoint "
                              f"file): {type(exc).__name__}: {first}") from None


@dataclass
class Checkpoint:
    """A validated checkpoint on disk (meta read; tensors loaded on demand)."""

    path: Path
    meta: dict[str, Any]

    @property
    def train_config(self) -> TrainConfig:
        """The run's settings; a time limit saved before new ones were capped at
        :data:`TIME_LIMIT_MAX_S` reads as the cap (a resume's ``--time-limit`` replaces it)."""
        try:
            data = dict(self.meta["train_config"])
            limit = data.get("time_limit_s")
            if isinstance(limit, int | float) and limit > TIME_LIMIT_MAX_S:
                data["time_limit_s"] = float(TIME_LIMIT_MAX_S)
            return TrainConfig.from_dict(data)
        except (ValueError, KeyError, TypeError) as exc:
            raise CheckpointError(f"{self.path / 'meta.json'}: train_config: {exc}") from None

    @property
    def learner_specs(self) -> list[LearnerSpec]:
        try:
            return [LearnerSpec.from_dict({k: v for k, v in d.items() if k != "scenario_seats"})
                    for d in self.meta["learners"]]
        except (ValueError, KeyError, TypeError) as exc:
            raise CheckpointError(f"{self.path / 'meta.json'}: learners: {exc}") from None

    @property
    def scenario(self) -> Scenario:
        try:
            return parse_scenario(self.meta["scenario"], f"{self.path / 'meta.json'}:scenario",
                                  check_paths=False)
        except ScenarioError as exc:
            raise CheckpointError(str(exc)) from None

    @property
    def obs_dim(self) -> int:
        return int(self.meta["observation"]["obs_dim"])

    @property
    def trained_as(self) -> str:
        """Its training scenario for error messages: name, map, teams and observation
        kind."""
        sc = self.meta.get("scenario", {})
        teams = [str(t.get("team", "?")) for t in sc.get("seats", [])]
        if not teams:
            return ""
        where = f"map {sc['map']!r}, " if isinstance(sc.get("map"), str) else ""
        return (f"its training scenario {sc.get('name', '?')!r} ({where}teams {teams}, "
                f"{self.meta['observation']['kind']} observation)")

    @property
    def trained_teams(self) -> tuple[str, ...]:
        """The team of each seat of its training scenario (empty when not recorded)."""
        return tuple(str(t.get("team", "?")) for t in
                     self.meta.get("scenario", {}).get("seats", []))

    def learner_names(self) -> list[str]:
        return [d["name"] for d in self.meta["learners"]]

    def state(self, name: str) -> dict[str, Any]:
        """``torch.load(weights_only=True)`` of learner ``name``'s file, errors explained."""
        if name not in self.learner_names():
            raise CheckpointError(f"{self.path}: no learner {name!r}; learners: "
                                  f"{self.learner_names()}")
        file = self.path / f"{name}.pt"
        self._check_file(file)
        state = _torch_load(file)
        if not isinstance(state, dict):
            raise CheckpointError(f"{file}: not a learner state (a {type(state).__name__}, "
                                  "expected a dict of tensors)")
        bad = non_finite(state)
        if bad is not None:
            raise CheckpointError(f"{file}: tensor {bad!r} holds NaN or infinite values; "
                                  "the training diverged or the file was altered")
        return state

    def extra_state(self, key: str) -> dict[str, Any]:
        """``torch.load(weights_only=True)`` of the run state ``extra/<key>.pt``."""
        file = self.path / "extra" / f"{key}.pt"
        self._check_file(file, f"extra/{key}.pt")
        return _torch_load(file)

    def replay(self, name: str) -> dict[str, np.ndarray] | None:
        file = self.path / f"{name}.replay.npz"
        if f"{name}.replay.npz" not in self.meta.get("files", {}):
            return None
        self._check_file(file)
        try:
            arrays = npz_arrays(file)
        except Exception as exc:
            raise CheckpointError(f"{file}: cannot be read: {type(exc).__name__}: {exc}") from None
        bad = non_finite(arrays)
        if bad is not None:
            raise CheckpointError(f"{file}: array {bad!r} holds NaN or infinite values")
        return arrays

    def _check_file(self, file: Path, key: str | None = None) -> None:
        want = self.meta.get("files", {}).get(key or file.name)
        if not file.is_file():
            raise CheckpointError(f"{file}: missing from the checkpoint")
        if want is not None and _sha256(file) != want:
            raise CheckpointError(f"{file}: corrupt or truncated (SHA-256 differs from the one "
                                  f"recorded in meta.json; size {file.stat().st_size} bytes)")

    def load_learner(self, name: str, weights_only: bool = False) -> Any:
        """A learner rebuilt from its spec with this checkpoint's state (one env's worth of
        streams: one per seat it drives)."""
        specs = {s.name: s for s in self.learner_specs}
        if name not in specs:
            raise CheckpointError(f"{self.path}: no learner {name!r}; learners: {list(specs)}")
        spec = specs[name]
        learner = make_learner(spec, self.obs_dim, len(spec.seats), 0,
                               input_dims=self.meta.get("input_dims"))
        state = self.state(name)
        try:
            learner.load_state_dict(state, weights_only=weights_only)
        except FIT_ERRORS as exc:
            raise CheckpointError(f"{self.path / (name + '.pt')}: does not fit a {spec.algo} "
                                  f"learner with obs_dim {self.obs_dim} and its saved config: "
                                  f"{type(exc).__name__}: {load_problem(exc)}") from None
        return learner


def load_checkpoint(path: str | Path) -> Checkpoint:
    """Open and validate a checkpoint directory (or a run directory's latest save)."""
    ckpt_dir = resolve_checkpoint_dir(path)
    meta_file = ckpt_dir / "meta.json"
    try:
        meta = json.loads(meta_file.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise CheckpointError(f"{meta_file}: invalid JSON (line {exc.lineno}, column "
                              f"{exc.colno}): {exc.msg}; the checkpoint is corrupt or "
                              f"truncated") from None
    except UnicodeDecodeError:
        raise CheckpointError(f"{meta_file}: not UTF-8 text; the checkpoint is corrupt") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise CheckpointError(f"{meta_file}: not an alphatank checkpoint (format "
                              f"{meta.get('format') if isinstance(meta, dict) else None!r})")
    version = meta.get("version")
    if not isinstance(version, int) or isinstance(version, bool):
        raise CheckpointError(f"{meta_file}: version: must be an integer (this alphatank reads "
                              f"version {VERSION}), got {version!r}")
    if version != VERSION:
        raise CheckpointError(f"{meta_file}: checkpoint version {version}, this alphatank "
                              f"reads version {VERSION}")
    for key in ("train_config", "scenario", "observation", "learners", "files", "progress"):
        if key not in meta:
            raise CheckpointError(f"{meta_file}: missing field {key!r}")
    _check_meta(meta, meta_file)
    return Checkpoint(ckpt_dir, meta)


# meta.json fields read outside the train config: key -> (types, range)
_OBSERVATION_FIELDS: dict[str, tuple[tuple[type, ...], tuple[Any, Any] | None]] = {
    "kind": ((str,), None), "obs_dim": ((int,), (1, 10**7)),
    "max_walls": ((int,), (0, 10**6)), "max_buffs": ((int,), (0, 10**6)),
    "max_debuffs": ((int,), (0, 10**6)), "team_flags": ((bool,), None),
    "tanks": ((int,), (2, 10**4)), "seat_learner": ((dict,), None),
    "action_repeat": ((int,), (1, ACTION_REPEAT_MAX))}
_PROGRESS_FIELDS = {"global_step": ((int,), (0, None)), "iteration": ((int,), (0, None)),
                    "episodes": ((int,), (0, None)), "elapsed": ((float,), (0, None)),
                    "cut": ((int,), (0, None)), "clone_pending": ((bool,), None)}
# fields added later, which older checkpoints lack: their defaults
_OPTIONAL_FIELDS = {"observation": {"action_repeat": 1},
                    "progress": {"cut": 0, "clone_pending": False}}


# what a learner's load_state_dict raises for a state that does not fit it: a tensor of
# another shape, a missing key, a value of another type (a hand-edited file)
FIT_ERRORS = (RuntimeError, KeyError, ValueError, TypeError, AttributeError, IndexError)


def load_problem(exc: BaseException) -> str:
    """What a failed ``load_state_dict`` says, on one line: torch's heading and the first
    two tensors that differ (their names and shapes follow the heading's line)."""
    lines = [x.strip() for x in str(exc).splitlines() if x.strip()]
    return " ".join(lines[:3])


def _check_meta(meta: dict[str, Any], meta_file: Path) -> None:
    """Type-check the meta fields that loading and resuming read (CheckpointError names
    the field) and fill in the optional ones an older checkpoint lacks with their
    defaults."""
    def fail(where: str, why: str) -> CheckpointError:
        return CheckpointError(f"{meta_file}: {where}: {why}")

    for key, table in (("observation", _OBSERVATION_FIELDS), ("progress", _PROGRESS_FIELDS)):
        data = meta[key]
        if not isinstance(data, dict):
            raise fail(key, f"must be an object, got {data!r}")
        for name, (kinds, rng) in table.items():
            if name not in data:
                if name not in _OPTIONAL_FIELDS[key]:
                    raise fail(f"{key}.{name}", "missing")
                data[name] = _OPTIONAL_FIELDS[key][name]
                continue
            _, why = check_value(kinds, data[name], rng)
            if why is not None:
                raise fail(f"{key}.{name}", why)
    if meta["observation"]["kind"] not in OBS_KINDS:
        raise fail("observation.kind", f"unknown observation kind "
                   f"{meta['observation']['kind']!r}; valid: {list(OBS_KINDS)}")
    for key in ("scenario", "train_config"):
        if not isinstance(meta[key], dict):
            raise fail(key, f"must be an object, got {meta[key]!r}")
    seats = meta["scenario"].get("seats", [])
    if not isinstance(seats, list) or not all(isinstance(t, dict) for t in seats):
        raise fail("scenario.seats", f"must be a list of seat objects, got {seats!r}")
    learners = meta["learners"]
    if (not isinstance(learners, list) or not learners
            or not all(isinstance(d, dict) and isinstance(d.get("name"), str) and d["name"]
                       for d in learners)):
        raise fail("learners", "must be a non-empty list of objects with a 'name'")
    names = {d["name"] for d in learners}
    seat_learner = meta["observation"]["seat_learner"]
    if not all(isinstance(k, str) and k.isdigit() and v in names
               for k, v in seat_learner.items()):
        raise fail("observation.seat_learner", f"must map seat numbers to learner names "
                   f"{sorted(names)}, got {seat_learner!r}")
    files = meta["files"]
    if not isinstance(files, dict) or not all(
            isinstance(k, str) and _file_key(k) and isinstance(v, str) for k, v in files.items()):
        raise fail("files", "must map file names in the checkpoint folder (or extra/NAME) to "
                            "SHA-256 digests")
    if not isinstance(meta.get("schedule", {}), dict):
        raise fail("schedule", f"must be an object, got {meta['schedule']!r}")
    windows = meta.get("windows", {})
    if not isinstance(windows, dict):
        raise fail("windows", f"must be an object, got {windows!r}")
    for part in ("outcomes", "returns"):
        table = windows.get(part, {})
        if not isinstance(table, dict) or not all(
                k in names and isinstance(v, list)
                and all(check_value((float,), x)[1] is None for x in v)
                for k, v in table.items()):
            raise fail(f"windows.{part}", f"must map learner names {sorted(names)} to lists "
                                          f"of numbers")
    lengths = windows.get("lengths", [])
    if not isinstance(lengths, list) or not all(
            check_value((int,), x, (0, None))[1] is None for x in lengths):
        raise fail("windows.lengths", "must be a list of episode lengths (integers >= 0)")
    opps = windows.get("by_opponent", {})
    if not isinstance(opps, dict) or not all(
            k in names and isinstance(v, dict) and all(
                isinstance(o, str) and isinstance(xs, list)
                and all(check_value((float,), x)[1] is None for x in xs)
                for o, xs in v.items())
            for k, v in opps.items()):
        raise fail("windows.by_opponent", f"must map learner names {sorted(names)} to "
                                          "{opponent: list of numbers}")


def _file_key(key: str) -> bool:
    """A checkpoint file name: ``NAME`` or ``extra/NAME`` (no other folder, no ``..``)."""
    name = key.removeprefix("extra/")
    return bool(name) and "/" not in name and "\\" not in name and name not in (".", "..")


def npz_arrays(file: Path) -> dict[str, np.ndarray]:
    """The arrays of a ``.npz`` file (no pickles), those stored uncompressed (``np.savez``)
    memory-mapped read-only from the file: a replay buffer restored from them on resume
    needs no second copy of itself in memory (the whole file was read first, twice the
    buffer's size at the peak)."""
    out = {}
    with np.load(file, allow_pickle=False) as data, zipfile.ZipFile(file) as z:
        for key in data.files:
            info = z.getinfo(f"{key}.npy")
            if info.compress_type != zipfile.ZIP_STORED or info.file_size < 1 << 16:
                out[key] = data[key]  # compressed, or small: read as it is
                continue
            with z.open(info) as f:  # the array's own header: shape, order, dtype
                version = np.lib.format.read_magic(f)
                shape, fortran, dtype = (np.lib.format.read_array_header_1_0(f) if version
                                         == (1, 0) else np.lib.format.read_array_header_2_0(f))
                header = f.tell()
            with open(file, "rb") as raw:  # the member's data start: after its local header
                raw.seek(info.header_offset + 26)
                names, extra = np.frombuffer(raw.read(4), dtype="<u2")
            start = info.header_offset + 30 + int(names) + int(extra) + header
            out[key] = np.memmap(file, dtype=dtype, mode="r", offset=start, shape=shape,
                                 order="F" if fortran else "C")
    return out


def non_finite(state: Any, prefix: str = "") -> str | None:
    """Dotted name of the first floating-point tensor or array in ``state`` (nested dicts,
    lists) holding NaN or infinity, else None."""
    if isinstance(state, torch.Tensor):
        ok = not state.is_floating_point() or bool(torch.isfinite(state).all())
        return None if ok else prefix or "<tensor>"
    if isinstance(state, np.ndarray):  # in blocks: no temporary the size of a replay buffer
        flat = state.ravel(order="K")
        ok = state.dtype.kind != "f" or all(bool(np.isfinite(flat[i:i + (1 << 20)]).all())
                                             for i in range(0, flat.size, 1 << 20))
        return None if ok else prefix or "<array>"
    if isinstance(state, float):
        return None if math.isfinite(state) else prefix or "<number>"
    items = (state.items() if isinstance(state, dict)
             else enumerate(state) if isinstance(state, list | tuple) else ())
    for key, value in items:
        bad = non_finite(value, f"{prefix}.{key}" if prefix else str(key))
        if bad is not None:
            return bad
    return None


BANK_ROWS = 16  # matches one observation bank of a NetworkPolicy holds


class _Bank:
    """Observation rows of up to :data:`BANK_ROWS` matches for one seat, built in one
    call: row ``r`` belongs to the match ``owners[r]`` refers to (free when that match is
    gone or the row was given up)."""

    def __init__(self, kind: str, match: Any, seat: int, slots: tuple[int, int, int],
                 team_flags: bool):
        from alphatank.game.observe import ObservationBuilder, StateBatch

        self.key = (match.cfg, tuple(match.teams), seat)
        self.walls = slots[0]
        self.batch = StateBatch(match.cfg, match.n, BANK_ROWS, *slots)
        self.builder = ObservationBuilder(kind, self.batch, match.teams, [seat],
                                          team_flags=team_flags)
        self.owners: list[weakref.ref | None] = [None] * BANK_ROWS

    def owner(self, row: int) -> Any:
        ref = self.owners[row]
        return None if ref is None else ref()

    def free_row(self) -> int | None:
        return next((r for r in range(BANK_ROWS) if self.owner(r) is None), None)


@dataclass
class _SeatState:
    """What a :class:`NetworkPolicy` keeps for one seat of one match."""

    learner: Any
    bank: _Bank
    row: int
    rng: np.random.Generator
    sid: int | None  # MAPPO's seat id
    held: np.ndarray  # the action of the last decision


class NetworkPolicy:
    """Trained learners as a :class:`alphatank.sim.policy.BatchPolicy` for any seat of any
    match with the same number of tanks and observation size as their training scenario,
    and (``trained_teams``, when given) a place in its teams that a training seat had.

    The learner is picked per seat at :meth:`reset`: ``learner`` if given, else the one
    that trained in that scenario seat, else the first. Observations come from the
    caller's ``observe`` where it can build them (an env's own batch), else from banks of
    the policy's own (the env's :class:`~alphatank.game.observe.ObservationBuilder` for up
    to :data:`BANK_ROWS` matches per call, one bank per seat and game).
    :meth:`act_batch` decides for many matches in one forward pass, each row's sampling
    noise drawn from that seat's own generator, so a seat's actions do not depend on the
    other matches of the call. One object may fill several seats of several matches at
    once: everything per seat (the learner, the bank row, the random generator, MAPPO's
    seat id) is kept per (match, seat) and replaced at that seat's next :meth:`reset`.
    """

    def __init__(self, observation: dict[str, Any], learner_names: list[str],
                 learner: str | None = None, deterministic: bool = False,
                 source: str = "policy", trained_as: str = "",
                 trained_teams: Sequence[str] = ()):
        if learner is not None and learner not in learner_names:
            raise CheckpointError(f"{source}: no learner {learner!r}; learners: "
                                  f"{learner_names}")
        self.source, self.names = source, list(learner_names)
        self.learner_name, self.deterministic = learner, deterministic
        self.kind, self.obs_dim = observation["kind"], int(observation["obs_dim"])
        self.slots = (int(observation["max_walls"]), int(observation["max_buffs"]),
                      int(observation["max_debuffs"]))
        self.team_flags = bool(observation["team_flags"])
        self.seat_learner = {int(k): v for k, v in observation["seat_learner"].items()}
        self.n_tanks = int(observation["tanks"])
        self.repeat = int(observation["action_repeat"])  # ticks an action is held
        self.trained_as = trained_as  # the training scenario, for error messages
        self.trained_teams = tuple(trained_teams)  # its seats' teams, when known
        self._seats: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
        self._banks: list[_Bank] = []

    def __getstate__(self) -> dict[str, Any]:
        # per-match state stays with the matches
        return {**self.__dict__, "_seats": None, "_banks": []}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._seats = weakref.WeakKeyDictionary()

    def name_for_seat(self, seat: int) -> str:
        if self.learner_name is not None:
            return self.learner_name
        return self.seat_learner.get(seat, self.names[0])

    def get_learner(self, name: str) -> Any:
        raise NotImplementedError

    def seat_id(self, match: Any, seat: int, name: str, num_seats: int) -> int:
        """The seat id a learner that tells its seats apart (MAPPO) gets for ``seat``: its
        index among the seats it trained in, else its rank within its team (mod the
        learner's seat count)."""
        trained = sorted(s for s, n in self.seat_learner.items() if n == name)
        if seat in trained and len(trained) == num_seats:
            return trained.index(seat)
        mates = [s for s in range(match.n) if match.teams[s] == match.teams[seat]]
        return mates.index(seat) % num_seats

    def _fit_hint(self) -> str:
        return (f"; it fits seats of matches with {self.n_tanks} tanks and the same team "
                f"sizes as {self.trained_as}" if self.trained_as else "")

    def _row(self, match: Any, seat: int, old: _SeatState | None, walls: int
             ) -> tuple[_Bank, int]:
        """A bank row for ``seat`` of ``match``: its old one if it still fits, else a free
        row of a fitting bank (a new bank when none has one)."""
        key = (match.cfg, tuple(match.teams), seat)
        if (old is not None and old.bank.key == key and old.bank.walls >= walls
                and old.bank.owner(old.row) is match):
            return old.bank, old.row
        if old is not None and old.bank.owner(old.row) is match:
            old.bank.owners[old.row] = None
        for bank in self._banks:
            if bank.key == key and bank.walls >= walls:
                row = bank.free_row()
                if row is not None:
                    return bank, row
        bank = _Bank(self.kind, match, seat, (walls, *self.slots[1:]), self.team_flags)
        if bank.builder.layout.size != self.obs_dim or match.n != self.n_tanks:
            raise CheckpointError(
                f"{self.source}: expects {self.obs_dim} observation features "
                f"({self.kind}, {self.n_tanks} tanks); seat {seat} of this match "
                f"({match.n} tanks, teams {match.teams}) gives {bank.builder.layout.size}"
                f"{self._fit_hint()}")
        misfit = team_misfit(self.trained_teams, self.seat_learner, match.teams, seat)
        if misfit is not None:
            raise CheckpointError(f"{self.source}: {misfit}"
                                  + (f", in {self.trained_as}" if self.trained_as else ""))
        self._banks.append(bank)
        return bank, 0

    def reset(self, match: Any, seat: int, seed: int | None = None) -> None:
        from alphatank.game.observe import room_misfit, slot_counts

        name = self.name_for_seat(seat)
        learner = self.get_learner(name)
        per_match = self._seats.setdefault(match, {})
        need = slot_counts(match.cfg, [match.spec])
        # another tank count fits no map: _row says so instead of naming the map's room
        why = room_misfit(self.kind, self.slots, need, f"map {match.spec.name!r} has")
        if match.n == self.n_tanks and why:
            raise CheckpointError(
                f"{self.source}: {'; '.join(why)}"
                + (f" (it fits maps like those of {self.trained_as})" if self.trained_as
                   else ""))
        bank, row = self._row(match, seat, per_match.get(seat), max(self.slots[0], need[0]))
        bank.owners[row] = weakref.ref(match)
        num_seats = getattr(learner, "num_seats", None)  # learners with seat ids (MAPPO)
        sid = None if num_seats is None else self.seat_id(match, seat, name, num_seats)
        per_match[seat] = _SeatState(learner, bank, row, np.random.default_rng(seed), sid,
                                     NOOP.copy())
        bank.batch.set_static(row, match)
        bank.batch.gather(row, match)
        bank.builder.set_static(row)

    @property
    def setting(self) -> tuple[Any, ...]:
        """What the observations depend on besides the match: kind, team flags, slots."""
        return (self.kind, self.team_flags, *self.slots)

    def act(self, match: Any, seat: int) -> np.ndarray:
        return self.act_batch(((match, seat),))[0]

    def act_batch(self, pairs: Sequence[tuple[Any, int]],
                  observe: Observe | None = None) -> np.ndarray:
        """Actions (k, 3) of ``pairs`` (match, seat): the held action between decisions,
        else the observations from ``observe`` (or one build per bank of our own) and one
        forward pass per learner."""
        out = np.empty((len(pairs), 3), dtype=np.int64)
        due: list[tuple[int, _SeatState]] = []
        for i, (match, seat) in enumerate(pairs):
            if not match.alive[seat]:
                out[i] = NOOP
                continue
            st = self._seats[match][seat]
            if match.tick % self.repeat:  # between decisions: the action trained as held
                out[i] = st.held
                continue
            due.append((i, st))
        if due:
            self._decide(pairs, due, out, observe)
        return out

    def _observations(self, pairs: Sequence[tuple[Any, int]],
                      due: list[tuple[int, _SeatState]], observe: Observe | None
                      ) -> np.ndarray:
        """The observations (len(due), obs_dim) of the pairs due to decide."""
        if observe is not None:
            x = observe(self.setting, self.obs_dim, np.array([i for i, _ in due]))
            if x is not None:
                return x
        banks: dict[int, Any] = {}
        for i, st in due:
            st.bank.batch.gather(st.row, pairs[i][0])
            banks[id(st.bank)] = st.bank
        built = {k: bank.builder.build() for k, bank in banks.items()}
        return np.stack([built[id(st.bank)][st.row, 0] for _, st in due])

    def _decide(self, pairs: Sequence[tuple[Any, int]], due: list[tuple[int, _SeatState]],
                out: np.ndarray, observe: Observe | None) -> None:
        obs = self._observations(pairs, due, observe)
        groups: dict[int, list[tuple[int, int, _SeatState]]] = {}
        for k, (i, st) in enumerate(due):
            groups.setdefault(id(st.learner), []).append((k, i, st))
        for group in groups.values():
            learner = group[0][2].learner
            x = obs[[k for k, _, _ in group]]
            rng = GameStreams([st.rng for _, _, st in group], 1)
            if group[0][2].sid is None:
                acts = learner.policy_actions(x, self.deterministic, rng)
            else:
                acts = learner.policy_actions(x, self.deterministic, rng,
                                              seat=np.array([st.sid for _, _, st in group]))
            for (_, i, st), a in zip(group, acts, strict=True):
                st.held[:] = a
                out[i] = a


class LivePolicy(NetworkPolicy):
    """In-memory learners of a running training (videos, evaluation during training)."""

    def __init__(self, learners: dict[str, Any], observation: dict[str, Any],
                 learner: str | None = None):
        super().__init__(observation, list(learners), learner, False, "training")
        self.learners = learners

    def get_learner(self, name: str) -> Any:
        return self.learners[name]


class CheckpointPolicy(NetworkPolicy):
    """A checkpoint's learners as a Policy (all weights loaded and checked up front)."""

    def __init__(self, ckpt: Checkpoint, deterministic: bool = False):
        super().__init__(ckpt.meta["observation"], ckpt.learner_names(), None, deterministic,
                         str(ckpt.path), ckpt.trained_as, ckpt.trained_teams)
        self.ckpt = ckpt
        self.learners = {name: ckpt.load_learner(name, weights_only=True)
                         for name in ckpt.learner_names()}

    def get_learner(self, name: str) -> Any:
        return self.learners[name]

    def __repr__(self) -> str:
        return f"CheckpointPolicy({str(self.ckpt.path)!r}, learners={list(self.learners)})"


def load_policy(path: str | Path, deterministic: bool = False) -> CheckpointPolicy:
    """A checkpoint (directory, or a run directory's latest) as a Policy for any seat."""
    return CheckpointPolicy(load_checkpoint(path), deterministic)


# ---- the line-up's "checkpoint" and "agent" controller kinds (alphatank.game.seats) ----

def checkpoint_seat(seat: Any, seed: int | None = None) -> CheckpointPolicy:
    """The controller of a ``checkpoint`` seat: the checkpoint at ``seat.path``."""
    return load_policy(seat.path)


def agent_seat(seat: Any, seed: int | None = None) -> CheckpointPolicy:
    """The controller of an ``agent`` seat: the shipped agent ``seat.agent``."""
    return load_policy(agent_path(seat.agent))


def check_checkpoint_seat(seat: Any) -> tuple[str, str] | None:
    """A ``checkpoint`` seat's problem as (key, message), or None: ``path`` must be a
    checkpoint folder or a run folder with a ``latest`` save (weights are not loaded)."""
    try:
        resolve_checkpoint_dir(seat.path)
    except CheckpointError as exc:
        return "path", str(exc)
    return None

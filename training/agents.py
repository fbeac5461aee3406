"""Shipped agents: trained checkpoints that come with the package
(``alphatank/data/agents/<NAME>/``) and load by name wherever a checkpoint does
(``agent:NAME`` seats, ``alphatank eval agent:NAME``, ``--init-from agent:NAME``).

An agent folder is a checkpoint folder stripped to what inference and warm starts need:
``meta.json`` (with an ``agent`` record: where it came from, its training budget and its
evaluation) and one ``<learner>.pt`` per learner. :func:`export_agent` writes to each only
what the learner's ``load_state_dict(weights_only=True)`` reads
(:func:`~alphatank.training.learners.inference_state`): no optimiser, target network,
generator or reward scaling states. The shipped agents were exported before it dropped the
rest: their files also carry the learner's update count ``updates`` (and the ``league``
agent's ``anchor``, the starting policy its ``anchor_kl`` pulled towards), which loading
does not read. It loads with ``torch.load(weights_only=True)`` like any checkpoint; it
cannot be resumed (``alphatank train --resume`` needs the optimiser), but a new run can
start from it with ``--init-from agent:NAME``.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path
from typing import Any

from alphatank.errors import InputError
from alphatank.files import missing_folders, remove_empty_folders, temp_name
from alphatank.training.checkpoint import _sha256, _torch_save, load_checkpoint
from alphatank.training.learners import inference_state


def export_agent(source: str | Path, dest: str | Path, record: dict[str, Any] | None = None
                 ) -> Path:
    """Write the checkpoint at ``source`` (a checkpoint or run folder) as an agent folder
    ``dest``; ``record`` (description, evaluation, commands, ...) is stored as
    ``meta["agent"]`` beside the source's progress. An existing ``dest`` is replaced only
    if it is an agent folder holding nothing but the agent's files (InputError otherwise:
    nothing else is ever deleted)."""
    ckpt = load_checkpoint(source)
    dest = Path(dest)
    if dest.exists():
        meta = _agent_meta(dest)
        if meta is None:
            raise InputError(f"{dest}: exists and is not an agent folder (no meta.json with "
                             f"an 'agent' record); give a new folder or an agent folder to "
                             f"replace")
        files = meta.get("files")
        own = {"meta.json", *(files if isinstance(files, dict) else ())}
        others = sorted(p.name for p in dest.iterdir() if p.name not in own)
        if others:
            raise InputError(f"{dest}: an agent folder that also holds {', '.join(others)}, "
                             f"which replacing it would delete; move them out or give "
                             f"another folder")
    # every learner file read and checked before anything is written
    states = {spec.name: inference_state(spec.algo, ckpt.state(spec.name))
              for spec in ckpt.learner_specs}
    tmp = dest.with_name(temp_name(dest.name))
    made = missing_folders(dest.parent)
    if tmp.exists():
        shutil.rmtree(tmp)
    try:
        tmp.mkdir(parents=True)
        files = {}
        for name, state in states.items():
            _torch_save(state, tmp / f"{name}.pt")
            files[f"{name}.pt"] = _sha256(tmp / f"{name}.pt")
        meta = {k: v for k, v in ckpt.meta.items() if k not in ("windows", "wandb_id", "files")}
        meta["agent"] = {"source": str(ckpt.path), "progress": ckpt.meta.get("progress", {}),
                         **(record or {})}
        meta["files"] = files
        (tmp / "meta.json").write_text(json.dumps(meta, indent=1) + "\n", encoding="utf-8")
    except BaseException as exc:  # a failed or aborted export leaves nothing behind
        shutil.rmtree(tmp, ignore_errors=True)
        remove_empty_folders(made)
        if isinstance(exc, OSError):  # disk full, folder not writable
            raise OSError(f"{dest}: the agent folder cannot be written "
                          f"({exc.strerror or exc}); nothing was changed") from None
        raise
    old = dest.with_name(temp_name(dest.name, kind="old"))
    if dest.exists():
        os.replace(dest, old)  # kept until the new folder is in place
    try:
        os.replace(tmp, dest)
    except OSError:
        if old.exists():
            os.replace(old, dest)
        raise
    shutil.rmtree(old, ignore_errors=True)
    return dest


def _agent_meta(path: Path) -> dict[str, Any] | None:
    """The meta.json of ``path`` if it is a folder that :func:`export_agent` wrote."""
    try:
        meta = json.loads((path / "meta.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return meta if isinstance(meta, dict) and isinstance(meta.get("agent"), dict) else None


def agent_summary(path: str | Path) -> dict[str, Any]:
    """Name, scenario, learners, training seed, steps and time, and the recorded
    evaluation of an agent folder (for ``alphatank agents``)."""
    ckpt = load_checkpoint(path)
    rec = ckpt.meta.get("agent", {})
    prog = rec.get("progress", ckpt.meta.get("progress", {}))
    return {"name": Path(path).name, "scenario": ckpt.meta["scenario"].get("name", "?"),
            "learners": ", ".join(f"{s.name} ({s.algo})" for s in ckpt.learner_specs),
            "seed": ckpt.train_config.seed, "steps": int(prog.get("global_step", 0)),
            "elapsed_s": float(prog.get("elapsed", 0)),
            "description": rec.get("description", ""), "eval": rec.get("eval", {})}

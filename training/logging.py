"""Run logging: wandb (offline by default, files under the run folder, no account needed),
optional TensorBoard, and always a plain ``metrics.jsonl`` the learning-curve plot reads.

Metric names follow the house convention: ``charts/*``, ``losses/*``, ``eval/*``.

A resumed run continues from its checkpoint's step, so rows logged after it (by a run
that crashed or was killed before its next save) are rewound: ``metrics.jsonl`` is
rewritten without them (atomically) and TensorBoard hides them (``purge_step``).
"""

from __future__ import annotations

import io
import json
import math
import os
from pathlib import Path
from typing import IO, Any

import numpy as np

from alphatank.errors import InputError, MissingPackageError, one_line
from alphatank.files import read_text, write_atomic, write_text_atomic
from alphatank.training.presets import WANDB_MODES


class RunLogger:
    """Fans metrics out to wandb, TensorBoard and ``<run_dir>/metrics.jsonl``."""

    def __init__(self, run_dir: str | Path, config: dict[str, Any], name: str,
                 wandb_mode: str = "offline", project: str = "alphatank",
                 tensorboard: bool = False, run_id: str | None = None,
                 resume_step: int | None = None):
        """``resume_step``: the step of the checkpoint a resumed run continues from (rows
        logged after it are rewound; :attr:`rewound` counts them); None for a fresh run,
        which starts ``metrics.jsonl`` afresh (rows there, of a run killed before its first
        save, belong to no checkpoint)."""
        if wandb_mode not in WANDB_MODES:
            raise ValueError(f"wandb mode must be one of {WANDB_MODES}, got {wandb_mode!r}")
        if tensorboard:  # before anything is created for the run
            try:
                from torch.utils.tensorboard import SummaryWriter
            except ImportError:
                raise MissingPackageError(
                    "TensorBoard logging needs the 'tensorboard' package: pip install "
                    "tensorboard (or run without --tensorboard)") from None
        self.run_dir = Path(run_dir)
        self.run_dir.mkdir(parents=True, exist_ok=True)
        self.rewound = (rewind_metrics(self.run_dir / "metrics.jsonl", resume_step)
                        if resume_step is not None else 0)
        self._jsonl: IO[str] | None = None
        self.wandb_run = None
        self.run_id = run_id
        self.tb = None
        try:
            if wandb_mode != "disabled":
                import wandb
                from pydantic import ValidationError
                os.environ.setdefault("WANDB_SILENT", "true")
                try:
                    self.wandb_run = wandb.init(
                        project=project, name=name, dir=str(self.run_dir), mode=wandb_mode,
                        config=config, id=run_id, resume="allow" if run_id else None,
                        reinit=True)
                except wandb.errors.Error as exc:  # e.g. online without `wandb login`
                    raise InputError(f"wandb {wandb_mode}: {one_line(exc)} (--wandb "
                                     "offline logs without an account)") from None
                except ValidationError as exc:  # a setting wandb cannot read, e.g. WANDB_MODE
                    raise InputError(f"wandb {wandb_mode}: {unreadable_setting(exc)}"
                                     ) from None
                self.run_id = self.wandb_run.id
            if tensorboard:
                self.tb = SummaryWriter(str(self.run_dir / "tensorboard"), purge_step=None
                                        if resume_step is None else resume_step + 1)
            # last: a run that wandb refused leaves no metrics file behind
            mode = "w" if resume_step is None else "a"
            self._jsonl = open(self.run_dir / "metrics.jsonl", mode, encoding="utf-8")  # noqa: SIM115
        except BaseException:  # wandb or TensorBoard failed: close what was opened
            self.close()
            raise

    def log(self, metrics: dict[str, float], step: int) -> None:
        clean = {k: float(v) for k, v in metrics.items()
                 if isinstance(v, int | float) and math.isfinite(float(v))}
        self._jsonl.write(json.dumps({"step": int(step), **clean}) + "\n")
        self._jsonl.flush()
        if self.wandb_run is not None:
            self.wandb_run.log(clean, step=int(step))
        if self.tb is not None:
            for k, v in clean.items():
                self.tb.add_scalar(k, v, int(step))

    def video(self, path: str | Path, step: int) -> None:
        """Attach an MP4 already written to disk (as ``media/match``)."""
        if self.wandb_run is not None:
            import wandb
            self.wandb_run.log({"media/match": wandb.Video(str(path), format="mp4")},
                               step=int(step))

    def close(self) -> None:
        if self._jsonl is not None:
            self._jsonl.close()
        if self.wandb_run is not None:
            self.wandb_run.finish()
            self.wandb_run = None
        if self.tb is not None:
            self.tb.close()


def unreadable_setting(exc: Any) -> str:
    """What wandb could not read in its settings (``exc``: pydantic's ValidationError),
    naming the ``WANDB_*`` environment variable that gave it: wandb reads them whatever
    the mode ``wandb.init`` is given."""
    err = exc.errors()[0]
    field, given = ".".join(map(str, err["loc"])), err.get("input")
    var = f"WANDB_{field.upper()}"
    if os.environ.get(var) != given:
        var = next((k for k, v in os.environ.items() if k.startswith("WANDB_") and v == given),
                   "")
    where = (f"the environment's {var}={given!r}" if var
             else f"wandb's setting {field} = {given!r}")
    return (f"{where}: {one_line(err['msg'])}; unset it or give it a value wandb takes (or "
            "train with --wandb disabled)")


def rewind_metrics(path: str | Path, step: int) -> int:
    """Drop the rows of a ``metrics.jsonl`` logged after ``step`` (and a line cut short by
    a crash), rewriting the file atomically; returns how many rows were dropped.
    ValueError naming the file for one that is not UTF-8 text (left as it is)."""
    path = Path(path)
    if not path.is_file():
        return 0
    keep, dropped = [], 0
    for line in io.StringIO(read_text(path), newline=None):  # lines as open() reads them
        try:
            row = json.loads(line)
        except json.JSONDecodeError:
            row = None
        if isinstance(row, dict) and isinstance(row.get("step"), int) and row["step"] <= step:
            keep.append(line if line.endswith("\n") else line + "\n")
        elif line.strip():
            dropped += 1
    if dropped:
        write_text_atomic(path, "".join(keep))
    return dropped


def read_metrics(run_dir: str | Path) -> list[dict[str, float]]:
    """Rows of ``metrics.jsonl`` (empty if the run logged nothing yet): those
    :func:`rewind_metrics` keeps, JSON objects with an int ``step``; a last line cut short
    by a crash and rows not logged here (no ``step``) are skipped. ValueError naming the
    file for one that is not UTF-8 text, and the line for one before the last that is not
    JSON, or a row with a value that is not a number (a damaged file)."""
    path = Path(run_dir) / "metrics.jsonl"
    if not path.is_file():
        return []
    lines = read_text(path).split("\n")
    rows = []
    for n, line in enumerate(lines, 1):
        if not line.strip():
            continue
        try:
            row = json.loads(line)
        except json.JSONDecodeError as exc:
            if n == len(lines):  # no newline after it: cut short while being written
                continue
            raise ValueError(f"{path}, line {n}: not a JSON row ({exc.msg}); a metrics.jsonl "
                             "holds one JSON object per line") from None
        if isinstance(row, dict) and isinstance(row.get("step"), int):
            wrong = next((k for k, v in row.items() if type(v) not in (int, float)), None)
            if wrong is not None:  # what the curves read: numbers, as Logger.log wrote them
                raise ValueError(f'{path}, line {n}: "{wrong}" is not a number, got '
                                 f"{json.dumps(row[wrong])[:40]}; a metrics.jsonl row holds "
                                 "numbers")
            rows.append(row)
    return rows


def save_figure(fig: Any, path: str | Path) -> Path:
    """Write the matplotlib ``fig`` to ``path`` atomically (its format from the suffix, PNG
    without one), so an interrupted save leaves the old picture, never half of one."""
    return write_atomic(path, lambda tmp: fig.savefig(tmp, dpi=110,
                                                      format=Path(path).suffix[1:] or "png"))


def lone_point_marker(points: int) -> dict[str, Any]:
    """Keywords for a plotted line of ``points`` points: a line through a single point
    draws nothing (a run that logged one iteration), so that point gets a marker."""
    return {"marker": "o", "markersize": 4} if points == 1 else {}


def plot_learning_curve(run_dir: str | Path,
                        evals: list[tuple[int, float, float, float]] | None = None) -> Path:
    """``learning_curve.png`` in ``run_dir``: the win rate (last-100-episode window, per
    opponent when there are several; ``eval/win_rate`` points and ``evals`` = (step,
    rate, ci_low, ci_high) with their intervals) and the episode return against env
    steps."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = read_metrics(run_dir)
    out = Path(run_dir) / "learning_curve.png"
    keys = {k for r in rows for k in r}
    per_opp = sorted(k for k in keys if k.startswith("charts/win_rate_vs/"))
    lines = sorted(k for k in keys if k.startswith("charts/win_rate") and
                   not k.startswith("charts/win_rate_vs/"))
    if len(per_opp) > 1:
        lines += per_opp
    fig, (ax_w, ax_r) = plt.subplots(1, 2, figsize=(11, 4))
    for key in lines:
        pts = [(r["step"], r[key]) for r in rows if key in r]
        ax_w.plot(*zip(*pts, strict=True), label=key.replace("charts/", "train "), lw=1.2,
                  **lone_point_marker(len(pts)))
    points = [(r["step"], r["eval/win_rate"], r["eval/win_ci_low"], r["eval/win_ci_high"])
              for r in rows if "eval/win_rate" in r] + list(evals or [])
    if points:
        x, y, lo, hi = (np.array(v) for v in zip(*points, strict=True))
        ax_w.errorbar(x, y, yerr=[y - lo, hi - y], fmt="o", color="black", capsize=3,
                      markersize=4, label="evaluation (Wilson 95%)")
    for key in sorted(k for k in keys if k.startswith("charts/episode_return")):
        pts = [(r["step"], r[key]) for r in rows if key in r]
        ax_r.plot(*zip(*pts, strict=True), label=key.replace("charts/", ""),
                  **lone_point_marker(len(pts)))
    ax_w.set(xlabel="env steps", ylabel="win rate", ylim=(-0.02, 1.02), title="Win rate")
    ax_r.set(xlabel="env steps", ylabel="return", title="Episode return (last 100)")
    for ax in (ax_w, ax_r):
        ax.grid(alpha=0.3)
        if ax.lines:
            ax.legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, out)
    plt.close(fig)
    return out

"""Figures from runs' ``metrics.jsonl``: learning curves (win rate and return against env
steps and wall time, one line per run and learner), a grid of curves per experiment row,
and the heatmap of a trained-against x evaluated-against table.

Every function returns the matplotlib Figure (closed after saving when ``out`` is given;
tests inspect its axes and lines) and uses the Agg backend: no display needed.
"""

from __future__ import annotations

import math
import textwrap
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from alphatank.training.logging import lone_point_marker, read_metrics, save_figure


def _pyplot() -> Any:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def _steps_axis(ax: Any) -> None:
    """Env steps in k / M (``800k``, ``1.2M``) so that the tick labels of a narrow panel
    do not run into each other."""
    from matplotlib.ticker import EngFormatter
    ax.xaxis.set_major_formatter(EngFormatter(sep=""))


def _wrapped(text: str, width: int) -> str:
    """``text`` broken into lines of at most ``width`` characters (a long row title
    would otherwise overlap its neighbour's)."""
    return "\n".join(textwrap.wrap(text, width)) if text else text


def learner_series(run_dir: str | Path) -> dict[str, dict[str, np.ndarray]]:
    """Per learner (``""`` for a single-learner run): arrays ``step``, ``minutes``,
    ``win_rate`` and ``return`` over the run's logged iterations."""
    rows = read_metrics(run_dir)
    if not rows:
        raise ValueError(f"{run_dir}: no metrics.jsonl with logged iterations (not a run "
                         f"folder, or the run has not finished an iteration)")
    keys = sorted({k for r in rows for k in r if k == "charts/win_rate"
                   or (k.startswith("charts/win_rate/"))})
    out: dict[str, dict[str, np.ndarray]] = {}
    for key in keys:
        name = key[len("charts/win_rate/"):] if "/" in key[len("charts/"):] else ""
        ret_key = "charts/episode_return" + (f"/{name}" if name else "")
        pts = [r for r in rows if key in r]
        out[name] = {"step": np.array([r["step"] for r in pts], dtype=float),
                     "minutes": np.array([r.get("charts/elapsed_s", np.nan) for r in pts]) / 60,
                     "win_rate": np.array([r[key] for r in pts]),
                     "return": np.array([r.get(ret_key, np.nan) for r in pts])}
    if not out:
        raise ValueError(f"{run_dir}: its metrics hold no win rate yet (no episode finished)")
    return out


def plot_runs(runs: Sequence[str | Path], out: str | Path | None = None,
              labels: Sequence[str] | None = None) -> Any:
    """Win rate and episode return (last-100-episode windows) against env steps and wall
    time, one line per run and learner."""
    if labels is not None and len(labels) != len(runs):
        raise ValueError(f"{len(labels)} labels for {len(runs)} runs")
    series = [(labels[i] if labels else Path(r).name, learner_series(r))
              for i, r in enumerate(runs)]
    plt = _pyplot()
    fig, axes = plt.subplots(2, 2, figsize=(12, 7.5), squeeze=False)
    for label, per_learner in series:
        for name, s in per_learner.items():
            tag = f"{label} {name}".strip()
            style = {"lw": 1.2, "label": tag, **lone_point_marker(len(s["step"]))}
            for row, metric in enumerate(("win_rate", "return")):
                axes[row][0].plot(s["step"], s[metric], **style)
                axes[row][1].plot(s["minutes"], s[metric], **style)
    for row, metric in enumerate(("win rate", "episode return")):
        for col, xlabel in enumerate(("env steps", "wall time (minutes)")):
            ax = axes[row][col]
            ax.set(xlabel=xlabel, ylabel=metric, title=f"{metric} (last 100 episodes)")
            if row == 0:
                ax.set_ylim(-0.02, 1.02)
            if col == 0:
                _steps_axis(ax)
            ax.grid(alpha=0.3)
    axes[0][0].legend(fontsize=7)
    fig.tight_layout()
    return _save(fig, out)


def plot_row_curves(groups: Sequence[tuple[str, Sequence[str | Path]]],
                    out: str | Path | None = None, title: str = "") -> Any:
    """One panel per experiment row: the training win rate of each of its runs (seeds)
    against env steps."""
    plt = _pyplot()
    n = max(1, len(groups))
    cols = min(3, n)
    rows = math.ceil(n / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.6 * cols, 3.2 * rows), squeeze=False)
    for k, (label, runs) in enumerate(groups):
        ax = axes[k // cols][k % cols]
        for run in runs:
            try:
                per_learner = learner_series(run)
            except ValueError:
                continue
            for name, s in per_learner.items():
                ax.plot(s["step"], s["win_rate"], lw=1.1,
                        label=f"{Path(run).name.rsplit('-', 1)[0]} {name}".strip(),
                        **lone_point_marker(len(s["step"])))
        ax.set(xlabel="env steps", ylabel="win rate", ylim=(-0.02, 1.02))
        ax.set_title(_wrapped(label, 44), fontsize=10)
        _steps_axis(ax)
        ax.grid(alpha=0.3)
        if ax.lines:
            ax.legend(fontsize=6)
    for k in range(len(groups), rows * cols):
        axes[k // cols][k % cols].set_visible(False)
    if title:
        fig.suptitle(_wrapped(title, int(10 * 4.6 * cols)))
    fig.tight_layout()
    return _save(fig, out)


def plot_heatmap(values: np.ndarray, row_labels: Sequence[str], col_labels: Sequence[str],
                 out: str | Path | None = None, title: str = "",
                 paper: np.ndarray | None = None) -> Any:
    """Win rates in percent (rows: trained against, columns: evaluated against; NaN: not
    run), each cell annotated, with the paper's figure under ours where given."""
    v = np.asarray(values, dtype=float)
    if v.shape != (len(row_labels), len(col_labels)):
        raise ValueError(f"values of shape {v.shape} for {len(row_labels)} rows x "
                         f"{len(col_labels)} columns")
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(1.6 * len(col_labels) + 3, 0.6 * len(row_labels) + 1.8))
    im = ax.imshow(np.ma.masked_invalid(v), cmap="viridis", vmin=0, vmax=100, aspect="auto")
    ax.set_xticks(range(len(col_labels)), col_labels, rotation=20, ha="right")
    ax.set_yticks(range(len(row_labels)), row_labels)
    for i in range(v.shape[0]):
        for j in range(v.shape[1]):
            text = "-" if math.isnan(v[i, j]) else f"{v[i, j]:.0f}"
            if paper is not None and not math.isnan(paper[i, j]):
                text += f"\n(paper {paper[i, j]:.0f})"
            dark = math.isnan(v[i, j]) or v[i, j] < 55
            ax.text(j, i, text, ha="center", va="center", fontsize=8,
                    color="white" if dark else "black")
    fig.colorbar(im, ax=ax, label="win rate (%)")
    ax.set(xlabel="evaluated against", ylabel="trained against", title=title)
    fig.tight_layout()
    return _save(fig, out)


def _save(fig: Any, out: str | Path | None) -> Any:
    if out is not None:
        save_figure(fig, out)
        _pyplot().close(fig)
    return fig

"""``alphatank plot`` and the figures of experiment reports (checked on the Figure objects,
not on pixels)."""

import json
import os

import numpy as np
import pytest

from alphatank.cli import main
from alphatank.training.logging import plot_learning_curve, read_metrics
from alphatank.training.plots import plot_heatmap, plot_row_curves, plot_runs


def fake_run(path, learners=("",), n=5, scale=1.0):
    """A run folder whose metrics.jsonl holds ``n`` iterations."""
    path.mkdir(parents=True)
    with open(path / "metrics.jsonl", "w") as f:
        for i in range(1, n + 1):
            row = {"step": 1000 * i, "charts/elapsed_s": 30.0 * i}
            for name in learners:
                sfx = f"/{name}" if name else ""
                row[f"charts/win_rate{sfx}"] = min(1.0, 0.1 * i * scale)
                row[f"charts/episode_return{sfx}"] = float(i)
            f.write(json.dumps(row) + "\n")
    return path


def test_plot_runs_draws_one_line_per_run_and_learner(tmp_path):
    a = fake_run(tmp_path / "a")
    b = fake_run(tmp_path / "b", learners=("ppo_a", "ppo_b"), scale=0.5)
    fig = plot_runs([a, b])
    axes = fig.axes
    assert len(axes) == 4
    for ax in axes:
        assert len(ax.lines) == 3  # run a, and both learners of run b
    steps_ax, time_ax = axes[0], axes[1]
    assert list(steps_ax.lines[0].get_xdata()) == [1000, 2000, 3000, 4000, 5000]
    assert list(time_ax.lines[0].get_xdata()) == [0.5, 1.0, 1.5, 2.0, 2.5]  # minutes
    assert [ln.get_label() for ln in steps_ax.lines] == ["a", "b ppo_a", "b ppo_b"]
    assert steps_ax.get_xlabel() == "env steps" and "wall time" in time_ax.get_xlabel()
    assert axes[2].get_ylabel() == "episode return"


def test_a_run_of_one_iteration_shows_its_point(tmp_path, monkeypatch):
    """A line through a single point draws nothing: the curves of a run that logged one
    iteration (a short demo, a run just started) were empty panels. Its point is marked,
    in every figure; longer runs stay plain lines."""
    import matplotlib.pyplot as plt

    one, five = fake_run(tmp_path / "one", n=1), fake_run(tmp_path / "five")

    def markers(fig):
        return {ln.get_label(): ln.get_marker() for ax in fig.axes for ln in ax.lines}

    assert markers(plot_runs([one, five])) == {"one": "o", "five": "None"}
    assert markers(plot_row_curves([("row", [one, five])])) == {"one": "o", "five": "None"}
    close = plt.close
    monkeypatch.setattr(plt, "close", lambda fig=None: None)  # keep it to look at it
    plot_learning_curve(one)  # the demo's learning_curve.png
    fig = plt.figure(plt.get_fignums()[-1])
    assert markers(fig) == {"train win_rate": "o", "episode_return": "o"}
    close(fig)


def test_plot_command_writes_a_png(tmp_path, capsys):
    runs = [str(fake_run(tmp_path / n)) for n in ("x", "y")]
    out = tmp_path / "curves.png"
    assert main(["plot", *runs, "-o", str(out), "--labels", "first,second"]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert main(["plot", str(tmp_path / "missing"), "-o", str(out)]) == 2
    assert "no such run folder" in capsys.readouterr().err
    (tmp_path / "empty").mkdir()
    assert main(["plot", str(tmp_path / "empty"), "-o", str(out)]) == 2
    assert "metrics.jsonl" in capsys.readouterr().err
    assert main(["plot", *runs, "-o", str(tmp_path / "c.pdf")]) == 2
    assert main(["plot", *runs, "--labels", "only_one"]) == 2


def test_figures_replace_the_file_they_write_whole(tmp_path, capsys):
    """A figure is written beside its file and renamed over it (an interrupted save
    leaves the old picture, not half of one): the old file's other name, a hard link,
    still holds the old picture; its folders are made; the run's figure too."""
    run = fake_run(tmp_path / "run")
    out, other = tmp_path / "curves.png", tmp_path / "kept.png"
    out.write_bytes(b"the old picture")
    os.link(out, other)
    assert main(["plot", str(run), "-o", str(out)]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert other.read_bytes() == b"the old picture"
    curve = run / "learning_curve.png"
    curve.write_bytes(b"the old curve")
    os.link(curve, tmp_path / "old_curve.png")
    assert plot_learning_curve(run) == curve and curve.read_bytes()[:4] == b"\x89PNG"
    assert (tmp_path / "old_curve.png").read_bytes() == b"the old curve"
    plot_runs([run], tmp_path / "new" / "c.png")
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".")) == []
    assert (tmp_path / "new" / "c.png").read_bytes()[:4] == b"\x89PNG"


def test_damaged_metrics_skip_a_cut_line_and_foreign_rows_or_fail_in_one_line(tmp_path,
                                                                            capsys):
    """A crash can cut the last line short, and rows that are not JSON objects with an int
    ``step`` were not logged here: both skipped (as ``rewind_metrics`` drops them). A
    damaged line before the last, or a file that is not text: one line naming the file."""
    run = fake_run(tmp_path / "run", n=3)
    with open(run / "metrics.jsonl", "a") as f:
        f.write('[1, 2]\n{"charts/win_rate": 0.5}\n{"step": "4000"}\n7\n{"step": 4000, "char')
    assert [r["step"] for r in read_metrics(run)] == [1000, 2000, 3000]
    out = tmp_path / "c.png"
    assert main(["plot", str(run), "-o", str(out)]) == 0 and out.is_file()
    capsys.readouterr()
    lines = (run / "metrics.jsonl").read_text().splitlines()
    (run / "metrics.jsonl").write_text("\n".join([lines[0], lines[-1], *lines[1:3]]) + "\n")
    with pytest.raises(ValueError, match=r"metrics\.jsonl, line 2: not a JSON row "):
        read_metrics(run)
    assert main(["plot", str(run), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{run / 'metrics.jsonl'}, line 2: not a JSON row" in err
    (run / "metrics.jsonl").write_bytes(b'{"step": 1000}\n\xff\xfe\x00\x00\n')
    assert main(["plot", str(run), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{run / 'metrics.jsonl'}: not a UTF-8 text file" in err


@pytest.mark.parametrize(("key", "value"), [
    ("charts/win_rate", '"high"'), ("charts/win_rate", "null"), ("charts/win_rate", "[0.5, 1]"),
    ("charts/episode_return", '{"a": 1}'), ("charts/elapsed_s", "true")])
def test_a_logged_row_with_a_value_that_is_not_a_number_fails_in_one_line(tmp_path, capsys,
                                                                         key, value):
    """A logged row (an int ``step``) holds numbers: a string, null, list, object or
    true/false in it names the file, line and key, exit 2, no figure (it was drawn, strings
    as categories, or a traceback or numpy's words)."""
    run = fake_run(tmp_path / "run", n=3)
    with open(run / "metrics.jsonl", "a") as f:
        f.write(f'{{"step": 4000, "charts/win_rate": 0.5, "{key}": {value}}}\n')
    out = tmp_path / "c.png"
    assert main(["plot", str(run), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f'{run / "metrics.jsonl"}, line 4: "{key}" is not a ' \
        f"number, got {value}; a metrics.jsonl row holds numbers" in err, err
    assert not out.exists()


def test_row_curves_and_heatmap(tmp_path):
    runs = [fake_run(tmp_path / f"r-s{s}") for s in range(3)]
    fig = plot_row_curves([("row A", runs), ("row B", runs[:1])])
    visible = [ax for ax in fig.axes if ax.get_visible()]
    assert [len(ax.lines) for ax in visible] == [3, 1]
    long = "2 PPO Agents (shared, full) vs Defensive + Aggressive + 2 Smart Bots"
    fig = plot_row_curves([(long, runs)], title="Table 3: " + "a long table title " * 8)
    ax = fig.axes[0]
    assert ax.get_title().replace("\n", " ") == long
    assert max(map(len, ax.get_title().split("\n"))) <= 44  # wrapped to the panel
    assert fig._suptitle.get_text().count("\n") >= 1
    fig.canvas.draw()
    ticks = [t.get_text() for t in ax.get_xticklabels() if t.get_text()]
    assert "2k" in ticks and "2000" not in ticks  # steps in k / M
    values = np.array([[61.0, np.nan], [20.0, 90.0]])
    paper = np.array([[72.0, 47.0], [np.nan, np.nan]])
    fig = plot_heatmap(values, ["Random Bot", "Cycle"], ["Random", "Aggressive"], paper=paper)
    texts = [t.get_text() for t in fig.axes[0].texts]
    assert texts == ["61\n(paper 72)", "-\n(paper 47)", "20", "90"]
    with pytest.raises(ValueError, match="rows"):
        plot_heatmap(values, ["one"], ["a", "b"])

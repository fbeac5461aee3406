"""The core CLI verbs: maps and bench."""

import functools
import json
import re
import shutil
import signal
import subprocess
import sys
import textwrap
import time

import pytest

from alphatank.cli import main
from alphatank.commands import benchenv
from alphatank.commands.benchfloor import find_floor


def test_maps_lists_shipped_maps(capsys):
    assert main(["maps"]) == 0
    out = capsys.readouterr().out
    for name in ("open", "battlefield", "maze", "arena4", "arena8"):
        assert name in out


def test_maps_gives_sizes_as_rows_x_cols_in_aligned_columns(capsys):
    """ROWSxCOLS, as mapgen.py --size takes it (the list said arena4 was 13x10), and one
    column for the long train_d8/ names (they pushed their rows out of line)."""
    assert main(["maps"]) == 0
    lines = capsys.readouterr().out.splitlines()
    table = [ln for ln in lines if not ln.startswith("folder ")]
    start = table[0].index("rows x cols")
    arena4 = next(ln for ln in table if ln.startswith("arena4 "))
    assert arena4[start:].split()[:4] == ["10", "x", "13", "4"]
    assert {ln.index(" x ", start - 1) for ln in table[1:]} == {start + 4}
    assert main(["maps", "arena4"]) == 0
    assert "maps/arena4.txt: ok, 10 rows x 13 cols of 70 px" in capsys.readouterr().out


def test_maps_validates_files(tmp_path, capsys):
    bad = tmp_path / "bad.txt"
    bad.write_text("#####\n#1x2#\n#####\n")
    assert main(["maps", str(bad), "maze"]) == 2  # every map checked, the bad one named
    out, err = capsys.readouterr()
    assert "maps/maze.txt: ok" in out
    assert err.startswith(f"alphatank maps: error: {bad}:2:3: unknown character 'x';")
    assert len(err.splitlines()) == 1


def test_bench_reports_match_ticks_and_the_floor_ratio(tmp_path, capsys):
    report = tmp_path / "bench.json"
    assert main(["bench", "--ticks", "200", "--repeats", "1", "--json", str(report)]) == 0
    figures = json.loads(report.read_text())
    assert figures["match_1v1_ticks_per_s"] > 0 and figures["match_4v4_ticks_per_s"] > 0
    out = capsys.readouterr().out
    assert "1v1:" in out
    if find_floor(None) is None:  # a checkout without the shared prototype beside it
        assert "no shared/bench/proto found" in out and "match_1v1_over_floor" not in figures
    else:
        for label in ("1v1", "4v4"):
            ratio = figures[f"match_{label}_over_floor"]
            assert 0 < ratio < 100 and figures[f"floor_{label}_us_per_tick"] > 0
            assert f"{ratio:.2f}x the pymunk floor" in out


def test_bench_names_a_wrong_floor_folder(tmp_path, capsys):
    assert main(["bench", "--ticks", "10", "--floor", str(tmp_path)]) == 2
    assert f"error: --floor {tmp_path}: no sim_core.py" in capsys.readouterr().err


def test_bench_env_compares_with_the_floor_given(tmp_path, capsys, monkeypatch):
    """--floor DIR is the yardstick of --env too, not only of the match ticks."""
    proto = find_floor(None)
    if proto is None:
        pytest.skip("no shared/bench/proto beside this checkout to copy")
    given = tmp_path / "proto"
    shutil.copytree(proto, given)
    # the real env bench, on a small workload (one scenario, no worker processes)
    monkeypatch.setattr(benchenv, "env_bench", functools.partial(
        benchenv.env_bench, scenarios=["vs_random"], num_envs=2, steps=5, workers=1,
        repeats=1))
    assert main(["bench", "--ticks", "10", "--repeats", "1", "--env", "--floor",
                 str(given)]) == 0
    env_line = next(x for x in capsys.readouterr().out.splitlines()
                    if x.startswith("references"))
    assert "pymunk floor" in env_line and env_line.endswith(f"({given})")


def test_console_script_runs():
    out = subprocess.run([sys.executable, "-m", "alphatank.cli", "--help"], capture_output=True,
                         text=True, check=True)
    assert "bench" in out.stdout and "maps" in out.stdout


def test_ctrl_c_while_torch_imports_is_raised_once_the_import_is_done():
    """A Ctrl-C raised inside torch's import could abort the process (exit 134, 'terminate
    called after throwing an instance of pybind11::error_already_set': 1 in 40 Ctrl-Cs
    during `import torch` here) or leave torch half-imported. The command line's handler
    holds it until the import is done: one line, status 130, torch whole."""
    script = textwrap.dedent("""
        import os, signal, sys, threading, time
        from alphatank import cli

        def kick():  # Ctrl-C as soon as torch is being imported
            while not cli.torch_importing():
                time.sleep(0.0005)
            os.kill(os.getpid(), signal.SIGINT)

        threading.Thread(target=kick, daemon=True).start()
        rc = cli.main(["eval", "agent:ppo_vs_smart", "--games", "100000"])
        torch = sys.modules.get("torch")
        print(rc, torch is not None and hasattr(torch, "nn"))
    """)
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=120,
                          preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    assert (proc.returncode, proc.stdout, proc.stderr) == (
        0, "130 True\n", "alphatank eval: interrupted\n")


def test_ctrl_c_swallowed_by_a_pymunk_callback_is_raised_again():
    """A KeyboardInterrupt raised inside a C callback (pymunk's collision handlers and
    finalizers, through cffi) was printed as 'Exception ignored' and lost: eval, record
    and play went on. The command line raises it again once out of the callback."""
    script = textwrap.dedent("""
        import os, signal, time
        import pymunk
        from alphatank.cli import ctrl_c_kept

        space = pymunk.Space()
        for x in (0, 3):
            body = pymunk.Body(1, 1)
            body.position = (x, 0)
            space.add(body, pymunk.Circle(body, 5))

        def begin(arbiter, space, data):  # Ctrl-C lands inside pymunk's callback
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.05)

        space.on_collision(begin=begin)
        try:
            with ctrl_c_kept():
                for _ in range(1000):  # about 1 s
                    space.step(0.01)
                    time.sleep(0.001)
        except KeyboardInterrupt:
            print("interrupted")
    """)
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=60,
                          preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    assert (proc.returncode, proc.stdout, proc.stderr) == (0, "interrupted\n", "")


@pytest.mark.parametrize("wait_s", [0.0, 3.0])
def test_ctrl_c_in_a_verb_without_its_own_stop_is_one_line_and_status_130(wait_s):
    """Ctrl-C in the arena: one line, status 130, and the table of the games played
    before it (they were lost: the line said only 'interrupted'). A flag polled every tick
    stops it: a KeyboardInterrupt raised where pymunk frees a space (a cffi callback) was
    swallowed there, and the arena played on."""
    # as from a terminal: a job started in the background by a script ignores SIGINT, and
    # its children inherit that (the Python in them then never sees Ctrl-C)
    proc = subprocess.Popen([sys.executable, "-m", "alphatank.cli", "arena", "--seats",
                             "smart,dodge", "--games", "100000", "--max-steps", "20"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        assert proc.stdout.readline().startswith("arena: 2 seats")  # playing now
        time.sleep(wait_s)  # 20-tick games: many are played in 3 s
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=120)
    finally:
        proc.kill()  # no-op once it has ended; a hung one must not outlive the test
    assert proc.returncode == 130
    played = re.fullmatch(r"alphatank arena: interrupted by SIGINT(?: after (\d+) of 100000 "
                          r"games \(their table above\))?\n", err)
    assert played, err
    if wait_s:
        assert int(played[1]) > 0 and out.startswith("rows: W-D-L")
        # the table's games are the ones the line counts: smart's row holds them all
        smart = next(line for line in out.splitlines() if line.startswith("smart "))
        w, d, loss = map(int, re.search(r"(\d+)-(\d+)-(\d+)", smart).groups())
        assert w + d + loss == int(played[1])

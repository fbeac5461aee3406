"""tools/instructions.py: the per-object split of a real callgrind file, and its bad input."""

import importlib.util
import re
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("instructions_tool",
                                               ROOT / "tools" / "instructions.py")
tool = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(tool)


@pytest.mark.skipif(shutil.which("valgrind") is None, reason="valgrind is not installed")
def test_objects_split_the_whole_count(tmp_path):
    """Every instruction callgrind collected lands in exactly one object: the split sums
    to the total (calls' inclusive costs not counted twice) and names libc by file."""
    out = tmp_path / "callgrind.out"
    run = subprocess.run(["valgrind", "--tool=callgrind", "--cache-sim=no",
                          f"--callgrind-out-file={out}", "/bin/ls", str(ROOT)],
                         capture_output=True, text=True, check=True)
    collected = int(re.search(r"Collected\s*:\s*(\d+)", run.stderr).group(1))
    split = tool.by_object(out)
    assert sum(split.values()) == collected == tool.valgrind_summary(out)["Ir"]
    assert any(name.startswith("libc.so") for name in split)
    assert all("/" not in name for name in split)
    assert split["ls"] > 0


def test_unknown_scenario_lists_the_valid_ones(capsys):
    with pytest.raises(SystemExit) as exc:
        tool.main(["--scenario", "vs_nobody", "--objects"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "'vs_nobody': not a shipped scenario" in err and "vs_smart" in err


def test_floor_child_ticks_the_prototype(monkeypatch):
    """``--floor``'s child run ticks the shared prototype, as floor_ratio.py drives it."""
    from alphatank.commands import benchfloor

    if benchfloor.find_floor(None) is None:
        pytest.skip("no shared/bench/proto above the project")
    ticked = []
    real = benchfloor.floor_us_per_tick
    monkeypatch.setattr(benchfloor, "floor_us_per_tick",
                        lambda *a, **k: ticked.append(a) or real(*a, **k))
    tool.child(tool.FLOOR, 0, 30, None)
    assert len(ticked) == 1 and ticked[0][1:] == (2, 30)


def test_tick_child_ticks_a_bare_match(monkeypatch):
    """``--floor``'s second child run ticks a bare 1v1 match, as ``alphatank bench`` does."""
    from alphatank.commands import benchenv

    ticked = []
    real = benchenv.match_tick_us
    monkeypatch.setattr(benchenv, "match_tick_us",
                        lambda *a, **k: ticked.append((a, k)) or real(*a, **k))
    tool.child(tool.TICK, 0, 30, None)
    assert ticked == [((30,), {"repeats": 1})]


def test_team_scenarios_step_the_engine_and_refuse_one_env(capsys, monkeypatch):
    """A scenario with several learner seats (no Gymnasium id) runs on the engine, every
    learner acting; ``--envs 0`` (one ``gymnasium.make`` env) is refused for it."""
    from alphatank.envs import vector

    stepped = []
    real = vector.VectorMatchEnv.step
    monkeypatch.setattr(vector.VectorMatchEnv, "step",
                        lambda self, a: stepped.append(a.shape) or real(self, a))
    tool.child("team_vs_bot", 2, 3, None)
    assert stepped == [(2, 2, 3)] * (tool.WARMUP + 3)
    with pytest.raises(SystemExit) as exc:
        tool.main(["--scenario", "team_vs_bot", "--envs", "0"])
    assert exc.value.code == 2
    assert "--envs 0" in capsys.readouterr().err


@pytest.mark.skipif(shutil.which("valgrind") is None, reason="valgrind is not installed")
def test_l2_run_reads_cachegrinds_totals_with_this_machines_l2(tmp_path):
    """``--l2``'s geometry is what valgrind simulates as the last level, and the summary
    read back holds the instructions valgrind printed and the three L2 miss counts."""
    size, ways, line = tool.l2_geometry()
    assert size >= 64 * 1024 and size % ways == 0 and ways > 0 and line in (32, 64, 128)
    out = tmp_path / "cachegrind.out"
    run = subprocess.run(["valgrind", "--tool=cachegrind", "--cache-sim=yes",
                          "--branch-sim=no", f"--LL={size},{ways},{line}",
                          f"--cachegrind-out-file={out}", "/bin/ls", str(ROOT)],
                         capture_output=True, text=True, check=True)
    assert f"desc: LL cache: {size} B, {line} B, {ways}-way associative" in " ".join(
        out.read_text().split())  # simulated as given, not the host's L3 valgrind finds
    totals = tool.valgrind_summary(out)
    refs = int(re.search(r"I\s+refs:\s*([\d,]+)", run.stderr).group(1).replace(",", ""))
    assert totals["Ir"] == refs
    assert all(0 <= totals[k] <= totals["Ir"] for k in tool.L2_EVENTS)
    assert totals["DLmr"] <= totals["D1mr"] and totals["DLmr"] > 0


def test_a_cut_valgrind_file_is_named(tmp_path):
    out = tmp_path / "cachegrind.out"
    out.write_text("events: Ir I1mr ILmr Dr D1mr DLmr Dw D1mw DLmw\nfl=x\n")
    with pytest.raises(ValueError, match="cachegrind.out: no summary line"):
        tool.valgrind_summary(out)


def test_l2_and_objects_exclude_each_other(capsys):
    with pytest.raises(SystemExit) as exc:
        tool.main(["--l2", "--objects"])
    assert exc.value.code == 2
    assert "not allowed with argument" in capsys.readouterr().err

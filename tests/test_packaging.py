"""The wheel holds every source and data file of the project, and builds without warnings."""

import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# Source folder -> its place in the installed package (pyproject's package-dir).
PACKAGE_DIRS = {"alphatank": "alphatank", "bots": "alphatank/bots",
                "training": "alphatank/training", "maps": "alphatank/maps"}
SKIP = shutil.ignore_patterns("__pycache__", "*.pyc", "*.egg-info")


def source_files() -> set[str]:
    """Every file of the packaged folders, as its path inside the wheel."""
    out = set()
    for src, dest in PACKAGE_DIRS.items():
        for f in (ROOT / src).rglob("*"):
            if f.is_file() and "__pycache__" not in f.parts and f.suffix != ".pyc":
                out.add(f"{dest}/{f.relative_to(ROOT / src).as_posix()}")
    return out


def test_wheel_holds_every_source_and_data_file(tmp_path):
    tree = tmp_path / "src"
    tree.mkdir()
    for name in ("pyproject.toml", "README.md"):
        shutil.copy2(ROOT / name, tree / name)
    for src in PACKAGE_DIRS:
        shutil.copytree(ROOT / src, tree / src, ignore=SKIP)
    proc = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", str(tree), "--no-deps", "--no-build-isolation",
         "-w", str(tmp_path / "dist")], capture_output=True, text=True, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    log = proc.stdout + proc.stderr
    assert "Warning" not in log, log
    (wheel,) = (tmp_path / "dist").glob("alphatank-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    expected = source_files()
    assert not expected - names, f"missing from the wheel: {sorted(expected - names)}"
    assert {n for n in expected if n.startswith("alphatank/data/agents/")}, "no shipped agents"

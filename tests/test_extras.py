"""The core install (no extras) runs the envs; commands that need an extra name it.

The proof builds a throwaway venv whose site-packages holds only the core dependency
graph of alphatank's installed metadata (Requires-Dist without extras, followed
recursively), linked from this venv, plus the installed alphatank itself; then runs a full
episode and the CLI there in a subprocess.
"""

from __future__ import annotations

import importlib.metadata as md
import os
import re
import subprocess
import sys
import sysconfig
import textwrap
from pathlib import Path

import pytest

from alphatank.extras import EXTRAS, MissingExtraError, install_hint, missing, require

SITE = [Path(sysconfig.get_paths()[k]) for k in ("purelib", "platlib")]


def _norm(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def installed(name: str) -> md.Distribution:
    """The distribution ``name`` from this interpreter's site-packages (not the source
    tree's egg-info that a current directory on sys.path would show)."""
    for dist in md.distributions(path=[str(p) for p in SITE]):
        if _norm(dist.metadata["Name"]) == _norm(name):
            return dist
    raise LookupError(f"{name} is not installed in {SITE}")


def core_closure() -> list[md.Distribution]:
    """alphatank and everything its core requirements pull in (markers other than extras
    are kept: they hold on this machine, which installed them)."""
    seen: dict[str, md.Distribution] = {}
    todo = ["alphatank"]
    while todo:
        name = todo.pop()
        if _norm(name) in seen:
            continue
        dist = seen[_norm(name)] = installed(name)
        for req in dist.requires or []:
            spec, _, marker = req.partition(";")
            if "extra" not in marker:
                todo.append(re.match(r"[A-Za-z0-9._-]+", spec.strip()).group(0))
    return list(seen.values())


def core_venv(root: Path) -> Path:
    """A venv at ``root`` with only the core closure linked into its site-packages."""
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(root)], check=True)
    site = root / "lib" / f"python{sys.version_info.major}.{sys.version_info.minor}" / \
        "site-packages"
    for dist in core_closure():
        tops = {Path(f).parts[0] for f in dist.files or () if not str(f).startswith("..")}
        tops.discard("__pycache__")
        assert tops, f"{dist.metadata['Name']}: no RECORD of installed files"
        for top in tops:
            src = Path(dist.locate_file(top))
            if src.exists() and not (site / top).exists():
                (site / top).symlink_to(src)
    return root / "bin" / "python"


EPISODE = textwrap.dedent("""
    import importlib.util, sys
    import gymnasium as gym
    import numpy as np
    import alphatank.envs
    from alphatank.envs import parallel_env

    assert importlib.util.find_spec("torch") is None, "torch is importable"
    env = gym.make("AlphaTank/VsRandom-v0")
    env.action_space.seed(0)
    env.reset(seed=0)
    steps, done = 0, False
    while not done:
        _, _, term, trunc, info = env.step(env.action_space.sample())
        steps, done = steps + 1, term or trunc
    vec = gym.make_vec("AlphaTank/VsRandom-v0", num_envs=4)
    vec.reset(seed=0)
    for _ in range(50):
        vec.step(np.ones((4, 3), dtype=np.int64))
    team = parallel_env(scenario="team")
    team.reset(seed=0)
    team.step({a: np.ones(3, dtype=np.int64) for a in team.agents})
    assert not any(m in sys.modules for m in ("torch", "wandb", "imageio", "matplotlib"))
    print("episode", steps, info["outcome"])
""")


def test_envs_run_without_any_extra_and_commands_name_the_missing_one(tmp_path):
    python = core_venv(tmp_path / "venv")
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PYTHON", "VIRTUAL_ENV"))}
    env.update(SDL_VIDEODRIVER="dummy", SDL_AUDIODRIVER="dummy", PYGAME_HIDE_SUPPORT_PROMPT="1")

    def run(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run([str(python), *args], cwd=tmp_path, env=env, capture_output=True,
                              text=True, timeout=120)

    out = run("-c", EPISODE)
    assert out.returncode == 0, out.stderr
    assert re.fullmatch(r"episode \d+ (win|loss|draw)\n", out.stdout)
    assert run("-c", "import torch").returncode != 0  # the venv really lacks torch
    assert run("-m", "alphatank.cli", "--help").returncode == 0
    train = run("-m", "alphatank.cli", "train", "--preset", "ppo_vs_aggressive")
    assert train.returncode == 2
    assert train.stderr == ("alphatank train needs the 'train' extra: "
                            "pip install 'alphatank[train]'\n")
    imp = run("-c", "import alphatank.training.ppo")
    assert "alphatank.training needs the 'train' extra (torch, wandb, tqdm, matplotlib, " \
           "openskill not installed): pip install 'alphatank[train]'" in imp.stderr


def test_require_names_the_extra_and_the_feature():
    assert all(missing(extra) == [] for extra in EXTRAS)  # this venv has every extra
    require("train", "anything")
    err = MissingExtraError("video", "MP4 recording", ["imageio_ffmpeg"])
    assert isinstance(err, ImportError) and err.extra == "video"
    assert str(err) == ("MP4 recording needs the 'video' extra (imageio_ffmpeg not "
                        "installed): pip install 'alphatank[video]'")
    assert install_hint("sb3") == "pip install 'alphatank[sb3]'"
    with pytest.raises(ValueError, match="unknown extra 'gpu'; extras: "):
        missing("gpu")

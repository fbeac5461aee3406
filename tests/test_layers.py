"""Imports point down the layers of DESIGN.md: every module of alphatank/, bots/ and
training/ is parsed with ``ast`` and each import (module level, inside functions, under
TYPE_CHECKING) must target its own layer or one the table below allows. Late-resolved
entry-point strings (``"alphatank.bots.registry:seat_bot"``) are data, not imports. The
project's module graph has no import cycle (the old scenarios <-> checkpoint one is gone).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = {"alphatank": "alphatank", "bots": "alphatank.bots",
            "training": "alphatank.training"}

# Bottom first. A layer may import itself and the layers it lists, each of which comes
# earlier in this table; "base" (plain statistics) and the bare package may be imported
# by anyone.
LAYERS: dict[str, tuple[str, ...]] = {
    "base": (),  # statistics, optional-dependency checks, the bad-input error base
    "sim": (),  # config, maps, grid, world, match, episodes, navigation, Policy
    "render": ("sim",),  # renderer, render modes, videos, replays (episode hooks)
    "game": ("sim",),  # scenarios, seats, line-ups, arena, observations, rewards
    "players": ("game", "sim"),  # keyboard seats (the "human" controller kind)
    "envs": ("game", "sim", "render"),  # Gymnasium, PettingZoo, vector env
    "bots": ("sim",),  # policies over match state
    "training": ("envs", "game", "sim", "render", "bots"),
    "tools": ("sim", "render"),  # map generation, lint, editor
    "app": ("game", "sim", "render", "players"),  # the interactive play session
    "cli": ("app", "tools", "training", "bots", "envs", "players", "game", "render", "sim"),
}
LAYER_OF = {  # module prefix -> layer; the longest matching prefix wins
    "alphatank.stats": "base",
    "alphatank.extras": "base",  # optional-dependency checks
    "alphatank.errors": "base",  # InputError, the base of every bad-input error
    "alphatank.files": "base",  # text files in (UTF-8 checks) and out (atomic writes)
    "alphatank.cluster": "base",  # the door to Ray (--ray), an optional dependency
    "alphatank.sim": "sim",
    "alphatank.ui": "render",
    "alphatank.ui.human": "players",
    "alphatank.ui.session": "app",
    "alphatank.game": "game",
    "alphatank.envs": "envs",
    "alphatank.bots": "bots",
    "alphatank.training": "training",
    "alphatank.mapgen": "tools",
    "alphatank.commands": "cli",
    "alphatank.cli": "cli",
}


def layer_of(module: str) -> str | None:
    best = None
    for prefix in LAYER_OF:
        if (module == prefix or module.startswith(prefix + ".")) and (
                best is None or len(prefix) > len(best)):
            best = prefix
    return LAYER_OF[best] if best else None


def project_modules() -> dict[str, Path]:
    out = {}
    for folder, package in PACKAGES.items():
        for path in sorted((ROOT / folder).rglob("*.py")):
            parts = path.relative_to(ROOT / folder).with_suffix("").parts
            name = ".".join((package, *parts)).removesuffix(".__init__")
            out[name] = path
    return out


MODULES = project_modules()


def imports_of(module: str, path: Path) -> list[tuple[int, str]]:
    """(line, imported project module) of every import statement anywhere in the file."""
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(package.split(".")[:len(package.split(".")) - node.level + 1]
                                + ([base] if base else []))
            for a in node.names:
                sub = f"{base}.{a.name}"
                found.append((node.lineno, sub if sub in MODULES else base))
    return [(line, m) for line, m in found if m == "alphatank" or m.startswith("alphatank.")]


def test_the_table_points_down():
    order = list(LAYERS)
    for layer, allowed in LAYERS.items():
        for low in allowed:
            assert order.index(low) < order.index(layer), (layer, low)
    assert set(LAYER_OF.values()) <= set(LAYERS)
    unplaced = [m for m in MODULES if m != "alphatank" and layer_of(m) is None]
    assert not unplaced, f"modules with no layer in LAYER_OF: {unplaced}"


@pytest.mark.parametrize("module", sorted(MODULES))
def test_imports_point_down(module):
    mine = layer_of(module)
    bad = []
    for line, target in imports_of(module, MODULES[module]):
        theirs = layer_of(target)
        if target == "alphatank" or theirs in (mine, "base"):
            continue
        if mine is None or theirs not in LAYERS[mine]:
            bad.append(f"{MODULES[module].relative_to(ROOT)}:{line} imports {target} "
                       f"({mine} -> {theirs})")
    assert not bad, "imports against the layers:\n" + "\n".join(bad)


def test_no_import_cycles():
    graph = {m: sorted({t for _, t in imports_of(m, p) if t in MODULES and t != m})
             for m, p in MODULES.items()}
    state: dict[str, int] = {}  # 1 on the stack, 2 done
    stack: list[str] = []

    def visit(m: str) -> None:
        state[m] = 1
        stack.append(m)
        for t in graph[m]:
            if state.get(t) == 1:
                cycle = stack[stack.index(t):] + [t]
                raise AssertionError("import cycle: " + " -> ".join(cycle))
            if t not in state:
                visit(t)
        stack.pop()
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m)


def test_the_table_sees_function_level_imports():
    """The checker reads imports inside functions too: the old hidden cycle would fail."""
    src = "def f():\n    from alphatank.training.checkpoint import load_policy\n"
    tree = ast.parse(src)
    inner = [n for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)]
    assert inner and inner[0].module == "alphatank.training.checkpoint"
    assert layer_of("alphatank.game.scenarios") == "game"
    assert "training" not in LAYERS["game"]

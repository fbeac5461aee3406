"""Generated parts of the docs match the code (tools/envdocs.py)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

from alphatank.envs.core import MatchSet
from alphatank.game.observe import BLOCK_HELP, FIELD_HELP, OBS_KINDS

ROOT = Path(__file__).resolve().parent.parent
_spec = importlib.util.spec_from_file_location("envdocs", ROOT / "tools" / "envdocs.py")
envdocs = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(envdocs)


def test_environments_doc_holds_the_current_generated_tables():
    text = envdocs.DOC.read_text(encoding="utf-8")
    assert envdocs.regenerate(text) == text, "docs/environments.md is out of date: run " \
        "python tools/envdocs.py"
    assert "<!-- begin generated: observations -->\n`paper`" in text


def test_regenerate_replaces_a_stale_section():
    stale = "x\n<!-- begin generated: observations -->\nold\n<!-- end generated: " \
            "observations -->\ny"
    new = envdocs.regenerate(stale)
    assert "\nold\n" not in new and new.startswith("x\n") and new.endswith("-->\ny")
    for kind in OBS_KINDS:
        assert envdocs.layout("vs_smart", kind).markdown(BLOCK_HELP) in new


@pytest.mark.parametrize("kind", OBS_KINDS)
@pytest.mark.parametrize("scenario", ["vs_smart", "mixed_teams"])
def test_every_block_and_field_is_explained(kind, scenario):
    lay = MatchSet(scenario, 1, observation=kind).obs.layout
    for block, names in lay.slot_fields.items():
        assert block in BLOCK_HELP
        assert all(n in FIELD_HELP for n in names), [n for n in names if n not in FIELD_HELP]

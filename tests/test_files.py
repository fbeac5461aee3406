"""Text files: atomic writes keep the old file whole when a write fails, and the writers
of results (eval --json/--csv) leave no temporary files behind."""

from __future__ import annotations

import json

import pytest

from alphatank.files import read_text, write_text_atomic
from alphatank.training.evaluate import EvalResult, write_csv, write_json


def test_atomic_write_replaces_whole_file_and_creates_folders(tmp_path):
    path = tmp_path / "a" / "b" / "out.txt"
    write_text_atomic(path, "first\n")
    write_text_atomic(path, "second\n")
    assert read_text(path) == "second\n"
    assert [p.name for p in path.parent.iterdir()] == ["out.txt"]


def test_failed_atomic_write_keeps_old_file_and_no_temporary(tmp_path):
    path = tmp_path / "keep.json"
    write_text_atomic(path, '{"ok": 1}\n')
    with pytest.raises(UnicodeEncodeError):
        write_text_atomic(path, "half written \ud800 then fails")
    assert json.loads(read_text(path)) == {"ok": 1}
    assert [p.name for p in tmp_path.iterdir()] == ["keep.json"]


def test_eval_writers_are_atomic_and_readable(tmp_path):
    results = [EvalResult("vs smart", "smart", wins=3, losses=1, draws=1)]
    write_json(results, tmp_path / "r.json")
    write_csv(results, tmp_path / "r.csv")
    rows = json.loads(read_text(tmp_path / "r.json"))
    assert rows[0]["wins"] == 3 and rows[0]["draws"] == 1
    lines = read_text(tmp_path / "r.csv").splitlines()
    assert lines[0].split(",")[0] == next(iter(results[0].as_dict()))
    assert len(lines) == 2 and ",vs smart,smart," in lines[1]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.csv", "r.json"]

"""Text files: atomic writes keep the old file whole when a write fails, and the writers
of results (eval --json/--csv) leave no temporary files behind. Folder locks keep a second
process out of a folder this one holds, and let it in once released."""

from __future__ import annotations

import json
import os
import re
import stat
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

from alphatank.errors import BusyError, InputError
from alphatank.files import (
    FolderLock,
    check_folder,
    check_writable,
    read_text,
    replace_into,
    write_text_atomic,
)
from alphatank.training.evaluate import EvalResult, write_csv, write_json


def test_atomic_write_replaces_whole_file_and_creates_folders(tmp_path):
    path = tmp_path / "a" / "b" / "out.txt"
    write_text_atomic(path, "first\n")
    write_text_atomic(path, "second\n")
    assert read_text(path) == "second\n"
    assert [p.name for p in path.parent.iterdir()] == ["out.txt"]


def test_atomic_write_of_a_name_as_long_as_the_file_system_takes(tmp_path):
    path = tmp_path / ("é" * 125 + ".txt")  # 254 bytes: the temporary name is cut short
    for text in ("first\n", "second\n"):
        write_text_atomic(path, text)
    assert [(p.name, read_text(p)) for p in tmp_path.iterdir()] == [(path.name, "second\n")]


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


@pytest.mark.parametrize("via_link", [False, True])
def test_atomic_write_to_a_pipe_writes_into_it_and_leaves_it_a_pipe(tmp_path, via_link):
    """``--json /dev/stdout`` or ``/dev/null``: no file swapped in for what is not one (as
    root a rename would replace the device itself); a fifo stands in for them here."""
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    target = fifo
    if via_link:  # as /dev/stdout links to the process's output
        target = tmp_path / "stdout"
        target.symlink_to(fifo)
    reader = os.open(fifo, os.O_RDONLY | os.O_NONBLOCK)
    try:
        write_text_atomic(target, '{"ok": 1}\n')
        assert os.read(reader, 100) == b'{"ok": 1}\n'
    finally:
        os.close(reader)
    assert stat.S_ISFIFO(os.stat(fifo).st_mode) and target.is_symlink() == via_link
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted({"pipe", target.name})


def test_atomic_write_through_a_symlink_keeps_the_link_and_fills_its_target(tmp_path):
    """``--json link.json``: a rename onto the link would put a file in its place and
    leave the target as it was (as root, ``/dev/stdout`` itself)."""
    (tmp_path / "real").mkdir()
    target = tmp_path / "real" / "target.json"
    target.write_text("old\n")
    link = tmp_path / "link.json"
    link.symlink_to(Path("real") / "target.json")
    dangling = tmp_path / "new.json"
    dangling.symlink_to(tmp_path / "real" / "made.json")
    write_text_atomic(link, "new\n")
    write_text_atomic(dangling, "made\n")
    assert link.is_symlink() and target.read_text() == "new\n"
    assert dangling.is_symlink() and (tmp_path / "real" / "made.json").read_text() == "made\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["link.json", "new.json", "real"]
    assert sorted(p.name for p in (tmp_path / "real").iterdir()) == ["made.json", "target.json"]


def test_atomic_write_through_a_symlink_to_another_file_system(tmp_path):
    """The temporary file is made beside the link; a target on another file system (here
    /dev/shm) cannot be renamed onto, so it gets a copy beside it first."""
    shm = Path("/dev/shm")
    if not shm.is_dir() or os.stat(shm).st_dev == os.stat(tmp_path).st_dev:
        pytest.skip("needs /dev/shm on a file system of its own")
    with tempfile.TemporaryDirectory(dir=shm) as other:
        target = Path(other) / "target.json"
        target.write_text("old\n")
        link = tmp_path / "link.json"
        link.symlink_to(target)
        write_text_atomic(link, "new\n")
        assert link.is_symlink() and target.read_text() == "new\n"
        assert [p.name for p in Path(other).iterdir()] == ["target.json"]
    assert [p.name for p in tmp_path.iterdir()] == ["link.json"]


def test_output_paths_are_checked_before_the_work(tmp_path):
    (tmp_path / "f.txt").write_text("x")
    os.mkfifo(tmp_path / "pipe")
    check_writable(tmp_path / "new" / "deeper" / "out.json", "--json")  # folders to make
    check_writable(tmp_path / "f.txt", "--json")  # replaced whole
    check_writable(tmp_path / "pipe", "--json")  # written into, as /dev/stdout
    check_folder(tmp_path / "runs" / "more", "--runs")
    with pytest.raises(InputError, match=r"^--json: .*: is a folder"):
        check_writable(tmp_path, "--json")
    with pytest.raises(InputError, match=r"^--json: is empty; give a file name$"):
        check_writable("", "--json")  # not the working folder
    with pytest.raises(InputError, match=r"^--csv: .*f\.txt/out\.csv: .*f\.txt is a file"):
        check_writable(tmp_path / "f.txt" / "out.csv", "--csv")
    with pytest.raises(InputError, match=r"^--runs: .*f\.txt: is a file, not a folder"):
        check_folder(tmp_path / "f.txt", "--runs")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f.txt", "pipe"]  # nothing made


def test_replace_into_swaps_a_regular_file_whole(tmp_path):
    tmp = tmp_path / ".out.tmp"
    tmp.write_bytes(b"new")
    (tmp_path / "out").write_bytes(b"old")
    replace_into(tmp, tmp_path / "out")  # a regular file: swapped whole
    assert (tmp_path / "out").read_bytes() == b"new" and not tmp.exists()


def test_replace_into_a_link_makes_its_targets_folders(tmp_path):
    tmp = tmp_path / ".out.tmp"
    tmp.write_bytes(b"new")
    link = tmp_path / "out.mp4"  # `record -o out.mp4`, a link into a folder not made yet
    link.symlink_to(tmp_path / "videos" / "today" / "out.mp4")
    replace_into(tmp, link)  # before: FileNotFoundError after the whole match
    assert link.is_symlink() and link.read_bytes() == b"new" and not tmp.exists()


def lock_in_another_process(folder) -> str:
    """What a second Python process gets when it tries ``FolderLock(folder)``."""
    code = ("import sys\nfrom alphatank.files import FolderLock\n"
            "from alphatank.errors import BusyError\n"
            "try:\n    FolderLock(sys.argv[1]).acquire()\nexcept BusyError as e:\n"
            "    print('busy:', e)\nelse:\n    print('got it')\n")
    return subprocess.run([sys.executable, "-c", code, str(folder)], capture_output=True,
                          text=True, check=True, timeout=60).stdout.strip()


def test_a_held_folder_lock_keeps_other_processes_out_until_released(tmp_path):
    run = tmp_path / "runs" / "mine"
    outer = FolderLock(run).acquire()
    inner = FolderLock(run).acquire()  # holds in one process nest
    said = lock_in_another_process(run)
    assert said.startswith(f"busy: {run}: pid {os.getpid()} on ") and "wait for it" in said
    inner.release()
    assert lock_in_another_process(run).startswith("busy:")  # the outer hold remains
    outer.release()
    assert lock_in_another_process(run) == "got it"
    with FolderLock(run) as lock:
        assert lock.held and lock_in_another_process(run).startswith("busy:")
    assert not lock.held
    assert not run.exists()  # the lock is a sibling file, gone once released
    assert list(run.parent.iterdir()) == []


def test_a_folder_lock_is_one_lock_however_the_folder_is_named(tmp_path, monkeypatch,
                                                              held_elsewhere):
    """``cd runs/mine && alphatank train --resume .``, ``runs/mine/.``, ``../mine`` and a
    symbolic link to the run all meet the lock of ``runs/mine`` (``.`` made the lock
    ``./..lock`` inside the run, and a link had a lock of its own)."""
    run = tmp_path / "runs" / "mine"
    run.mkdir(parents=True)
    (tmp_path / "link").symlink_to(run)
    with held_elsewhere(run) as pid, monkeypatch.context() as inside:
        inside.chdir(run)
        for name in (".", f"{run}/.", "../mine", tmp_path / "link"):
            with pytest.raises(BusyError, match=f"^{re.escape(str(run))}: pid {pid} on "):
                FolderLock(name).acquire()
    with monkeypatch.context() as inside:
        inside.chdir(run)
        lock = FolderLock(".").acquire()  # taken from inside the run: the same lock
    assert lock.folder == run
    assert lock_in_another_process(tmp_path / "link").startswith(f"busy: {run}: ")
    lock.release()
    assert list(run.iterdir()) == [] and [p.name for p in run.parent.iterdir()] == ["mine"]


def test_a_run_that_another_process_trains_is_refused_in_one_line(tmp_path, capsys,
                                                                  held_elsewhere):
    """``alphatank train`` on a run folder another process holds: exit 2, one line naming the
    folder and the holder, nothing written; once the holder is gone it trains."""
    from alphatank.cli import main

    run = tmp_path / "tiny.toml"
    run.write_text('scenario = "vs_random"\ntotal_steps = 32\nnum_envs = 2\n'
                   'wandb = "disabled"\n[[learners]]\nname = "p"\n[learners.config]\n'
                   'num_steps = 16\nupdate_epochs = 1\n')
    argv = ["train", "--config", str(run), "--runs", str(tmp_path / "runs"), "--no-progress"]
    with held_elsewhere(tmp_path / "runs" / "tiny") as pid:
        assert main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and f"{tmp_path / 'runs' / 'tiny'}: pid {pid} on " in err
        assert not (tmp_path / "runs" / "tiny").exists()
    assert main(argv) == 0
    assert (tmp_path / "runs" / "tiny" / "latest").is_file()


def test_a_file_system_without_locks_warns_and_goes_on(tmp_path, monkeypatch):
    """Some network mounts refuse flock (ENOLCK): training must still run there. The
    refusal cannot be made on this machine's disk, so the system call is replaced."""
    import errno
    import fcntl

    def refuse(*args: object) -> None:
        raise OSError(errno.ENOLCK, "No locks available")

    monkeypatch.setattr(fcntl, "flock", refuse)
    with pytest.warns(UserWarning, match="cannot lock .No locks available"):
        lock = FolderLock(tmp_path / "run").acquire()
    assert lock.held
    lock.release()
    assert list(tmp_path.iterdir()) == []

"""Text files in and out: UTF-8 reading with errors that name the file, and atomic writes
(a temporary sibling, then ``os.replace``), so a reader never sees half a file; and an
exclusive lock on a folder, so two processes never write one run at once.

Every atomic writer finishes with :func:`replace_into`, which writes through a symbolic
link (its target gets the file, the link stays) and never swaps a file in for what is not a
regular file (``--json /dev/stdout``, ``/dev/null``, a pipe): those get the bytes written
into them."""

from __future__ import annotations

import errno
import fcntl
import os
import re
import shutil
import socket
import stat
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import IO, Any

from alphatank.errors import BusyError, InputError


def read_text(path: str | Path, max_bytes: int | None = None, kind: str = "file") -> str:
    """A text file's contents as UTF-8 (a leading byte-order mark dropped); ValueError
    naming the file, and the offset of the first bad byte, for anything else, or when the
    file holds more than ``max_bytes`` (read no further; ``kind`` names what it should be)."""
    try:
        with Path(path).open("rb") as f:
            raw = f.read() if max_bytes is None else f.read(max_bytes + 1)
    except OSError as exc:
        raise ValueError(f"{path}: cannot read: {exc.strerror or exc}") from None
    if max_bytes is not None and len(raw) > max_bytes:
        raise ValueError(f"{path}: over {max_bytes:,} bytes, too large for a {kind}")
    return decode_text(raw, str(path))


def decode_text(raw: bytes, source: str = "<bytes>") -> str:
    """``raw`` decoded as UTF-8 without a byte-order mark; ValueError naming ``source``."""
    try:
        return raw.decode("utf-8").removeprefix("\ufeff")
    except UnicodeDecodeError as exc:
        kind = ("UTF-16" if raw[:2] in (b"\xff\xfe", b"\xfe\xff")
                else "binary" if b"\x00" in raw[:1024] else "not UTF-8")
        raise ValueError(f"{source}: not a UTF-8 text file ({kind}: byte "
                         f"0x{raw[exc.start]:02x} at offset {exc.start}); save it as "
                         "UTF-8") from None


def text_lines(text: str) -> list[str]:
    """``text`` split into lines at ``\\n``, ``\\r\\n`` and ``\\r`` only, as editors number them
    (:meth:`str.splitlines` also breaks at form feeds, ``\\x85``, ``\\u2028`` and more, so the
    line numbers of an error would not be the file's)."""
    lines = re.split(r"\r\n|\r|\n", text)
    return lines[:-1] if lines[-1] == "" else lines


def temp_name(name: str, suffix: str = "", kind: str = "tmp") -> str:
    """The hidden name ``.NAME.KIND-PID[SUFFIX]`` of a file or folder made before it
    replaces ``name`` (``kind`` "old": one kept until then); ``NAME`` is cut short so
    that it fits a file system's 255 bytes."""
    tail = f".{kind}-{os.getpid()}{suffix}"
    room = 255 - 1 - len(tail.encode())
    return f".{name.encode()[:room].decode(errors='ignore')}{tail}"


def write_atomic(path: str | Path, write: Callable[[Path], None], suffix: str = "") -> Path:
    """Make ``path`` by ``write(tmp)`` into a temporary sibling renamed over it, so the file
    is either the old one or the whole new one; creates missing parent folders. ``suffix``
    ends the temporary name, for writers that pick a format from it. Returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(temp_name(path.name, suffix))
    try:
        write(tmp)
        replace_into(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def write_text_atomic(path: str | Path, text: str, newline: str | None = None) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically (:func:`write_atomic`); ``newline``
    as for :func:`open` (``""`` for CSV). Returns the path."""

    def write(tmp: Path) -> None:
        with open(tmp, "w", encoding="utf-8", newline=newline) as f:
            f.write(text)

    return write_atomic(path, write)


def check_writable(path: str | Path, label: str, overwrite: bool = True) -> None:
    """InputError ``label: path: why`` unless a file can be written at ``path`` (missing
    folders are made when it is): asked before a long job whose result would be lost.
    With ``overwrite=False`` an existing file is refused too (the command's ``--force``)."""
    if not str(path):  # Path("") is the working folder
        raise InputError(f"{label}: is empty; give a file name")
    p = Path(path)
    if p.is_dir():
        raise InputError(f"{label}: {path}: is a folder; give a file name in it")
    if p.is_file() and not overwrite:
        raise InputError(f"{label}: {path}: exists (use --force to overwrite)")
    if p.exists() and not p.is_file():  # a device or pipe (/dev/stdout): written into
        if not os.access(p, os.W_OK):
            raise InputError(f"{label}: {path}: is not writable")
        return
    _check_nearest(p.absolute().parent, path, label)


def check_distinct(paths: dict[str, str | Path | None]) -> None:
    """InputError when two of ``paths`` (label -> path; None: not given) name one file
    (relative spellings and links resolved): the later write would destroy the other."""
    seen: dict[Path, str] = {}
    for label, path in paths.items():
        if path is None:
            continue
        key = Path(path).resolve()
        if key in seen:
            raise InputError(f"{seen[key]} and {label} name the same file ({path}): one "
                             "would overwrite the other")
        seen[key] = label


def check_folder(path: str | Path, label: str) -> None:
    """InputError ``label: path: why`` unless ``path`` is a folder, or can be made one,
    that files can be written in."""
    _check_nearest(Path(path).absolute(), path, label)


def _check_nearest(folder: Path, path: str | Path, label: str) -> None:
    existing = next(q for q in (folder, *folder.parents) if q.exists())
    if not existing.is_dir():
        what = "" if existing == Path(path).absolute() else f"{existing} "
        raise InputError(f"{label}: {path}: {what}is a file, not a folder")
    if not os.access(existing, os.W_OK):
        raise InputError(f"{label}: {path}: {existing} is not writable")


def missing_folders(path: str | Path) -> list[Path]:
    """``path`` and its parent folders that do not exist yet, deepest first: what making
    ``path`` would create, for :func:`remove_empty_folders` to undo when a job fails."""
    missing = []
    for folder in (Path(path).absolute(), *Path(path).absolute().parents):
        if folder.exists():
            break
        missing.append(folder)
    return missing


def remove_empty_folders(folders: list[Path]) -> None:
    """Remove those of ``folders`` (deepest first, as :func:`missing_folders` lists them)
    that are empty; one that holds anything is kept, and so are the folders above it."""
    for folder in folders:
        try:
            folder.rmdir()
        except FileNotFoundError:
            continue  # never made
        except OSError:
            return  # holds a file (or cannot be removed)


def replace_into(tmp: str | Path, path: str | Path) -> None:
    """Finish an atomic write: ``os.replace`` the complete temporary file ``tmp`` onto
    ``path``, its symbolic links resolved (a rename onto a link would put a file in the
    link's place and leave its target as it was; the target's missing folders are made, as
    the writer made those of ``path``); a target on another file system gets a
    copy of ``tmp`` beside it renamed over it. Where ``path`` (its links followed) is
    something other than a regular file (a device such as ``/dev/null`` or ``/dev/stdout``,
    a pipe), a rename would put a file in its place (as root, ``/dev/null`` itself), so the
    bytes are copied into it instead and ``tmp`` removed."""
    try:
        mode = os.stat(path).st_mode
    except (FileNotFoundError, NotADirectoryError):
        mode = None
    if mode is None or stat.S_ISREG(mode):
        real = os.path.realpath(path)
        os.makedirs(os.path.dirname(real), exist_ok=True)
        try:
            os.replace(tmp, real)
        except OSError as exc:
            if exc.errno != errno.EXDEV:
                raise
            near = os.path.join(os.path.dirname(real), temp_name(os.path.basename(real)))
            try:
                shutil.copyfile(tmp, near)
                os.replace(near, real)
            finally:
                Path(near).unlink(missing_ok=True)
                Path(tmp).unlink(missing_ok=True)
        return
    try:
        with open(tmp, "rb") as src, open(path, "wb") as dst:
            shutil.copyfileobj(src, dst)
    finally:
        Path(tmp).unlink(missing_ok=True)


_HELD: dict[str, list[Any]] = {}  # lock file -> [open file, holds] of the locks held here


def check_free(folder: str | Path) -> None:
    """:class:`BusyError` at once if another process holds ``folder``'s
    :class:`FolderLock`: a probe, before work that comes ahead of taking the lock; it
    holds nothing after it and makes nothing where no lock file is."""
    lock = FolderLock(folder)
    if os.path.exists(lock.path):
        lock.acquire().release()


class FolderLock:
    """An exclusive lock on ``folder`` (``flock`` on the hidden sibling file
    ``.<name>.lock``, which says who holds it and is removed on release), for as long as
    this object holds it. Another process holding it: :class:`BusyError` naming the folder
    and the holder. Holds within one process nest (the lock goes when the last one is
    released); the operating system drops it when the process ends, however it ends."""

    def __init__(self, folder: str | Path):
        self.folder = Path(folder).resolve()  # one lock however the folder is reached
        self.path = str(self.folder.parent / f".{self.folder.name}.lock")
        self.held = False

    def acquire(self) -> FolderLock:
        if self.held:
            return self
        entry = _HELD.get(self.path)
        if entry is None:
            entry = _HELD[self.path] = [self._lock_file(), 0]
        entry[1] += 1
        self.held = True
        return self

    def _lock_file(self) -> IO[str]:
        """The lock file, open and locked by this process (a file that was removed
        between opening and locking it is opened again)."""
        Path(self.path).parent.mkdir(parents=True, exist_ok=True)
        while True:
            f: IO[str] = open(self.path, "a+", encoding="utf-8")  # noqa: SIM115 (kept open)
            try:
                fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                f.seek(0)
                holder = f.read().strip() or "a process"
                f.close()
                raise BusyError(f"{self.folder}: {holder} is using it (lock "
                                f"{self.path}); wait for it to end or stop it, "
                                "then try again") from None
            except OSError as exc:  # a file system without locks (some network mounts)
                warnings.warn(f"{self.path}: cannot lock ({exc.strerror or exc}); going on "
                              "without: keep other processes out of this folder yourself",
                              stacklevel=3)
                break
            try:
                if os.stat(self.path).st_ino == os.fstat(f.fileno()).st_ino:
                    break
            except FileNotFoundError:
                pass
            f.close()  # its holder released and removed it meanwhile: take the new one
        f.seek(0)
        f.truncate()
        f.write(f"pid {os.getpid()} on {socket.gethostname()}\n")
        f.flush()
        return f

    def release(self) -> None:
        if not self.held:
            return
        self.held = False
        entry = _HELD[self.path]
        entry[1] -= 1
        if not entry[1]:
            del _HELD[self.path]
            Path(self.path).unlink(missing_ok=True)  # while still locked
            entry[0].close()  # closing the file drops the flock

    def __enter__(self) -> FolderLock:
        return self.acquire()

    def __exit__(self, *exc: object) -> None:
        self.release()

    def __del__(self) -> None:
        self.release()

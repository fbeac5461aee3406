"""Text files in and out: UTF-8 reading with errors that name the file, and atomic writes
(a temporary sibling, then ``os.replace``), so a reader never sees half a file."""

from __future__ import annotations

import os
from pathlib import Path


def read_text(path: str | Path) -> str:
    """A text file's contents as UTF-8 (a leading byte-order mark dropped); ValueError
    naming the file, and the offset of the first bad byte, for anything else."""
    try:
        raw = Path(path).read_bytes()
    except OSError as exc:
        raise ValueError(f"{path}: cannot read: {exc.strerror or exc}") from None
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


def write_text_atomic(path: str | Path, text: str, newline: str | None = None) -> Path:
    """Write ``text`` (UTF-8) to ``path`` through a temporary sibling renamed over it, so
    the file is either the old one or the whole new one; creates missing parent folders.
    ``newline`` as for :func:`open` (``""`` for CSV). Returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:
        with open(tmp, "w", encoding="utf-8", newline=newline) as f:
            f.write(text)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path

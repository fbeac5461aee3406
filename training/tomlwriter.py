"""A small TOML writer for the values run files hold (the standard library only reads
TOML): strings, numbers, booleans, lists of those, tables and arrays of tables."""

from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping
from typing import Any

_BARE_KEY = re.compile(r"^[A-Za-z0-9_-]+$")


def _key(key: str) -> str:
    return key if _BARE_KEY.match(key) else json.dumps(key)


def _value(v: Any, where: str) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return f"{v:_}" if abs(v) >= 10_000 else str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):  # JSON's escapes are TOML's, but TOML refuses a raw DEL too
        return json.dumps(v, ensure_ascii=False).replace("\x7f", "\\u007f")
    if isinstance(v, list | tuple):
        return "[" + ", ".join(_value(x, where) for x in v) + "]"
    if isinstance(v, Mapping):
        return "{" + ", ".join(f"{_key(k)} = {_value(x, where)}" for k, x in v.items()) + "}"
    raise TypeError(f"{where}: cannot write {type(v).__name__} {v!r} as TOML")


def _is_table_array(v: Any) -> bool:
    return isinstance(v, list | tuple) and bool(v) and all(isinstance(x, Mapping) for x in v)


def dumps(data: Mapping[str, Any], _path: str = "") -> str:
    """TOML text for ``data``: scalars first, then sub-tables and arrays of tables.
    ``None`` values are skipped (TOML has no null)."""
    lines = [f"{_key(k)} = {_value(v, _path + k)}" for k, v in data.items()
             if v is not None and not isinstance(v, Mapping) and not _is_table_array(v)]
    for k, v in data.items():
        name = f"{_path}{_key(k)}"
        if isinstance(v, Mapping):
            lines += ["", f"[{name}]", dumps(v, name + ".")]
        elif _is_table_array(v):
            for item in v:
                lines += ["", f"[[{name}]]", dumps(item, name + ".")]
    return "\n".join(line for line in lines).strip("\n") + ("\n" if not _path else "")

"""Documented, typed dataclass fields for run settings and hyperparameters.

A field made with :func:`hp` carries a one-line help and its allowed range in its
metadata. :func:`validate` (called from ``__post_init__``) checks every field's type and
range; :func:`build` makes an instance from a mapping (TOML, JSON) and names the bad key;
:func:`parse_value` types a command-line string by the field's type; :func:`describe`
lists the fields for ``alphatank train --list``. Torch-free, so listing and validating
hyperparameters stays cheap.
"""

from __future__ import annotations

import dataclasses
import difflib
import functools
import math
import types
import typing
from collections.abc import Iterable, Mapping
from typing import Any, NamedTuple

from alphatank.errors import InputError

SCALARS = (bool, int, float, str)


class FieldError(InputError, ValueError):
    """A field value is not allowed: ``owner.name problem`` (e.g. ``PPOConfig.gamma must
    be in [0, 1], got 1.5``); :attr:`name` and :attr:`problem` let callers say where."""

    def __init__(self, owner: str, name: str, problem: str):
        super().__init__(f"{owner}.{name} {problem}")
        self.owner, self.name, self.problem = owner, name, problem


def hp(default: Any, help: str, *, gt: float | None = None, ge: float | None = None,
       lt: float | None = None, le: float | None = None,
       choices: tuple[str, ...] | None = None) -> Any:
    """A dataclass field with a one-line ``help`` and bounds (``gt`` = greater than,
    ``ge`` = at least, ...) or ``choices`` for strings. Mutable defaults (dicts, lists)
    are copied per instance; ``dataclasses.MISSING`` makes the field required."""
    meta = {"help": help, "gt": gt, "ge": ge, "lt": lt, "le": le, "choices": choices}
    meta = {k: v for k, v in meta.items() if v is not None}
    if isinstance(default, dict | list):
        return dataclasses.field(default_factory=lambda: type(default)(default), metadata=meta)
    return dataclasses.field(default=default, metadata=meta)


class FieldInfo(NamedTuple):
    """One field for listings: name, type label, default, allowed range, help."""

    name: str
    type: str
    default: Any
    allowed: str
    help: str


@functools.cache
def _hints(cls: type) -> dict[str, Any]:
    return typing.get_type_hints(cls)


def _kind(tp: Any) -> tuple[type | None, bool]:
    """(scalar base type or None for containers, whether None is allowed)."""
    optional = False
    if isinstance(tp, types.UnionType) or typing.get_origin(tp) is typing.Union:
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        optional = len(args) < len(typing.get_args(tp))
        tp = args[0] if len(args) == 1 else None
    if tp in SCALARS:
        return tp, optional
    return None, optional


def type_label(tp: Any) -> str:
    base, optional = _kind(tp)
    if base is None:
        origin = typing.get_origin(tp) or tp
        label = {dict: "table", tuple: "list", list: "list"}.get(origin, str(tp))
    else:
        label = base.__name__
    return f"{label} or none" if optional else label


def a_type(tp: Any) -> str:
    """``"an int"``, ``"a float or none"``: the type label with its article."""
    label = type_label(tp)
    return f"{'an' if label[0] in 'aeiou' else 'a'} {label}"


def allowed(f: dataclasses.Field) -> str:
    """``"> 0"``, ``"in [0, 1]"``, ``"one of a, b"`` or ``""`` from a field's metadata."""
    m = f.metadata
    if "choices" in m:
        return "one of " + ", ".join(m["choices"])
    lo = ("(", m["gt"]) if "gt" in m else ("[", m["ge"]) if "ge" in m else None
    hi = (")", m["lt"]) if "lt" in m else ("]", m["le"]) if "le" in m else None
    if lo and hi:
        return f"in {lo[0]}{lo[1]:g}, {hi[1]:g}{hi[0]}"
    if lo:
        return f"{'>' if lo[0] == '(' else '>='} {lo[1]:g}"
    if hi:
        return f"{'<' if hi[0] == ')' else '<='} {hi[1]:g}"
    return ""


def _in_range(f: dataclasses.Field, v: Any) -> bool:
    m = f.metadata
    return not (("gt" in m and not v > m["gt"]) or ("ge" in m and not v >= m["ge"])
                or ("lt" in m and not v < m["lt"]) or ("le" in m and not v <= m["le"]))


def check_value(cls: type, f: dataclasses.Field, value: Any) -> Any:
    """``value`` typed for field ``f`` of ``cls`` (ints become floats for float fields);
    raises :class:`FieldError` naming the type or range allowed."""
    tp = _hints(cls)[f.name]
    base, optional = _kind(tp)
    owner = cls.__name__
    if value is None:
        if optional:
            return None
        raise FieldError(owner, f.name, f"needs {a_type(tp)}, got None")
    if base is None:
        origin = typing.get_origin(tp) or tp
        if origin is dict and not isinstance(value, dict):
            raise FieldError(owner, f.name, f"needs a table, got {value!r}")
        return value
    accepted = (bool,) if base is bool else (int, float) if base is float else (base,)
    if not isinstance(value, accepted) or (base is not bool and isinstance(value, bool)):
        whole = base is int and isinstance(value, float) and value.is_integer() and \
            abs(value) < 2**53  # TOML reads 2e6 and 2.0 as floats
        hint = (f" (an integer is written without a point or exponent: {int(value):_})"
                if whole else "")
        raise FieldError(owner, f.name, f"needs {a_type(tp)}, got {value!r}{hint}")
    if base is float:
        value = float(value)
        if not math.isfinite(value):  # as the game and reward configs: no NaN or inf
            raise FieldError(owner, f.name, f"must be a finite number, got {value!r}")
    if "choices" in f.metadata and value not in f.metadata["choices"]:
        raise FieldError(owner, f.name, f"must be {allowed(f)}, got {value!r}")
    if base in (int, float) and not _in_range(f, value):
        raise FieldError(owner, f.name, f"must be {allowed(f)}, got {value!r}")
    return value


def validate(obj: Any) -> None:
    """Check (and normalise, on frozen dataclasses too) every field of ``obj``."""
    cls = type(obj)
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        typed = check_value(cls, f, value)
        if typed is not value:
            object.__setattr__(obj, f.name, typed)


def field_map(cls: type) -> dict[str, dataclasses.Field]:
    return {f.name: f for f in dataclasses.fields(cls)}


def did_you_mean(name: Any, valid: Iterable[str]) -> str:
    """``"; did you mean 'total_steps'?"`` when ``name`` is a near miss of one of ``valid``
    (a typo, or another case), else ``""``: the end of an unknown-name error that lists
    the valid ones."""
    if not isinstance(name, str):
        return ""
    lower = {v.lower(): v for v in valid}
    close = difflib.get_close_matches(name.lower(), list(lower), n=1)
    return f"; did you mean {lower[close[0]]!r}?" if close else ""


def build(cls: type, data: Mapping[str, Any], prefix: str = "") -> Any:
    """``cls(**data)`` with unknown keys and bad values reported as ``{prefix}{key}:
    problem`` (``prefix`` e.g. ``"presets/x.toml: learners[0].config."``)."""
    fields = field_map(cls)
    data = dict(data)
    for key, value in data.items():
        if key not in fields:
            raise ValueError(f"{prefix}{key}: unknown key; valid keys: {sorted(fields)}"
                             f"{did_you_mean(key, fields)}")
        base, optional = _kind(_hints(cls)[key])
        if optional and base is not str and isinstance(value, str) and \
                value.lower() in ("none", "null"):  # TOML has no null; as parse_value
            data[key] = None
    try:
        return cls(**data)
    except FieldError as exc:
        raise ValueError(f"{prefix}{exc.name}: {exc.problem}") from None


def parse_value(cls: type, name: str, text: str) -> Any:
    """Command-line text typed by field ``name`` of ``cls`` (``none`` for optional
    fields; ``true/false/1/0/yes/no`` for booleans; ``1e6`` is an int when whole)."""
    tp = _hints(cls)[name]
    base, optional = _kind(tp)
    raw = text.strip()
    if optional and raw.lower() in ("none", "null"):
        return None
    try:
        if base is bool:
            low = raw.lower()
            if low not in ("true", "false", "1", "0", "yes", "no"):
                raise ValueError(raw)
            return low in ("true", "1", "yes")
        if base is int:
            try:
                return int(raw)
            except ValueError:
                x = float(raw)
                if not x.is_integer():
                    raise
                return int(x)
        if base is float:
            return float(raw)
        if base is str:
            return raw
    except ValueError:
        raise FieldError(cls.__name__, name, f"needs {a_type(tp)}, got {raw!r}") from None
    raise FieldError(cls.__name__, name, f"is a {type_label(tp)}; it cannot be set from "
                     f"the command line")


def describe(cls: type) -> list[FieldInfo]:
    """Every field of ``cls`` with its type, default, allowed range and help."""
    out = []
    for f in dataclasses.fields(cls):
        default = (f.default if f.default is not dataclasses.MISSING
                   else f.default_factory() if f.default_factory is not dataclasses.MISSING
                   else None)
        out.append(FieldInfo(f.name, type_label(_hints(cls)[f.name]), default, allowed(f),
                             f.metadata.get("help", "")))
    return out

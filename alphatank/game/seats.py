"""Seats: who sits in one tank, the controller kinds, and the ``--seats`` grammar.

A controller kind is data: its seat-table keys and the entry points (``"module:attribute"``
strings, resolved with importlib on first use, like Gymnasium's entry points) of the
function that makes its controller and of the one that validates its seats. So this layer
never imports ``alphatank.bots``, ``alphatank.training`` or ``alphatank.ui``; a kind's
module is imported only when a seat of that kind is checked or filled.

* ``learner``: no controller, the env's caller (a training run) acts;
* ``bot`` (keys ``bot``, ``weakness``, ``options``): ``alphatank.bots`` (``make_bot``);
* ``human`` (``keys``): ``alphatank.ui.human.KeyboardPolicy``; idles without a keyboard;
* ``checkpoint`` (``path``): ``alphatank.training.checkpoint.load_policy`` of a folder;
* ``agent`` (``agent``): a shipped trained agent, the checkpoint folder
  ``alphatank/data/agents/<NAME>/``.

``register_controller(kind, "package.module:factory")`` adds a kind: ``factory(seat, seed)``
returns a Policy (see :mod:`alphatank.sim.policy`).

``--seats`` grammar (``play``, ``record``; single seats in ``arena``): a comma-separated
list of ``[TEAM=]SEAT``, where SEAT is ``human[:wasd|arrows|ijkl]``, ``learner``,
``checkpoint:PATH``, ``agent:NAME``, ``KIND:ARG`` for a registered kind, or a bot
``[bot:]NAME[:KEY=VALUE...][@WEAKNESS]``. Without ``TEAM=`` seat k gets team A, B, C, ...
(after Z: AA, AB, ...)
"""

from __future__ import annotations

import importlib
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, fields
from importlib import resources
from typing import Any

from alphatank.errors import InputError
from alphatank.extras import MissingExtraError
from alphatank.sim.config import name_problem
from alphatank.sim.policy import NoopPolicy, Policy

KEYSETS = ("wasd", "arrows", "ijkl")  # key layouts of players 1, 2, 3
SEAT_HELP = ("comma-separated seats, each [TEAM=]SEAT; SEAT: human[:wasd|arrows|ijkl], "
             "learner, checkpoint:PATH, agent:NAME, or a bot [bot:]NAME[:KEY=VALUE...]"
             "[@WEAKNESS]; without TEAM= seat k gets its own team A, B, C, ... e.g. "
             "'A=human:wasd,B=smart' or 'A=human,A=smart,B=human:arrows,B=aggressive@0.5'")


class SeatError(InputError, ValueError):
    """A seat description is invalid; the message names the seat, the field and what is
    allowed."""


@dataclass(frozen=True)
class Seat:
    """One tank slot: its team and who controls it (``controller`` is a kind name)."""

    team: str
    controller: str
    bot: str | None = None
    weakness: float = 1.0
    options: dict[str, Any] = field(default_factory=dict)
    keys: str | None = None
    path: str | None = None
    agent: str | None = None

    def describe(self) -> str:
        """Short description, e.g. ``smart(w=0.5)``, ``learner``, ``human:wasd``,
        ``checkpoint:PATH``, ``agent:NAME``."""
        opts = "".join(f",{k}={v}" for k, v in sorted(self.options.items()))
        if self.controller == "bot":
            return f"{self.bot}(w={self.weakness:g}{opts})"
        kind = CONTROLLER_KINDS.get(self.controller)
        arg = getattr(self, kind.arg) if kind is not None and kind.arg else None
        return self.controller + (f":{arg}" if arg else "") + (f"({opts[1:]})" if opts else "")

    def to_dict(self) -> dict[str, Any]:
        """The ``[[seats]]`` table that parses back to this seat."""
        d: dict[str, Any] = {"team": self.team, "controller": self.controller}
        for key in controller_kind(self.controller).keys:
            value = getattr(self, key)
            d[key] = dict(value) if isinstance(value, dict) else value
        return d


SEAT_KEYS = tuple(f.name for f in fields(Seat))


# ---- controller kinds ------------------------------------------------------------------

@dataclass(frozen=True)
class ControllerKind:
    """How seats of one kind are filled.

    ``factory``: entry point of ``factory(seat, seed) -> Policy`` (None: nobody, the
    env's caller drives the seat). ``keys``: the seat-table keys the kind uses besides
    ``team`` and ``controller`` (``keys[0]`` required unless it is ``bot``'s). ``arg``: the
    key that ``KIND:ARG`` fills in ``--seats``. ``parse``: entry point of
    ``parse(text) -> dict`` for the text after ``KIND:`` (instead of ``arg``). ``check``:
    entry point of ``check(seat) -> (key, message) | None``. ``interactive``: needs a
    person at the keyboard; without one the seat idles.
    """

    name: str
    factory: str | None
    keys: tuple[str, ...] = ()
    arg: str | None = None
    parse: str | None = None
    check: str | None = None
    interactive: bool = False


CONTROLLER_KINDS: dict[str, ControllerKind] = {k.name: k for k in (
    ControllerKind("learner", None),
    ControllerKind("bot", "alphatank.bots.registry:seat_bot", ("bot", "weakness", "options"),
                   parse="alphatank.bots.registry:bot_seat_fields",
                   check="alphatank.bots.registry:check_seat_bot"),
    ControllerKind("human", "alphatank.ui.human:keyboard_seat", ("keys",), arg="keys",
                   check="alphatank.game.seats:check_human_seat", interactive=True),
    ControllerKind("checkpoint", "alphatank.training.checkpoint:checkpoint_seat", ("path",),
                   arg="path", check="alphatank.training.checkpoint:check_checkpoint_seat"),
    ControllerKind("agent", "alphatank.training.checkpoint:agent_seat", ("agent",),
                   arg="agent", check="alphatank.game.seats:check_agent_seat"),
)}
_RESOLVED: dict[str, Any] = {}


def register_controller(kind: str, factory: str, *, keys: Sequence[str] = ("path",),
                        arg: str | None = "path", check: str | None = None,
                        interactive: bool = False) -> ControllerKind:
    """Add (or replace) controller kind ``kind``: ``factory`` is a ``"module:attribute"``
    entry point of ``factory(seat, seed) -> Policy``, resolved when a seat of the kind is
    first filled. ``keys`` are the seat fields it reads (from :data:`SEAT_KEYS`)."""
    if not re.fullmatch(r"[a-z][a-z0-9_]*", kind) or kind in ("learner", "bot"):
        raise ValueError(f"kind {kind!r}: a lower-case identifier other than 'learner' and "
                         "'bot' is required")
    for ep in (factory, check):
        if ep is not None and not re.fullmatch(r"[\w.]+:[\w.]+", ep):
            raise ValueError(f"kind {kind!r}: entry point {ep!r} is not 'module:attribute'")
    bad = [k for k in keys if k not in SEAT_KEYS or k in ("team", "controller")]
    if bad or (arg is not None and arg not in keys):
        raise ValueError(f"kind {kind!r}: keys {list(keys)} / arg {arg!r} must come from "
                         f"{list(SEAT_KEYS[2:])}")
    spec = ControllerKind(kind, factory, tuple(keys), arg, None, check, interactive)
    CONTROLLER_KINDS[kind] = spec
    return spec


def controller_kind(name: str) -> ControllerKind:
    kind = CONTROLLER_KINDS.get(name)
    if kind is None:
        raise SeatError(f"unknown controller {name!r}; valid: {list(CONTROLLER_KINDS)}")
    return kind


def plays_by_itself(seat: Seat) -> bool:
    """Whether ``seat`` acts with no one at it: not a learner seat, not a keyboard."""
    return seat.controller != "learner" and not controller_kind(seat.controller).interactive


def resolve(entry_point: str) -> Any:
    """The object an entry point ``"module:attribute"`` names (imported on first use)."""
    obj = _RESOLVED.get(entry_point)
    if obj is None:
        module, _, attr = entry_point.partition(":")
        try:
            obj = importlib.import_module(module)
            for part in attr.split("."):
                obj = getattr(obj, part)
        except MissingExtraError:
            raise  # its message names the pip line that fixes it
        except (ImportError, AttributeError) as exc:
            raise SeatError(f"entry point {entry_point!r} cannot be loaded: {exc}") from None
        _RESOLVED[entry_point] = obj
    return obj


def make_controller(seat: Seat, seed: int | None = None, *,
                    interactive: bool = False) -> Policy | None:
    """The controller of ``seat``: None for a learner seat (the env's caller acts), an
    idle :class:`~alphatank.sim.policy.NoopPolicy` for a human seat when nobody is at the
    keyboard (``interactive=False``), else the kind's factory's Policy."""
    kind = controller_kind(seat.controller)
    if kind.factory is None:
        return None
    if kind.interactive and not interactive:
        return NoopPolicy()
    factory: Callable[[Seat, int | None], Policy] = resolve(kind.factory)
    return factory(seat, seed)


# ---- seat tables (scenario [[seats]] entries) ------------------------------------------

def parse_seat_table(data: Any, where: str = "seat", *, check: bool = True) -> Seat:
    """Validate one ``[[seats]]`` table; SeatError names ``where.key`` and the allowed
    values. The kind's own check (bot names, checkpoint folders, ...) runs here unless
    ``check`` is False (keys and types are checked regardless)."""
    if not isinstance(data, dict):
        raise SeatError(f"{where}: must be a table")
    unknown = sorted(set(data) - set(SEAT_KEYS))
    if unknown:
        raise SeatError(f"{where}.{unknown[0]}: unknown key; valid keys: {list(SEAT_KEYS)}")
    team = data.get("team")
    if not isinstance(team, str) or not team:
        raise SeatError(f"{where}.team: required, a non-empty string like 'A'")
    why = name_problem(team)
    if why:
        raise SeatError(f"{where}.team: {why}")
    name = data.get("controller")
    if name not in CONTROLLER_KINDS:
        raise SeatError(f"{where}.controller: got {name!r}; valid: {list(CONTROLLER_KINDS)}")
    kind = CONTROLLER_KINDS[name]
    allowed = {"team", "controller", *kind.keys}
    extra = sorted(set(data) - allowed)
    if extra:
        raise SeatError(f"{where}.{extra[0]}: not used by a {name!r} seat; its keys: "
                        f"{sorted(allowed)}")
    values = {k: data[k] for k in kind.keys if k in data}
    if name == "human":
        values.setdefault("keys", KEYSETS[0])
    for key in kind.keys:
        _check_type(key, values, where, required=key == kind.keys[0])
    seat = Seat(team, name, **values)
    if check and kind.check is not None:
        problem = resolve(kind.check)(seat)
        if problem is not None:
            key, message = problem
            raise SeatError(f"{where}.{key}: {message}")
    return seat


_HINTS = {"bot": "the bot's name", "keys": f"one of {list(KEYSETS)}",
          "path": "the checkpoint folder", "agent": "a shipped agent's name"}


def _check_type(key: str, values: dict[str, Any], where: str, required: bool) -> None:
    if key not in values:
        if required:
            raise SeatError(f"{where}.{key}: required, {_HINTS.get(key, 'a string')}")
        return
    v = values[key]
    if key == "weakness":
        if isinstance(v, bool) or not isinstance(v, int | float) or not 0.0 <= v <= 1.0:
            raise SeatError(f"{where}.weakness: must be a number in [0, 1], got {v!r}")
        values[key] = float(v)
    elif key == "options":
        if not isinstance(v, dict):
            raise SeatError(f"{where}.options: must be a table of options")
        values[key] = dict(v)
    elif not isinstance(v, str) or not v:
        raise SeatError(f"{where}.{key}: must be a non-empty string "
                        f"({_HINTS.get(key, 'text')}), got {v!r}")


# ---- the --seats grammar ---------------------------------------------------------------

_TEAM = re.compile(r"([A-Za-z0-9_]+)=(.*)", re.S)


def parse_seat_spec(text: str, where: str | None = None) -> dict[str, Any]:
    """One seat without its team, e.g. ``smart:ricochet=false@0.5``, ``human:arrows``,
    ``checkpoint:runs/x``, ``agent:NAME``, as a ``[[seats]]`` table without ``team``
    (validated when the scenario is built)."""
    where = where or f"seat {text!r}"
    body = text.strip()
    head = body.partition("@")[0].partition(":")[0].strip()
    named = CONTROLLER_KINDS.get(head)
    if "@" in body and named is not None and head != "bot" and named.arg != "path":
        raise SeatError(f"{where}: @weakness only applies to bots")
    kind, colon, arg = body.partition(":")
    kind = kind.strip()
    spec = CONTROLLER_KINDS.get(kind)
    if spec is None or kind == "bot":
        bot_text = arg if kind == "bot" else body
        if kind == "bot" and not arg.strip():
            raise SeatError(f"{where}: bot needs a name, e.g. bot:smart")
        try:
            values = resolve(CONTROLLER_KINDS["bot"].parse)(bot_text.strip())
        except ValueError as exc:
            if kind == "bot":
                raise SeatError(f"{where}: {exc}") from None
            kinds = [k for k in CONTROLLER_KINDS if k != "bot"]
            raise SeatError(f"{where}: neither a seat kind ({', '.join(kinds)}) nor a valid "
                            f"bot spec: {exc}") from None
        return {"controller": "bot", **values}
    seat: dict[str, Any] = {"controller": kind}
    arg = arg.strip()
    if spec.parse is not None and colon:
        return {**seat, **resolve(spec.parse)(arg)}
    if colon and spec.arg is None:
        raise SeatError(f"{where}: a {kind!r} seat takes no ':' argument")
    if colon and not arg:
        raise SeatError(f"{where}: {kind}: needs {_HINTS.get(spec.arg, 'an argument')} "
                        f"after ':'")
    if arg:
        seat[spec.arg] = arg
    return seat


def parse_seat_list(text: str) -> list[dict[str, Any]]:
    """The ``[[seats]]`` tables of a ``--seats`` list (see the module docstring); human
    seats without keys get the first of WASD, arrows, IJKL that no other seat names."""
    items = [s.strip() for s in text.split(",") if s.strip()]
    if len(items) < 2:
        raise SeatError(f"--seats needs at least 2 seats, got {text!r}; {SEAT_HELP}")
    seats = []
    for k, item in enumerate(items):
        m = _TEAM.fullmatch(item)
        team, body = (m.group(1), m.group(2)) if m else (seat_team(k), item)
        seat = parse_seat_spec(body, where=f"--seats[{k}] {item!r}")  # seats count from 0
        seats.append({"team": team, **seat})
    humans = [s for s in seats if s["controller"] == "human"]
    free = [k for k in KEYSETS if k not in {s.get("keys") for s in humans}]
    for seat in humans:
        if "keys" not in seat:  # with none free, the check of the seats names the clash
            seat["keys"] = free.pop(0) if free else KEYSETS[-1]
    return seats


def seat_team(k: int) -> str:
    """The team of seat ``k`` of a ``--seats`` list without ``TEAM=``: A .. Z, then AA,
    AB, ... (spreadsheet columns)."""
    name = ""
    k += 1
    while k:
        k, r = divmod(k - 1, 26)
        name = chr(ord("A") + r) + name
    return name


def check_human_seat(seat: Seat) -> tuple[str, str] | None:
    """The ``human`` kind's check: a known key layout."""
    if seat.keys not in KEYSETS:
        return "keys", f"got {seat.keys!r}; valid: {list(KEYSETS)}"
    return None


# ---- shipped agents --------------------------------------------------------------------

def agents_root() -> Any:
    """The folder of shipped agents, ``alphatank/data/agents`` (a Traversable)."""
    return resources.files("alphatank").joinpath("data", "agents")


def shipped_agents() -> list[str]:
    """Names of the trained agents shipped in ``alphatank/data/agents/<NAME>/`` (each a
    checkpoint folder: ``meta.json`` plus weights)."""
    root = agents_root()
    if not root.is_dir():
        return []
    return sorted(p.name for p in root.iterdir()
                  if p.is_dir() and p.joinpath("meta.json").is_file())


def agent_path(name: str) -> str:
    """The checkpoint folder of shipped agent ``name``; SeatError lists the shipped ones."""
    names = shipped_agents()
    if name not in names:
        raise SeatError(f"unknown agent {name!r}; shipped agents: "
                        f"{', '.join(names) if names else 'none yet'}")
    return str(agents_root().joinpath(name))


def check_agent_seat(seat: Seat) -> tuple[str, str] | None:
    """The ``agent`` kind's check: the name must be a shipped agent."""
    try:
        agent_path(str(seat.agent))
    except SeatError as exc:
        return "agent", str(exc)
    return None


def checkpoint_source(text: str) -> str:
    """The checkpoint folder an argument names, for commands that need the checkpoint
    itself rather than a Policy (``eval``): ``checkpoint:PATH`` -> PATH, ``agent:NAME`` ->
    the shipped agent's folder; any other text is taken as a path."""
    kind, colon, arg = text.partition(":")
    if colon and kind == "agent":
        return agent_path(arg.strip())
    if colon and kind == "checkpoint":
        if not arg.strip():
            raise SeatError(f"{text!r}: checkpoint: needs the checkpoint folder after ':'")
        return arg.strip()
    return text

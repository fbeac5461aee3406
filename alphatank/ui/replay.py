"""Replays: a match's seed, map, config, seats and every tick's actions in one small file.

A replay re-simulates bit-identically: same GameConfig, same map text, same teams, same
match seed and the same (ticks, n_tanks, 3) int8 actions give the same final state hash
(:meth:`alphatank.sim.match.Match.state_hash`) and the same winner, which the file
stores and :func:`simulate` checks. The bots' planned routes ride along (``routes``), so
a replay's video shows the same path overlay as the original recording.

Files are ``.npz`` archives (``actions``, ``routes`` and a JSON ``meta`` record), written
atomically (temporary file + ``os.replace``) and loaded without pickle. A replay from
someone else is untrusted input: :func:`load_replay` bounds the archive's sizes, checks
the type and range of every meta field (the config through GameConfig's own ranges, and
that its tanks fit the map's cells), caps
the physics work a re-simulation may take (:data:`MAX_SUBSTEPS`, :data:`MAX_BODY_SUBSTEPS`),
and checks ``digest``, a
SHA-256 over the map text, config, seats, teams, actions, routes and recorded outcome
(every meta field and array), so an edit anywhere in the file is caught even where it
would not change the re-simulation.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
import re
import tempfile
import zipfile
import zlib
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from alphatank.errors import InputError
from alphatank.files import replace_into
from alphatank.sim.config import ConfigError, GameConfig, check_value, from_dict, name_problem
from alphatank.sim.episode import Episode, EpisodeHook, EpisodeSeeds
from alphatank.sim.mapspec import MapError, MapSpec, map_text, parse_map
from alphatank.sim.match import Match, TickEvents
from alphatank.sim.policy import NOOP
from alphatank.sim.world import substeps_for

FORMAT = "alphatank-replay"
VERSION = 2  # 2: routes, digest, checked winner (version 1 files: record them again)
_META_KEYS = ("format", "version", "seed", "match_seed", "scenario", "seats", "map_name",
              "map_text", "config", "teams", "labels", "ticks", "final_hash", "winner",
              "digest")
MAX_SUBSTEPS = 5_000_000  # physics substeps a re-simulation may take (ticks x substeps)
# ... and substeps x bodies (each tank and every bullet it may have alive): what
# MAX_SUBSTEPS of a default duel take (2 tanks x (1 + 10 bullets)); a substep of 64 tanks
# with 64 bullets each costs ~200 times one of a duel
MAX_BODY_SUBSTEPS = 110_000_000
MAX_TANKS = 64
LABEL_MAX = 4096  # characters of a seat's description or label (a checkpoint path), of the
# scenario (its name or .toml path) and of the map's name
MAX_META_BYTES = 8 << 20
_MEMBERS = ("actions.npy", "routes.npy", "meta.npy")
MAX_ARRAY_BYTES = 256 << 20
_HEX64 = re.compile(r"[0-9a-f]{64}")
_U64 = (0, 2**64 - 1)


class ReplayError(InputError, ValueError):
    """A replay file is missing, corrupt, or does not re-simulate to its recorded end."""


@dataclass
class Replay:
    """Everything needed to re-simulate one episode."""

    match_seed: int
    map_name: str
    map_text: str
    config: dict[str, Any]
    teams: list[str]
    actions: np.ndarray  # (ticks, n_tanks, 3) int8: rotate, move, fire
    final_hash: str
    winner: str | None = None
    seed: int | None = None  # the episode seed the match seed was derived from
    scenario: str | None = None  # scenario name or source, if the match came from one
    seats: list[str] = field(default_factory=list)  # seat descriptions, e.g. "bot:smart"
    labels: list[str] = field(default_factory=list)  # names drawn over the tanks
    # (ticks, n_tanks, 4) int16: each seat's planned route (start row, col, goal row, col)
    # when its actions of that tick were chosen; -1 where the seat had none.
    routes: np.ndarray | None = None
    source: str = ""  # the file it was loaded from (named in errors); not stored

    @property
    def ticks(self) -> int:
        return int(self.actions.shape[0])

    def game_config(self) -> GameConfig:
        return from_dict(GameConfig, self.config, where="replay config")

    def map_spec(self) -> MapSpec:
        return parse_map(self.map_text, f"<replay map {self.map_name}>", name=self.map_name)

    def new_match(self) -> Match:
        """A fresh Match in the replay's initial state."""
        return Match(self.game_config(), self.map_spec(), self.teams, seed=self.match_seed)

    def policies(self) -> list[ReplayPolicy]:
        """One playback controller per seat (actions and planned routes)."""
        return [ReplayPolicy(self.actions, self.routes) for _ in self.teams]

    def meta(self) -> dict[str, Any]:
        """The JSON record stored beside the arrays (``digest`` included)."""
        meta = {"format": FORMAT, "version": VERSION, "seed": self.seed,
                "match_seed": self.match_seed, "scenario": self.scenario,
                "seats": list(self.seats), "map_name": self.map_name,
                "map_text": self.map_text, "config": self.config, "teams": list(self.teams),
                "labels": list(self.labels), "ticks": self.ticks,
                "final_hash": self.final_hash, "winner": self.winner}
        return {**meta, "digest": content_digest(meta, self.arrays())}

    def arrays(self) -> dict[str, np.ndarray]:
        routes = self.routes
        if routes is None:
            routes = np.full((*self.actions.shape[:2], 4), -1, dtype=np.int16)
        return {"actions": np.ascontiguousarray(self.actions, dtype=np.int8),
                "routes": np.ascontiguousarray(routes, dtype=np.int16)}


def content_digest(meta: dict[str, Any], arrays: dict[str, np.ndarray]) -> str:
    """SHA-256 over every meta field but ``digest`` (canonical JSON) and every array
    (name, dtype, shape, bytes)."""
    h = hashlib.sha256()
    body = {k: v for k, v in meta.items() if k != "digest"}
    h.update(json.dumps(body, sort_keys=True, separators=(",", ":"), default=_plain)
             .encode("utf-8"))
    for name in sorted(arrays):
        arr = np.ascontiguousarray(arrays[name])
        h.update(f"|{name}|{arr.dtype.str}|{arr.shape}|".encode())
        h.update(arr.tobytes())
    return h.hexdigest()


def planned_route(policy: object, match: Match, seat: int) -> tuple[int, int, int, int]:
    """(start row, col, goal row, col) of the path a bot plans to drive, or -1s."""
    own = getattr(policy, "planned_path", None)
    cells = own(match, seat) if callable(own) else None
    if not cells or len(cells) < 2:
        return (-1, -1, -1, -1)
    (r0, c0), (r1, c1) = cells[0], cells[-1]
    return (int(r0), int(c0), int(r1), int(c1))


class ReplayRecorder(EpisodeHook):
    """Collects the actions of one episode, and each seat's planned route (what the path
    overlay draws) from ``policies`` (one per seat; as a hook, the episode's controllers
    unless given). As an episode hook it binds to the episode at ``on_start`` (unless made
    with a ``match``), records every tick and, at ``on_end``, keeps the :class:`Replay` in
    :attr:`replay` and saves it to ``path`` if given. By hand: :meth:`record` each tick's
    actions (before or after ``match.step``) and :meth:`finish` once the episode is
    over."""

    def __init__(self, match: Match | None = None, *, match_seed: int | None = None,
                 seed: int | None = None, scenario: str | None = None,
                 seats: Sequence[str] = (), labels: Sequence[str] = (),
                 path: str | Path | None = None, policies: Sequence[object] | None = None):
        self.match: Match | None = None
        self.match_seed, self.seed = match_seed, seed
        self.scenario, self.seats, self.labels = scenario, list(seats), list(labels)
        self.path = Path(path) if path is not None else None
        self.policies = list(policies) if policies is not None else None
        self.replay: Replay | None = None
        self._actions: list[np.ndarray] = []
        self._routes: list[np.ndarray] = []
        if match is not None:
            if match_seed is None:
                raise ValueError("a ReplayRecorder made with a match needs its match_seed")
            self._bind(match)

    def _bind(self, match: Match) -> None:
        if match.tick != 0:
            raise ValueError(f"start recording at tick 0 (match is at tick {match.tick})")
        self.match = match

    def on_start(self, episode: Episode) -> None:
        if self.policies is None:
            self.policies = list(episode.controllers)
        if self.match is None:
            if episode.seeds is None:
                raise ValueError("a replay needs the episode's seeds (start episodes with "
                                 "start_episode or Lineup.start)")
            self.match_seed, self.seed = episode.seeds.match_seed, episode.seeds.seed
            self._bind(episode.match)

    def on_tick(self, episode: Episode, events: TickEvents) -> None:
        self.record(episode.actions)

    def on_end(self, episode: Episode) -> None:
        self.replay = self.finish()
        if self.path is not None:
            save_replay(self.replay, self.path)

    def record(self, actions: np.ndarray) -> None:
        self._actions.append(np.asarray(actions, dtype=np.int8).copy())
        m = self.match
        routes = np.full((m.n, 4), -1, dtype=np.int16)
        if self.policies is not None:
            for seat in np.flatnonzero(m.alive):
                routes[seat] = planned_route(self.policies[seat], m, int(seat))
        self._routes.append(routes)

    def finish(self) -> Replay:
        m = self.match
        if m is None or self.match_seed is None:
            raise ValueError("nothing recorded: the recorder was never bound to a match")
        if len(self._actions) != m.tick:
            raise ValueError(f"recorded {len(self._actions)} ticks of actions but the match "
                             f"is at tick {m.tick}: call record() once per step()")
        actions = (np.stack(self._actions) if self._actions
                   else np.zeros((0, m.n, 3), dtype=np.int8))
        routes = (np.stack(self._routes) if self._routes
                  else np.zeros((0, m.n, 4), dtype=np.int16))
        return Replay(match_seed=self.match_seed, map_name=m.spec.name,
                      map_text=map_text(m.spec), config=dataclasses.asdict(m.cfg),
                      teams=list(m.teams), actions=actions, final_hash=m.state_hash(),
                      winner=m.winner, seed=self.seed, scenario=self.scenario,
                      seats=self.seats, labels=self.labels, routes=routes)


class ReplayPolicy:
    """Plays back one seat of a replay (so replays run through the same loops as bots);
    its :meth:`planned_path` is the route the seat's bot had planned at that tick."""

    def __init__(self, actions: np.ndarray, routes: np.ndarray | None = None):
        self.actions, self.routes = actions, routes

    def reset(self, match: Match, seat: int, seed: int | None = None) -> None:
        return None

    def act(self, match: Match, seat: int) -> np.ndarray:
        if match.tick >= len(self.actions):
            return NOOP.copy()
        return self.actions[match.tick, seat].astype(np.int64)

    def planned_path(self, match: Match, seat: int) -> list[tuple[int, int]] | None:
        """Cells of the route drawn after tick ``match.tick`` (chosen with its actions)."""
        t = match.tick - 1
        if self.routes is None or not 0 <= t < len(self.routes) or not match.alive[seat]:
            return None
        r0, c0, r1, c1 = (int(v) for v in self.routes[t, seat])
        if r0 < 0:
            return None
        from alphatank.sim.navigation import nav_grid

        return nav_grid(match.spec).path((r0, c0), (r1, c1)) or None


def save_replay(replay: Replay, path: str | Path) -> Path:
    """Write ``replay`` to ``path`` atomically; returns the path. What is written is read
    back with :func:`load_replay` first: a replay that would not load is not saved
    (ReplayError naming ``path`` and the field)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        text = json.dumps(replay.meta(), default=_plain)
    except (TypeError, ValueError) as exc:
        raise ReplayError(f"{path}: not saved: {exc}") from None
    blob = np.frombuffer(text.encode("utf-8"), dtype=np.uint8)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            np.savez_compressed(f, **replay.arrays(), meta=blob)
        try:
            load_replay(tmp)
        except ReplayError as exc:
            raise ReplayError(f"{path}: not saved, it would not load: "
                              f"{str(exc).removeprefix(f'{tmp}: ')}") from None
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600 files
        replace_into(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def _plain(value: Any) -> Any:
    """numpy scalars as the JSON numbers they are (``json.dumps``' ``default``)."""
    if isinstance(value, np.integer | np.floating | np.bool_):
        return value.item()
    raise TypeError(f"{type(value).__name__} {value!r} is not a JSON value")


def check_replay_room(cfg: GameConfig, specs: Sequence[MapSpec], tanks: int, flag: str) -> None:
    """InputError ``flag: why`` when a game of ``tanks`` tanks and ``cfg`` on one of
    ``specs`` might make a replay that :func:`load_replay` refuses (more than
    :data:`MAX_TANKS` tanks, or a longest game that would ask for more than
    :data:`MAX_SUBSTEPS` or :data:`MAX_BODY_SUBSTEPS` of re-simulation): asked before
    recording one."""
    if tanks > MAX_TANKS:
        raise InputError(f"{flag}: a replay holds at most {MAX_TANKS} tanks, this game has "
                         f"{tanks}")
    work = max(cfg.max_steps * substeps_for(cfg, s.min_wall_thickness()) for s in specs)
    if work > MAX_SUBSTEPS:
        raise InputError(f"{flag}: a game of up to {cfg.max_steps:,} ticks (max_steps) may "
                         f"take {work:,} physics substeps to re-simulate; a replay may ask "
                         f"for at most {MAX_SUBSTEPS:,} (lower max_steps)")
    if (why := _body_work_problem(cfg, tanks, work)) is not None:
        raise InputError(f"{flag}: a game of up to {cfg.max_steps:,} ticks (max_steps) {why} "
                         "(lower max_steps, or the tanks or bullets)")


def _body_work_problem(cfg: GameConfig, tanks: int, substeps: int) -> str | None:
    """Why ``substeps`` of ``tanks`` tanks and their bullets exceed
    :data:`MAX_BODY_SUBSTEPS`; None if they do not."""
    bodies = tanks * (1 + cfg.bullet_capacity)
    if substeps * bodies <= MAX_BODY_SUBSTEPS:
        return None
    return (f"would take {substeps:,} physics substeps of up to {bodies:,} bodies ({tanks} "
            f"tanks and {cfg.bullet_capacity} bullets each), {substeps * bodies:,} in all; a "
            f"replay may ask for at most {MAX_BODY_SUBSTEPS:,}")


def _declared_bytes(zf: zipfile.ZipFile, info: zipfile.ZipInfo) -> int:
    """The bytes an ``.npy`` member's header says its array holds (``np.load`` allocates
    them before reading the data, whatever the member's real size); 0 for other members."""
    if not info.filename.endswith(".npy"):
        return 0
    with zf.open(info) as f:
        major, _ = np.lib.format.read_magic(f)
        read = (np.lib.format.read_array_header_1_0 if major == 1
                else np.lib.format.read_array_header_2_0)
        shape, _, dtype = read(f)
    return math.prod(shape) * dtype.itemsize


def _some(names: list[str], shown: int = 8) -> str:
    """The first ``shown`` of ``names`` as a list, with how many more there are."""
    more = len(names) - shown
    return f"{names[:shown]}" + (f" and {more:,} more" if more > 0 else "")


def _read_archive(path: Path) -> tuple[dict[str, np.ndarray], Any]:
    """The arrays and the decoded meta of a replay archive; sizes bounded before reading."""
    try:
        with zipfile.ZipFile(path) as zf:
            names = zf.namelist()
            missing = [k for k in ("actions", "meta") if f"{k}.npy" not in names]
            if missing:
                raise ReplayError(f"{path}: not a replay file: missing {missing} "
                                  f"(found {_some(names)})")
            extra = sorted(set(names) - set(_MEMBERS))
            if extra:  # refused unread: each could unpack to MAX_ARRAY_BYTES
                raise ReplayError(f"{path}: arrays: unexpected member(s) {_some(extra)}; a "
                                  "replay holds actions, routes and meta")
            for info in zf.infolist():
                name = info.filename
                cap = MAX_META_BYTES if name == "meta.npy" else MAX_ARRAY_BYTES
                size = max(info.file_size, _declared_bytes(zf, info))
                if size > cap:
                    raise ReplayError(f"{path}: member {name!r} unpacks to {size:,} bytes; "
                                      f"a replay member may hold at most {cap:,}")
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files if k != "meta"}
            raw = z["meta"]
        if raw.dtype != np.uint8 or raw.ndim != 1:
            raise ReplayError(f"{path}: meta must be UTF-8 JSON bytes, got {raw.dtype} "
                              f"{raw.shape}")
        meta = json.loads(raw.tobytes().decode("utf-8"))
    except ReplayError:
        raise
    except (zipfile.BadZipFile, zlib.error, ValueError, OSError, EOFError, KeyError,
            UnicodeDecodeError, NotImplementedError, RecursionError) as exc:
        first = (str(exc).strip().splitlines() or [""])[0]
        raise ReplayError(f"{path}: not a readable replay file (corrupt or another format): "
                          f"{type(exc).__name__}: {first}") from None
    return arrays, meta


def load_replay(path: str | Path) -> Replay:
    """Read and check a replay file; ReplayError names the file, the field and what is
    allowed (see the module doc for what is checked)."""
    path = Path(path)
    if path.is_dir():
        raise ReplayError(f"{path}: is a folder, not a replay file (.npz)")
    if path.exists() and not path.is_file():  # zip archives are read by seeking
        raise ReplayError(f"{path}: is not a regular file (a pipe or device); save the "
                          "replay to a file and give that")
    if not path.is_file():
        raise ReplayError(f"{path}: no such replay file")
    arrays, meta = _read_archive(path)

    def fail(where: str, why: str) -> ReplayError:
        return ReplayError(f"{path}: {where}: {why}")

    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise ReplayError(f"{path}: not an AlphaTank replay (meta.format is not {FORMAT!r})")
    version = meta.get("version")
    if version != VERSION:
        newer = isinstance(version, int) and not isinstance(version, bool) and version > VERSION
        fix = ("a newer AlphaTank wrote it: upgrade AlphaTank to replay it" if newer
               else "record the match again")
        raise ReplayError(f"{path}: replay version {version!r} is not supported: this "
                          f"AlphaTank reads version {VERSION} ({fix})")
    missing = [k for k in _META_KEYS if k not in meta]
    if missing:
        raise ReplayError(f"{path}: replay meta lacks field(s) {missing}")
    for key, kinds, rng in (("seed", (int, type(None)), _U64), ("match_seed", (int,), _U64),
                            ("scenario", (str, type(None)), None), ("map_name", (str,), None),
                            ("map_text", (str,), None), ("ticks", (int,), (0, None)),
                            ("final_hash", (str,), None), ("digest", (str,), None),
                            ("winner", (str, type(None)), None)):
        _, why = check_value(kinds, meta[key], rng)
        if why is not None:
            raise fail(f"meta.{key}", why)
    for key in ("final_hash", "digest"):
        if not _HEX64.fullmatch(meta[key]):
            raise fail(f"meta.{key}", "must be 64 lowercase hex digits (a SHA-256)")
    for key in ("scenario", "map_name"):  # printed and drawn, as labels are: one line
        if meta[key] and (why := name_problem(meta[key], LABEL_MAX)):
            raise fail(f"meta.{key}", why[:300])
    teams = meta["teams"]
    if (not isinstance(teams, list) or not 2 <= len(teams) <= MAX_TANKS
            or not all(isinstance(t, str) and t for t in teams)):
        raise fail("meta.teams", f"must be a list of 2 to {MAX_TANKS} team names, got "
                   f"{teams!r}"[:300])
    for k, t in enumerate(teams):
        if why := name_problem(t):
            raise fail(f"meta.teams[{k}]", why[:300])
    if len(set(teams)) < 2:
        raise fail("meta.teams", f"need at least 2 different teams, got {teams!r}")
    n = len(teams)
    for key in ("seats", "labels"):
        val = meta[key]
        if (not isinstance(val, list) or len(val) not in (0, n)
                or not all(isinstance(v, str) for v in val)):
            raise fail(f"meta.{key}", f"must be a list of {n} strings (one per seat) or "
                       "empty")
        for k, v in enumerate(val):
            if v and (why := name_problem(v, LABEL_MAX)):
                raise fail(f"meta.{key}[{k}]", why[:300])
    if meta["winner"] is not None and meta["winner"] not in teams:
        raise fail("meta.winner", f"must be one of the teams {sorted(set(teams))} or null, "
                   f"got {meta['winner']!r}")
    if not isinstance(meta["config"], dict):
        raise fail("meta.config", "must be an object of GameConfig settings")
    try:
        cfg = from_dict(GameConfig, meta["config"], where=f"{path}: meta.config")
        spec = parse_map(meta["map_text"], f"{path}: meta.map_text", name=meta["map_name"])
    except (ConfigError, MapError) as exc:
        raise ReplayError(str(exc)) from None
    if spec.tank_room(n) < n:
        raise fail("meta.map_text", f"map has room for {spec.tank_room(n)} tanks, the "
                   f"replay has {n}")
    try:  # rules across config and map (tanks must fit the map's cells), checked up front
        Match(cfg, spec, teams, seed=meta["match_seed"])
    except MapError as exc:
        raise fail("meta.config", f"does not fit meta.map_text: {exc.message}") from None
    ticks = meta["ticks"]
    if ticks > cfg.max_steps:
        raise fail("meta.ticks", f"{ticks} ticks exceed the config's max_steps "
                   f"({cfg.max_steps})")
    work = ticks * substeps_for(cfg, spec.min_wall_thickness())
    if work > MAX_SUBSTEPS:
        raise fail("meta.config", f"re-simulating {ticks:,} ticks would take {work:,} physics "
                   f"substeps; a replay may ask for at most {MAX_SUBSTEPS:,}")
    if (why := _body_work_problem(cfg, n, work)) is not None:
        raise fail("meta.config", f"re-simulating {ticks:,} ticks {why}")
    actions = arrays.get("actions")
    if actions.dtype != np.int8 or actions.ndim != 3 or actions.shape[1:] != (n, 3):
        raise fail("actions", f"must be int8 of shape (ticks, {n}, 3), got {actions.dtype} "
                   f"{actions.shape}")
    if actions.shape[0] != ticks:
        raise fail("meta.ticks", f"is {ticks} but the file holds {actions.shape[0]} ticks of "
                   "actions")
    if actions.size and ((actions < 0).any() or (actions > [2, 2, 1]).any()):
        raise fail("actions", "out of range (rotate 0..2, move 0..2, fire 0..1)")
    routes = arrays.get("routes")
    if routes is None or routes.dtype != np.int16 or routes.shape != (ticks, n, 4):
        raise fail("routes", f"must be int16 of shape ({ticks}, {n}, 4), got "
                   f"{None if routes is None else (routes.dtype, routes.shape)}")
    none = (routes == -1).all(axis=-1)
    rows, cols = spec.rows, spec.cols
    inside = ((routes[..., 0::2] >= 0) & (routes[..., 0::2] < rows)
              & (routes[..., 1::2] >= 0) & (routes[..., 1::2] < cols)).all(axis=-1)
    if not (none | inside).all():
        raise fail("routes", f"cells must lie in the {rows} x {cols} grid (or be -1)")
    if content_digest(meta, {"actions": actions, "routes": routes}) != meta["digest"]:
        raise fail("meta.digest", "does not match the file's contents: the replay was "
                   "altered or damaged after it was saved")
    return Replay(match_seed=meta["match_seed"], map_name=meta["map_name"],
                  map_text=meta["map_text"], config=meta["config"], teams=list(teams),
                  actions=actions, final_hash=meta["final_hash"], winner=meta["winner"],
                  seed=meta["seed"], scenario=meta["scenario"], seats=list(meta["seats"]),
                  labels=list(meta["labels"]), routes=routes, source=str(path))


def check_replayed(replay: Replay, match: Match) -> None:
    """ReplayError unless ``match`` (played back from ``replay``) ended as the replay says:
    the recorded tick count, final state hash and winner. Errors name the replay's file."""
    where = f"{replay.source}: " if replay.source else ""
    if match.tick != replay.ticks:
        raise ReplayError(f"{where}replay diverged: the match ended at tick {match.tick} but "
                          f"{replay.ticks} ticks were recorded")
    got = match.state_hash()
    if got != replay.final_hash:
        raise ReplayError(f"{where}replay diverged: final state hash {got[:16]}... != "
                          f"recorded {replay.final_hash[:16]}... after {match.tick} ticks")
    if match.winner != replay.winner:
        raise ReplayError(f"{where}replay diverged: the re-simulated winner is "
                          f"{_result(match.winner)}, the file claims {_result(replay.winner)}")


class ReplayCheck(EpisodeHook):
    """An episode hook that raises :func:`check_replayed`'s ReplayError when the played-back
    episode ends: placed before a video's hook, a replay that diverges leaves no video
    (the recorder removes its partial file, an existing file at its path is kept)."""

    def __init__(self, replay: Replay):
        self.replay = replay

    def on_end(self, episode: Episode) -> None:
        check_replayed(self.replay, episode.match)


def _result(winner: str | None) -> str:
    return f"team {winner}" if winner is not None else "no winner"


def replay_episode(replay: Replay, hooks: Sequence[EpisodeHook] = ()) -> Episode:
    """An episode that plays ``replay`` back from its initial state: every seat is a
    :class:`ReplayPolicy` (actions and planned routes), and it ends after the recorded
    number of ticks."""
    match = replay.new_match()
    seeds = EpisodeSeeds(replay.seed if replay.seed is not None else 0, 0, replay.match_seed,
                         ())
    return Episode(match, replay.policies(), seeds=seeds, hooks=hooks,
                   tick_limit=replay.ticks)


def simulate(replay: Replay, hooks: Sequence[EpisodeHook] = (), check: bool = True) -> Match:
    """Re-run a replay from its seed through the episode loop (``hooks`` see it as any
    episode); with ``check``, ReplayError if it ends differently from the recording
    (:func:`check_replayed`)."""
    match = replay_episode(replay, hooks).run().match
    if check:
        check_replayed(replay, match)
    return match

"""Replays: a match's seed, map, config, seats and every tick's actions in one small file.

A replay re-simulates bit-identically: same GameConfig, same map text, same teams, same
match seed and the same (ticks, n_tanks, 3) int8 actions give the same final state hash
(:meth:`alphatank.sim.match.Match.state_hash`), which the file stores and :func:`simulate`
checks. Files are ``.npz`` archives (``actions`` plus a JSON ``meta`` record), written
atomically (temporary file + ``os.replace``) and loaded without pickle.
"""

from __future__ import annotations

import dataclasses
import json
import os
import tempfile
import zipfile
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from alphatank.sim.config import ConfigError, GameConfig, from_dict
from alphatank.sim.episode import Episode, EpisodeHook, EpisodeSeeds
from alphatank.sim.mapspec import MapError, MapSpec, map_text, parse_map
from alphatank.sim.match import Match, TickEvents
from alphatank.sim.policy import NOOP

FORMAT = "alphatank-replay"
VERSION = 1
_META_KEYS = ("format", "version", "seed", "match_seed", "scenario", "seats", "map_name",
              "map_text", "config", "teams", "labels", "ticks", "final_hash", "winner")


class ReplayError(ValueError):
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


class ReplayRecorder(EpisodeHook):
    """Collects the actions of one episode. As an episode hook it binds to the episode at
    ``on_start`` (unless made with a ``match``), records every tick and, at ``on_end``,
    keeps the :class:`Replay` in :attr:`replay` and saves it to ``path`` if given. By
    hand: :meth:`record` each tick's actions (before or after ``match.step``) and
    :meth:`finish` once the episode is over."""

    def __init__(self, match: Match | None = None, *, match_seed: int | None = None,
                 seed: int | None = None, scenario: str | None = None,
                 seats: Sequence[str] = (), labels: Sequence[str] = (),
                 path: str | Path | None = None):
        self.match: Match | None = None
        self.match_seed, self.seed = match_seed, seed
        self.scenario, self.seats, self.labels = scenario, list(seats), list(labels)
        self.path = Path(path) if path is not None else None
        self.replay: Replay | None = None
        self._actions: list[np.ndarray] = []
        if match is not None:
            if match_seed is None:
                raise ValueError("a ReplayRecorder made with a match needs its match_seed")
            self._bind(match)

    def _bind(self, match: Match) -> None:
        if match.tick != 0:
            raise ValueError(f"start recording at tick 0 (match is at tick {match.tick})")
        self.match = match

    def on_start(self, episode: Episode) -> None:
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

    def finish(self) -> Replay:
        m = self.match
        if m is None or self.match_seed is None:
            raise ValueError("nothing recorded: the recorder was never bound to a match")
        if len(self._actions) != m.tick:
            raise ValueError(f"recorded {len(self._actions)} ticks of actions but the match "
                             f"is at tick {m.tick}: call record() once per step()")
        actions = (np.stack(self._actions) if self._actions
                   else np.zeros((0, m.n, 3), dtype=np.int8))
        return Replay(match_seed=self.match_seed, map_name=m.spec.name,
                      map_text=map_text(m.spec), config=dataclasses.asdict(m.cfg),
                      teams=list(m.teams), actions=actions, final_hash=m.state_hash(),
                      winner=m.winner, seed=self.seed, scenario=self.scenario,
                      seats=self.seats, labels=self.labels)


class ReplayPolicy:
    """Plays back one seat of a replay (so replays run through the same loops as bots)."""

    def __init__(self, actions: np.ndarray):
        self.actions = actions

    def reset(self, match: Match, seat: int, seed: int | None = None) -> None:
        return None

    def act(self, match: Match, seat: int) -> np.ndarray:
        if match.tick >= len(self.actions):
            return NOOP.copy()
        return self.actions[match.tick, seat].astype(np.int64)


def save_replay(replay: Replay, path: str | Path) -> Path:
    """Write ``replay`` to ``path`` atomically; returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    meta = {"format": FORMAT, "version": VERSION, "seed": replay.seed,
            "match_seed": replay.match_seed, "scenario": replay.scenario,
            "seats": replay.seats, "map_name": replay.map_name, "map_text": replay.map_text,
            "config": replay.config, "teams": replay.teams, "labels": replay.labels,
            "ticks": replay.ticks, "final_hash": replay.final_hash, "winner": replay.winner}
    blob = np.frombuffer(json.dumps(meta).encode("utf-8"), dtype=np.uint8)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            np.savez_compressed(f, actions=replay.actions.astype(np.int8), meta=blob)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600 files
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def load_replay(path: str | Path) -> Replay:
    """Read a replay file; ReplayError names the file and what is wrong."""
    path = Path(path)
    if not path.is_file():
        raise ReplayError(f"{path}: no such replay file")
    try:
        with np.load(path, allow_pickle=False) as z:
            missing = [k for k in ("actions", "meta") if k not in z.files]
            if missing:
                raise ReplayError(f"{path}: not a replay file: missing {missing} "
                                  f"(found {z.files})")
            actions = z["actions"]
            meta = json.loads(z["meta"].tobytes().decode("utf-8"))
    except ReplayError:
        raise
    except (zipfile.BadZipFile, ValueError, OSError, EOFError, KeyError,
            UnicodeDecodeError) as exc:
        raise ReplayError(f"{path}: not a readable replay file (corrupt or another format): "
                          f"{type(exc).__name__}: {exc}") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise ReplayError(f"{path}: not an AlphaTank replay (meta.format is not {FORMAT!r})")
    if meta.get("version") != VERSION:
        raise ReplayError(f"{path}: replay version {meta.get('version')!r} is not supported "
                          f"(this AlphaTank reads version {VERSION})")
    missing = [k for k in _META_KEYS if k not in meta]
    if missing:
        raise ReplayError(f"{path}: replay meta lacks field(s) {missing}")
    teams = meta["teams"]
    if actions.dtype != np.int8 or actions.ndim != 3 or actions.shape[1:] != (len(teams), 3):
        raise ReplayError(f"{path}: actions must be int8 of shape (ticks, {len(teams)}, 3), "
                          f"got {actions.dtype} {actions.shape}")
    if actions.shape[0] != meta["ticks"]:
        raise ReplayError(f"{path}: meta.ticks is {meta['ticks']} but the file holds "
                          f"{actions.shape[0]} ticks of actions")
    if actions.size and ((actions < 0).any() or (actions > [2, 2, 1]).any()):
        raise ReplayError(f"{path}: actions out of range (rotate 0..2, move 0..2, fire 0..1)")
    replay = Replay(match_seed=int(meta["match_seed"]), map_name=meta["map_name"],
                    map_text=meta["map_text"], config=meta["config"], teams=list(teams),
                    actions=actions, final_hash=meta["final_hash"], winner=meta["winner"],
                    seed=meta["seed"], scenario=meta["scenario"], seats=list(meta["seats"]),
                    labels=list(meta["labels"]))
    try:
        replay.game_config()
        replay.map_spec()
    except (ConfigError, MapError, TypeError) as exc:
        raise ReplayError(f"{path}: {exc}") from None
    return replay


def replay_episode(replay: Replay, hooks: Sequence[EpisodeHook] = ()) -> Episode:
    """An episode that plays ``replay`` back from its initial state: every seat is a
    :class:`ReplayPolicy`, and it ends after the recorded number of ticks."""
    match = replay.new_match()
    seeds = EpisodeSeeds(replay.seed if replay.seed is not None else 0, 0, replay.match_seed,
                         ())
    return Episode(match, [ReplayPolicy(replay.actions) for _ in range(match.n)],
                   seeds=seeds, hooks=hooks, tick_limit=replay.ticks)


def check_replayed(replay: Replay, match: Match) -> None:
    """ReplayError unless ``match`` (played back from ``replay``) reached the recorded
    tick count and final state hash."""
    if match.tick != replay.ticks:
        raise ReplayError(f"replay diverged: the match ended at tick {match.tick} but "
                          f"{replay.ticks} ticks were recorded")
    if match.state_hash() != replay.final_hash:
        raise ReplayError(f"replay diverged: final state hash {match.state_hash()[:16]}... "
                          f"!= recorded {replay.final_hash[:16]}... after {match.tick} ticks")


def simulate(replay: Replay, hooks: Sequence[EpisodeHook] = (), check: bool = True) -> Match:
    """Re-run a replay from its seed through the episode loop (``hooks`` see it as any
    episode); with ``check``, ReplayError if it ends differently from the recording."""
    match = replay_episode(replay, hooks).run().match
    if check:
        check_replayed(replay, match)
    return match

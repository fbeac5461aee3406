"""Self-play against a window of the learner's own past snapshots (issue 12, point 4).

A :class:`SnapshotPool` keeps the last ``window`` frozen copies of a learner. Each game's
opponent is drawn from ``(seed, env, episode)`` alone, so a run and its resume draw the
same opponents whatever order the envs finish in: with probability ``latest_share`` the
newest snapshot, else one of the older ones uniformly (all of them are the newest while
the window holds one). Ratings: openskill Plackett-Luce (:class:`alphatank.stats.League`)
for the learner and every snapshot ever added (a new snapshot starts at the learner's
current rating); decided games and double knock-outs are rated, games cut by the time
limit are not (a timeout says nothing about who is better).

:class:`SelfPlay` drives a pool inside a training run: every ``every`` env steps it adds
a snapshot of the learner and registers it with the vector env as a named opponent (a
frozen Policy, :meth:`~alphatank.envs.vector.VectorMatchEnv.add_opponent`); before each
env's next episode starts it names that episode's snapshot
(:meth:`~alphatank.envs.vector.VectorMatchEnv.set_env_opponents`), and it rates every
finished game.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from alphatank.stats import League
from alphatank.training.learners import inference_state
from alphatank.training.presets import check_pool_args

OUTCOMES = {"win": 1, "draw": 0, "loss": -1}


def frozen_state(state: dict[str, Any]) -> dict[str, Any]:
    """A detached copy of a learner state (tensors cloned, dicts copied)."""

    def copy(v: Any) -> Any:
        if isinstance(v, torch.Tensor):
            return v.detach().clone()
        if isinstance(v, dict):
            return {k: copy(x) for k, x in v.items()}
        return v

    return {k: copy(v) for k, v in state.items()}


@dataclass
class Snapshot:
    id: int
    step: int
    state: dict[str, Any]

    @property
    def name(self) -> str:
        return f"snap{self.id}@{self.step}"


class SnapshotPool:
    """A window of frozen snapshots of one learner, opponent sampling and ratings."""

    def __init__(self, window: int = 8, latest_share: float = 0.5, every: int = 200_000,
                 seed: int = 0, learner: str = "learner"):
        check_pool_args(window, latest_share, every)
        self.window, self.latest_share, self.every = int(window), float(latest_share), int(every)
        self.seed = int(seed)
        self.snapshots: deque[Snapshot] = deque(maxlen=self.window)
        self.league = League([learner])
        self.index: dict[int, int] = {}  # snapshot id -> league row
        self.next_id = 0
        self.last_step: int | None = None
        self.games = {"rated": 0, "timeouts": 0}
        self._frozen: dict[int, Any] = {}

    def __len__(self) -> int:
        return len(self.snapshots)

    @property
    def latest(self) -> Snapshot:
        if not self.snapshots:
            raise RuntimeError("the snapshot pool is empty: add() a snapshot first")
        return self.snapshots[-1]

    def due(self, step: int) -> bool:
        """Time to add a snapshot at env step ``step`` (always while empty)."""
        return self.last_step is None or step - self.last_step >= self.every

    def add(self, state: dict[str, Any], step: int) -> int:
        """Freeze a learner's inference state
        (:func:`~alphatank.training.learners.inference_state`) taken at env step ``step``;
        returns its id. The oldest snapshot leaves the window when it is full (its rating
        stays)."""
        snap = Snapshot(self.next_id, int(step), frozen_state(state))
        self.next_id += 1
        me = self.league.ratings[0]
        self.index[snap.id] = self.league.add(snap.name, me.mu, me.sigma)
        if len(self.snapshots) == self.window:
            self._frozen.pop(self.snapshots[0].id, None)
        self.snapshots.append(snap)
        self.last_step = int(step)
        return snap.id

    def opponent_for(self, env_index: int, episode: int) -> int:
        """Snapshot id to play in env ``env_index``'s episode ``episode``."""
        snaps = self.snapshots
        if not snaps:
            raise RuntimeError("the snapshot pool is empty: add() a snapshot first")
        rng = np.random.default_rng([self.seed, int(env_index), int(episode)])
        if len(snaps) == 1 or rng.random() < self.latest_share:
            return snaps[-1].id
        return snaps[int(rng.integers(len(snaps) - 1))].id

    def snapshot(self, snap_id: int) -> Snapshot:
        for s in self.snapshots:
            if s.id == snap_id:
                return s
        raise KeyError(f"snapshot {snap_id} is not in the pool's window "
                       f"{[s.id for s in self.snapshots]}")

    def frozen(self, snap_id: int, make: Callable[[], Any]) -> Any:
        """A learner (built by ``make()``) holding snapshot ``snap_id``'s weights; cached
        while the snapshot is in the window."""
        if snap_id not in self._frozen:
            learner = make()
            learner.load_state_dict(self.snapshot(snap_id).state, weights_only=True)
            self._frozen[snap_id] = learner
        return self._frozen[snap_id]

    def record(self, snap_id: int, outcome: str, truncated: bool = False) -> None:
        """The learner's ``outcome`` (win / loss / draw) against snapshot ``snap_id``;
        games ended by the time limit (``truncated``) are counted but not rated."""
        if outcome not in OUTCOMES:
            raise ValueError(f"outcome must be one of {sorted(OUTCOMES)}, got {outcome!r}")
        if snap_id not in self.index:
            raise KeyError(f"no snapshot {snap_id} was ever added")
        if truncated:
            self.games["timeouts"] += 1
            return
        self.games["rated"] += 1
        self.league.record(0, self.index[snap_id], OUTCOMES[outcome])

    def ratings(self) -> list[tuple[str, float, float, float]]:
        """(name, mu, sigma, ordinal), best first: the learner and every snapshot."""
        return self.league.table()

    def metrics(self) -> dict[str, float]:
        me = self.league.ratings[0]
        return {"selfplay/mu": me.mu, "selfplay/sigma": me.sigma,
                "selfplay/ordinal": me.ordinal(), "selfplay/snapshots": float(len(self)),
                "selfplay/rated_games": float(self.games["rated"]),
                "selfplay/timeouts": float(self.games["timeouts"])}

    def state_dict(self) -> dict[str, Any]:
        """Snapshots (tensors) and ratings; ``torch.save``-able, loads with
        ``weights_only=True``."""
        return {"snapshots": [{"id": s.id, "step": s.step, "state": s.state}
                              for s in self.snapshots],
                "league": [{"name": n, "mu": r.mu, "sigma": r.sigma}
                           for n, r in zip(self.league.names, self.league.ratings, strict=True)],
                "index": {str(k): v for k, v in self.index.items()},
                "next_id": self.next_id, "last_step": self.last_step,
                "games": dict(self.games)}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.snapshots.clear()
        self._frozen.clear()
        for s in state["snapshots"][-self.window:]:
            self.snapshots.append(Snapshot(int(s["id"]), int(s["step"]), s["state"]))
        rows = state["league"]
        self.league = League([rows[0]["name"]])
        self.league.ratings[0] = self.league.model.rating(mu=rows[0]["mu"],
                                                          sigma=rows[0]["sigma"],
                                                          name=rows[0]["name"])
        for r in rows[1:]:
            self.league.add(r["name"], r["mu"], r["sigma"])
        self.index = {int(k): int(v) for k, v in state["index"].items()}
        self.next_id = int(state["next_id"])
        self.last_step = None if state["last_step"] is None else int(state["last_step"])
        self.games = {k: int(v) for k, v in state["games"].items()}


def opponent_name(snap_id: int) -> str:
    """The env's name of a snapshot opponent; per-opponent win rates show it as
    ``selfplay``."""
    return f"selfplay(snap{snap_id})"


class SelfPlay:
    """A :class:`SnapshotPool` inside a training run over ``num_envs`` envs.

    ``make_policy(snapshot)`` turns a snapshot into the Policy that fills the pool's seats
    (the seats no learner drives). Each env's ``k``-th episode since the run started plays
    ``pool.opponent_for(env, k)``: chosen before that episode starts (the vector env resets
    ended episodes inside ``step``), so a run and its resume play the same games.
    """

    def __init__(self, pool: SnapshotPool, make_policy: Callable[[Snapshot], Any],
                 num_envs: int, learner: str = "learner"):
        self.pool, self.make_policy, self.num_envs = pool, make_policy, int(num_envs)
        self.learner = learner  # the name of the learner the snapshots are taken of
        self.games = np.zeros(self.num_envs, dtype=np.int64)  # episodes started per env
        self.current: list[int | None] = [None] * self.num_envs
        self.next: list[int] = [0] * self.num_envs
        self._registered: set[int] = set()

    def snapshot(self, env: Any, learner: Any, step: int) -> None:
        """Add a snapshot of ``learner`` when one is due at env step ``step``, and
        register every snapshot of the window the env does not know yet."""
        if self.pool.due(step):
            self.pool.add(inference_state(learner.algo, learner.state_dict()), step)
        for snap in self.pool.snapshots:
            if snap.id not in self._registered:
                env.add_opponent(opponent_name(snap.id), self.make_policy(snap))
                self._registered.add(snap.id)

    def _choose(self, env: Any, envs: Sequence[int]) -> None:
        for e in envs:
            self.next[e] = self.pool.opponent_for(e, int(self.games[e]))
        env.set_env_opponents([opponent_name(i) for i in self.next])

    def before_reset(self, env: Any) -> None:
        """Every env is about to start a new episode (``env.reset``)."""
        self._choose(env, range(self.num_envs))

    def after_reset(self, env: Any) -> None:
        self.current = list(self.next)
        self.games += 1
        self._choose(env, range(self.num_envs))

    def on_episodes(self, env: Any, episodes: Sequence[dict], truncated: np.ndarray,
                    col: int) -> None:
        """Rate the finished ``episodes`` (outcome of learner column ``col``; truncated
        games are not rated); their envs already play the next episode's snapshot."""
        ended = []
        for ep in episodes:
            e = int(ep["env"])
            self.pool.record(self.current[e], ep["outcome"][col], bool(truncated[e]))
            self.current[e] = self.next[e]
            self.games[e] += 1
            ended.append(e)
        if ended:
            self._choose(env, ended)

    def metrics(self) -> dict[str, float]:
        return self.pool.metrics()

    def state_dict(self) -> dict[str, Any]:
        return {"pool": self.pool.state_dict(), "games": torch.from_numpy(self.games.copy())}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.pool.load_state_dict(state["pool"])
        games = state["games"].numpy()
        k = min(len(games), self.num_envs)  # a resume may change num_envs
        self.games[:] = 0
        self.games[:k] = games[:k]
        self._registered.clear()

"""A league: prioritised fictitious self-play (PFSP) over bots at several weaknesses and
the learner's own past snapshots, with one openskill table over all of them.

:class:`LeagueSchedule` is an opponent schedule (``schedule.kind = "league"`` in a run
file). The trainer calls it like the others: :meth:`~LeagueSchedule.apply` before every
rollout, :meth:`~LeagueSchedule.record` for every finished episode. At each ``apply``:

* every ``snapshot_every`` env steps it freezes the learner (weights and observation
  statistics, no optimiser) and adds the snapshot to the pool; the newest ``snapshots``
  stay playable, older ones leave the pool but keep their rating;
* it draws each env's opponent for that env's next episode (named opponents of the
  vector env, :meth:`set_env_opponents`): opponent ``o`` with probability proportional
  to ``max(floor, (1 - s_o) ** power)``, where ``s_o`` is the learner's score against
  ``o`` (wins + draws / 2) over its last ``window`` games against it (an opponent never
  played has ``s_o = 0``: it is tried first). With ``snapshot_share`` set, the snapshots
  together get that share of the draws (of each scenario's block) and the bots the rest,
  each side weighted as above. Draws come from a generator seeded by ``(seed, step)``, so
  a run is reproducible.

``settings`` (bot name -> scenario names) keeps a bot to the matches of those scenarios
of a mixed env (:class:`~alphatank.training.mixed.MixedVectorEnv`), e.g. each bot in the
map and game preset its specialist trains on; each scenario's block of envs then draws
among the bots allowed there and the snapshots, with the same weights renormalised. A bot
not named plays everywhere.

Bots are named ``NAME@WEAKNESS`` (a seat spec, e.g. ``smart@0.5``); snapshots
``self@STEP``. Every finished game rates the learner against its opponent in one
openskill (Plackett-Luce) table (draws are ties), logged as ``league/*`` and kept in the
checkpoint's schedule state (ratings and results; snapshot weights are not saved: a
resumed league starts its snapshot pool afresh).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping, Sequence
from numbers import Real
from typing import Any

import numpy as np

from alphatank.stats import League
from alphatank.training.schedules import OpponentSchedule

DEFAULT_BOTS = ("random", "aggressive", "defensive", "dodge", "smart")
SCORE = {"win": 1.0, "draw": 0.5, "loss": 0.0}
RATED = {"win": 1, "draw": 0, "loss": -1}
LEARNER = "learner"


def opponent_name(label: str) -> str:
    """The league name in an episode's opponent label: ``B:smart@0.5`` -> ``smart@0.5``,
    ``B:self@4096`` -> ``self@4096``."""
    first = label.split(", ")[0]
    return first.partition(":")[2] if ":" in first else first


class LeagueSchedule(OpponentSchedule):
    """PFSP over bots and snapshots (see the module docstring)."""

    kind = "league"
    fills_seats = True

    def __init__(self, bots: Sequence[str] = DEFAULT_BOTS,
                 weaknesses: Sequence[float] = (0.25, 0.5, 1.0),
                 snapshot_every: int = 200_000, snapshots: int = 8, power: float = 2.0,
                 floor: float = 0.1, window: int = 50, seed: int = 0,
                 settings: dict[str, Sequence[str]] | None = None,
                 snapshot_share: float | None = None):
        from alphatank.game.scenarios import bot_names

        valid = bot_names()
        if isinstance(bots, str) or not isinstance(bots, Sequence) or not bots or any(
                b not in valid for b in bots) or len(set(bots)) != len(bots):
            raise ValueError(f"league bots must be a list of distinct names from "
                             f"{list(valid)}, got {bots!r}")
        if isinstance(weaknesses, str) or not isinstance(weaknesses, Sequence) \
                or not weaknesses or any(isinstance(w, bool) or not isinstance(w, Real)
                                         or not 0.0 < w <= 1.0 for w in weaknesses):
            raise ValueError(f"league weaknesses must be a list of numbers in (0, 1], got "
                             f"{weaknesses!r}")
        names = [f"{float(w):g}" for w in weaknesses]  # as the opponents are named
        if len(set(names)) != len(names):
            raise ValueError(f"league weaknesses must differ (an opponent is named with 6 "
                             f"digits: {names}), got {list(weaknesses)}")
        if snapshot_every < 0 or snapshots < 0:
            raise ValueError(f"league snapshot_every and snapshots must be >= 0 (0: no "
                             f"snapshots), got {snapshot_every}, {snapshots}")
        if power < 0 or not 0.0 < floor <= 1.0 or window < 1:
            raise ValueError(f"league needs power >= 0, floor in (0, 1] and window >= 1, got "
                             f"{power}, {floor}, {window}")
        if snapshot_share is not None and not 0.0 <= snapshot_share < 1.0:
            raise ValueError(f"league snapshot_share must be in [0, 1) (the snapshots' share "
                             f"of the games; leave it out to weigh them with the bots), got "
                             f"{snapshot_share}")
        self.snapshot_share = None if snapshot_share is None else float(snapshot_share)
        self.bots = [f"{b}@{float(w):g}" for b in bots for w in weaknesses]
        if not isinstance(settings, Mapping | None):
            raise ValueError(f"league settings must be a table of bot name = [scenario "
                             f"names], got {settings!r}")
        for b, sc in (settings or {}).items():
            if b not in bots or not isinstance(sc, Sequence) or isinstance(sc, str) \
                    or not sc or not all(isinstance(x, str) for x in sc):
                raise ValueError(f"league settings: {b!r} = {sc!r}; keys must be some of the "
                                 f"league's bots {list(bots)}, values non-empty lists of "
                                 f"scenario names")
        self.settings = {str(b): [str(x) for x in sc] for b, sc in (settings or {}).items()}
        self.snapshot_every, self.max_snapshots = int(snapshot_every), int(snapshots)
        self.power, self.floor, self.window, self.seed = float(power), float(floor), \
            int(window), int(seed)
        self.results: dict[str, deque[float]] = {}
        self.league = League([LEARNER])
        self.index: dict[str, int] = {}
        for name in self.bots:
            self._add(name)
        self.pool: deque[str] = deque()  # playable snapshots, oldest first
        self.last_snapshot: int | None = None
        self.trainer: Any = None
        self._env: Any = None  # the env the bots were registered with
        self.games = 0

    # ---- set-up ---------------------------------------------------------------------

    def _add(self, name: str) -> None:
        self.results[name] = deque(maxlen=self.window)
        me = self.league.ratings[0]
        self.index[name] = self.league.add(name, me.mu if name.startswith("self@") else None,
                                           me.sigma if name.startswith("self@") else None)

    def bind(self, trainer: Any) -> None:
        """Keep the trainer: snapshots copy its (single) learner."""
        if self.max_snapshots and self.snapshot_every and len(trainer.specs) != 1:
            raise ValueError(f"league snapshots need one learner, the run has "
                             f"{[s.name for s in trainer.specs]} (set snapshots = 0)")
        self.trainer = trainer

    # ---- the schedule ---------------------------------------------------------------

    def opponents(self) -> list[str]:
        """Playable opponents: the bots, then the snapshots in the pool."""
        return [*self.bots, *self.pool]

    def score(self, name: str) -> float:
        res = self.results[name]
        return float(np.mean(res)) if res else 0.0

    def probabilities(self, allowed: np.ndarray | None = None) -> np.ndarray:
        """Sampling probability of each of :meth:`opponents` (of those ``allowed``, a
        boolean mask over them, when given)."""
        w = np.array([max(self.floor, (1.0 - self.score(n)) ** self.power)
                      for n in self.opponents()])
        if allowed is not None:
            w = np.where(allowed, w, 0.0)
        if self.snapshot_share is not None and self.pool:
            snap = np.arange(len(w)) >= len(self.bots)
            if w[~snap].sum() > 0:
                w[snap] *= self.snapshot_share / w[snap].sum()
                w[~snap] *= (1.0 - self.snapshot_share) / w[~snap].sum()
        return w / w.sum()

    def _snapshot(self, env: Any, step: int) -> None:
        from alphatank.training.checkpoint import LivePolicy
        from alphatank.training.learners import make_learner
        from alphatank.training.selfplay import frozen_state

        tr = self.trainer
        spec = tr.specs[0]
        # one stream per seat the learner drives (MAPPO needs its seat count's streams)
        learner = make_learner(spec, tr.D, len(spec.seats), self.seed,
                               input_dims=tr.input_dims)
        learner.load_state_dict(frozen_state(tr.learners[spec.name].state_dict()),
                                weights_only=True)
        name = f"self@{step}"
        meta = dict(tr.observation_meta)
        if meta["kind"] != "paper":  # room for the walls of every map the env plays
            cores = [b.core for b in getattr(env, "blocks", [env]) if hasattr(b, "core")]
            meta["max_walls"] = max([int(meta["max_walls"]),
                                     *(c.batch.walls.shape[1] for c in cores)])
        # one Policy object for every env: it acts for all the matches it plays at once
        env.add_opponent(name, LivePolicy({spec.name: learner}, meta, spec.name))
        if name not in self.index:
            self._add(name)
        self.pool.append(name)
        while len(self.pool) > self.max_snapshots:
            self.pool.popleft()
        self.last_snapshot = step

    def apply(self, env: Any, step: int) -> dict[str, float]:
        if self._env is not env:
            for name in self.bots:
                env.add_opponent(name, name)
            self._env = env
        if (self.trainer is not None and self.max_snapshots and self.snapshot_every
                and (self.last_snapshot is None
                     or step - self.last_snapshot >= self.snapshot_every)):
            self._snapshot(env, step)
        names = self.opponents()
        rng = np.random.default_rng([self.seed, int(step), 0x1EA6])
        if not self.settings:
            picks = rng.choice(len(names), size=env.num_envs, p=self.probabilities())
            env.set_env_opponents([names[i] for i in picks])
            return self.metrics()
        chosen: list[str] = []
        for scenario, size in self._blocks(env):
            ok = np.array([self._plays_in(n, scenario) for n in names])
            if not ok.any():
                raise ValueError(f"league settings: no opponent plays in scenario "
                                 f"{scenario!r} (settings {self.settings})")
            p = self.probabilities(ok)
            chosen += [names[i] for i in rng.choice(len(names), size=size, p=p)]
        env.set_env_opponents(chosen)
        return self.metrics()

    def _plays_in(self, name: str, scenario: str) -> bool:
        """Whether opponent ``name`` (``bot@w`` or ``self@step``) may fill a match of
        ``scenario`` (see ``settings``)."""
        allowed = self.settings.get(name.partition("@")[0])
        return allowed is None or scenario in allowed

    def _blocks(self, env: Any) -> list[tuple[str, int]]:
        """(scenario name, number of envs) of each block of ``env``, in env order; every
        scenario named in ``settings`` must be one of them."""
        if hasattr(env, "slices"):
            blocks = [(sc.name, sl.stop - sl.start)
                      for sc, sl in zip(env.scenarios, env.slices, strict=True)]
        else:
            blocks = [(env.scenario.name, env.num_envs)]
        have = {name for name, _ in blocks}
        missing = sorted({x for sc in self.settings.values() for x in sc} - have)
        if missing:
            raise ValueError(f"league settings name scenario(s) {missing} that the env does "
                             f"not play; it plays {sorted(have)}")
        return blocks

    def check(self, scenario: Any, env: Any) -> None:
        if self.settings:
            self._blocks(env)

    def record(self, opponent: str, outcome: str) -> None:
        name = opponent_name(opponent)
        if name not in self.results or outcome not in SCORE:
            return  # an episode begun before the league set this env's opponent
        self.results[name].append(SCORE[outcome])
        self.league.record(0, self.index[name], RATED[outcome])
        self.games += 1

    def metrics(self) -> dict[str, float]:
        me = self.league.ratings[0]
        m = {"league/mu": me.mu, "league/sigma": me.sigma, "league/ordinal": me.ordinal(),
             "league/snapshots": float(len(self.pool)), "league/games": float(self.games)}
        for name in self.bots:
            if self.results[name]:
                m[f"league/score/{name}"] = self.score(name)
        if self.pool:
            m["league/score/newest_self"] = self.score(self.pool[-1])
        return m

    def table(self) -> list[tuple[str, float, float, float]]:
        """(name, mu, sigma, ordinal), best first: the learner, bots and snapshots."""
        return self.league.table()

    # ---- persistence (JSON-able; snapshot weights are not kept) ------------------------

    def state_dict(self) -> dict[str, Any]:
        return {"results": {n: list(r) for n, r in self.results.items()},
                "ratings": [{"name": n, "mu": r.mu, "sigma": r.sigma}
                            for n, r in zip(self.league.names, self.league.ratings,
                                            strict=True)],
                "games": self.games}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        if not state:
            return
        rows = state["ratings"]
        self.league = League([LEARNER])
        self.league.ratings[0] = self.league.model.rating(mu=rows[0]["mu"],
                                                          sigma=rows[0]["sigma"], name=LEARNER)
        self.index, self.results = {}, {}
        for r in rows[1:]:
            self.index[r["name"]] = self.league.add(r["name"], r["mu"], r["sigma"])
            self.results[r["name"]] = deque(state["results"].get(r["name"], []),
                                            maxlen=self.window)
        for name in self.bots:
            if name not in self.index:
                self._add(name)
        self.games = int(state.get("games", 0))
        self.pool.clear()
        self.last_snapshot = None
        self._env = None

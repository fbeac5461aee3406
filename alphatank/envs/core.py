"""The engine under every env: ``num_envs`` matches of one scenario stepped together.

:class:`MatchSet` owns the matches, the controllers of the seats its caller does not
drive (bots, checkpoints, frozen policies, idle humans), one :class:`StateBatch`, the
:class:`ObservationBuilder` and the :class:`RewardTracker`. A step plays one tick in every
match, then computes rewards and observations for all of them with batched numpy.

Rules shared by all envs:

* Seeding: ``reset_env(e, seed)`` derives the map choice, the match seed and one seed per
  seat with :func:`alphatank.sim.episode.episode_seeds` (``SeedSequence(seed)``), the rule
  ``play``, ``record`` and the arena use too; same seed + same actions => same episode.
* Controllers come from the seat kinds of :mod:`alphatank.game.seats` (bots, checkpoints,
  shipped agents; human seats idle).
* Dead driven seats keep their slot: their actions are ignored and they still receive
  rewards (e.g. their team's victory).
* When no driven seat is alive but the match goes on (bots left in several teams), the
  match is played out at once with the remaining controllers, so the episode ends on this
  step with its real winner; the rewards of that play-out are added to this step.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any

import numpy as np
from gymnasium import spaces

from alphatank.game.lineup import spec_seat
from alphatank.game.observe import (
    ADVICE_KINDS,
    OBS_KINDS,
    GlobalState,
    ObservationBuilder,
    StateBatch,
    slot_counts,
)
from alphatank.game.rewards import RewardTracker, as_index
from alphatank.game.scenarios import Scenario, ScenarioError, Seat, bot_names, load_scenario
from alphatank.game.seats import make_controller
from alphatank.sim.config import (
    ACTION_REPEAT_MAX,
    MATCHES_MAX,
    MAX_STEPS_MAX,
    check_value,
)
from alphatank.sim.episode import episode_match, episode_seeds, reset_controllers
from alphatank.sim.match import Match, TickEvents
from alphatank.sim.policy import NOOP, BatchPolicy, Policy, is_batch_policy

ACTION_NVEC = np.array([3, 3, 2], dtype=np.int64)
_NVEC_U = ACTION_NVEC.astype(np.uint64)
ACTION_HELP = "rotate 0..2 (0 ccw, 1 none, 2 cw), move 0..2 (0 back, 1 stop, 2 forward), fire 0..1"


def action_space() -> spaces.MultiDiscrete:
    return spaces.MultiDiscrete(ACTION_NVEC)


def check_reset_options(options: Mapping[str, Any] | None, why: str = "") -> None:
    """The envs' ``reset`` takes no options: refuse any rather than ignore them."""
    if options:
        raise ValueError(f"reset takes no options (got {sorted(options)}){why}")


def check_actions(actions: Any, shape: tuple[int, ...], name_of: Any) -> np.ndarray:
    """Validate an integer action array of ``shape`` (last axis 3); errors name the agent
    (``name_of(index_tuple)``; for one agent's action, shape (3,), every error does) and
    the allowed values. Returns an int64 array."""
    try:
        arr = actions if type(actions) is np.ndarray else np.asarray(actions)
    except ValueError:  # nested sequences of different lengths
        who = f"{name_of(())}: " if len(shape) == 1 else ""
        raise ValueError(f"{who}actions must have shape {shape} (last axis: rotate, move, "
                         "fire), got nested sequences of different lengths") from None
    # Common cases first: one agent's row in plain Python (cheaper than numpy calls);
    # more rows by one comparison (negatives wrap round to huge unsigned values).
    if arr.dtype.type is np.int64 and arr.shape == shape:
        if shape == (3,):
            rot, move, fire = arr.tolist()
            if 0 <= rot <= 2 and 0 <= move <= 2 and 0 <= fire <= 1:
                return arr
        elif arr.size and not np.count_nonzero(np.greater_equal(arr.view(np.uint64),
                                                                _NVEC_U)):
            return arr
    who = f"{name_of(())}: " if len(shape) == 1 else ""  # one agent's action
    if arr.dtype == object or not (np.issubdtype(arr.dtype, np.integer)
                                   or arr.dtype == np.bool_):
        raise TypeError(f"{who}actions must be integers ({ACTION_HELP}), got dtype "
                        f"{arr.dtype}")
    if arr.shape != shape:
        raise ValueError(f"{who}actions must have shape {shape} (last axis: rotate, move, "
                         f"fire), got {arr.shape}")
    bad = (arr < 0) | (arr >= ACTION_NVEC)
    if bad.any():
        idx = tuple(int(i) for i in np.argwhere(bad)[0][:-1])
        raise ValueError(f"{name_of(idx)}: action {arr[idx].tolist()} out of range; allowed: "
                         f"{ACTION_HELP} (MultiDiscrete([3, 3, 2]))")
    return arr.astype(np.int64, copy=False)


def check_weakness(weakness: Any) -> float:
    """``weakness`` (a bot's chance to act each tick) as a float; ValueError unless a
    number in [0, 1]."""
    value, why = check_value((float,), weakness, (0, 1))
    if why:
        raise ValueError(f"weakness {why}")
    return value


def check_bot_names(names: Sequence[str] | None) -> list[str] | None:
    """``names`` (bot types for the bot seats; None: the scenario's own) as a list;
    ValueError unless a non-empty list of bot types, naming the valid ones."""
    if names is None:
        return None
    valid = list(bot_names())
    if isinstance(names, str):
        raise ValueError(f"bot names must be a list, got the string {names!r} (e.g. "
                         f"[{names!r}]); valid: {valid}")
    names = list(names)
    bad = [b for b in names if b not in valid]
    if bad or not names:
        raise ValueError(f"unknown bot name(s) {bad or names}; valid: {valid}")
    return names


def check_policy(policy: Any, what: str) -> None:
    """TypeError naming the argument ``what`` unless ``policy`` is a
    :class:`~alphatank.sim.policy.Policy` (an object with ``reset`` and ``act``)."""
    if not isinstance(policy, Policy) or isinstance(policy, type):
        raise TypeError(f"{what} must be a Policy (an object with reset(match, seat, seed) and "
                        "act(match, seat), e.g. alphatank.bots.make_bot('smart') or "
                        "alphatank.training.checkpoint.load_policy(path)), got "
                        f"{type(policy).__name__} {policy!r}")


def opponent_entry(name: str, opponent: str | Policy) -> Seat | Policy:
    """The named opponent ``name`` as :meth:`MatchSet.add_opponent` keeps it: a seat spec
    parsed into a Seat (ScenarioError naming it), or a Policy (TypeError otherwise)."""
    if isinstance(opponent, str):
        return spec_seat(opponent, "A", where=f"opponent {name!r}")
    check_policy(opponent, f"opponent {name!r}")
    return opponent


def check_env_opponents(names: Sequence[str | None], num_envs: int,
                        registered: Iterable[str]) -> list[str | None]:
    """``names`` as a list after checking it holds one registered opponent name (or
    None) per env; ValueError names what is allowed."""
    if len(names) != num_envs:
        raise ValueError(f"need one opponent name per env ({num_envs}), got {len(names)}")
    known = set(registered)
    bad = sorted({n for n in names if n is not None and n not in known})
    if bad:
        raise ValueError(f"unknown opponent(s) {bad}; registered: {sorted(known)}")
    return list(names)


def check_benched(scenario: Scenario, driven: Sequence[int], seats: Sequence[int]
                  ) -> tuple[int, ...]:
    """``seats`` as a sorted tuple after checking that each is a bot seat of ``scenario``
    (not a learner seat in ``driven``) and that every team keeps a seat; ValueError
    names what is allowed."""
    bots = [i for i, s in enumerate(scenario.seats) if s.controller == "bot" and i not in driven]
    if isinstance(seats, str) or not isinstance(seats, Iterable):
        raise ValueError(f"{scenario.name}: seats to bench must be a list of seat indices, got "
                         f"{seats!r}; bot seats: {bots}")
    seats = list(seats)
    strays = [s for s in seats if check_value((int,), s)[1]]
    if strays:
        raise ValueError(f"{scenario.name}: seats to bench must be seat indices (integers), "
                         f"got {strays!r}; bot seats: {bots}")
    out = tuple(sorted({int(s) for s in seats}))
    bad = [s for s in out if s not in bots]
    if bad:
        raise ValueError(f"{scenario.name}: cannot bench seats {bad}; bot seats: {bots}")
    left = {scenario.seats[i].team for i in range(len(scenario.seats)) if i not in out}
    if len(left) < len({s.team for s in scenario.seats}):
        raise ValueError(f"{scenario.name}: benching seats {list(out)} leaves a team with no "
                         f"tank")
    return out


def check_num_envs(num_envs: Any) -> int:
    """``num_envs`` as an int; ValueError unless a whole number in 1..MATCHES_MAX."""
    value, why = check_value((int,), num_envs, (1, MATCHES_MAX))
    if why:
        raise ValueError(f"num_envs must be a whole number in 1..{MATCHES_MAX} (each match "
                         f"holds about 0.5 MB), got {num_envs!r}")
    return value


def check_mapping(value: Any, what: str, key: type, example: str) -> dict:
    """``value`` (None: empty) as a dict; TypeError naming the argument ``what`` unless a
    mapping whose keys are ``key`` (str: setting names; int: seat indices)."""
    if value is None:
        return {}
    if not isinstance(value, Mapping):
        raise TypeError(f"{what} must be a dict, e.g. {example}, got "
                        f"{type(value).__name__} {value!r}")
    bad = [k for k in value if check_value((key,), k)[1]]
    if bad:
        keys = "setting names (strings)" if key is str else "seat indices (ints)"
        raise TypeError(f"{what}: keys must be {keys}, e.g. {example}, got {bad!r}")
    return dict(value)


def check_overrides(overrides: Any, what: str) -> dict[str, Any]:
    """``what`` (game_overrides / reward_overrides; None: none) checked by
    :func:`check_mapping`."""
    example = "{'max_steps': 600}" if what == "game_overrides" else "{'victory': 2.0}"
    return check_mapping(overrides, what, str, example)


def check_seat_policies(seat_policies: Any) -> dict[int, Policy]:
    """``seat_policies`` (None: none) checked by :func:`check_mapping` (the policies
    themselves by :func:`check_policy` where the seats are known)."""
    return check_mapping(seat_policies, "seat_policies", int,
                         "{1: alphatank.bots.make_bot('smart')}")


def check_learner_seats(sc: Scenario, seats: Any) -> list[int] | None:
    """``seats`` (the learner seats a vector env drives; None: all) as a list of ints;
    ScenarioError unless distinct learner seats of ``sc``."""
    if seats is None:
        return None
    allowed = f"its learner seats: {sc.learner_seats}"
    if isinstance(seats, str) or not isinstance(seats, Iterable):
        raise ScenarioError(f"{sc.source}: learner_seats must be a list of seat indices, got "
                            f"{seats!r}; {allowed}")
    seats = list(seats)
    strays = [s for s in seats if check_value((int,), s)[1] or s not in sc.learner_seats]
    if strays:
        raise ScenarioError(f"{sc.source}: learner_seats {strays} are not learner seats; "
                            f"{allowed}")
    twice = sorted({int(s) for s in seats if seats.count(s) > 1})
    if twice:
        raise ScenarioError(f"{sc.source}: learner_seats names seat(s) {twice} more than "
                            f"once; {allowed}")
    return [int(s) for s in seats]


def check_step_limit(steps: Any, what: str) -> int:
    """``steps`` (an argument ``what`` that sets GameConfig.max_steps, e.g. PettingZoo's
    ``max_cycles``) as an int; ScenarioError naming ``what`` unless in max_steps' range."""
    value, why = check_value((int,), steps, (1, MAX_STEPS_MAX))
    if why:
        raise ScenarioError(f"{what}: {why}")
    return value


def check_action_repeat(k: Any) -> None:
    """ValueError unless ``k`` is a whole number of ticks in 1..ACTION_REPEAT_MAX."""
    if check_value((int,), k, (1, ACTION_REPEAT_MAX))[1]:
        raise ValueError(f"action_repeat must be a whole number of ticks in "
                         f"1..{ACTION_REPEAT_MAX}, got {k!r}")


class MatchSet:
    """``num_envs`` matches of a scenario; the caller drives ``driven`` seats (default:
    the scenario's learner seats) and the set plays every other seat. With
    ``action_repeat`` k each :meth:`step` holds the driven seats' actions for k ticks
    (fewer when the match ends first) while the other seats act every tick. ``slots``
    (walls, buff zones, debuff zones) pads the observations to at least that room, as a
    policy trained with it sees maps with fewer."""

    def __init__(self, scenario: str | Scenario, num_envs: int = 1, *,
                 observation: str | None = None, game_overrides: Mapping | None = None,
                 reward_overrides: Mapping | None = None,
                 driven: Sequence[int] | None = None,
                 seat_policies: Mapping[int, Policy] | None = None,
                 env_ids: Sequence[int] | None = None, action_repeat: int = 1,
                 slots: tuple[int, int, int] = (0, 0, 0)):
        sc = self.scenario = load_scenario(scenario)
        num_envs = check_num_envs(num_envs)
        check_action_repeat(action_repeat)
        self.action_repeat = int(action_repeat)
        self.num_envs = E = num_envs
        self.env_ids = list(range(E)) if env_ids is None else list(env_ids)
        self.game = sc.game_config(**check_overrides(game_overrides, "game_overrides"))
        self.reward_cfg = sc.reward_config(**check_overrides(reward_overrides,
                                                             "reward_overrides"))
        self.specs = sc.map_specs()
        self.kind = sc.observation if observation is None else observation
        if self.kind not in OBS_KINDS:
            raise ScenarioError(f"observation {self.kind!r} is not one of {list(OBS_KINDS)}")
        self.teams = sc.teams
        self.n = n = len(sc.seats)
        self.driven = list(sc.learner_seats if driven is None else driven)
        for s in self.driven:
            if not 0 <= s < n:
                raise ScenarioError(f"{sc.source}: driven seat {s} out of range 0..{n - 1}")
        self.seat_policies = check_seat_policies(seat_policies)
        for s, policy in self.seat_policies.items():
            if s in self.driven or not 0 <= s < n:
                raise ScenarioError(f"{sc.source}: seat_policies names seat {s}; allowed: "
                                    f"{[i for i in range(n) if i not in self.driven]}")
            check_policy(policy, f"seat_policies[{s}]")
        orphans = [s for s in sc.learner_seats
                   if s not in self.driven and s not in self.seat_policies]
        self.orphans = orphans  # learner seats nobody drives: need an opponent policy
        self.opponent_policy: Policy | None = None
        self.opponents: dict[str, Seat | Policy] = {}  # named, for set_env_opponents
        self.env_opponent: list[str | None] = [None] * E
        self.episode_label: list[str] = ["none"] * E  # who the current episode is against
        self.bot_override: list[str] | None = None
        self.weakness: float | None = None
        self.benched: tuple[int, ...] = ()  # seats out of every next episode (set_benched)
        walls, buffs, debuffs = (max(int(a), int(b)) for a, b in
                                 zip(slot_counts(self.game, self.specs), slots, strict=True))
        self.batch = StateBatch(self.game, n, E, walls, buffs, debuffs)
        self.obs = ObservationBuilder(self.kind, self.batch, self.teams, self.driven,
                                      team_flags=sc.team_mode)
        self.global_state = GlobalState(self.batch, self.teams)
        self.tracker = RewardTracker(self.reward_cfg, self.game, self.teams, E,
                                     rewarded=self.driven)
        self._acc = np.zeros_like(self.tracker.terms)  # a step's terms over its ticks
        self.matches: list[Match] = []
        self.map_index = np.zeros(E, dtype=np.int64)
        self.controllers: list[list[Policy | None]] = [[None] * n for _ in range(E)]
        self._bots: list[dict[int, tuple[tuple, Policy]]] = [{} for _ in range(E)]
        # seat specs whose controller is a batch policy: one object for every env and seat
        self._shared: dict[tuple, BatchPolicy] = {}
        # per env, the seats this set plays and their controllers: all of them, those that
        # act one match at a time, and the batch policies (asked for every env at once)
        self._played: list[list[tuple[int, Policy]]] = [[] for _ in range(E)]
        self._single: list[list[tuple[int, Policy]]] = [[] for _ in range(E)]
        self._batched: list[list[tuple[int, BatchPolicy]]] = [[] for _ in range(E)]
        # the observations of the seats this set plays, one builder per way the batch
        # policies that play them observe (None: one this batch cannot serve), rebuilt
        # when ``batch`` changed since (``_version`` counts its gathers)
        self.played_seats = np.array([s for s in range(n) if s not in self.driven],
                                     dtype=np.int64)
        self._seat_obs: dict[tuple, ObservationBuilder | None] = {}
        self._seat_obs_at: dict[tuple, int] = {}
        self._version = 0
        self._orphaned: list[int] = []  # envs whose driven seats all died this step
        self.joint = np.ones((E, n, 3), dtype=np.int64)
        self._joint_rows = list(self.joint)  # per-env views
        self.driven_idx = np.array(self.driven, dtype=np.int64)
        self._driven_sel = as_index(self.driven_idx)
        # Episode ends of the current step (set as matches end, cleared at reset).
        self.terminated = np.zeros(E, dtype=bool)
        self.truncated = np.zeros(E, dtype=bool)
        cap = self.game.bullet_capacity
        self._driven_bullets = np.isin(np.arange(n * cap) // cap, self.driven_idx)
        self.team_of = np.array([sc.seats[s].team for s in self.driven], dtype=object)
        # called as tick_watch(e, match, events) after every tick (e.g. team statistics)
        self.tick_watch: Callable[[int, Match, TickEvents], None] | None = None

    # ---- pickling -------------------------------------------------------------------

    def __getstate__(self) -> dict[str, Any]:
        """Everything but the live matches and their controllers: pymunk's solver caches
        do not survive pickling bit for bit, so an unpickled set must be reset (episodes
        are reproducible from their seeds)."""
        state = self.__dict__.copy()
        state["matches"] = []
        state["_seat_obs"], state["_seat_obs_at"] = {}, {}  # rebuilt on demand
        state["controllers"] = [[None] * self.n for _ in range(self.num_envs)]
        state["_bots"] = [{} for _ in range(self.num_envs)]
        state["_shared"] = {}
        for key in ("_played", "_single", "_batched"):
            state[key] = [[] for _ in range(self.num_envs)]
        del state["_joint_rows"]  # views of ``joint``: rebuilt on unpickling
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._joint_rows = list(self.joint)

    # ---- spaces ---------------------------------------------------------------------

    @property
    def obs_dim(self) -> int:
        return self.obs.layout.size

    def observation_space(self) -> spaces.Box:
        return spaces.Box(-1.0, 1.0, shape=(self.obs_dim,), dtype=np.float32)

    def state_space(self) -> spaces.Box:
        return spaces.Box(-1.0, 1.0, shape=(self.global_state.layout.size,), dtype=np.float32)

    # ---- controllers ----------------------------------------------------------------

    def seat_controller_spec(self, e: int, seat: int) -> Seat | Policy | None:
        """Who plays ``seat`` in env ``e`` next episode: None (driven), a Policy object,
        or the scenario Seat (possibly with bot type / weakness overridden)."""
        if seat in self.driven:
            return None
        if seat in self.seat_policies:
            return self.seat_policies[seat]
        name = self.env_opponent[e]
        if name is not None:
            opp = self.opponents[name]
            return dataclasses.replace(opp, team=self.teams[seat]) if isinstance(opp, Seat) else opp
        if self.opponent_policy is not None:
            return self.opponent_policy
        s = self.scenario.seats[seat]
        if s.controller == "learner":
            raise ScenarioError(
                f"{self.scenario.source}: seats[{seat}] is a learner seat that this env does "
                f"not drive (it drives seats {self.driven}); pass a Policy for seats "
                f"{self.orphans} (seat_policies= or opponent_policy=)")
        if s.controller == "bot" and (self.bot_override or self.weakness is not None):
            bot = (self.bot_override[self.env_ids[e] % len(self.bot_override)]
                   if self.bot_override else s.bot)
            w = s.weakness if self.weakness is None else self.weakness
            opts = s.options if bot == s.bot else {}
            s = Seat(s.team, "bot", bot=bot, weakness=w, options=opts)
        return s

    def add_opponent(self, name: str, opponent: str | Policy) -> None:
        """Register a named opponent for :meth:`set_env_opponents`: a seat spec
        (``smart@0.5``, ``checkpoint:PATH``, ``agent:NAME``) or a Policy (one object may
        fill every seat of every env: policies keep their state per match and seat)."""
        self.opponents[name] = opponent_entry(name, opponent)

    def set_env_opponents(self, names: Sequence[str | None]) -> None:
        """Per env: the named opponent that fills every seat this set plays (not the
        ``seat_policies``) from that env's next episode; None restores the default."""
        self.env_opponent = check_env_opponents(names, self.num_envs, self.opponents)

    def set_benched(self, seats: Sequence[int]) -> None:
        """Bot seats left out of every env's next episodes (a line-up curriculum; see
        :func:`check_benched`); ``()`` restores the full line-up."""
        self.benched = check_benched(self.scenario, self.driven, seats)

    def describe_opponents(self, e: int) -> str:
        """Label of the seats this set plays in env ``e`` from its next episode, e.g.
        ``B:smart(w=1)``; a named opponent (:meth:`set_env_opponents`) is labelled by its
        name. ``episode_label[e]`` keeps the label of the episode being played (taken at
        its reset: opponents changed during an episode apply from the next one)."""
        name = self.env_opponent[e]
        if name is not None:
            teams = dict.fromkeys(self.teams[s] for s in range(self.n)
                                  if s not in self.driven and s not in self.seat_policies)
            return ", ".join(f"{t}:{name}" for t in teams) or "none"
        parts = []
        for seat in range(self.n):
            c = self.seat_controller_spec(e, seat)
            if c is None:
                continue
            label = ("absent" if seat in self.benched else c.describe() if isinstance(c, Seat)
                     else f"policy:{type(c).__name__}")
            parts.append(f"{self.teams[seat]}:{label}")
        return ", ".join(parts) or "none"

    def _controller(self, e: int, seat: int, seed: int) -> Policy | None:
        spec = self.seat_controller_spec(e, seat)
        if spec is None or not isinstance(spec, Seat):
            return spec
        key = (spec.controller, spec.bot, spec.weakness, tuple(sorted(spec.options.items())),
               spec.keys, spec.path, spec.agent)
        cached = self._bots[e].get(seat)
        if cached is not None and cached[0] == key:
            return cached[1]
        pol = self._shared.get(key) or make_controller(spec, seed)
        if is_batch_policy(pol):  # keeps its state per match and seat
            self._shared[key] = pol
        self._bots[e][seat] = (key, pol)
        return pol

    # ---- episodes -------------------------------------------------------------------

    def reset_env(self, e: int, seed: int) -> None:
        """Start a new episode in env ``e``, everything derived from ``seed``."""
        seeds = episode_seeds(seed, self.n, len(self.specs))
        old = self.matches[e] if e < len(self.matches) else None
        m = episode_match(self.game, self.specs, self.teams, seeds, old)
        if self.benched:
            m.bench(self.benched)
        if old is None:
            self.matches.append(m)
        else:
            self.matches[e] = m
        self.map_index[e] = seeds.map_index
        ctrls = self.controllers[e]
        for seat in range(self.n):
            ctrls[seat] = self._controller(e, seat, seeds.seat_seeds[seat])
        reset_controllers(m, ctrls, seeds)
        self.episode_label[e] = self.describe_opponents(e)
        played = self._played[e] = [(seat, c) for seat, c in enumerate(ctrls) if c is not None]
        single, batched = [], []
        for pair in played:
            (batched if is_batch_policy(pair[1]) else single).append(pair)
        self._single[e], self._batched[e] = single, batched
        self.joint[e] = 1
        self.terminated[e] = self.truncated[e] = False
        b = self.batch
        b.set_static(e, m)
        b.gather(e, m)
        self._version += 1
        self.obs.set_static(e)
        for builder in self._seat_obs.values():
            if builder is not None:
                builder.set_static(e)
        self.tracker.reset_env(e, m)

    def reset_all(self, seeds: Sequence[int]) -> np.ndarray:
        for e, s in enumerate(seeds):
            self.reset_env(e, int(s))
        return self.obs.build()

    # ---- stepping -------------------------------------------------------------------

    def _tick(self, e: int, batched: bool = False) -> None:
        """One tick of env ``e`` with the driven seats' rows of ``joint`` already set;
        the set's controllers fill the other live seats (``batched``: the batch policies'
        seats are set too, by :meth:`_act_batched`)."""
        m, joint = self.matches[e], self._joint_rows[e]
        alive = m.alive
        for seat, ctrl in (self._single[e] if batched else self._played[e]):
            if alive[seat]:
                joint[seat] = ctrl.act(m, seat)
        events = m.step(joint)
        for seat in self.driven:  # none of them alive: play the match out (_step_all)
            if alive[seat]:
                break
        else:
            if self.driven:
                self._orphaned.append(e)
        if self.tick_watch is not None:
            self.tick_watch(e, m, events)
        self.batch.gather(e, m)
        self._version += 1
        if m.terminated or m.truncated:
            self.terminated[e], self.truncated[e] = m.terminated, m.truncated

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """One tick in every env (``action_repeat`` ticks, the driven seats' actions
        held). ``actions``: validated int (E, L, 3). Returns the (E, len(TERMS), n) reward
        terms of this step, summed over its ticks, and the (E, L, D) observations
        (internal buffers: copy what you keep). ``terminated`` / ``truncated`` hold the
        episode ends."""
        if len(self.matches) < self.num_envs:
            raise RuntimeError("step() before reset() (an unpickled env must be reset)")
        terms = self._step_all(actions, None)
        if self.action_repeat > 1:
            acc = self._acc
            acc[...] = terms
            for _ in range(self.action_repeat - 1):
                live = ~(self.terminated | self.truncated)
                if not live.any():
                    break
                acc += self._step_all(actions, live) * live[:, None, None]
            terms = acc
        return terms, self.obs.build()

    def _step_all(self, actions: np.ndarray, live: np.ndarray | None) -> np.ndarray:
        """One tick of every env (of the ``live`` ones only, when given); its terms."""
        if len(self.driven):
            self.joint[:, self._driven_sel] = actions
        batched = any(self._batched)
        if batched:
            self._act_batched(live)
        self._orphaned = []
        for e in range(self.num_envs):
            if live is None or live[e]:
                self._tick(e, batched)
        terms = self.tracker.step(slice(None), self.batch, self.matches, self.joint)
        orphaned, self._orphaned = self._orphaned, []  # play-outs tick too
        for e in orphaned:  # no driven seat alive: play the match out now
            if not (self.terminated[e] or self.truncated[e]):
                self._play_out(e)
        return terms

    def _act_batched(self, live: np.ndarray | None) -> None:
        """Into ``joint``: the actions of every batch policy's live seats in the envs
        about to tick, one :meth:`~alphatank.sim.policy.BatchPolicy.act_batch` call per
        policy object."""
        groups: dict[int, tuple[BatchPolicy, list[tuple[int, int]]]] = {}
        for e in range(self.num_envs):
            if live is not None and not live[e]:
                continue
            alive = self.matches[e].alive
            for seat, ctrl in self._batched[e]:
                if alive[seat]:
                    groups.setdefault(id(ctrl), (ctrl, []))[1].append((e, seat))
        matches, joint = self.matches, self.joint
        for ctrl, pairs in groups.values():
            envs = np.array([e for e, _ in pairs])
            seats = np.array([seat for _, seat in pairs])

            def observe(setting: Any, obs_dim: int, rows: np.ndarray,
                        envs: np.ndarray = envs, seats: np.ndarray = seats
                        ) -> np.ndarray | None:
                return self.seat_observations(setting, obs_dim, envs[rows], seats[rows])

            acts = ctrl.act_batch([(matches[e], seat) for e, seat in pairs], observe)
            for (e, seat), a in zip(pairs, acts, strict=True):
                joint[e, seat] = a

    def seat_observations(self, setting: Any, obs_dim: int, envs: np.ndarray,
                          seats: np.ndarray) -> np.ndarray | None:
        """Observations (k, obs_dim) of played seats ``seats`` of envs ``envs`` in
        ``setting`` = (kind, team_flags, max_walls, max_buffs, max_debuffs), from this
        set's ``batch`` as gathered now; one build per way of observing and batch change
        serves every policy. None where this batch cannot build them exactly as the policy's own
        observations: another size, or the ``advice`` kinds (whose bot asked per
        observation would move on every tick, not at the policy's decisions)."""
        kind, team_flags, walls, buffs, debuffs = setting
        # only the paper kind has wall and zone blocks; the others read any capacity
        key = (kind, team_flags, *((walls, buffs, debuffs) if kind == "paper" else ()))
        if key not in self._seat_obs:
            self._seat_obs[key] = self._serve(kind, team_flags, (walls, buffs, debuffs))
        builder = self._seat_obs[key]
        if builder is None or builder.layout.size != obs_dim:
            return None
        if self._seat_obs_at.get(key) != self._version:
            builder.build()
            self._seat_obs_at[key] = self._version
        col = np.searchsorted(self.played_seats, seats)
        return builder.out[envs, col]

    def _serve(self, kind: str, team_flags: bool, slots: tuple[int, int, int]
               ) -> ObservationBuilder | None:
        """A builder of the played seats' observations on ``batch``, statics set; None
        where it could not match the policy's own (see :meth:`seat_observations`)."""
        b = self.batch
        if (kind in ADVICE_KINDS or not len(self.played_seats)
                or (kind == "paper"
                    and (b.walls.shape[1], b.max_buffs, b.max_debuffs) != slots)):
            return None
        builder = ObservationBuilder(kind, b, self.teams, self.played_seats.tolist(),
                                     team_flags=team_flags)
        for e, m in enumerate(self.matches):
            builder.set_static(e)
            if b.shot_seats:  # the shots of seats wanted only now
                b.trace_shots(e, m)
        return builder

    def _play_out(self, e: int) -> None:
        """Finish env ``e``'s match without its (dead) driven seats; adds the rewards of
        the remaining ticks to this step's terms. Only ticks where a driven seat's bullet
        still flies, and the last one, can reward a dead driven seat: only those are
        scored."""
        acc = self.tracker.terms[e].copy()
        m, sl = self.matches[e], slice(e, e + 1)
        mine = self._driven_bullets
        while not m.done:
            self.joint[e, self._driven_sel] = NOOP
            self._tick(e)
            if m.done or (m.bullet_active & mine).any():
                acc += self.tracker.step(sl, self.batch, self.matches, self.joint)[0]
        self.tracker.terms[e] = acc

    def rewards(self, terms: np.ndarray) -> np.ndarray:
        """(E, L) per-step rewards of the driven seats."""
        return terms[:, :, self.driven_idx].sum(axis=1)

    def outcome(self, e: int) -> list[str]:
        """'win' / 'loss' / 'draw' of each driven seat in env ``e``'s finished match."""
        w = self.matches[e].winner
        return ["draw" if w is None else "win" if t == w else "loss" for t in self.team_of]

    def map_name(self, e: int) -> str:
        return self.specs[int(self.map_index[e])].name

    def first_match(self, call: str) -> Match:
        """Match 0 (a single env's match) for ``call``; RuntimeError before a reset."""
        if not self.matches:
            raise RuntimeError(f"{call} before reset() (an unpickled env must be reset)")
        return self.matches[0]



class FirstMatchRenderer:
    """Draws match 0 of a :class:`MatchSet` with its controllers' overlays. The pygame
    renderer is made on the first ``render()`` (so ``render_mode=None`` never touches
    pygame) and is not pickled; ``human`` mode is refused at once where no window can
    show (DisplayUnavailable), unless ``SDL_VIDEODRIVER`` names a driver that shows
    nothing (automated tests)."""

    def __init__(self, core: MatchSet, mode: str, fps: float):
        self.core, self.mode, self.fps = core, mode, fps
        self._renderer: Any = None
        if mode == "human":  # refused at once where no window would show
            import pygame

            from alphatank.ui.render import DisplayUnavailable, init_display

            try:
                init_display()
            except DisplayUnavailable as exc:
                raise DisplayUnavailable(f"render_mode='human' needs a display ({exc}); "
                                         "render_mode='rgb_array' gives the frames as "
                                         "arrays") from None
            pygame.display.quit()  # only asked: the window opens on the first render()

    def render(self) -> np.ndarray | None:
        if self._renderer is None:
            from alphatank.ui.render import Renderer

            self._renderer = Renderer(self.mode, fps=self.fps)
        return self._renderer.render(self.core.first_match("render()"),
                                     self.core.controllers[0])

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def __getstate__(self) -> dict[str, Any]:
        return {**self.__dict__, "_renderer": None}

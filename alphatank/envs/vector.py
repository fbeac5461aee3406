"""Batched envs: many matches of one scenario stepped together in one process (or split
over worker processes), arrays in and out.

Two faces over one engine:

:class:`TankBattleVectorEnv` is a ``gymnasium.vector.VectorEnv``, the vector entry point of
every AlphaTank id: ``gymnasium.make_vec("AlphaTank/VsSmart-v0", num_envs=16,
vectorization_mode="vector_entry_point")``. Each sub-env is exactly
``gymnasium.make(id)``'s env (one learner seat; the env plays every other seat).

* Action space: ``MultiDiscrete([[3, 3, 2]] * num_envs)``, int (num_envs, 3): rotate
  {0 ccw, 1 none, 2 cw}, move {0 back, 1 stop, 2 forward}, fire {0, 1}.
* Observation space: ``Box(-1, 1, (num_envs, obs_dim), float32)``; the layout (feature
  name -> column) is ``env.layout``; docs/environments.md tabulates it.
* Rewards: float32 (num_envs,), the sum of the scenario's reward terms for the learner this
  step (RewardConfig; defaults: the paper's Table 5).
* Episode end: terminated when at most one team has a live tank, truncated at
  ``max_steps``. Autoreset is ``AutoresetMode.SAME_STEP``: an ended sub-env is reset in the
  same ``step``; the returned observation is its new episode's first, and ``infos`` holds
  ``final_obs`` (object array, the last observation where ``_final_obs``) and
  ``final_info`` (dict of arrays masked by ``_final_info``: winner, outcome, map,
  opponent, return, length, and ``terms``: the episode's reward by term).
* Seeding: ``reset(seed=s)`` gives env ``i`` its ``k``-th episode seed
  ``SeedSequence(s, spawn_key=(i, k))``; ``reset()`` continues with fresh episodes.
* Arguments: ``scenario``, ``num_envs``, ``observation``, ``learner_seat``,
  ``opponent_policy``, ``seat_policies``, ``game_overrides``, ``reward_overrides``,
  ``action_repeat`` (ticks each step holds the action for, as the single env),
  ``num_workers`` (>1: worker processes, same results), ``render_mode`` (None or
  ``"rgb_array"``: ``render()`` returns one frame per sub-env), ``max_episode_steps``
  (what ``make_vec`` passes for ``gymnasium.make``'s TimeLimit: the sub-envs' episodes
  are truncated after that many steps, as the game's ``max_steps`` where it is lower).
* Version history: see :mod:`alphatank.envs.gym` (one ``ENV_VERSION`` for all envs).

The engine under it, :class:`VectorMatchEnv` (``env.engine``), drives *every* learner seat
of a scenario and speaks (num_envs, L learners, ...) arrays: observations float32
(num_envs, L, obs_dim), actions int (num_envs, L, 3), rewards float32 (num_envs, L),
terminated / truncated bool (num_envs,); ``info["final_obs"]`` (zeros where no episode
ended) and ``info["episodes"]``, one summary dict per ended episode. Dead learners keep
their slot until their match ends. AlphaTank's trainer uses this view.

Extra per-learner inputs (for learners that need more than observations, e.g. a
centralised critic's state): an env made with ``inputs=("alive", ...)`` keeps
``env.inputs[name]`` (num_envs, L, ...) for the current step, puts the values of ended
episodes (taken before the autoreset) in ``info["final_inputs"][name]``, and gives each
one's trailing shape in ``env.input_shapes``. Input ``x`` is the method ``input_x()`` of
:class:`VectorMatchEnv`: adding an input is adding that one method.

:class:`SubprocVectorMatchEnv` has the same interface and, for the same seed, the same
results bit for bit: worker processes each own a contiguous block of envs and exchange
arrays through shared memory. :func:`make_vector_env` picks one by ``num_workers``.
Both also act whole rollouts with a frozen policy copy (``rollout``, one call per shard
per rollout: :mod:`alphatank.envs.fragments`).
"""

from __future__ import annotations

import atexit
import contextlib
import multiprocessing as mp
import pickle
import shutil
import signal
import sys
import traceback
import weakref
from collections.abc import Mapping, Sequence
from multiprocessing import shared_memory
from typing import Any

import numpy as np
from gymnasium import logger as gym_logger
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from alphatank.envs.core import (
    MatchSet,
    action_space,
    check_action_repeat,
    check_actions,
    check_benched,
    check_bot_names,
    check_env_opponents,
    check_learner_seats,
    check_num_envs,
    check_overrides,
    check_policy,
    check_reset_options,
    check_step_limit,
    check_weakness,
    opponent_entry,
)
from alphatank.envs.fragments import (
    Fragment,
    RolloutPolicy,
    SplitRollout,
    collect_fragment,
    fragment_of,
    fragment_specs,
    merge_episodes,
    merge_fragments,
)
from alphatank.envs.gym import single_learner_seat
from alphatank.game.observe import ObsLayout
from alphatank.game.rewards import TERMS
from alphatank.game.scenarios import Scenario, load_scenario
from alphatank.sim.config import check_seed, check_value
from alphatank.sim.policy import Policy


def episode_seed(seed: int, env_id: int, episode: int) -> int:
    """Seed of episode ``episode`` of env ``env_id`` in a vector env seeded ``seed``."""
    ss = np.random.SeedSequence(entropy=seed, spawn_key=(env_id, episode))
    return int(ss.generate_state(1, np.uint64)[0])


class VectorMatchEnv(SplitRollout):
    """``num_envs`` matches of ``scenario`` with every learner seat driven by the caller.

    Dead learners keep their slot until their match ends (alive flag 0 in the
    observation, actions ignored, rewards such as their team's victory still delivered).
    ``learner_seats`` picks the learner seats the caller drives (default: all); the others
    need a Policy (``seat_policies`` or :meth:`set_opponent_policy`).
    """

    render_mode = None  # the engine draws nothing (TankBattleVectorEnv renders)

    def __init__(self, scenario: str | Scenario, num_envs: int, seed: int = 0,
                 observation: str | None = None, game_overrides: dict | None = None,
                 reward_overrides: dict | None = None, *,
                 seat_policies: Mapping[int, Policy] | None = None,
                 learner_seats: Sequence[int] | None = None,
                 env_ids: Sequence[int] | None = None, inputs: Sequence[str] = (),
                 action_repeat: int = 1):
        self.scenario = sc = load_scenario(scenario)
        learner_seats = check_learner_seats(sc, learner_seats)
        if isinstance(inputs, str):
            raise ValueError(f"inputs must be a list of input names, got the string {inputs!r} "
                             f"(e.g. [{inputs!r}])")
        self.core = MatchSet(self.scenario, num_envs, observation=observation,
                             game_overrides=game_overrides, reward_overrides=reward_overrides,
                             driven=learner_seats, seat_policies=seat_policies,
                             env_ids=env_ids, action_repeat=action_repeat)
        core = self.core
        self.action_repeat = core.action_repeat
        self.num_envs = num_envs = core.num_envs
        self.num_learners = L = len(core.driven)
        self.learner_seats = list(core.driven)
        self.learner_teams = [self.scenario.seats[s].team for s in core.driven]
        self.observation_space: spaces.Box = core.observation_space()
        self.action_space: spaces.MultiDiscrete = action_space()
        self.obs_dim = core.obs_dim
        self.seed = check_seed(seed)
        self.env_ids = list(core.env_ids)
        self._episode = np.zeros(num_envs, dtype=np.int64)
        self._return = np.zeros((num_envs, L))
        self._terms = np.zeros((num_envs, len(TERMS), L))
        self._length = np.zeros(num_envs, dtype=np.int64)
        self._started = False
        self._pending: tuple[RolloutPolicy, np.ndarray, int] | None = None  # rollout_start
        self._shape = (num_envs, L, 3)
        self._input_names = tuple(inputs)
        self._agent_state: Any = None  # built on first use of input_state
        for name in inputs:
            check_input(self, name)
        self.inputs: dict[str, np.ndarray] = self._read_inputs()
        self.input_shapes = {name: a.shape[2:] for name, a in self.inputs.items()}

    # ---- extra learner inputs (see the module docstring) ------------------------------

    def _read_inputs(self) -> dict[str, np.ndarray]:
        return {name: np.array(getattr(self, f"input_{name}")(), dtype=np.float32)
                for name in self._input_names}

    def input_alive(self) -> np.ndarray:
        """(num_envs, L): 1 where the learner seat's tank is alive."""
        return self.core.batch.alive[:, self.core.driven_idx]

    def input_state(self) -> np.ndarray:
        """(num_envs, L, S): each learner seat's agent-specific global state for a
        centralised critic (:class:`~alphatank.game.state.AgentState`; zeros but the seat
        id once the seat is dead)."""
        if self._agent_state is None:
            from alphatank.game.state import AgentState
            core = self.core
            self._agent_state = AgentState(core.batch, core.teams, core.driven)
        return self._agent_state.build()

    @property
    def layout(self) -> ObsLayout:
        """Index map of one learner's observation vector."""
        return self.core.obs.layout

    # ---- opponents (take effect from each env's next episode) -------------------------

    def set_bot_weakness(self, weakness: float) -> None:
        """Weakness (0..1) of every bot seat from the next episode on (curriculum)."""
        weakness = check_weakness(weakness)
        self.check_idle("set_bot_weakness")
        self.core.weakness = weakness

    def set_opponents(self, bot_names: Sequence[str] | None,
                      weakness: float | None = None) -> None:
        """Bot type of the bot seats from the next episode on: env ``i`` uses
        ``bot_names[i % len(bot_names)]`` (one name: all envs; several: a mixture for
        cycle learning). ``None`` restores the scenario's bots."""
        bot_names = check_bot_names(bot_names)
        if weakness is not None:
            weakness = check_weakness(weakness)
        self.check_idle("set_opponents")
        self.core.bot_override = bot_names
        if weakness is not None:
            self.core.weakness = weakness

    def set_opponent_policy(self, policy: Policy | None) -> None:
        """A frozen Policy in every non-learner seat from the next episode on (self-play
        against a snapshot); ``None`` restores the scenario's controllers."""
        if policy is not None:
            check_policy(policy, "set_opponent_policy's policy")
        self.check_idle("set_opponent_policy")
        self.core.opponent_policy = policy

    def set_benched(self, seats: Sequence[int]) -> None:
        """Bot seats left out of the next episodes (dead from the start: a line-up
        curriculum); ``()`` restores the full line-up."""
        self.check_idle("set_benched")
        self.core.set_benched(seats)

    def add_opponent(self, name: str, opponent: str | Policy) -> None:
        """Register a named opponent (a seat spec such as ``smart@0.5`` or
        ``checkpoint:PATH``, or a Policy) for :meth:`set_env_opponents`."""
        self.check_idle("add_opponent")
        self.core.add_opponent(name, opponent)

    def set_env_opponents(self, names: Sequence[str | None]) -> None:
        """One registered opponent name per env (None: the scenario's own controllers),
        filling every non-learner seat from that env's next episode (league and
        self-play pools)."""
        self.check_idle("set_env_opponents")
        self.core.set_env_opponents(names)

    # ---- episodes -------------------------------------------------------------------

    def _reset_env(self, e: int) -> None:
        self.core.reset_env(e, episode_seed(self.seed, self.env_ids[e], int(self._episode[e])))
        self._episode[e] += 1
        self._return[e] = 0.0
        self._terms[e] = 0.0
        self._length[e] = 0

    def reset(self, seed: int | None = None) -> np.ndarray:
        """Reset every env. A new ``seed`` restarts the episode sequence; ``None``
        continues it (fresh episodes). Returns (num_envs, L, obs_dim) float32."""
        self.check_idle("reset")
        if seed is not None:
            self.seed = check_seed(seed)
            self._episode[:] = 0
        for e in range(self.num_envs):
            self._reset_env(e)
        self._started = True
        obs = self.core.obs.build().copy()
        self.inputs = self._read_inputs()
        return obs

    def step(self, actions: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                          dict[str, Any]]:
        """One tick in every env, with SAME_STEP autoreset of ended envs."""
        if not self._started:
            raise RuntimeError("step() before reset()")
        self.check_idle("step")
        return self._step(check_actions(actions, self._shape, self._name))

    def _step(self, acts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                               np.ndarray, dict[str, Any]]:
        """:meth:`step` with validated int64 (num_envs, L, 3) actions."""
        E, L, D = self.num_envs, self.num_learners, self.obs_dim
        obs, final_obs = np.empty((E, L, D), np.float32), np.zeros((E, L, D), np.float32)
        rewards = np.empty((E, L), np.float32)
        terminated, truncated = np.empty(E, bool), np.empty(E, bool)
        final_inputs = {name: np.zeros_like(a) for name, a in self.inputs.items()}
        episodes = self.step_into(acts, obs, rewards, terminated, truncated, final_obs,
                                   final_inputs)
        return obs, rewards, terminated, truncated, {"final_obs": final_obs,
                                                     "episodes": episodes,
                                                     "final_inputs": final_inputs}

    def step_into(self, acts: np.ndarray, obs: np.ndarray, rewards: np.ndarray,
                  terminated: np.ndarray, truncated: np.ndarray, final_obs: np.ndarray,
                  final_inputs: dict[str, np.ndarray]) -> list[dict[str, Any]]:
        """One step written into the given arrays (what local workers and Ray env runners
        call with their shared buffers; ``final_obs``, ``final_inputs``: only the rows of
        ended episodes are written; the caller keeps the others zero). Returns the
        episode records; ``self.inputs`` holds the step's inputs."""
        core = self.core
        terms, built = core.step(acts)
        lt = terms[:, :, core.driven_idx]  # (E, T, L)
        reward = np.add.reduce(lt, axis=1)
        self._return += reward
        self._terms += lt
        self._length += 1
        rewards[...] = reward
        terminated[...] = core.terminated
        truncated[...] = core.truncated
        episodes = []
        done = (terminated | truncated).nonzero()[0]
        if done.size:
            final_obs[done] = built[done]
            for name in self._input_names:
                final_inputs[name][done] = getattr(self, f"input_{name}")()[done]
            for e in done.tolist():
                m = core.matches[e]
                episodes.append({
                    "env": self.env_ids[e], "return": self._return[e].copy(),
                    "length": int(self._length[e]), "winner": m.winner,
                    "outcome": core.outcome(e), "opponent": core.episode_label[e],
                    "map": core.map_name(e),
                    "terms": dict(zip(TERMS, self._terms[e].copy(), strict=True))})
                self._reset_env(e)
            built = core.obs.build()
        obs[...] = built
        if self._input_names:
            self.inputs = self._read_inputs()
        return episodes

    def rollout_start(self, policy: RolloutPolicy, obs: np.ndarray, steps: int) -> None:
        """Begin :meth:`rollout`; :meth:`rollout_finish` returns its fragment. In one
        process the rollout is played at the finish, by the copy given here, so a run that
        overlaps rollouts with updates (``train --overlap``) is the same run here as in one
        worker process."""
        if not self._started:
            raise RuntimeError("rollout() before reset()")
        if self._pending is not None:
            raise RuntimeError("rollout_start() while a rollout is in flight")
        self._pending = (policy, obs.copy(), steps)

    def rollout_finish(self) -> Fragment:
        """The fragment of the rollout begun by :meth:`rollout_start`."""
        if self._pending is None:
            raise RuntimeError("rollout_finish() without rollout_start()")
        args, self._pending = self._pending, None
        return collect_fragment(self, *args)

    @property
    def rollout_in_flight(self) -> bool:
        return self._pending is not None

    def _name(self, idx: tuple[int, ...]) -> str:
        e, slot = idx
        seat = self.learner_seats[slot]
        return (f"env {self.env_ids[e]}, learner {slot} (seat {seat}, team "
                f"{self.learner_teams[slot]})")

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_started"] = False  # the live matches are not carried: reset after unpickling
        return state

    def close(self) -> None:
        """Drop a rollout started and not finished (nothing else to release in-process)."""
        self._pending = None


# ---- worker processes ---------------------------------------------------------------

def _nbytes(shape: tuple[int, ...], dtype: str) -> int:
    return int(np.prod(shape)) * np.dtype(dtype).itemsize


class _Shared:
    """Named shared-memory arrays of a subprocess vector env."""

    def __init__(self, specs: dict[str, tuple[tuple[int, ...], str]],
                 names: dict[str, str] | None = None):
        self.specs = specs
        self.mem: dict[str, shared_memory.SharedMemory] = {}
        self.arr: dict[str, np.ndarray] = {}
        for key, (shape, dtype) in specs.items():
            size = max(1, _nbytes(shape, dtype))
            if names is None:
                mem = shared_memory.SharedMemory(create=True, size=size)
            else:
                mem = shared_memory.SharedMemory(name=names[key])
            self.mem[key] = mem
            self.arr[key] = np.ndarray(shape, dtype=dtype, buffer=mem.buf)

    @property
    def names(self) -> dict[str, str]:
        return {k: m.name for k, m in self.mem.items()}

    def close(self, unlink: bool) -> None:
        self.arr.clear()
        for m in self.mem.values():
            m.close()
            if unlink:
                m.unlink()
        self.mem.clear()


def _shm_room(size: int) -> bool:
    """Whether ``size`` more bytes of shared memory fit: /dev/shm (a tmpfs, 64 MB by
    default in a container) has room for them and a tenth of its size to spare. Shared
    memory past its end would kill the process that writes it (SIGBUS)."""
    try:
        usage = shutil.disk_usage("/dev/shm")
    except OSError:  # no /dev/shm: not Linux, nothing to check
        return True
    return size + usage.total // 10 <= usage.free


_STEP = b"s"  # the per-step command and its answer travel as raw bytes, not pickles


def _worker(conn: Any, kwargs: dict, lo: int, hi: int, specs: dict, names: dict) -> None:
    """Own envs lo..hi-1; answer commands from the parent until 'close'. A step reads
    the validated actions from shared memory and writes every result there; its answer
    is empty bytes, or the pickled episode records when episodes ended."""
    # Ctrl-C reaches the whole process group and `timeout` signals it too: the parent
    # decides when to stop (it saves a checkpoint first) and closes the workers
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    shared = _Shared(specs, names)
    frag: _Shared | None = None  # the parent's fragment arrays, once it sends them
    a = shared.arr
    try:
        env = VectorMatchEnv(num_envs=hi - lo, env_ids=range(lo, hi), **kwargs)
        out = [a[k][lo:hi] for k in ("obs", "rewards", "terminated", "truncated", "final_obs")]
        final_inputs = {name: a[f"final:{name}"][lo:hi] for name in env.inputs}
        input_rows = {name: a[f"input:{name}"][lo:hi] for name in env.inputs}
        finals, dirty = [out[-1], *final_inputs.values()], False
        conn.send(("ok", None))
        while True:
            msg = conn.recv_bytes()
            if msg == _STEP:
                if dirty:  # last step's final observations and inputs
                    for arr in finals:
                        arr.fill(0)
                episodes = env.step_into(a["actions"][lo:hi], *out, final_inputs)
                for name, rows in input_rows.items():
                    rows[...] = env.inputs[name]
                dirty = bool(episodes)
                conn.send_bytes(pickle.dumps(("ok", episodes)) if episodes else b"")
                continue
            cmd, arg = pickle.loads(msg)
            if cmd == "reset":
                a["obs"][lo:hi] = env.reset(arg)
                for name, rows in input_rows.items():
                    rows[...] = env.inputs[name]
                for arr in finals:
                    arr.fill(0)
                dirty = False
                conn.send(("ok", None))
            elif cmd == "call":
                name, args = arg
                getattr(env, name)(*args)
                conn.send(("ok", None))
            elif cmd == "rollout":  # (policy, obs, steps): the fragment goes by the pipe
                conn.send(("ok", env.rollout(*arg)))
            elif cmd == "rollout_shared":  # the fragment goes to the parent's shared arrays
                policy, obs, steps, frag_specs, frag_names = arg
                if frag is None or frag.names != frag_names:
                    if frag is not None:
                        frag.close(unlink=False)
                    frag = _Shared(frag_specs, frag_names)
                views = {k: v[:, lo:hi] for k, v in frag.arr.items()}
                conn.send(("ok", collect_fragment(env, policy, obs, steps, views).episodes))
            elif cmd == "close":
                conn.send(("ok", None))
                break
    except BaseException as exc:  # report any failure to the parent, then stop
        with contextlib.suppress(OSError):  # else the parent is gone: nobody to tell
            conn.send(("error", f"{type(exc).__name__}: {exc}\n{traceback.format_exc()}"))
    finally:
        shared.close(unlink=False)
        if frag is not None:
            frag.close(unlink=False)
        conn.close()


class ShardedEnv:
    """What the sharded vector envs (worker processes here, Ray actors in
    :mod:`alphatank.envs.ray_vector`) share: the description of the batch, taken from a
    one-match probe, the keyword arguments each shard's :class:`VectorMatchEnv` is made
    with, and the blocks of env ids the shards own."""

    def _plan_shards(self, scenario: str | Scenario, num_envs: int, num_shards: int,
                     seed: int, observation: str | None, game_overrides: dict | None,
                     reward_overrides: dict | None, seat_policies: Mapping[int, Policy] | None,
                     learner_seats: Sequence[int] | None, inputs: Sequence[str],
                     action_repeat: int = 1) -> dict:
        """Describe the batch, set ``_blocks`` ((lo, hi) env ids per shard) and return the
        shards' VectorMatchEnv keyword arguments."""
        probe = VectorMatchEnv(scenario, 1, seed, observation, game_overrides,
                               reward_overrides, seat_policies=seat_policies,
                               learner_seats=learner_seats, inputs=inputs,
                               action_repeat=action_repeat)
        self.action_repeat = probe.action_repeat
        self.scenario = probe.scenario
        self.num_envs, self.num_learners = num_envs, probe.num_learners
        self.learner_seats, self.learner_teams = probe.learner_seats, probe.learner_teams
        self.observation_space, self.action_space = probe.observation_space, probe.action_space
        self.obs_dim, self.layout, self.seed = probe.obs_dim, probe.layout, check_seed(seed)
        self.input_shapes = probe.input_shapes
        bounds = np.linspace(0, num_envs, num_shards + 1).round().astype(int)
        self._blocks = list(zip(bounds[:-1].tolist(), bounds[1:].tolist(), strict=True))
        return {"scenario": self.scenario, "seed": seed, "observation": observation,
                "game_overrides": game_overrides, "reward_overrides": reward_overrides,
                "seat_policies": seat_policies, "learner_seats": learner_seats,
                "inputs": tuple(inputs), "action_repeat": self.action_repeat}

    def _name(self, idx: tuple[int, ...]) -> str:
        e, slot = idx
        return (f"env {e}, learner {slot} (seat {self.learner_seats[slot]}, team "
                f"{self.learner_teams[slot]})")


# worker envs not closed yet: closed at exit, before multiprocessing's own exit handler
# (registered earlier, so run later) would wait for workers that ignore SIGTERM
_OPEN_ENVS: weakref.WeakSet[SubprocVectorMatchEnv] = weakref.WeakSet()


def _close_open_envs() -> None:
    for env in list(_OPEN_ENVS):
        env.close()


def worker_context(start_method: str | None = None) -> Any:
    """The multiprocessing context worker processes start in: ``start_method``, by default
    "forkserver" where the platform has it, else "spawn" (both safe next to torch's
    threads). The fork server imports this module, and torch when this process has, once;
    each worker is then forked from it instead of importing them again (seconds a worker
    on a slow machine). The server starts with SIGINT blocked: it ignores SIGINT only once
    those imports are done, so a Ctrl-C to the process group before then ended it with a
    KeyboardInterrupt traceback (the workers it forks ignore SIGINT too)."""
    if start_method is None:
        start_method = "forkserver" if "forkserver" in mp.get_all_start_methods() else "spawn"
    ctx = mp.get_context(start_method)
    if start_method == "forkserver":  # no effect once this process's server runs
        ctx.set_forkserver_preload([__name__, *(["torch"] if "torch" in sys.modules else [])])
        from multiprocessing import forkserver

        blocked = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        try:
            forkserver.ensure_running()
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
    return ctx


class WorkerDied(RuntimeError):
    """A worker process of a :class:`SubprocVectorMatchEnv` ended (killed, out of memory)
    without answering; the env is closed."""


# why a worker that ended without answering did: its most common cause in a script
_EXITED = ("the worker process exited without answering (with the 'forkserver' and "
           "'spawn' start methods a script must create the env under "
           "`if __name__ == \"__main__\":`)")


class SubprocVectorMatchEnv(ShardedEnv, SplitRollout):
    """:class:`VectorMatchEnv` split over ``num_workers`` processes (shared-memory arrays,
    same interface, bit-identical results for the same seed; rollout fragments too are
    written to shared memory, where /dev/shm has room). Workers start with
    ``start_method`` (:func:`worker_context`; with "forkserver" or "spawn" a script must
    create the env under ``if __name__ == "__main__":``). Frozen policies and
    ``seat_policies`` are pickled to the workers."""

    render_mode = None

    def __init__(self, scenario: str | Scenario, num_envs: int, seed: int = 0,
                 observation: str | None = None, game_overrides: dict | None = None,
                 reward_overrides: dict | None = None, *, num_workers: int = 2,
                 seat_policies: Mapping[int, Policy] | None = None,
                 learner_seats: Sequence[int] | None = None,
                 start_method: str | None = None, inputs: Sequence[str] = (),
                 action_repeat: int = 1):
        num_envs = check_num_envs(num_envs)
        num_workers, why = check_value((int,), num_workers, (1, num_envs))
        if why:
            raise ValueError(f"num_workers must be a whole number in 1..num_envs={num_envs}, "
                             f"got {num_workers!r}")
        kwargs = self._plan_shards(scenario, num_envs, num_workers, seed, observation,
                                   game_overrides, reward_overrides, seat_policies,
                                   learner_seats, inputs, action_repeat)
        E, L, D = num_envs, self.num_learners, self.obs_dim
        specs = {"obs": ((E, L, D), "float32"), "final_obs": ((E, L, D), "float32"),
                 "rewards": ((E, L), "float32"), "terminated": ((E,), "bool"),
                 "truncated": ((E,), "bool"), "actions": ((E, L, 3), "int64")}
        for name, shape in self.input_shapes.items():
            specs[f"input:{name}"] = specs[f"final:{name}"] = ((E, L, *shape), "float32")
        self._shared = _Shared(specs)
        self.inputs = self._inputs()
        ctx = worker_context(start_method)
        self._conns, self._procs = [], []
        for lo, hi in self._blocks:
            parent, child = ctx.Pipe()
            p = ctx.Process(target=_worker, args=(child, kwargs, lo, hi, specs,
                                                  self._shared.names), daemon=True)
            p.start()
            child.close()
            self._conns.append(parent)
            self._procs.append(p)
        self._closed = False
        self._failed: str | None = None  # why a worker failed (the env closed then)
        self._opponent_names: set[str] = set()  # registered by add_opponent
        self._in_flight = False  # a rollout sent by rollout_start, not yet collected
        # shared arrays the workers write fragments into (made by the first rollout that
        # fits in /dev/shm, larger when a longer one comes), and the steps in flight
        self._frag: _Shared | None = None
        self._frag_steps = 0
        _OPEN_ENVS.add(self)
        atexit.unregister(_close_open_envs)  # registered last: run first
        atexit.register(_close_open_envs)
        self._gather()
        self._started = False

    def _inputs(self, kind: str = "input") -> dict[str, np.ndarray]:
        return {name: self._shared.arr[f"{kind}:{name}"].copy() for name in self.input_shapes}

    def __getstate__(self) -> dict[str, Any]:
        """Refused at once: a copy would hold this env's pipes, whose closing when the
        half-made copy is dropped would cut this env off from its workers."""
        raise TypeError("a vector env with worker processes (num_workers > 1) cannot be "
                        "pickled or copied: its workers, pipes and shared memory belong to "
                        "this one; make another env, or use num_workers=1 (in-process envs "
                        "pickle, without their live matches)")

    def _gather(self, raw: bool = False) -> list:
        """Every worker's answer, in worker order; ``raw``: answers to a step (empty
        bytes: no episodes)."""
        out = []
        for conn in self._conns:
            try:
                if raw:
                    msg = conn.recv_bytes()
                    status, payload = pickle.loads(msg) if msg else ("ok", [])
                else:
                    status, payload = conn.recv()
            except (EOFError, OSError):
                self._died()
            if status == "error":
                self._failed = payload.splitlines()[0]
                self.close()
                raise RuntimeError(f"vector env worker failed: {payload}")
            out.append(payload)
        return out

    def _send(self, conn: Any, msg: Any) -> None:
        """Send ``msg`` (bytes: as they are) to a worker; :class:`WorkerDied` when it is
        gone (its pipe broke)."""
        try:
            if isinstance(msg, bytes):
                conn.send_bytes(msg)
            else:
                conn.send(msg)
        except OSError:  # BrokenPipeError, ConnectionResetError
            self._died()

    def _died(self) -> None:
        """A worker ended without answering: close the env and raise :class:`WorkerDied`."""
        self._failed = _EXITED
        self.close()
        raise WorkerDied(f"vector env worker failed: {_EXITED}")

    def check_idle(self, call: str) -> None:
        """As :meth:`SplitRollout.check_idle`, and RuntimeError naming ``call`` once the
        env is closed (by :meth:`close`, or because a worker failed)."""
        if self._closed:
            why = (f"a worker failed earlier ({self._failed})" if self._failed
                   else "close() was called")
            raise RuntimeError(f"{call}(): the env is closed: {why}; make a new env")
        super().check_idle(call)

    def _broadcast(self, cmd: str, arg: Any = None) -> list:
        """Send ``cmd`` to every worker and gather the answers (refused while a rollout
        is in flight: the workers would answer it first)."""
        self.check_idle(arg[0] if cmd == "call" else cmd)
        for conn in self._conns:
            self._send(conn, (cmd, arg))
        return self._gather()

    # each setting is checked here, as in-process, before it goes to the workers: a
    # worker that fails stops, and the env with it

    def set_bot_weakness(self, weakness: float) -> None:
        self._broadcast("call", ("set_bot_weakness", (check_weakness(weakness),)))

    def set_opponents(self, bot_names: Sequence[str] | None,
                      weakness: float | None = None) -> None:
        bot_names = check_bot_names(bot_names)
        if weakness is not None:
            weakness = check_weakness(weakness)
        self._broadcast("call", ("set_opponents", (bot_names, weakness)))

    def set_opponent_policy(self, policy: Policy | None) -> None:
        if policy is not None:
            check_policy(policy, "set_opponent_policy's policy")
        self._broadcast("call", ("set_opponent_policy", (policy,)))

    def set_benched(self, seats: Sequence[int]) -> None:
        seats = check_benched(self.scenario, self.learner_seats, seats)
        self._broadcast("call", ("set_benched", (seats,)))

    def add_opponent(self, name: str, opponent: str | Policy) -> None:
        opponent_entry(name, opponent)
        self._broadcast("call", ("add_opponent", (name, opponent)))
        self._opponent_names.add(name)

    def set_env_opponents(self, names: Sequence[str | None]) -> None:
        names = check_env_opponents(names, self.num_envs, self._opponent_names)
        self.check_idle("set_env_opponents")
        for conn, (lo, hi) in zip(self._conns, self._blocks, strict=True):
            self._send(conn, ("call", ("set_env_opponents", (list(names[lo:hi]),))))
        self._gather()

    def reset(self, seed: int | None = None) -> np.ndarray:
        if seed is not None:
            self.seed = seed = check_seed(seed)
        self._broadcast("reset", seed)
        self._started = True
        self.inputs = self._inputs()
        return self._shared.arr["obs"].copy()

    def step(self, actions: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                          dict[str, Any]]:
        self.check_idle("step")
        if not self._started:
            raise RuntimeError("step() before reset()")
        return self._step(check_actions(actions, self._shared.arr["actions"].shape,
                                        self._name))

    def _step(self, acts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                               np.ndarray, dict[str, Any]]:
        """:meth:`step` with validated int64 (num_envs, L, 3) actions."""
        a = self._shared.arr
        a["actions"][...] = acts
        for conn in self._conns:
            self._send(conn, _STEP)
        episodes = []
        for part in self._gather(raw=True):
            episodes.extend(part)
        if self.input_shapes:
            self.inputs = self._inputs()
        info = {"final_obs": a["final_obs"].copy(), "episodes": episodes,
                "final_inputs": self._inputs("final")}
        return (a["obs"].copy(), a["rewards"].copy(), a["terminated"].copy(),
                a["truncated"].copy(), info)

    def rollout_start(self, policy: RolloutPolicy, obs: np.ndarray, steps: int) -> None:
        """Send the rollout to the workers and return at once: they play it while this
        process does other work (:meth:`rollout_finish` collects it)."""
        self.check_idle("rollout_start")
        if not self._started:
            raise RuntimeError("rollout() before reset()")
        frag = self._fragment_arrays(steps)
        for conn, (lo, hi) in zip(self._conns, self._blocks, strict=True):
            if frag is None:
                self._send(conn, ("rollout", (policy, obs[lo:hi], steps)))
            else:
                self._send(conn, ("rollout_shared", (policy, obs[lo:hi], steps, frag.specs,
                                                    frag.names)))
        self._in_flight, self._frag_steps = True, steps if frag is not None else 0

    def _fragment_arrays(self, steps: int) -> _Shared | None:
        """Shared arrays with room for a fragment of ``steps`` steps of every env (kept
        for the next rollouts), or None where /dev/shm has no room for them: the shards'
        fragments then come by the pipes."""
        if self._frag is not None and self._frag.arr["actions"].shape[0] >= steps:
            return self._frag
        specs = fragment_specs(steps, self.num_envs, self.num_learners, self.obs_dim,
                               self.input_shapes)
        if not _shm_room(sum(_nbytes(*spec) for spec in specs.values())):
            return None
        if self._frag is not None:
            self._frag.close(unlink=True)
        self._frag = _Shared(specs)
        return self._frag

    def rollout_finish(self) -> Fragment:
        """The fragment of the rollout sent by :meth:`rollout_start`."""
        if not self._in_flight:
            if self._closed:
                self.check_idle("rollout_finish")
            raise RuntimeError("rollout_finish() without rollout_start()")
        self._in_flight = False
        parts = self._gather()
        if not self._frag_steps:
            return merge_fragments(parts)
        # a copy: the next rollout writes the shared arrays while this one is learned from
        arrays = {k: v[:self._frag_steps + 1].copy() for k, v in self._frag.arr.items()}
        return fragment_of(arrays, self._frag_steps, merge_episodes(parts))

    @property
    def rollout_in_flight(self) -> bool:
        return self._in_flight

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        _OPEN_ENVS.discard(self)
        for conn in self._conns:
            try:
                if self._in_flight:  # its answer comes before close's
                    conn.recv()
                conn.send(("close", None))
                conn.recv()
            except (OSError, EOFError):
                pass
            conn.close()
        self._in_flight = False
        for p in self._procs:
            p.join(timeout=5)
            if p.is_alive():
                p.terminate()
        self._shared.close(unlink=True)
        if self._frag is not None:
            self._frag.close(unlink=True)
            self._frag = None

    def __del__(self) -> None:
        if hasattr(self, "_closed"):
            self.close()


def check_input(env: VectorMatchEnv, name: str) -> None:
    """Raise unless ``env`` has the input method ``input_<name>`` (listing those it has)."""
    if not callable(getattr(type(env), f"input_{name}", None)):
        have = sorted(a[6:] for a in dir(type(env))
                      if a.startswith("input_") and callable(getattr(type(env), a)))
        raise ValueError(f"unknown env input {name!r}; this env supplies: {have}")


def make_vector_env(scenario: str | Scenario, num_envs: int, seed: int = 0,
                    num_workers: int = 1, **kwargs: Any
                    ) -> VectorMatchEnv | SubprocVectorMatchEnv:
    """In-process env for ``num_workers == 1``, else worker processes (same results;
    ``num_workers`` in 1..num_envs)."""
    if num_workers == 1:
        return VectorMatchEnv(scenario, num_envs, seed, **kwargs)
    return SubprocVectorMatchEnv(scenario, num_envs, seed, num_workers=num_workers, **kwargs)


# ---- the Gymnasium face ---------------------------------------------------------------

VECTOR_RENDER_MODES = ["rgb_array"]
_FINAL_INFO_KEYS = ("winner", "outcome", "map", "opponent", "return", "length", "terms")


class TankBattleVectorEnv(VectorEnv):
    """``num_envs`` copies of the one-learner env ``TankBattleEnv`` as one
    ``gymnasium.vector.VectorEnv`` over the batched engine (see the module docstring for
    spaces, rewards, episode end, autoreset and seeding)."""

    metadata = {"autoreset_mode": AutoresetMode.SAME_STEP, "render_modes": VECTOR_RENDER_MODES,
                "render_fps": 30}

    def __init__(self, scenario: str | Scenario = "vs_smart", num_envs: int = 1, *,
                 observation: str | None = None, learner_seat: int | None = None,
                 opponent_policy: Policy | None = None,
                 seat_policies: Mapping[int, Policy] | None = None,
                 game_overrides: Mapping[str, Any] | None = None,
                 reward_overrides: Mapping[str, Any] | None = None,
                 action_repeat: int = 1, num_workers: int = 1,
                 render_mode: str | None = None, max_episode_steps: int | None = None):
        sc = load_scenario(scenario)
        seat = single_learner_seat(sc, learner_seat, seat_policies, opponent_policy)
        game = check_overrides(game_overrides, "game_overrides")
        check_action_repeat(action_repeat)
        if max_episode_steps is not None:  # make_vec's TimeLimit: the game's own step limit
            limit = check_step_limit(max_episode_steps, "max_episode_steps") * action_repeat
            game["max_steps"] = min(limit, sc.game_config(**game).max_steps)
        if render_mode is not None and render_mode not in VECTOR_RENDER_MODES:
            raise ValueError(f"render_mode must be one of {VECTOR_RENDER_MODES} or None, "
                             f"got {render_mode!r}")
        if render_mode is not None and num_workers > 1:
            raise ValueError("render_mode needs the matches in this process: num_workers=1")
        self.engine: VectorMatchEnv | SubprocVectorMatchEnv = make_vector_env(
            sc, num_envs, 0, num_workers, observation=observation,
            game_overrides=game or None,
            reward_overrides=check_overrides(reward_overrides, "reward_overrides") or None,
            seat_policies=seat_policies, learner_seats=[seat], action_repeat=action_repeat)
        if opponent_policy is not None:
            self.engine.set_opponent_policy(opponent_policy)
        self.scenario, self.learner_seat = sc, seat
        self.num_envs = num_envs = self.engine.num_envs
        self.render_mode = render_mode
        self.single_observation_space = self.engine.observation_space
        self.single_action_space = self.engine.action_space
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        fps = sc.game_config(**game).tick_hz
        self.metadata = {**self.metadata, "render_fps": fps}
        self._shape = (num_envs, 3)
        self._started = False
        self._renderers: list[Any] = []

    @property
    def layout(self) -> ObsLayout:
        """Index map of one sub-env's observation vector (feature name -> slice)."""
        return self.engine.layout

    # ---- opponents (from each sub-env's next episode), as on the engine ---------------

    def set_bot_weakness(self, weakness: float) -> None:
        self.engine.set_bot_weakness(weakness)

    def set_opponents(self, bot_names: Sequence[str] | None,
                      weakness: float | None = None) -> None:
        self.engine.set_opponents(bot_names, weakness)

    def set_opponent_policy(self, policy: Policy | None) -> None:
        self.engine.set_opponent_policy(policy)

    def set_benched(self, seats: Sequence[int]) -> None:
        self.engine.set_benched(seats)

    # ---- episodes ---------------------------------------------------------------------

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None
              ) -> tuple[np.ndarray, dict[str, Any]]:
        """Reset every sub-env. ``seed`` restarts the episode sequence; ``None`` continues
        it (the first reset without a seed draws one from ``np_random``). No options."""
        check_reset_options(options, "; every ended sub-env is reset inside step "
                                     "(AutoresetMode.SAME_STEP)")
        if seed is not None:
            if isinstance(seed, bool) or not isinstance(seed, int | np.integer):
                raise TypeError(f"seed must be an int or None, got {type(seed).__name__} "
                                "(one seed seeds every sub-env's episode sequence)")
            seed = check_seed(seed)  # a Python int, as Gymnasium's seeding takes
        super().reset(seed=seed)
        if seed is None and not self._started:
            seed = int(self.np_random.integers(2**63 - 1))
        obs = self.engine.reset(seed)
        self._started = True
        return obs[:, 0], {}

    def step(self, actions: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                          dict[str, Any]]:
        self.engine.check_idle("step")
        if not self._started:
            raise RuntimeError("step() before reset()")
        acts = check_actions(actions, self._shape, self._name)
        obs, rew, term, trunc, info = self.engine._step(acts[:, None, :])
        infos: dict[str, Any] = {}
        episodes = info["episodes"]
        if episodes:
            final_obs = np.full(self.num_envs, None, dtype=object)
            ended = np.zeros(self.num_envs, dtype=bool)
            final_info: dict[str, Any] = {}
            for ep in episodes:
                e = ep["env"]
                final_obs[e] = info["final_obs"][e, 0]
                ended[e] = True
                record = {k: ep[k] for k in _FINAL_INFO_KEYS}
                record["return"] = float(ep["return"][0])
                record["outcome"] = ep["outcome"][0]
                record["terms"] = {k: float(v[0]) for k, v in ep["terms"].items()}
                final_info = self._add_info(final_info, record, e)
            infos = {"final_obs": final_obs, "_final_obs": ended, "final_info": final_info,
                     "_final_info": ended.copy()}
        return obs[:, 0], rew[:, 0], term, trunc, infos

    def _name(self, idx: tuple[int, ...]) -> str:
        return f"env {idx[0]} (seat {self.learner_seat}, {self.scenario.name})"

    # ---- rendering and closing --------------------------------------------------------

    def render(self) -> tuple[np.ndarray, ...] | None:
        """One HxWx3 uint8 frame per sub-env (``render_mode="rgb_array"``)."""
        if self.render_mode is None:
            gym_logger.warn("render() called with render_mode=None; pass "
                            f"render_mode='rgb_array' ({VECTOR_RENDER_MODES})")
            return None
        from alphatank.ui.render import Renderer

        core = self.engine.core
        core.first_match("render()")  # RuntimeError before a reset (or after unpickling)
        while len(self._renderers) < self.num_envs:
            self._renderers.append(Renderer(self.render_mode, fps=self.metadata["render_fps"]))
        return tuple(r.render(m, c) for r, m, c in
                     zip(self._renderers, core.matches, core.controllers, strict=True))

    def __getstate__(self) -> dict[str, Any]:
        """As the single env: the renderers (pygame surfaces and fonts) are not carried;
        ``render()`` makes them again."""
        return {**self.__dict__, "_renderers": []}

    def close_extras(self, **kwargs: Any) -> None:
        for r in self._renderers:
            r.close()
        self._renderers = []
        self.engine.close()

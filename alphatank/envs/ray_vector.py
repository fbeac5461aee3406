"""The vector env over a Ray cluster: env shards in Ray actors (``alphatank train --ray
--env-runners N``).

:class:`RayVectorMatchEnv` has the interface of
:class:`~alphatank.envs.vector.SubprocVectorMatchEnv` (arrays in and out, opponent
controls, extra learner inputs) and, for the same seed, its results bit for bit: env
runner ``k`` is a Ray actor (:class:`EnvRunner`, one CPU) owning a
:class:`~alphatank.envs.vector.VectorMatchEnv` over the same contiguous block of env ids
as worker ``k`` of the subprocess env. Every step is one actor call per runner carrying
its block of actions; all runners step at once, and each answers with one record array
(observations, rewards, episode ends, final observations and extra inputs of its envs,
one structured row per env: a single buffer for Ray to serialise) plus the records of the
episodes that ended (usually none).

:meth:`RayVectorMatchEnv.rollout` instead acts a whole rollout in the runners with a
frozen policy copy (:mod:`alphatank.envs.fragments`): one call per runner per rollout,
the same fragment as :meth:`SubprocVectorMatchEnv.rollout` with as many workers.

Ray Compiled Graphs (``experimental_compile``) are not used: in Ray 2.60 their
shared-memory channels wait by polling (``sched_yield`` loops), so each idle runner and the
waiting learner keep a core busy, which on a host with fewer free cores than runners + 1
(or during the learner's update) costs more than the ~1 ms per call it saves
(docs/distributed.md).

Failures: Ray restarts a runner whose process or node dies (``max_restarts``); the
restarted actor rebuilds its envs from the constructor arguments and this env replays the
opponent settings made since (the last call of each kind, in order). The matches of that
shard are gone, so the rollout in flight is lost: :meth:`step` raises
:class:`RolloutLost` (after the runner is back), the caller drops the partial rollout and
resets (the Trainer does; see :mod:`alphatank.training.runner`). A runner lost during
:meth:`reset` costs nothing: the reset is redone. A runner that does not answer a call
within ``step_timeout_s`` (hung: deadlocked, stopped, stuck in a system call) is killed
and restarted the same way, and the message says so. A runner out of restarts ends the
run with a RuntimeError naming it.

Ray is imported when the env is built, never at module import.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from alphatank.cluster import ENV_RUNNER_TIMEOUT_S
from alphatank.envs.core import (
    check_actions,
    check_benched,
    check_bot_names,
    check_env_opponents,
    check_num_envs,
    check_policy,
    check_weakness,
    opponent_entry,
)
from alphatank.envs.fragments import Fragment, RolloutPolicy, SplitRollout, merge_fragments
from alphatank.envs.vector import ShardedEnv, VectorMatchEnv
from alphatank.game.scenarios import Scenario
from alphatank.sim.config import check_value
from alphatank.sim.policy import Policy

DEFAULT_MAX_RESTARTS = 3
RESTART_TIMEOUT_S = 300.0  # how long to wait for Ray to bring a lost runner back
START_TIMEOUT_S = 120.0  # how long the runners may wait for free CPUs on the cluster


class RolloutLost(RuntimeError):
    """An env runner died mid-rollout and was restarted: every match must be reset and
    the partial rollout dropped. The message says which runner and what happened."""


def step_record(num_learners: int, obs_dim: int,
                input_shapes: Mapping[str, tuple[int, ...]]) -> np.dtype:
    """One env's row of a step's answer: everything :meth:`VectorMatchEnv.step` returns
    for it but the episode records, and its extra inputs."""
    L, D = num_learners, obs_dim
    fields: list[tuple] = [("obs", np.float32, (L, D)), ("rewards", np.float32, (L,)),
                           ("terminated", np.bool_), ("truncated", np.bool_),
                           ("final_obs", np.float32, (L, D))]
    for name, shape in input_shapes.items():
        fields += [(f"input:{name}", np.float32, (L, *shape)),
                   (f"final:{name}", np.float32, (L, *shape))]
    return np.dtype(fields)


class EnvRunner:
    """One shard: a :class:`VectorMatchEnv` over env ids ``lo..hi-1`` (a Ray actor). A
    step writes its results into one record array made once (:func:`step_record`)."""

    def __init__(self, kwargs: dict[str, Any], lo: int, hi: int):
        self.env = env = VectorMatchEnv(num_envs=hi - lo, env_ids=range(lo, hi), **kwargs)
        self.started = False
        self.rec = np.zeros(hi - lo, step_record(env.num_learners, env.obs_dim,
                                                 env.input_shapes))
        rec = self.rec
        self._out = [rec[k] for k in ("obs", "rewards", "terminated", "truncated",
                                      "final_obs")]
        self._finals = {name: rec[f"final:{name}"] for name in env.input_shapes}
        self._dirty = False  # final_obs / final inputs rows written by the last step

    def configure(self, calls: Sequence[tuple[str, tuple]]) -> None:
        """Apply opponent settings (method name, arguments) in order."""
        for name, args in calls:
            getattr(self.env, name)(*args)

    def reset(self, seed: int | None) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        obs = self.env.reset(seed)
        self.started = True
        return obs, self.env.inputs

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, list[dict[str, Any]]]:
        """One step of the validated (n, L, 3) actions: the record array and the records
        of the episodes that ended."""
        if not self.started:  # Ray restarted this actor since the last reset
            raise RolloutLost("the env runner was restarted; its matches were not reset")
        rec = self.rec
        if self._dirty:
            rec["final_obs"] = 0.0
            for arr in self._finals.values():
                arr[...] = 0.0
        episodes = self.env.step_into(actions, *self._out, self._finals)
        for name, value in self.env.inputs.items():
            rec[f"input:{name}"] = value
        self._dirty = bool(episodes)
        return rec, episodes

    def rollout(self, policy: RolloutPolicy, obs: np.ndarray, steps: int) -> Fragment:
        """A whole fragment of this shard (:mod:`alphatank.envs.fragments`)."""
        if not self.started:  # Ray restarted this actor since the last reset
            raise RolloutLost("the env runner was restarted; its matches were not reset")
        return self.env.rollout(policy, obs, steps)

    def pid(self) -> int:
        import os

        return os.getpid()


class RayVectorMatchEnv(ShardedEnv, SplitRollout):
    """:class:`VectorMatchEnv` split over ``num_runners`` Ray actors (same interface and
    results as :class:`~alphatank.envs.vector.SubprocVectorMatchEnv` with that many
    workers). Connects to Ray first if this process has not (a local instance)."""

    render_mode = None
    can_lose_rollouts = True  # step() may raise RolloutLost (the Trainer collects again)

    def __init__(self, scenario: str | Scenario, num_envs: int, seed: int = 0,
                 observation: str | None = None, game_overrides: dict | None = None,
                 reward_overrides: dict | None = None, *, num_runners: int = 2,
                 seat_policies: Mapping[int, Policy] | None = None,
                 learner_seats: Sequence[int] | None = None, inputs: Sequence[str] = (),
                 max_restarts: int = DEFAULT_MAX_RESTARTS,
                 step_timeout_s: float = ENV_RUNNER_TIMEOUT_S, action_repeat: int = 1):
        from alphatank.cluster import connect

        num_envs = check_num_envs(num_envs)
        num_runners, why = check_value((int,), num_runners, (1, num_envs))
        if why:
            raise ValueError(f"num_runners (env runners) must be a whole number in "
                             f"1..num_envs={num_envs}, got {num_runners!r}")
        if max_restarts < 0:
            raise ValueError(f"max_restarts must be >= 0, got {max_restarts}")
        if not step_timeout_s > 0:
            raise ValueError(f"step_timeout_s must be > 0 seconds, got {step_timeout_s}")
        connect()
        import ray

        cpus = ray.cluster_resources().get("CPU", 0.0)
        if num_runners > cpus:
            raise ValueError(f"{num_runners} env runners need {num_runners} CPUs; the Ray "
                             f"cluster has {cpus:g}")
        self._ray = ray
        kwargs = self._plan_shards(scenario, num_envs, num_runners, seed, observation,
                                   game_overrides, reward_overrides, seat_policies,
                                   learner_seats, inputs, action_repeat)
        self.inputs = {name: np.zeros((num_envs, self.num_learners, *shape), np.float32)
                       for name, shape in self.input_shapes.items()}
        self.max_restarts = max_restarts
        self.step_timeout_s = float(step_timeout_s)
        self._rec = np.zeros(num_envs, step_record(self.num_learners, self.obs_dim,
                                                   self.input_shapes))
        actor = ray.remote(EnvRunner).options(num_cpus=1, max_restarts=max_restarts,
                                              max_task_retries=0)
        self.runners = [actor.remote(kwargs, lo, hi) for lo, hi in self._blocks]
        self.restarts = [0] * num_runners  # restarts seen per runner
        self.lost_rollouts = 0
        self._settings: dict[Any, tuple[str, list[tuple]]] = {}  # replayed after a restart
        self._lost: str | None = None  # a loss seen outside step(), raised by the next step
        self._closed = False
        self._started = False
        self._pending: tuple[list[Any], int] | None = None  # refs of rollout_start, steps
        self._shape = (num_envs, self.num_learners, 3)
        try:
            pids = [r.pid.remote() for r in self.runners]
            ready, _ = ray.wait(pids, num_returns=len(pids), timeout=START_TIMEOUT_S)
            if len(ready) < len(pids):
                free = ray.available_resources().get("CPU", 0.0)
                raise RuntimeError(f"{len(pids) - len(ready)} of {num_runners} env runners "
                                   f"did not start within {START_TIMEOUT_S:.0f} s: the Ray "
                                   f"cluster has {free:g} of {cpus:g} CPUs free (each runner "
                                   f"needs one)")
            self._gather(pids)
        except BaseException:
            self.close()
            raise

    # ---- remote calls and recovery ---------------------------------------------------

    def _gather(self, refs: Sequence[Any], steps: int = 1) -> list:
        """Results of one call per runner; a runner that died is brought back (settings
        replayed), one silent for ``step_timeout_s`` per step of the call is killed and
        brought back, and :class:`RolloutLost` raised once every runner answered."""
        ray = self._ray
        refs = list(refs)
        timeout = self.step_timeout_s * steps
        deadline = time.monotonic() + timeout
        try:
            return ray.get(refs, timeout=timeout)  # one call: the common case
        except (ray.exceptions.RayError, RolloutLost):
            pass  # find out which runner failed, and how
        _, pending = ray.wait(refs, num_returns=len(refs),
                              timeout=max(0.0, deadline - time.monotonic()))
        hung = {ref.hex() for ref in pending}
        for k, ref in enumerate(refs):
            if ref.hex() in hung:  # restarted by Ray as if it had died
                ray.kill(self.runners[k], no_restart=False)
        out: list[Any] = []
        lost: list[tuple[int, BaseException]] = []
        for k, ref in enumerate(refs):
            if ref.hex() in hung:
                out.append(None)
                lost.append((k, TimeoutError(f"hung: no answer within {timeout:g} s, "
                                             f"killed")))
                continue
            try:
                out.append(ray.get(ref))
            except (ray.exceptions.RayActorError, RolloutLost) as exc:
                out.append(None)
                lost.append((k, exc))
            except ray.exceptions.RayTaskError as exc:
                raise RuntimeError(f"env runner {k} failed: {exc}") from None
        if lost:
            notes = [self._recover(k, exc) for k, exc in lost]
            self._started = False
            raise RolloutLost("; ".join(notes))
        return out

    def _recover(self, k: int, exc: BaseException) -> str:
        """Wait for Ray to restart runner ``k`` and replay the opponent settings; a line
        saying what happened."""
        ray = self._ray
        lo, hi = self._blocks[k]
        what = f"env runner {k} (envs {lo}-{hi - 1})"
        cause = ("it died between calls" if isinstance(exc, RolloutLost) else str(exc)
                 if isinstance(exc, TimeoutError) else
                 f"{type(exc).__name__}: {str(exc).strip().splitlines()[0]}")
        calls = self._replay_order(k)
        deadline = time.monotonic() + RESTART_TIMEOUT_S
        while True:
            try:
                ray.get(self.runners[k].configure.remote(calls))
                break
            except ray.exceptions.ActorUnavailableError:
                if time.monotonic() > deadline:
                    raise RuntimeError(f"{what} was lost ({cause}) and Ray did not bring "
                                       f"it back within {RESTART_TIMEOUT_S:.0f} s") from None
                time.sleep(0.1)
            except ray.exceptions.RayActorError as died:
                raise RuntimeError(f"{what} died and Ray cannot restart it (max_restarts="
                                   f"{self.max_restarts} used up): "
                                   f"{str(died).strip().splitlines()[0]}") from None
        self.restarts[k] += 1
        return (f"{what} was lost ({cause}); Ray restarted it (restart {self.restarts[k]}, "
                f"max_restarts={self.max_restarts}) and its opponent settings were replayed")

    def _replay_order(self, k: int) -> list[tuple[str, tuple]]:
        """Runner ``k``'s settings: registrations first, then the others in the order
        last made."""
        calls = [(name, args[k]) for name, args in self._settings.values()]
        return ([c for c in calls if c[0] == "add_opponent"]
                + [c for c in calls if c[0] != "add_opponent"])

    def _setting(self, key: Any, name: str, args: tuple,
                 per_runner: Sequence[tuple] | None = None) -> None:
        """Send one opponent setting to every runner (``per_runner``: each its own
        arguments) and remember it for replay after a restart."""
        if self._closed:
            raise RuntimeError("the env is closed")
        self.check_idle(name)
        each = list(per_runner) if per_runner is not None else [args] * self.num_runners
        self._settings.pop(key, None)
        self._settings[key] = (name, each)
        refs = [r.configure.remote([(name, each[k])]) for k, r in enumerate(self.runners)]
        try:
            self._gather(refs)
        except RolloutLost as lost:  # the runner is back with every setting; the next
            self._lost = str(lost)   # step tells the caller that the rollout is gone

    # ---- opponents (from each env's next episode), as on VectorMatchEnv ----------------

    def set_bot_weakness(self, weakness: float) -> None:
        self._setting("weakness", "set_bot_weakness", (check_weakness(weakness),))

    def set_opponents(self, bot_names: Sequence[str] | None,
                      weakness: float | None = None) -> None:
        bot_names = check_bot_names(bot_names)
        if weakness is not None:
            weakness = check_weakness(weakness)
        self._setting("opponents", "set_opponents", (bot_names, weakness))

    def set_opponent_policy(self, policy: Policy | None) -> None:
        if policy is not None:
            check_policy(policy, "set_opponent_policy's policy")
        self._setting("opponent_policy", "set_opponent_policy", (policy,))

    def set_benched(self, seats: Sequence[int]) -> None:
        seats = check_benched(self.scenario, self.learner_seats, seats)
        self._setting("benched", "set_benched", (seats,))

    def add_opponent(self, name: str, opponent: str | Policy) -> None:
        opponent_entry(name, opponent)
        self._setting(("add_opponent", name), "add_opponent", (name, opponent))

    def set_env_opponents(self, names: Sequence[str | None]) -> None:
        registered = [key[1] for key in self._settings
                      if isinstance(key, tuple) and key[0] == "add_opponent"]
        names = check_env_opponents(names, self.num_envs, registered)
        self._setting("env_opponents", "set_env_opponents", (names,),
                      [(names[lo:hi],) for lo, hi in self._blocks])

    # ---- episodes ---------------------------------------------------------------------

    def reset(self, seed: int | None = None) -> np.ndarray:
        self.check_idle("reset")
        if seed is not None:
            self.seed = int(seed)
        for _ in range(self.num_runners * (self.max_restarts + 1) + 1):
            try:
                parts = self._gather([r.reset.remote(seed) for r in self.runners])
                break
            except RolloutLost:  # nothing was in flight: reset again
                continue
        else:  # pragma: no cover - _recover raises first once restarts are used up
            raise RuntimeError("env runners keep dying during reset")
        self._lost = None
        self._started = True
        self.inputs = {name: np.concatenate([p[1][name] for p in parts])
                       for name in self.input_shapes}
        return np.concatenate([p[0] for p in parts])

    def _check_live(self, call: str) -> None:
        """Raise the loss of a rollout seen outside a step, or if never reset."""
        if self._lost is not None:
            lost, self._lost = self._lost, None
            self._started = False
            self.lost_rollouts += 1
            raise RolloutLost(lost)
        if not self._started:
            raise RuntimeError(f"{call}() before reset()")

    def step(self, actions: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                          dict[str, Any]]:
        self._check_live("step")
        self.check_idle("step")
        acts = check_actions(actions, self._shape, self._name)
        refs = [r.step.remote(acts[lo:hi]) for r, (lo, hi) in zip(self.runners, self._blocks,
                                                                   strict=True)]
        try:
            parts = self._gather(refs)
        except RolloutLost:
            self.lost_rollouts += 1
            raise
        rec, episodes = self._rec, []
        for (lo, hi), (part, eps) in zip(self._blocks, parts, strict=True):
            rec[lo:hi] = part
            episodes.extend(eps)
        if self.input_shapes:
            self.inputs = {name: rec[f"input:{name}"].copy() for name in self.input_shapes}
        info = {"final_obs": rec["final_obs"].copy(), "episodes": episodes,
                "final_inputs": {name: rec[f"final:{name}"].copy()
                                 for name in self.input_shapes}}
        return (rec["obs"].copy(), rec["rewards"].copy(), rec["terminated"].copy(),
                rec["truncated"].copy(), info)

    def rollout_start(self, policy: RolloutPolicy, obs: np.ndarray, steps: int) -> None:
        """Send the rollout to the runners and return at once (:meth:`rollout_finish`
        collects it)."""
        self._check_live("rollout")
        if self._pending is not None:
            raise RuntimeError("rollout_start() while a rollout is in flight")
        ref = self._ray.put(policy)
        self._pending = ([r.rollout.remote(ref, obs[lo:hi], steps)
                          for r, (lo, hi) in zip(self.runners, self._blocks, strict=True)],
                         steps)

    def rollout_finish(self) -> Fragment:
        """The fragment of the rollout sent by :meth:`rollout_start`; raises
        :class:`RolloutLost` if a runner died while playing it."""
        if self._pending is None:
            raise RuntimeError("rollout_finish() without rollout_start()")
        (refs, steps), self._pending = self._pending, None
        try:
            return merge_fragments(self._gather(refs, steps))
        except RolloutLost:
            self.lost_rollouts += 1
            raise

    @property
    def rollout_in_flight(self) -> bool:
        return self._pending is not None

    @property
    def num_runners(self) -> int:
        return len(self.runners)

    def close(self) -> None:
        """Stop the runners (the cluster itself stays up)."""
        if self._closed:
            return
        self._closed = True
        self._pending = None  # a rollout in flight goes with its runners
        for r in self.runners:
            with contextlib.suppress(Exception):  # already gone, or the cluster is down
                self._ray.kill(r, no_restart=True)
        self.runners = []

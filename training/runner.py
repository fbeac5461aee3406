"""The multi-learner training loop over the batched vector env.

Any number of independent learners (any registered algorithm, each with its own
parameters) drive the scenario's learner seats; bots, schedules or frozen policies fill
the rest. The loop speaks only the Learner protocol (:mod:`alphatank.training.learners`):
one iteration = ``rollout_steps`` vector steps (a multiple of every learner's rollout
length); each learner updates whenever it says it is ready. Checkpoints, evaluation,
videos and logging happen at iteration boundaries.

A checkpoint is an episode boundary: right after saving, every match restarts from a
seed derived from ``(seed, iteration)``. A run resumed from that checkpoint does the same,
so its next update equals the uninterrupted run's bit for bit (in-progress episodes are
cut there and bootstrapped like any time-limit truncation).

Stopping (:mod:`alphatank.training.stopping`): SIGINT, SIGTERM and the time budget of
this call (``time_limit_s``) set a flag that the loop polls after every vector step and
learners poll between gradient steps. A stop inside an iteration saves a checkpoint the
run resumes from:

* every learner has a fixed rollout (PPO, MAPPO): the partial iteration is dropped and
  the state from its start is saved (taken before every iteration), so the resumed run
  re-collects it and continues bit for bit like a run that checkpointed there;
* some learner has none (SAC): a *segment cut* at the current vector step. Off-policy
  learners keep everything (each gradient step is whole; owed steps are done after
  resuming), fixed-rollout learners in the same run drop their unfinished rollout. The
  resumed run restarts every match (seeds from ``(seed, iteration, cut)``) and starts a
  full iteration there; it is deterministic, but its iterations are shifted, and its last
  one is shorter so that the run ends at its planned steps (``planned_steps``; an
  unfinished rollout of a fixed-rollout learner there is left unused);
* the behaviour cloning of a fresh run (``imitate``) is still going: the learners as they
  were before it are saved, and the resumed run clones from the start, as the
  uninterrupted run did.
"""

from __future__ import annotations

import copy
import math
import re
import shutil
import sys
import time
import warnings
from collections import deque
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from alphatank.cluster import ENV_RUNNER_TIMEOUT_S
from alphatank.envs.core import ACTION_NVEC
from alphatank.envs.ids import env_id
from alphatank.envs.ray_vector import RolloutLost
from alphatank.envs.vector import WorkerDied, make_vector_env
from alphatank.errors import InputError
from alphatank.extras import require
from alphatank.files import FolderLock, missing_folders, remove_empty_folders
from alphatank.game.lineup import check_seats_fit
from alphatank.game.observe import slot_counts
from alphatank.game.scenarios import Scenario
from alphatank.training.buffers import memory_budget
from alphatank.training.checkpoint import (
    FIT_ERRORS,
    Checkpoint,
    CheckpointError,
    LivePolicy,
    SaveFailed,
    load_checkpoint,
    load_problem,
    resume_dir,
    save_checkpoint,
    scenario_to_dict,
)
from alphatank.training.fragments import (
    FragmentsRefused,
    FrozenLearners,
    fragment_problems,
    ingest_fragment,
    stream_rows,
)
from alphatank.training.hparams import imitate_config
from alphatank.training.imitate import imitate
from alphatank.training.learners import learner_class, make_learner
from alphatank.training.logging import RunLogger
from alphatank.training.presets import (
    DEFAULT_ROLLOUT_STEPS,
    TrainConfig,
    learners_fit,
    run_learners,
    run_scenario,
    selfplay_pool_args,
)
from alphatank.training.schedules import make_schedule
from alphatank.training.selfplay import SelfPlay, Snapshot, SnapshotPool
from alphatank.training.stopping import StopFlag, StopRequested, stop_on_signals
from alphatank.training.threads import limit_threads

WINDOW = 100  # episodes in the rolling win-rate / return windows


class RunWarning(UserWarning):
    """A run setting that works but probably not as intended (shown as one line)."""


class EnvWorkerDied(RuntimeError):
    """An env worker process died during :meth:`Trainer.train` (killed, out of memory):
    the pipe to it broke. The message says where the run stands (one line)."""


def derive_seed(*parts: int) -> int:
    return int(np.random.SeedSequence(list(parts)).generate_state(1, np.uint64)[0] >> 1)


def opponent_key(label: str, agents: tuple[str, ...] = ()) -> str:
    """'B:aggressive(w=1), B:smart(w=0.5)' -> 'aggressive+smart' (for per-opponent stats);
    ``agents``: the opposing learners' names (or ``selfplay``), joined to the bots."""
    names = set(re.findall(r"([A-Za-z_]+)\(", label)) | set(agents)
    if names:
        return "+".join(sorted(names))
    return re.sub(r"[^A-Za-z0-9_+]", "_", label)


def opposing_learners(specs: list, teams: list[str]) -> dict[str, tuple[str, ...]]:
    """Per learner, the learners it plays against: those driving a seat of another team
    (``teams``: the team of each learner seat); ``selfplay`` when it drives both sides."""
    team_of = {spec.name: {teams[c] for c in spec.seats} for spec in specs}
    out = {}
    for spec in specs:
        mine = team_of[spec.name]
        rivals = {o.name for o in specs if o.name != spec.name and team_of[o.name] - mine}
        out[spec.name] = tuple(sorted(rivals | ({"selfplay"} if len(mine) > 1 else set())))
    return out


class Trainer:
    """Runs a :class:`TrainConfig` in ``run_dir``. ``env`` (a vector env) and
    ``scenario`` may be given instead of being built from ``cfg.scenario``.

    ``env_runners`` > 0 (and no ``env``): the matches run in that many Ray actors
    (:class:`~alphatank.envs.ray_vector.RayVectorMatchEnv`, in place of ``num_workers``
    processes, same results); a runner that dies costs the iteration in flight, which is
    collected again (:attr:`lost_rollouts`, a ``warning`` on stderr and ``charts/
    lost_rollouts`` in the log); so does one that does not answer a step within
    ``env_runner_timeout_s`` (it is killed and restarted).

    ``fragments``: each iteration is acted by the env's shards with frozen copies of the
    learners, one call per shard (:mod:`alphatank.training.fragments`; PPO and MAPPO
    learners); reproducible for the same seed and number of shards, not step-equal to acting
    on the learner. ``overlap`` (implies ``fragments``): the shards act the next rollout
    while the learners update on this one, so each rollout is acted by the learners as they
    were one update earlier (the first rollout, and the first after each checkpoint, by the
    current ones: a resumed run goes on as the uninterrupted one).

    ``action_mask``: optional hook ``f(obs (E, L, D)) -> bool (E, L, 8)`` over the
    concatenated choices (rotate 3, move 3, fire 2); learners that take masks (PPO) never
    sample a masked choice and their losses use the same masks.

    ``stop``: the flag that stops the run (default: a new one), for a caller whose signal
    handlers set it from its own start-up on: a stop requested before or while the
    Trainer is made raises :class:`StopRequested` once what was made is undone (env
    workers, log, lock; a new run's folder), and one that comes after it ends
    :meth:`train` as soon as it begins, with its save.
    """

    def __init__(self, cfg: TrainConfig, run_dir: str | Path, env: Any = None,
                 resume: Checkpoint | None = None, progress: bool = True,
                 wandb_id: str | None = None,
                 action_mask: Callable[[np.ndarray], np.ndarray] | None = None,
                 scenario: Scenario | None = None, env_runners: int = 0,
                 env_runner_timeout_s: float = ENV_RUNNER_TIMEOUT_S, fragments: bool = False,
                 overlap: bool = False, stop: StopFlag | None = None):
        if env is not None and getattr(env, "action_repeat", 1) != cfg.action_repeat:
            raise ValueError(f"the env holds actions for {getattr(env, 'action_repeat', 1)} "
                             f"tick(s); the run's action_repeat is {cfg.action_repeat}")
        self.cfg = cfg
        self.action_mask = action_mask
        self.run_dir = Path(run_dir)
        if resume is None and (self.run_dir / "latest").exists():  # a new run would
            # overwrite its saves and metrics
            raise InputError(f"{self.run_dir} already holds a run; continue it with "
                             f"resume_trainer({str(self.run_dir)!r}) or give another folder")
        # one process at a time writes a run (BusyError otherwise), until train() ends
        made = missing_folders(self.run_dir)  # removed again if the run does not start
        self.stop = stop if stop is not None else StopFlag()  # its time limit: train()'s
        self.lock = FolderLock(self.run_dir).acquire()
        try:
            with self.stop.interruptible():  # a stop that came before is raised here
                self.progress = progress
                limit_threads(cfg.torch_threads)
                # an injected env brings its own scenario (tests use custom maps); a resumed
                # run uses the one saved in its checkpoint
                self.scenario: Scenario = (scenario or getattr(env, "scenario", None)
                                           or run_scenario(cfg))
                n_learners = len(self.scenario.learner_seats)
                self.specs = specs = list(run_learners(cfg, n_learners))
                if not learners_fit(specs, n_learners, selfplay=bool(cfg.selfplay)):
                    owned = sorted(s for spec in specs for s in spec.seats)
                    if cfg.selfplay:
                        raise ValueError(f"self-play: learners must drive some of the "
                                         f"scenario's {n_learners} learner seats at most once "
                                         f"and leave the others to the snapshot pool; they "
                                         f"drive {owned}")
                    raise ValueError(f"learners must drive each of the scenario's {n_learners} "
                                     f"learner seats exactly once; they drive {owned} "
                                     f"({[(s.name, list(s.seats)) for s in specs]})")
                # env columns: the learner seats the learners drive (all of them without
                # self-play), each learner's columns in ascending seat order (MAPPO's seat ids
                # follow it)
                driven = sorted(s for spec in specs for s in spec.seats)
                self.cols = {spec.name: [driven.index(s) for s in sorted(spec.seats)]
                             for spec in specs}
                # extra per-stream inputs the learners need from the env (Learner.inputs)
                self.inputs = sorted({x for spec in specs for x in learner_class(spec.algo).inputs})
                extra: dict[str, Any] = {"inputs": self.inputs} if self.inputs else {}
                if cfg.action_repeat != 1:
                    extra["action_repeat"] = cfg.action_repeat
                if cfg.selfplay:
                    extra["learner_seats"] = [self.scenario.learner_seats[s] for s in driven]
                if env is not None:
                    self.env = env
                else:  # a stop meanwhile waits: workers half started would be left behind
                    with self.stop.deferred():
                        self.env = self._make_env(env_runners, env_runner_timeout_s, extra)
                self.fragments = fragments or overlap
                self.overlap = overlap
                # schedule metrics of a rollout in flight
                self.ahead: dict[str, float] | None = None
                self._setup(specs, resume, wandb_id)
        except BaseException:
            if hasattr(self, "logger"):  # made last in _setup: its metrics file is open
                self.logger.close()
            if env is None and hasattr(self, "env"):  # do not leave worker processes behind
                self.env.close()
            if made and made[0] == self.run_dir.absolute():  # a new run's: no run in it yet
                shutil.rmtree(self.run_dir, ignore_errors=True)
            self.lock.release()
            remove_empty_folders(made)
            raise

    def _make_env(self, env_runners: int, env_runner_timeout_s: float,
                  extra: dict[str, Any]) -> Any:
        """The run's vector env: ``cfg.num_workers`` processes, or ``env_runners`` Ray
        actors (the same results as that many workers). A failure that follows a stop
        (a SIGTERM to the process group also ends the fork server the workers start
        from) is the stop: :class:`StopRequested`."""
        cfg = self.cfg
        try:
            if env_runners:
                from alphatank.envs.ray_vector import RayVectorMatchEnv
                return RayVectorMatchEnv(
                    self.scenario, cfg.num_envs, seed=cfg.seed, num_runners=env_runners,
                    step_timeout_s=env_runner_timeout_s, observation=cfg.observation,
                    game_overrides=cfg.game or None, reward_overrides=cfg.rewards or None,
                    **extra)
            return make_vector_env(
                self.scenario, cfg.num_envs, seed=cfg.seed, num_workers=cfg.num_workers,
                observation=cfg.observation, game_overrides=cfg.game or None,
                reward_overrides=cfg.rewards or None, **extra)
        except Exception as exc:
            if self.stop.signum is None:
                raise
            raise StopRequested(self.stop.reason) from exc

    def _setup(self, specs: list, resume: Checkpoint | None, wandb_id: str | None) -> None:
        cfg, env = self.cfg, self.env
        if cfg.video_every:
            require("video", "training videos (video_every)")
        # a scenario's checkpoint or agent seat that does not fit its maps would fail at
        # the first reset (in a worker process, after the run folder was made); self-play
        # and a league put their own opponents in every seat no learner drives, and then
        # only a cloning, evaluations and videos meet the scenario's own
        self.schedule = make_schedule(cfg.schedule, cfg.total_steps, cfg.seed)
        if not (cfg.selfplay or self.schedule.fills_seats) or cfg.imitate \
                or cfg.eval_every or cfg.video_every:
            for sc in getattr(env, "scenarios", [self.scenario]):
                check_seats_fit(sc, cfg.game)
        self.E, self.L, self.D = env.num_envs, env.num_learners, env.obs_dim
        mask_dim = int(ACTION_NVEC.sum()) if self.action_mask is not None else 0
        supplied = getattr(env, "input_shapes", {})
        missing = [x for x in self.inputs if x not in supplied]
        if missing:
            raise ValueError(f"the learners need env inputs {missing}, which this env does not "
                             f"supply (it supplies {sorted(supplied)})")
        self.input_dims = {x: int(np.prod(supplied[x], dtype=np.int64)) for x in self.inputs}
        with memory_budget():  # the learners' buffers fit together (SAC's: made by plan)
            self.learners = {spec.name: make_learner(spec, self.D, self.E * len(spec.seats),
                                                     derive_seed(cfg.seed, k), mask_dim,
                                                     self.input_dims)
                             for k, spec in enumerate(specs)}
            wants = {n: lr.rollout_steps for n, lr in self.learners.items() if lr.rollout_steps}
            self.rollout_steps = (cfg.rollout_steps or max(wants.values(), default=0)
                                  or DEFAULT_ROLLOUT_STEPS)
            if any(self.rollout_steps % n for n in wants.values()):
                raise ValueError(f"rollout_steps {self.rollout_steps} must be a multiple of every "
                                 f"learner's rollout length ({wants})")
            problems = fragment_problems(self.learners, self.rollout_steps,
                                         masks=self.action_mask is not None,
                                         selfplay=bool(cfg.selfplay),
                                         env=env) if self.fragments else []
            if problems:
                raise FragmentsRefused(problems)
            steps_per_iter = self.rollout_steps * self.E
            self.total_iterations = max(1, math.ceil(cfg.total_steps / steps_per_iter))
            # total_steps rounded up to whole iterations (presets.planned_steps): where it ends
            self.planned_steps = self.total_iterations * steps_per_iter
            for lr in self.learners.values():
                lr.plan(self.total_iterations * self.rollout_steps)
        self.rivals = opposing_learners(specs, [self.scenario.seats[s].team
                                                for s in self.scenario.learner_seats])
        layout = getattr(env, "layout", None)
        self.alive_col = (layout["self.alive"].start
                          if layout is not None and "self.alive" in layout else None)
        self.victory = (env.core.reward_cfg.victory if hasattr(env, "core")
                        else self.scenario.reward_config(**cfg.rewards).victory)
        self.schedule.check(self.scenario, env)
        game = self.scenario.game_config(**cfg.game)
        walls, buffs, debuffs = slot_counts(game, self.scenario.map_specs())
        seat_learner = {}
        for spec in specs:
            for col in self.cols[spec.name]:
                seat_learner[str(env.learner_seats[col])] = spec.name
        self.observation_meta = {
            "kind": cfg.observation or self.scenario.observation, "obs_dim": self.D,
            "max_walls": walls, "max_buffs": buffs, "max_debuffs": debuffs,
            "team_flags": self.scenario.team_mode, "seat_learner": seat_learner,
            "tanks": len(self.scenario.seats), "action_repeat": cfg.action_repeat}
        self.global_step = 0
        self.iteration = 0
        self.episodes = 0
        self.elapsed = 0.0
        self._load_windows({})  # outcomes, returns, lengths, by_opponent: the last episodes
        # (episodes, windows) at the start of an iteration of fixed-rollout learners
        self.counted: tuple[int, dict[str, Any]] = (0, {})
        self.cut = 0  # vector steps of a stopped iteration inside global_step (0: none)
        self.lost_rollouts = 0  # iterations collected again after an env runner died
        self.notes: list[str] = []  # what happened to the run (lost rollouts), in words
        self.saved_step = -1  # global_step of the newest checkpoint written or resumed from
        self.trained = False  # train() ran: its env and log are closed
        self.stopped: dict[str, Any] = {}  # how train() stopped early, if it did
        self.selfplay = self._make_selfplay() if cfg.selfplay else None
        self.warm_start: dict[str, dict[str, int]] = {}
        if resume is not None:
            self._restore(resume)
            self.saved_step = self.global_step
        elif cfg.init_from:
            self._warm_start(cfg.init_from)
        # the cloning to do first: a fresh run's, or one a stop cut short (restarted whole)
        self.imitation = (imitate_config(cfg.imitate) if resume is None
                          or resume.meta["progress"].get("clone_pending") is True else None)
        if self.imitation is not None:
            from alphatank.training.imitate import check_demonstrations_memory, check_teachers
            from alphatank.training.warmstart import WARM_STARTED
            others = [(s.name, s.algo) for s in self.specs if s.algo not in WARM_STARTED]
            if others:
                raise ValueError(f"imitate: the cloning fills "
                                 f"{' and '.join(a.upper() for a in WARM_STARTED)} learners "
                                 f"only; this run also has {others}")
            driven = sorted(s for spec in self.specs for s in spec.seats)
            check_demonstrations_memory(self.imitation, self.E, len(driven), self.D)
            check_teachers(self.imitation, getattr(env, "scenarios", [self.scenario]),
                           driven, cfg.game)
        if resume is None and self.imitation is None:  # with imitate: after the cloning
            for lr in self.learners.values():
                lr.anchor()
        self._check_cadence()
        self.logger = RunLogger(self.run_dir, cfg.to_dict(), cfg.name, cfg.wandb, cfg.project,
                                cfg.tensorboard, run_id=wandb_id,
                                resume_step=self.global_step if resume is not None else None)
        self.actions = np.ones((self.E, self.L, 3), dtype=np.int64)
        self.history: list[dict[str, float]] = []
        self.schedule.bind(self)

    def _check_cadence(self) -> None:
        """Warn when saves come more often than a game can last: every save restarts all
        matches, so no episode would ever reach its time limit."""
        every, steps = self.cfg.checkpoint_every, self.rollout_steps
        max_steps = self.scenario.game_config(**self.cfg.game).max_steps
        if every and every * steps < max_steps:
            warnings.warn(
                f"checkpoint_every {every} x {steps} vector steps per iteration = "
                f"{every * steps} steps per match between saves, fewer than an episode's "
                f"max_steps ({max_steps}): every save restarts all matches, so no game can "
                f"run its full length; use checkpoint_every >= {math.ceil(max_steps / steps)}",
                RunWarning, stacklevel=4)

    def _make_selfplay(self) -> SelfPlay:
        """The snapshot pool that plays the learner seats no learner drives."""
        name, args = selfplay_pool_args(self.cfg)
        spec = next(s for s in self.specs if s.name == name)
        pool = SnapshotPool(**args, seed=derive_seed(self.cfg.seed, 11), learner=name)

        def make_policy(snap: Snapshot) -> LivePolicy:
            def make() -> Any:
                return make_learner(spec, self.D, len(spec.seats), 0,
                                    input_dims=self.input_dims)
            return LivePolicy({name: pool.frozen(snap.id, make)}, self.observation_meta,
                              learner=name)

        return SelfPlay(pool, make_policy, self.E, learner=name)

    def _warm_start(self, source: str) -> None:
        """Start every PPO/MAPPO learner from the PPO learner of checkpoint ``source`` (the
        others start fresh)."""
        from alphatank.game.seats import checkpoint_source
        from alphatank.training.warmstart import WARM_STARTED, warm_start_from_checkpoint

        try:
            path = checkpoint_source(source)
            for spec in (s for s in self.specs if s.algo in WARM_STARTED):
                seat = self.scenario.learner_seats[spec.seats[0]]
                team = self.scenario.seats[seat].team
                mates = sum(s.team == team for s in self.scenario.seats) - 1
                self.warm_start[spec.name] = warm_start_from_checkpoint(
                    self.learners[spec.name], path, self.env.layout, mates)
        except (ValueError, KeyError) as exc:
            if isinstance(exc, CheckpointError):
                raise
            raise CheckpointError(f"init_from {source!r}: {str(exc).splitlines()[0]}") from None

    # ---- persistence ------------------------------------------------------------------

    def _restore(self, ckpt: Checkpoint) -> None:
        names = ckpt.learner_names()
        if sorted(names) != sorted(self.learners):
            raise ValueError(f"{ckpt.path}: learners {names} do not match this run's "
                             f"{sorted(self.learners)}")
        if ckpt.obs_dim != self.D:
            raise ValueError(f"{ckpt.path}: obs_dim {ckpt.obs_dim}, the env gives {self.D}")
        for name, learner in self.learners.items():
            try:
                learner.load_state_dict(ckpt.state(name))
                arrays = ckpt.replay(name)
                if arrays is not None:
                    learner.load_arrays(arrays)
            except FIT_ERRORS as exc:
                if isinstance(exc, CheckpointError):
                    raise
                raise CheckpointError(f"{ckpt.path / (name + '.pt')}: does not fit learner "
                                      f"{name!r}: {load_problem(exc)}") from None
        prog = ckpt.meta["progress"]
        self.global_step, self.iteration = int(prog["global_step"]), int(prog["iteration"])
        self.episodes, self.elapsed = int(prog["episodes"]), float(prog["elapsed"])
        self.cut = int(prog.get("cut", 0))
        self.schedule.load_state_dict(ckpt.meta.get("schedule", {}))
        self._load_windows(ckpt.meta.get("windows", {}))
        if self.selfplay is not None:
            try:
                self.selfplay.load_state_dict(ckpt.extra_state("selfplay"))
            except FIT_ERRORS as exc:
                if isinstance(exc, CheckpointError):
                    raise
                raise CheckpointError(f"{ckpt.path / 'extra' / 'selfplay.pt'}: does not fit "
                                      f"the run's self-play pool: {type(exc).__name__}: "
                                      f"{load_problem(exc)}") from None

    def _windows(self) -> dict[str, Any]:
        """The rolling episode windows as a checkpoint holds them (copies)."""
        return {"outcomes": {n: list(d) for n, d in self.outcomes.items()},
                "returns": {n: [float(x) for x in d] for n, d in self.returns.items()},
                "lengths": list(self.lengths),
                "by_opponent": {n: {opp: list(d) for opp, d in opps.items()}
                                for n, opps in self.by_opponent.items()}}

    def _load_windows(self, windows: dict[str, Any]) -> None:
        """Set the rolling episode windows to ``windows`` (:meth:`_windows`; older saves
        lack lengths and by_opponent)."""
        def window(values: Any) -> deque:
            return deque(values, maxlen=WINDOW)

        self.outcomes: dict[str, deque[float]] = {
            n: window(windows.get("outcomes", {}).get(n, ())) for n in self.learners}
        self.returns: dict[str, deque[float]] = {
            n: window(windows.get("returns", {}).get(n, ())) for n in self.learners}
        self.lengths: deque[int] = window(int(x) for x in windows.get("lengths", ()))
        self.by_opponent: dict[str, dict[str, deque[float]]] = {
            n: {opp: window(scores) for opp, scores
                                in windows.get("by_opponent", {}).get(n, {}).items()}
                            for n in self.learners}

    def _payload(self) -> dict[str, Any]:
        """What a checkpoint of the current state holds (:func:`save_checkpoint`'s
        ``meta``, ``states``, ``arrays``)."""
        meta = {
            "train_config": self.cfg.to_dict(),
            "scenario": scenario_to_dict(self.scenario),
            "observation": self.observation_meta,
            "input_dims": self.input_dims,
            "learners": [{**spec.to_dict(),
                          "scenario_seats": [self.env.learner_seats[c]
                                             for c in self.cols[spec.name]]}
                         for spec in self.specs],
            "progress": {"global_step": self.global_step, "iteration": self.iteration,
                         "episodes": self.episodes, "elapsed": self.elapsed, "cut": self.cut,
                         "clone_pending": self.imitation is not None},
            "schedule": self.schedule.state_dict(),
            "windows": self._windows(),
            "wandb_id": self.logger.run_id,
            "env": env_id(self.scenario),
        }
        states = {n: lr.state_dict() for n, lr in self.learners.items()}
        arrays = {n: a for n, lr in self.learners.items() if (a := lr.arrays())}
        extra = {"selfplay": self.selfplay.state_dict()} if self.selfplay is not None else None
        return {"meta": meta, "states": states, "arrays": arrays, "extra": extra}

    def save(self, payload: dict[str, Any] | None = None) -> Path:
        """Write a checkpoint of the current state (or of ``payload``, from
        :meth:`_payload`). A second Ctrl-C during it aborts the run once it is written."""
        with self.stop.shielded():
            payload = payload or self._payload()
            step = int(payload["meta"]["progress"]["global_step"])
            try:
                path = save_checkpoint(self.run_dir, f"step_{step:010d}", **payload,
                                       keep=self.cfg.keep_checkpoints)
            except SaveFailed as exc:
                raise SaveFailed(f"{exc}; " + (
                    f"continue from step {self.saved_step:,} with alphatank train --resume "
                    f"{self.run_dir} once it can be written" if self.saved_step >= 0
                    else "the run saved no checkpoint")) from None
            self.saved_step = step
        return path

    def _iteration_start(self) -> Any:
        """What a stop inside the coming iteration saves in place of learners' unfinished
        work: with only fixed-rollout learners the whole checkpoint of this moment (None
        when it is already on disk); otherwise the states of the fixed-rollout learners
        (their rollouts are empty now)."""
        fixed = [n for n, lr in self.learners.items() if lr.rollout_steps]
        if len(fixed) == len(self.learners):
            # the episodes a stop drops with the iteration leave the summary too
            self.counted = (self.episodes, self._windows())
            return None if self.global_step == self.saved_step else copy.deepcopy(
                self._payload())
        return {n: copy.deepcopy(self.learners[n].state_dict()) for n in fixed}

    def policy(self) -> LivePolicy:
        """The current learners as a Policy (for videos and matches in any seat)."""
        return LivePolicy(self.learners, self.observation_meta)

    # ---- the loop ---------------------------------------------------------------------

    def _segment_seed(self) -> int:
        """Seed of a segment reset: from (seed, iteration), and the step of a cut."""
        if self.cut:
            return derive_seed(self.cfg.seed, self.iteration, 7, self.global_step)
        return derive_seed(self.cfg.seed, self.iteration, 7)

    def _segment_reset(self, seed: int | None = None) -> np.ndarray:
        """Restart every match from seeds derived from (seed, iteration) (or ``seed``)."""
        seed = self._segment_seed() if seed is None else seed
        for lr in self.learners.values():
            lr.new_segment()
        # The schedule's setting for this step first: the env's setters reach each match
        # from its next episode, and a resumed run's env starts from the scenario's.
        self.schedule.apply(self.env, self.global_step)
        sp = self.selfplay
        if sp is None:
            return self.env.reset(seed=seed)
        sp.snapshot(self.env, self.learners[sp.learner], self.global_step)
        sp.before_reset(self.env)
        obs = self.env.reset(seed=seed)
        sp.after_reset(self.env)
        return obs

    def _record_episode(self, ep: dict[str, Any], rewards: np.ndarray, scale: float) -> None:
        self.episodes += 1
        self.lengths.append(int(ep["length"]))
        label = str(ep.get("opponent", ""))
        bots = "" if label == "none" else label
        outcome = ep["outcome"]
        unpaid = np.array([(1.0 - scale) * self.victory if out == "win" else 0.0
                           for out in outcome]) if scale < 1.0 else 0.0
        got = ep["return"] - unpaid  # the return the learners were paid
        for name, cols in self.cols.items():
            out = outcome[cols[0]]
            score = 1.0 if out == "win" else 0.0
            self.outcomes[name].append(score)
            self.returns[name].append(float(np.mean(got[cols])))
            key = opponent_key(bots, self.rivals[name]) if bots or self.rivals[name] else "none"
            self.by_opponent[name].setdefault(key, deque(maxlen=WINDOW)).append(score)
        self.schedule.record(str(ep.get("opponent", "")), outcome[0])
        if scale < 1.0:
            env_row = int(ep["env"])
            for col, out in enumerate(outcome):
                if out == "win":
                    rewards[env_row, col] -= (1.0 - scale) * self.victory

    def _iteration_length(self) -> int:
        """Vector steps of the coming iteration: ``rollout_steps``, or fewer where the
        run's iterations were shifted by a segment cut, to end at ``planned_steps``."""
        return min(self.rollout_steps, (self.planned_steps - self.global_step) // self.E)

    def _collect(self, obs: np.ndarray, steps: int | None = None
                 ) -> tuple[np.ndarray, dict[str, float]]:
        """One iteration of ``steps`` (default ``rollout_steps``) vector steps (updates
        included); ends early after the vector step in which a stop is requested (an
        interrupted fixed-rollout update raises :class:`StopRequested`)."""
        metrics: dict[str, float] = {}
        E, D, env = self.E, self.D, self.env
        sp = self.selfplay
        if sp is not None:
            sp.snapshot(env, self.learners[sp.learner], self.global_step)
        for _ in range(self.rollout_steps if steps is None else steps):
            masks = self.action_mask(obs) if self.action_mask is not None else None
            inputs = env.inputs if self.inputs else {}
            for name, learner in self.learners.items():
                cols = self.cols[name]
                x = obs[:, cols].reshape(-1, D)
                m = masks[:, cols].reshape(-1, masks.shape[-1]) if masks is not None else None
                extra = {k: stream_rows(inputs[k], cols) for k in learner.inputs}
                self.actions[:, cols] = learner.act(x, m, **extra).reshape(E, len(cols), 3)
            next_obs, rewards, term, trunc, info = env.step(self.actions)
            if info["episodes"]:
                scale = self.schedule.victory_scale(self.global_step)
                for ep in info["episodes"]:
                    self._record_episode(ep, rewards, scale)
                if sp is not None:
                    sp.on_episodes(env, info["episodes"], trunc, self.cols[sp.learner][0])
            final = info["final_obs"]
            inputs = env.inputs if self.inputs else {}
            ready = []
            for name, learner in self.learners.items():
                cols = self.cols[name]
                k = len(cols)
                active = (obs[:, cols, self.alive_col].reshape(-1) > 0.5
                          if self.alive_col is not None else None)
                nxt = next_obs[:, cols].reshape(-1, D)
                extra = {x: stream_rows(inputs[x], cols) for x in learner.inputs}
                finals = {f"final_{x}": stream_rows(info["final_inputs"][x], cols)
                          for x in learner.inputs}
                learner.observe(nxt, rewards[:, cols].reshape(-1), np.repeat(term, k),
                                np.repeat(trunc, k), final[:, cols].reshape(-1, D), active,
                                **extra, **finals)
                if learner.ready:
                    ready.append((name, learner, nxt, extra))
            obs = next_obs
            self.global_step += E
            for name, learner, nxt, extra in ready:  # after every learner has observed
                for key, val in learner.update(nxt, **extra).items():
                    metrics[f"{key}/{name}" if len(self.learners) > 1 else key] = val
            if self.stop():
                break
        if sp is not None:
            metrics.update(sp.metrics())
        return obs, metrics

    def _start_fragment(self, obs: np.ndarray, iteration: int) -> None:
        """Send the rollout of ``iteration`` to the env's shards, acted by frozen copies of
        the learners as they are now."""
        policy = FrozenLearners.of(self.learners, self.cols,
                                   derive_seed(self.cfg.seed, iteration, 17))
        self.env.rollout_start(policy, obs, self.rollout_steps)

    def _ahead_allowed(self, last_round: bool) -> bool:
        """Whether the next iteration's rollout may start before this one's update: with
        ``overlap``, unless this iteration ends the run, is stopped or saves a checkpoint
        (after which every match restarts)."""
        cfg, nxt = self.cfg, self.iteration + 1
        return (self.overlap and not last_round and not self.stop()
                and self.global_step < self.planned_steps
                and not (cfg.checkpoint_every and nxt % cfg.checkpoint_every == 0))

    def _collect_fragment(self, obs: np.ndarray, last_round: bool = False
                          ) -> tuple[np.ndarray, dict[str, float]]:
        """One iteration acted by the env's shards with frozen copies of the learners
        (:mod:`alphatank.training.fragments`), then each learner's update; a stop during
        the rollout drops it (:class:`StopRequested`, as a stopped update). With
        ``overlap`` the next iteration's rollout (its schedule applied first) starts before
        the update, unless ``last_round`` (a caller that stops after this iteration)."""
        if self.ahead is None:
            self._start_fragment(obs, self.iteration)
        self.ahead = None
        frag = self.env.rollout_finish()
        s0 = self.global_step
        if self.stop():  # dropped as a partial rollout is (_save_stopped)
            self.global_step += frag.steps * self.E
            raise StopRequested(self.stop.reason)
        for ep in frag.episodes:  # in step order, as the step loop records them
            self._record_episode(ep, frag.rewards[ep["step"]],
                                 self.schedule.victory_scale(s0 + ep["step"] * self.E))
        ingest_fragment(frag, self.learners, self.cols, self.alive_col)
        self.global_step += frag.steps * self.E
        if self._ahead_allowed(last_round):
            sched = self.schedule.apply(self.env, self.global_step)
            self._start_fragment(frag.next_obs, self.iteration + 1)
            self.ahead = sched
        metrics: dict[str, float] = {}
        for name, learner in self.learners.items():
            cols = self.cols[name]
            extra = {x: stream_rows(frag.next_inputs[x], cols) for x in learner.inputs}
            for key, val in learner.update(stream_rows(frag.next_obs, cols), **extra).items():
                metrics[f"{key}/{name}" if len(self.learners) > 1 else key] = val
        return frag.next_obs, metrics

    def _window_metrics(self) -> dict[str, float]:
        m: dict[str, float] = {}
        multi = len(self.learners) > 1
        for name in self.learners:
            sfx = f"/{name}" if multi else ""
            if self.outcomes[name]:
                m[f"charts/win_rate{sfx}"] = float(np.mean(self.outcomes[name]))
                m[f"charts/episode_return{sfx}"] = float(np.mean(self.returns[name]))
            for opp, d in self.by_opponent[name].items():
                m[f"charts/win_rate_vs/{opp}{sfx}"] = float(np.mean(d))
        if self.lengths:
            m["charts/episode_length"] = float(np.mean(self.lengths))
        m["charts/episodes"] = float(self.episodes)
        return m

    def evaluate(self, games: int) -> dict[str, float]:
        """Win rate of the current learners against the scenario's own opponents."""
        from alphatank.training.evaluate import evaluate_learners
        res = evaluate_learners(self.learners, self.observation_meta,
                                {s.name: s.algo for s in self.specs}, self.scenario, [None],
                                games=games, seed=derive_seed(self.cfg.seed, 99),
                                num_envs=min(16, games), game_overrides=self.cfg.game,
                                reward_overrides=self.cfg.rewards)[0]
        lo, hi = res.interval
        return {"eval/win_rate": res.win_rate, "eval/win_ci_low": lo, "eval/win_ci_high": hi,
                "eval/draw_rate": res.draws / res.games}

    def record_video(self, path: Path) -> Path | None:
        """An MP4 of one match of the current learners (None if video is unavailable)."""
        from alphatank.training.video import record_policy_match
        return record_policy_match(self.scenario, self.policy(), path,
                                   seed=derive_seed(self.cfg.seed, self.iteration, 3),
                                   game_overrides=self.cfg.game)

    def train(self) -> dict[str, Any]:
        """Run until ``total_steps``, the time budget of this call (``time_limit_s``) or
        SIGINT / SIGTERM, always ending with a checkpoint to resume from. Returns a
        summary; ``stopped`` says why it ended early (None: it reached ``total_steps``;
        ``finished``: a stop that came once the steps were trained, which skipped the final
        evaluation if ``final_eval_skipped``; ``no_progress``: the time limit came before
        this call saved anything further) and ``exit_code`` is 130 / 143 after SIGINT
        / SIGTERM, else 0. An env worker process that dies raises :class:`EnvWorkerDied`
        (the last checkpoint stays as it was). A Trainer trains once (its env and log close
        at the end): go on with :func:`resume_trainer`."""
        if self.trained:
            raise RuntimeError(f"this Trainer has trained; continue the run with "
                               f"resume_trainer({str(self.run_dir)!r})")
        self.trained = True
        cfg = self.cfg
        self.lock.acquire()
        start = time.perf_counter() - self.elapsed  # elapsed counts the whole run
        began = self.global_step
        self.stop.limit(cfg.time_limit_s)  # the budget counts this call only
        self.stopped = {}
        bar = None
        if self.progress:
            from tqdm import tqdm
            bar = tqdm(total=self.planned_steps, initial=min(self.global_step, self.planned_steps),
                       unit="step", unit_scale=True, dynamic_ncols=True, desc=cfg.name)
        for lr in self.learners.values():
            lr.interrupt = self.stop  # polled between gradient steps (Learner protocol)
        with stop_on_signals(self.stop):
            try:
                self._run(bar, start)
            except WorkerDied as exc:  # not this process's stdout going away (exit 141)
                kept = (f"the run's last checkpoint, step {self.saved_step:,}, is kept: "
                        f"continue with alphatank train --resume {self.run_dir}"
                        if self.saved_step >= 0 else "nothing was saved")
                raise EnvWorkerDied(f"an env worker process died at step "
                                    f"{self.global_step:,} (killed? out of memory?); "
                                    f"{kept}") from exc
            finally:
                for lr in self.learners.values():
                    lr.interrupt = None
                if bar is not None:
                    bar.close()
                self.logger.close()
                self.ahead = None
                self.env.close()  # a rollout started ahead is dropped with it
                self.lock.release()
        if self.stop.reason is not None:
            finished = {"finished": True} if self.saved_step >= self.planned_steps else {}
            # a time limit shorter than an iteration: a resume under it gets no further
            stuck = ({"no_progress": True} if self.stop.reason == "time limit"
                     and not finished and self.saved_step <= began
                     and "clone_pending" not in self.stopped else {})
            self.stopped = {"reason": self.stop.reason, "checkpoint_step": self.saved_step,
                            **finished, **stuck, **self.stopped}
        return {"run_dir": str(self.run_dir), "global_step": self.global_step,
                "saved_step": self.saved_step, "iterations": self.iteration,
                "episodes": self.episodes, "elapsed_s": self.elapsed,
                "stopped": self.stopped or None, "exit_code": self.stop.exit_code,
                "notes": list(self.notes),
                **self._window_metrics()}

    def _run(self, bar: Any, start: float) -> None:
        """The iterations of :meth:`train` (``start``: the perf_counter of elapsed 0)."""
        cfg = self.cfg
        if self.imitation is not None:  # a fresh run, or one stopped before its cloning ended
            fresh = {n: copy.deepcopy(lr.state_dict()) for n, lr in self.learners.items()}
            metrics = imitate(self, self.imitation)
            if self.stop():  # cut short: save the fresh learners, the cloning restarts whole
                for name, state in fresh.items():
                    self.learners[name].load_state_dict(state)
                self.stopped = {"clone_pending": True}
                self.elapsed = time.perf_counter() - start
                self.save()
                return
            self.imitation = None
            for lr in self.learners.values():
                lr.anchor()
            self.elapsed = time.perf_counter() - start
            self.logger.log({**metrics, "charts/elapsed_s": self.elapsed}, 0)
        obs = self._segment_reset()
        while self.global_step < self.planned_steps and not self.stop():
            before = self._iteration_start()
            rollback = self._rollback_point()
            sched = (self.ahead if self.ahead is not None  # applied when it started
                     else self.schedule.apply(self.env, self.global_step))
            t0, s0 = time.perf_counter(), self.global_step
            # fragments (fixed-rollout learners only) are never cut: whole iterations
            steps = self.rollout_steps if self.fragments else self._iteration_length()
            try:
                obs, metrics = (self._collect_fragment(obs) if self.fragments
                                else self._collect(obs, steps))
                complete = self.global_step - s0 == steps * self.E
            except StopRequested:  # a fixed-rollout learner's update was cut short
                metrics, complete = {}, False
            except RolloutLost as lost:  # an env runner died: collect the iteration again
                obs = self._lost_rollout(lost, rollback, s0)
                continue
            self.elapsed = time.perf_counter() - start
            if not complete:
                self._save_stopped(before, metrics, sched, s0, t0)
                return
            self.cut = 0
            self.iteration += 1
            dt = time.perf_counter() - t0
            metrics.update(sched)
            metrics.update(self._window_metrics())
            metrics["charts/sps"] = (self.global_step - s0) / dt
            metrics["charts/iteration"] = float(self.iteration)
            metrics["charts/elapsed_s"] = self.elapsed
            last = self.global_step >= self.planned_steps or self.stop()
            evaluate = cfg.eval_every and (self.iteration % cfg.eval_every == 0 or last)
            video = cfg.video_every and self.iteration % cfg.video_every == 0
            if evaluate or video:
                try:
                    with self.stop.interruptible():  # a stop skips them: nothing to save
                        if evaluate:
                            metrics.update(self.evaluate(cfg.eval_games))
                        if video:
                            self._video()
                except StopRequested:
                    last = True
                    if evaluate and self.global_step >= self.planned_steps:
                        self.stopped = {"final_eval_skipped": True}
            self.logger.log(metrics, self.global_step)
            self.history.append({"step": self.global_step, **metrics})
            if bar is not None:
                bar.update(min(self.global_step, self.planned_steps) - bar.n)
                win = metrics.get("charts/win_rate",
                                  next((v for k, v in metrics.items()
                                        if k.startswith("charts/win_rate/")), None))
                post = {"sps": f"{metrics['charts/sps']:.0f}"}
                if win is not None:  # else no episode has ended yet
                    post["win"] = f"{win:.2f}"
                bar.set_postfix(post, it=self.iteration, refresh=False)
            if last or (cfg.checkpoint_every and self.iteration % cfg.checkpoint_every == 0):
                self.elapsed = time.perf_counter() - start  # up to the save, stop check included
                self.save()
                if last:
                    return
                obs = self._segment_reset()
        if self.global_step != self.saved_step:  # stopped between iterations
            self.elapsed = time.perf_counter() - start
            self.save()

    def _rollback_point(self) -> dict[str, Any] | None:
        """With an env that can lose a rollout (env runners in Ray actors): the states of
        the fixed-rollout learners at the iteration start (their rollouts are empty)."""
        if not getattr(self.env, "can_lose_rollouts", False):
            return None
        return {n: copy.deepcopy(lr.state_dict()) for n, lr in self.learners.items()
                if lr.rollout_steps}

    def _lost_rollout(self, lost: RolloutLost, rollback: dict[str, Any] | None,
                      s0: int) -> np.ndarray:
        """An env runner died mid-iteration (Ray restarted it): fixed-rollout learners go
        back to the iteration start and drop their partial rollouts (an off-policy
        learner keeps its whole transitions), the step count goes back to ``s0``, and
        every match restarts; returns the first observations. Says so on stderr and in
        the log (``charts/lost_rollouts``)."""
        if rollback is None:
            raise lost
        for name, state in rollback.items():
            self.learners[name].load_state_dict(state)
            self.learners[name].drop_rollout()
        self.lost_rollouts += 1
        dropped = self.global_step - s0
        self.global_step = s0
        note = (f"iteration {self.iteration + 1}: {lost}; the rollout in flight "
                f"({dropped:,} steps) was dropped and is collected again")
        self.notes.append(note)
        print(f"warning: {note}", file=sys.stderr, flush=True)
        self.logger.log({"charts/lost_rollouts": float(self.lost_rollouts)}, self.global_step)
        return self._segment_reset(derive_seed(self.cfg.seed, self.iteration, 13,
                                               self.lost_rollouts))

    def _save_stopped(self, before: Any, metrics: dict[str, float], sched: dict[str, float],
                      s0: int, t0: float) -> None:
        """Save after a stop inside an iteration; ``before``: :meth:`_iteration_start`'s
        snapshot (see the module docstring)."""
        if all(lr.rollout_steps for lr in self.learners.values()):
            self.stopped = {"dropped_steps": self.global_step - s0}
            self.episodes, windows = self.counted  # as the save holds them
            self._load_windows(windows)
            if before is not None:  # else the state at the iteration start is on disk
                before["meta"]["progress"]["elapsed"] = self.elapsed  # the run's whole time
                self.save(before)
            return
        self.cut = (self.global_step - s0) // self.E
        metrics.update(sched)
        metrics.update(self._window_metrics())
        metrics["charts/sps"] = (self.global_step - s0) / max(time.perf_counter() - t0, 1e-9)
        metrics["charts/iteration"] = float(self.iteration)
        metrics["charts/elapsed_s"] = self.elapsed
        self.logger.log(metrics, self.global_step)
        self.history.append({"step": self.global_step, **metrics})
        payload = self._payload()
        payload["states"].update(before)  # fixed-rollout learners drop unfinished rollouts
        self.save(payload)
        self.stopped = {"cut_steps": self.global_step - s0,
                        "dropped_rollouts": sorted(before)}

    def _video(self) -> None:
        path = self.record_video(self.run_dir / "videos" / f"step_{self.global_step:010d}.mp4")
        if path is not None:
            self.logger.video(path, self.global_step)


def resume_trainer(path: str | Path, progress: bool = True, env: Any = None,
                   env_runners: int = 0, env_runner_timeout_s: float = ENV_RUNNER_TIMEOUT_S,
                   fragments: bool = False, overlap: bool = False,
                   stop: StopFlag | None = None, **overrides: Any) -> Trainer:
    """A :class:`Trainer` continuing the run saved at ``path`` (checkpoint or run dir);
    ``overrides`` change run settings such as ``total_steps``; ``env_runners``,
    ``env_runner_timeout_s``, ``fragments``, ``overlap`` and ``stop``: as for
    :class:`Trainer`."""
    ckpt = load_checkpoint(path)
    run_dir = resume_dir(ckpt)
    cfg = ckpt.train_config.with_overrides(**overrides)
    return Trainer(cfg, run_dir, env=env, resume=ckpt, progress=progress,
                   wandb_id=ckpt.meta.get("wandb_id"), scenario=ckpt.scenario,
                   env_runners=env_runners, env_runner_timeout_s=env_runner_timeout_s,
                   fragments=fragments, overlap=overlap, stop=stop)

"""``alphatank train``: run a training preset or a run file (any registered algorithm,
against bots, agents, teams), with flags for the scenario, map, schedule, hyperparameters
and run settings. Listing presets and hyperparameters never imports torch."""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import gc
import math
import sys
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

from alphatank.cluster import ENV_RUNNER_TIMEOUT_S
from alphatank.commands.argtypes import (
    action_repeat,
    given,
    in_range,
    int_in_range,
    match_count,
    non_negative_int,
    positive_float,
    positive_int,
    seed,
)
from alphatank.errors import InputError, as_input_error
from alphatank.files import check_folder, check_free
from alphatank.training.fields import FieldError
from alphatank.training.presets import (
    BOT_POOL,
    CYCLE_INTERVAL,
    TORCH_THREADS_MAX,
    WANDB_MODES,
    TrainConfig,
    check_run_fields,
    default_learners,
    get_preset,
    hyperparameter_help,
    iteration_steps,
    learners_fit,
    load_run,
    parse_hp,
    planned_steps,
    preset_names,
    run_learners,
    run_name_problem,
    run_scenario,
    run_toml,
    with_hp,
)
from alphatank.training.stopping import TIME_LIMIT_MAX_S, StopFlag, StopRequested, stop_on_signals

if TYPE_CHECKING:
    from alphatank.training.runner import Trainer

DEFAULT_PRESET = "ppo_vs_aggressive"
SCHEDULES = ("none", "cycle:fixed", "cycle:random", "cycle:adaptive")
SHAPES = ("linear", "sigmoid")
NEW_RUN_ONLY = ("preset", "config", "scenario", "map", "schedule", "curriculum", "hp", "ppo",
                "sac", "init_from", "action_repeat")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.formatter_class = argparse.RawDescriptionHelpFormatter
    p.epilog = ("Hyperparameters (set with --hp ALGO.FIELD=VALUE; default, type and range "
                "in brackets):\n" + hyperparameter_help())
    what = p.add_argument_group("what to train")
    what.add_argument("--preset", help=f"training preset (default: {DEFAULT_PRESET}); one of "
                      f"{preset_names()}")
    what.add_argument("--config", type=given, metavar="FILE.toml",
                      help="a run file (the format of the presets; --print-config writes one)")
    what.add_argument("--scenario", type=given, metavar="NAME|FILE",
                      help="play this scenario instead (learners that do not fit its learner "
                           "seats become one learner per seat, of the first learner's kind)")
    what.add_argument("--map", type=given, metavar="NAME|FOLDER",
                      help="override the scenario's map: a shipped map, a shipped folder such "
                           "as 'train' (16 training maps), a .txt file or a folder of maps")
    what.add_argument("--schedule", metavar="|".join(SCHEDULES),
                      help=f"cycle the opponent over the bots {', '.join(BOT_POOL)} in order "
                           f"(fixed), uniformly (random) or by weakness (adaptive), keeping "
                           f"a preset cycle's settings (else every {CYCLE_INTERVAL:,} env "
                           f"steps, or total/8 for shorter runs); none: no schedule")
    what.add_argument("--curriculum", nargs="?", const=True, metavar="START:END[:SHAPE]",
                      help="raise the bots' weakness (probability of acting per tick) over "
                           "the run; default 0.1:0.8, shape linear or sigmoid")
    what.add_argument("--init-from", type=given, metavar="CHECKPOINT",
                      help="warm start: every learner starts from the PPO learner of this "
                           "checkpoint (a run or checkpoint folder, or agent:NAME, e.g. a 1v1 "
                           "agent for a team run; new inputs start at zero weight)")
    what.add_argument("--action-repeat", type=action_repeat, metavar="K",
                      help="hold each learner action for K ticks (the bots still act every "
                           "tick): an env step is K ticks; default 1")
    what.add_argument("--hp", action="append", default=[], metavar="ALGO.FIELD=VALUE,...",
                      help="set a hyperparameter of every learner of that algorithm, e.g. "
                           "ppo.update_epochs=4 (repeatable; see the list below)")
    what.add_argument("--ppo", action="append", default=[], metavar="K=V,...",
                      help="same as --hp ppo.K=V,... (e.g. update_epochs=4,num_steps=128; "
                           "repeatable)")
    what.add_argument("--sac", action="append", default=[], metavar="K=V,...",
                      help="same as --hp sac.K=V,... (e.g. utd_ratio=0.25; repeatable)")
    info = p.add_argument_group("information")
    info.add_argument("--list", action="store_true",
                      help="list the presets and every hyperparameter, then exit")
    info.add_argument("--list-hp", action="store_true",
                      help="list every hyperparameter of every algorithm, then exit")
    info.add_argument("--print-config", action="store_true",
                      help="print the run (after all flags) as a run file, then exit")
    run = p.add_argument_group("run settings")
    run.add_argument("--name", help="run name; the run lives in <runs>/<name> "
                                    "(default: the preset's or the file's name)")
    run.add_argument("--runs", type=given, help="folder of runs (default: runs)")
    run.add_argument("--resume", type=given, metavar="DIR",
                     help="continue the run saved in DIR (a run folder or a checkpoint)")
    run.add_argument("--total-steps", type=positive_int,
                     help="env steps to train in total, rounded up to a whole iteration "
                          "(rollout_steps x num_envs env steps, e.g. SAC's 512 x 16 = "
                          "8,192): the step count is checked between iterations")
    run.add_argument("--num-envs", type=match_count, help="matches stepped together")
    run.add_argument("--workers", type=positive_int,
                     help="env worker processes (2 uses both cores)")
    run.add_argument("--seed", type=seed, help="run seed")
    run.add_argument("--time-limit", type=in_range(0, TIME_LIMIT_MAX_S), metavar="S",
                     help="stop (with a checkpoint) after S seconds of this invocation, at "
                          f"most a week ({TIME_LIMIT_MAX_S}): a resumed run gets S seconds "
                          "more (the logged elapsed time counts the whole run); SIGINT "
                          "(Ctrl-C) and SIGTERM also stop with a checkpoint within seconds "
                          "(a second Ctrl-C quits without it, but lets a save under way "
                          "finish first)")
    run.add_argument("--checkpoint-every", type=non_negative_int, metavar="N",
                     help="iterations per save (every save restarts all matches: keep N x "
                          "the rollout length above the episode length)")
    run.add_argument("--keep-checkpoints", type=non_negative_int, metavar="K",
                     help="newest saves kept (default: 3; 0 keeps all)")
    run.add_argument("--eval-every", type=non_negative_int, metavar="N",
                     help="iterations per evaluation")
    run.add_argument("--eval-games", type=positive_int, help="games per evaluation during training")
    run.add_argument("--video-every", type=non_negative_int, metavar="N",
                     help="iterations per match video")
    run.add_argument("--wandb", choices=WANDB_MODES, help="wandb mode (default: offline)")
    run.add_argument("--tensorboard", action="store_true", default=None,
                     help="also write TensorBoard logs (needs the tensorboard package)")
    run.add_argument("--torch-threads", type=int_in_range(1, TORCH_THREADS_MAX),
                     help="torch threads (default: 1)")
    run.add_argument("--no-progress", action="store_true", help="no progress bar")
    cluster = p.add_argument_group("Ray cluster (the ray extra; docs/distributed.md)")
    cluster.add_argument("--ray", nargs="?", const="", metavar="ADDRESS",
                         help="step the matches in Ray actors: join the cluster at "
                              "HOST:PORT, or without ADDRESS start a local Ray instance")
    cluster.add_argument("--env-runners", type=positive_int, metavar="N",
                         help="with --ray: env-runner actors (one CPU each), in place of "
                              "--workers processes; the same seed and N give the same run as "
                              "--workers N (default: the run's workers, at least 2)")
    cluster.add_argument("--env-runner-timeout", type=positive_float, metavar="SECONDS",
                         help="with --env-runners: a runner that does not answer a step "
                              "within SECONDS is hung: it is killed and restarted, and the "
                              f"iteration collected again (default: {ENV_RUNNER_TIMEOUT_S:g})")
    cluster.add_argument("--fragments", action="store_true",
                         help="each env shard (--env-runners actor, --workers process, or "
                              "the one process) acts a whole rollout with a copy of the "
                              "policy and answers once per iteration, not once per step "
                              "(PPO and MAPPO learners; reproducible for the same seed and "
                              "shard count, not step-equal to a run without it; "
                              "docs/distributed.md)")
    cluster.add_argument("--overlap", action="store_true",
                         help="--fragments, and the shards act the next rollout while the "
                              "learner updates on this one (each rollout acted by the "
                              "policy of one update earlier): the learner no longer "
                              "leaves the env cores idle (docs/distributed.md)")


# TrainConfig field -> the flag that sets it (run settings, also allowed with --resume)
RUN_FLAGS = {"total_steps": "--total-steps", "num_envs": "--num-envs",
             "num_workers": "--workers", "seed": "--seed", "time_limit_s": "--time-limit",
             "checkpoint_every": "--checkpoint-every", "eval_every": "--eval-every",
             "keep_checkpoints": "--keep-checkpoints", "eval_games": "--eval-games",
             "video_every": "--video-every", "wandb": "--wandb", "tensorboard": "--tensorboard",
             "torch_threads": "--torch-threads"}


def _overrides(args: argparse.Namespace) -> dict:
    return {field: getattr(args, flag[2:].replace("-", "_"))
            for field, flag in RUN_FLAGS.items()}


def _with_run_settings(cfg: TrainConfig, args: argparse.Namespace, name: str | None = None
                       ) -> TrainConfig:
    """``cfg`` with the run-setting flags (and ``name``) applied; a bad value names its
    flag."""
    try:
        return cfg.with_overrides(name=name, **_overrides(args))
    except FieldError as exc:
        flag = "--name" if exc.name == "name" else RUN_FLAGS.get(exc.name, exc.name)
        raise ValueError(f"{flag}: {exc.problem}") from None


def _check_workers(cfg: TrainConfig, args: argparse.Namespace, field: str) -> None:
    """Refuse more env worker processes than matches (each process steps at least one),
    naming --workers, or ``field`` (where the run's own count comes from) when it was not
    given. A --ray run steps its matches in env runners instead."""
    if args.ray is None and cfg.num_workers > cfg.num_envs:
        where = "--workers" if args.workers is not None else field
        raise ValueError(f"{where}: {cfg.num_workers} worker processes for {cfg.num_envs} "
                         f"matches; at most one per match (fewer --workers or more "
                         f"--num-envs)")


def _learners_label(cfg: TrainConfig) -> str:
    algos = [s.algo for s in cfg.learners] or ["ppo"]
    if len(set(algos)) == 1:
        return algos[0] + (f" x{len(algos)}" if len(algos) > 1 else "")
    return " + ".join(algos)


def list_presets() -> str:
    presets = {name: get_preset(name) for name in preset_names()}
    width = max(len(n) for n in presets)
    lines = [f"{'preset':{width}s}  {'scenario':18s} {'learners':12s} description"]
    for name, cfg in presets.items():
        lines.append(f"{name:{width}s}  {cfg.scenario:18s} {_learners_label(cfg):12s} "
                     f"{cfg.description}")
    return "\n".join(lines)


def _schedule(cfg: TrainConfig, args: argparse.Namespace) -> dict[str, Any]:
    """The run's schedule after --schedule / --curriculum."""
    if args.schedule is not None and args.curriculum is not None:
        raise ValueError("--schedule and --curriculum: give one (a bot cycle or a weakness "
                         "curriculum)")
    current = dict(cfg.schedule)
    if args.schedule is not None:
        if args.schedule not in SCHEDULES:
            raise ValueError(f"--schedule: got {args.schedule!r}; allowed: "
                             f"{', '.join(SCHEDULES)}")
        if args.schedule == "none":
            return {}
        base = current if current.get("kind") == "cycle" else {
            "pool": list(BOT_POOL), "interval": max(1, min(CYCLE_INTERVAL,
                                                           cfg.total_steps // 8))}
        return {**base, "kind": "cycle", "mode": args.schedule.split(":")[1]}
    if args.curriculum is not None:
        base = current if current.get("kind") == "curriculum" else {"start": 0.1, "end": 0.8}
        parts = [] if args.curriculum is True else args.curriculum.split(":")
        form = "--curriculum: expected START:END[:SHAPE] with weaknesses in [0, 1] and " \
               f"SHAPE one of {', '.join(SHAPES)}"
        if args.curriculum is not True and not 2 <= len(parts) <= 3:
            raise ValueError(f"{form}, got {args.curriculum!r}")
        try:
            ends = {"start": float(parts[0]), "end": float(parts[1])} if parts else {}
        except ValueError:
            raise ValueError(f"{form}, got {args.curriculum!r}") from None
        if any(not 0.0 <= w <= 1.0 for w in ends.values()) or (
                len(parts) == 3 and parts[2] not in SHAPES):
            raise ValueError(f"{form}, got {args.curriculum!r}")
        shape = {"shape": parts[2]} if len(parts) == 3 else {}
        return {**base, **ends, **shape, "kind": "curriculum"}
    return current


def _stretched(saved: TrainConfig, cfg: TrainConfig) -> list[str]:
    """What spans the whole run and moves when a resumed run's ``total_steps`` changes:
    a curriculum's ramp, learning-rate annealing."""
    if cfg.total_steps == saved.total_steps:
        return []
    out = ["the curriculum's weakness ramp"] if cfg.schedule.get("kind") == "curriculum" else []
    if any(getattr(s.config, "anneal_lr", False) for s in cfg.learners):
        out.append("the learning-rate annealing")
    return out


def build_run(args: argparse.Namespace) -> TrainConfig:
    """The TrainConfig a new run's flags describe; ValueError (one line) on bad input."""
    if args.config and args.preset:
        raise ValueError("--config and --preset: give one")
    if args.name is not None and (why := run_name_problem(args.name)):
        raise ValueError(f"--name: {why}")  # before it names a run file's run
    # where the run's own settings come from, for errors in the ones no flag replaces
    source = str(Path(args.config)) if args.config else \
        f"presets/{args.preset or DEFAULT_PRESET}.toml"
    try:
        cfg = (load_run(args.config, args.name) if args.config else
               get_preset(args.preset or DEFAULT_PRESET))
    except ValueError as exc:  # a run file's errors name the file; a preset's: the flag
        raise ValueError(f"{'' if args.config else '--preset: '}{exc}") from None
    cfg = _with_run_settings(cfg, args, args.name)
    _check_workers(cfg, args, f"{source}: num_workers")
    from alphatank.game.scenarios import load_scenario
    scenario, label = (args.scenario, "--scenario") if args.scenario is not None else \
        (cfg.scenario, f"{source}: scenario")
    try:
        load_scenario(scenario)
    except ValueError as exc:
        raise ValueError(f"{label}: {exc}") from None
    cfg = dataclasses.replace(cfg, scenario=scenario)
    if args.map is not None:
        cfg = dataclasses.replace(cfg, map=args.map)
    if args.action_repeat is not None:
        cfg = dataclasses.replace(cfg, action_repeat=args.action_repeat)
    if args.init_from is not None:
        cfg = dataclasses.replace(cfg, init_from=args.init_from)
    try:
        sc = run_scenario(cfg)
    except ValueError as exc:
        where = "--map: " if args.map is not None else f"{source}: map: " if cfg.map else ""
        raise ValueError(f"{where}{exc}") from None
    n = len(sc.learner_seats)
    if n and args.scenario is not None and not cfg.selfplay and \
            not learners_fit(run_learners(cfg, n), n):
        first = cfg.learners[0]
        learners = default_learners(n, first.algo, first.config)
        print(f"note: learners {[(s.name, list(s.seats)) for s in cfg.learners]} do not fit "
              f"scenario {sc.name!r} ({n} learner seats): one {first.algo} learner per seat "
              f"instead", file=sys.stderr)
        cfg = dataclasses.replace(cfg, learners=learners)
    schedule = _schedule(cfg, args)
    if (args.schedule or args.curriculum is not None) and schedule and not any(
            s.controller == "bot" for s in sc.seats):
        flag = "--schedule" if args.schedule else "--curriculum"
        raise ValueError(f"{flag}: scenario {sc.name!r} has no bot seats to schedule")
    cfg = dataclasses.replace(cfg, schedule=schedule)
    check_run_fields(cfg, sc, source, "--scenario" if args.scenario is not None else None)
    if cfg.init_from:
        from alphatank.training.warmstart import check_init_from
        check_init_from(cfg, "--init-from" if args.init_from is not None
                        else f"{source}: init_from")
    from alphatank.training.schedules import make_schedule
    try:
        make_schedule(cfg.schedule, cfg.total_steps)
    except ValueError as exc:
        raise ValueError(f"schedule: {exc}") from None
    hp_items = [(f"--{flag}", t) for flag in ("hp", "ppo", "sac") for t in getattr(args, flag)]
    flags: dict[str, list[str]] = {}
    cfg = with_hp(cfg, parse_hp(hp_items, flags), n, flags)
    wants = {s.name: s.config.num_steps for s in run_learners(cfg, n)
             if hasattr(s.config, "num_steps")}
    rollout = cfg.rollout_steps or max(wants.values(), default=0)  # as the Trainer's
    if rollout and any(rollout % k for k in wants.values()):
        if cfg.rollout_steps:
            raise ValueError(f"{source}: rollout_steps: {rollout} must be a multiple of "
                             f"every learner's rollout length, num_steps ({wants})")
        raise ValueError(f"{source}: rollout_steps: 0 (the longest num_steps, {rollout}) must "
                         f"be a multiple of every learner's rollout length, num_steps "
                         f"({wants}); set rollout_steps to a common multiple, e.g. "
                         f"{math.lcm(*wants.values())}")
    return cfg


def run(args: argparse.Namespace) -> int:
    """Bad input raises InputError (run files, presets, flags and hyperparameters raise
    ValueError: converted), reported by :func:`alphatank.cli.main` in one line, exit 2."""
    if args.list:
        print(list_presets())
        print("\nHyperparameters (--hp ALGO.FIELD=VALUE):\n" + hyperparameter_help())
        return 0
    if args.list_hp:
        print(hyperparameter_help())
        return 0
    progress = not args.no_progress
    if args.env_runners is not None and args.ray is None:
        raise InputError("--env-runners: needs --ray (env runners are Ray actors; --workers "
                         "sets local worker processes)")
    if args.env_runner_timeout is not None and args.ray is None:
        raise InputError("--env-runner-timeout: needs --ray (it applies to env runners)")
    with contextlib.ExitStack() as stack:  # holds the Ray connection of a --ray run
        return _run(args, progress, stack)


def _runner_timeout(args: argparse.Namespace) -> float:
    return (ENV_RUNNER_TIMEOUT_S if args.env_runner_timeout is None
            else args.env_runner_timeout)


def _env_runners(args: argparse.Namespace, cfg: TrainConfig, stack: contextlib.ExitStack
                 ) -> int:
    """Env-runner actors of a ``--ray`` run (0 without --ray). A count the run's envs
    cannot fill is refused before Ray starts; then the cluster is joined (or a local Ray
    started, closed with ``stack``) and a count it cannot place is refused."""
    if args.ray is None:
        return 0
    n = args.env_runners or min(max(2, cfg.num_workers), cfg.num_envs)
    if n > cfg.num_envs:
        raise InputError(f"--env-runners: {n} runners for {cfg.num_envs} envs; at most "
                         f"--num-envs")
    from alphatank.cluster import connect
    connection = connect(args.ray or None, feature="alphatank train --ray")
    stack.callback(connection.close)
    print(connection.describe(), flush=True)
    if n > connection.cpus:
        raise InputError(f"--env-runners: {n} runners need {n} CPUs; the Ray cluster has "
                         f"{connection.cpus:g}")
    return n


def _run(args: argparse.Namespace, progress: bool, stack: contextlib.ExitStack) -> int:
    """:func:`run` once the flags are checked. SIGINT and SIGTERM stop it from here on: in
    the start-up (reading the run, making its envs, workers and learners) with nothing
    written, its lock released and a new run's folder removed (one line, exit 130 or
    143); once the trainer is made, as in training (:meth:`Trainer.train`)."""
    stop = StopFlag()
    with stop_on_signals(stop):
        try:
            trainer = _start(args, progress, stack, stop)
        except StopRequested:
            kept = (f"{args.resume} is as it was; continue with alphatank train --resume "
                    f"{args.resume}" if args.resume else "nothing saved")
            print(f"alphatank train: interrupted by {stop.reason} during start-up; {kept}",
                  file=sys.stderr)
            gc.freeze()  # as after training: a quicker exit
            return stop.exit_code
        if trainer is None:  # --print-config
            return 0
        if args.total_steps is not None:
            _note_rounding(trainer.cfg)
        from alphatank.training.checkpoint import SaveFailed
        from alphatank.training.runner import EnvWorkerDied
        try:
            summary = trainer.train()
        except (EnvWorkerDied, SaveFailed) as exc:  # not bad input, nor the reader of
            # stdout going away (exit 141)
            print(f"alphatank train: error: {exc}", file=sys.stderr)
            return 1
        except KeyboardInterrupt:
            if not trainer.stop.aborted:
                raise
            # a second Ctrl-C during a save: it was finished first, so the run goes on from it
            raise KeyboardInterrupt(f"after saving step {trainer.saved_step:,}; continue "
                                    f"with alphatank train --resume {trainer.run_dir}"
                                    ) from None
    code = report(summary)
    # the process ends now: spare it the final garbage collections over torch's objects
    # (about a second of the time between Ctrl-C and the prompt on a busy machine)
    gc.freeze()
    return code


def _start(args: argparse.Namespace, progress: bool, stack: contextlib.ExitStack,
           stop: StopFlag) -> Trainer | None:
    """The run's Trainer (None after --print-config). A stop (``stop``, set by the signals)
    raises :class:`StopRequested`: at once while the run is read and checked, and while
    the Trainer is made once that has undone what it made. A --ray run joins Ray (held by
    ``stack``) when its settings are known, just before its trainer is made."""
    if args.resume:
        given = [f"--{k.replace('_', '-')}" for k in NEW_RUN_ONLY
                 if getattr(args, k) not in (None, "", [])]
        if given:
            raise InputError(f"{', '.join(given)} appl{'ies' if len(given) == 1 else 'y'} to "
                             f"new runs; a resumed run keeps its settings")
        if args.name is not None or args.runs is not None:
            raise InputError("--name and --runs name a new run's folder; a resumed run "
                             "continues in its own (--resume DIR); to branch a run, copy its "
                             "folder and resume the copy")
        try:  # a CheckpointError is an InputError already
            with stop.interruptible():
                saved_in = Path(args.resume)  # a run, or one of its saves
                check_free(saved_in.parent.parent if saved_in.parent.name == "checkpoints"
                           else saved_in)  # in use: said before torch and the load
                from alphatank.training.checkpoint import load_checkpoint, resume_dir
                from alphatank.training.runner import resume_trainer
                ckpt = load_checkpoint(args.resume)
                saved = ckpt.train_config
                if args.num_envs not in (None, saved.num_envs):
                    raise InputError(f"--num-envs: the run plays {saved.num_envs} matches, "
                                     f"and a resumed run keeps them (its normalisers and "
                                     f"rollouts hold one stream per match)")
                cfg = _with_run_settings(saved, args)
                _check_workers(cfg, args, "--workers")
                if args.print_config:
                    print(run_toml(cfg), end="")
                    return None
                resume_dir(ckpt)  # refused before Ray starts: not a run's save, or not writable
                runners = _env_runners(args, cfg, stack)
            with _one_line_warnings():
                trainer = resume_trainer(args.resume, progress=progress, env_runners=runners,
                                         env_runner_timeout_s=_runner_timeout(args),
                                         fragments=args.fragments, overlap=args.overlap,
                                         stop=stop, **_overrides(args))
        except ValueError as exc:
            raise _as_flag_error(exc, args) from None
        stretched = _stretched(saved, trainer.cfg)
        if stretched:
            print(f"note: --total-steps {trainer.cfg.total_steps:,} (the run was planned for "
                  f"{saved.total_steps:,}): {' and '.join(stretched)} "
                  f"{'is' if len(stretched) == 1 else 'are'} stretched over "
                  f"{trainer.cfg.total_steps:,} steps from the run's start, back to where "
                  f"step {trainer.global_step:,} falls in them", file=sys.stderr)
        rewound = trainer.logger.rewound
        print(f"resuming {trainer.run_dir} at step {trainer.global_step:,}"
              + (f" ({rewound} metrics rows logged after that checkpoint dropped)"
                 if rewound else ""))
        return trainer
    with stop.interruptible():
        try:
            cfg = build_run(args)
        except ValueError as exc:
            raise as_input_error(exc) from None
        if args.print_config:
            print(run_toml(cfg), end="")
            return None
        runs = args.runs or "runs"
        check_folder(runs, "--runs")
        run_dir = Path(runs) / cfg.name
        check_folder(run_dir, "--name" if args.name else "the run's folder")
        if (run_dir / "latest").exists():
            raise InputError(f"{run_dir} already holds a run; continue it with --resume "
                             f"{run_dir} or pick another --name")
        check_free(run_dir)  # a run starting under this name: said before torch is loaded
        from alphatank.training.runner import Trainer
        runners = _env_runners(args, cfg, stack)
    try:
        with _one_line_warnings():
            trainer = Trainer(cfg, run_dir, progress=progress, env_runners=runners,
                              env_runner_timeout_s=_runner_timeout(args),
                              fragments=args.fragments, overlap=args.overlap, stop=stop)
    except ValueError as exc:
        raise _as_flag_error(exc, args) from None
    for name, counts in trainer.warm_start.items():
        print(f"warm start {name} from {cfg.init_from}: {counts['mapped']} features "
              f"mapped, {counts['new']} new (zero weight), {counts['dropped']} dropped"
              f"{', critic copied' if counts['critic'] else ', critic fresh'}")
    return trainer


def _as_flag_error(exc: ValueError, args: argparse.Namespace) -> InputError:
    """``exc`` (raised while the trainer was made) as one line; a run that cannot act in
    fragments names the flag that asked for them."""
    from alphatank.training.fragments import FragmentsRefused

    if isinstance(exc, FragmentsRefused):
        flag = "--overlap" if args.overlap else "--fragments"
        return InputError(f"{flag}: this run cannot act in fragments: {exc.problems}")
    return as_input_error(exc)


def _note_rounding(cfg: TrainConfig) -> None:
    """Say on stderr when ``--total-steps`` is not a whole number of iterations: the run
    trains :func:`planned_steps`."""
    planned = planned_steps(cfg)
    if planned != cfg.total_steps:
        print(f"note: --total-steps {cfg.total_steps:,} rounded up to {planned:,} (whole "
              f"iterations of {iteration_steps(cfg):,} env steps)", file=sys.stderr)


@contextlib.contextmanager
def _one_line_warnings() -> Iterator[None]:
    """Print the run's setting warnings as ``warning: ...`` lines on stderr."""
    from alphatank.training.runner import RunWarning

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", RunWarning)
        yield
    for w in caught:
        if issubclass(w.category, RunWarning):
            print(f"warning: {w.message}", file=sys.stderr)
        else:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)


def _clone_cut(stopped: dict[str, Any]) -> str:
    """How a run stopped during its behaviour cloning goes on. The cloning starts again whole
    on resume, so one cut by the time limit is cut again by the same limit."""
    if stopped["reason"] != "time limit":
        return "before the cloning ended, which starts again on resume"
    return ("before the cloning ended: the cloning takes longer than the time limit and "
            "starts again whole on resume, so give the resume a longer --time-limit, or the "
            "run fewer imitate steps")


def report(summary: dict[str, Any]) -> int:
    """Print a finished (or stopped) run's summary; returns the exit code."""
    run_dir = Path(summary["run_dir"])
    latest = (run_dir / "latest").read_text().strip()
    stopped = summary.get("stopped")
    done = stopped["checkpoint_step"] if stopped else summary["global_step"]
    if stopped and stopped.get("finished"):  # nothing to resume
        print(f"stopped by {stopped['reason']}: the run is finished (saved step {done:,})"
              + ("; its final evaluation was skipped: alphatank eval "
                 f"{run_dir} plays one" if stopped.get("final_eval_skipped") else ""))
    elif stopped:
        how = (f"dropped the unfinished iteration of {stopped['dropped_steps']:,} steps, "
               f"collected again on resume" if "dropped_steps" in stopped else
               f"cut the iteration after {stopped['cut_steps']:,} steps; its matches restart on "
               f"resume" if "cut_steps" in stopped else
               _clone_cut(stopped) if "clone_pending" in stopped else "at an iteration end")
        print(f"stopped by {stopped['reason']}: saved step {done:,} ({how}); continue with "
              f"alphatank train --resume {run_dir}")
    print(f"run {run_dir}: {done:,} steps, {summary['episodes']:,} episodes, "
          f"{summary['elapsed_s']:.0f} s")
    for key, val in summary.items():
        if key.startswith("charts/win_rate"):
            print(f"  {key} (last 100 episodes): {val:.2f}")
    print(f"  checkpoint: {run_dir / 'latest'} -> {latest}")
    notes = list(summary.get("notes") or ())
    if stopped and stopped.get("no_progress"):
        notes.append("the time limit ended this run before it trained a whole iteration: a "
                     "resume under the same --time-limit gets no further; give it a longer "
                     "one")
    for note in notes:
        print(f"  note: {note}")
    return int(summary.get("exit_code") or 0)

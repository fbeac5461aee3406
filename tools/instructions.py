"""CPU instructions per env step, counted by valgrind: a speed figure that other programs
on the machine do not move, for comparing two versions of the code on a noisy machine.

    python tools/instructions.py [--scenario vs_smart] [--envs 16] [--steps 100]
                                 [--observation paper] [--objects | --l2] [--floor]
                                 [--json FILE]

Runs this file twice under ``valgrind --tool=callgrind`` (no cache simulation), each run
building the env, stepping it 50 warm-up steps and then ``--steps`` or twice that many
timed steps with random actions drawn in advance (seeded); the difference of the two
runs' instruction counts, divided by ``--steps x --envs``, is the count per env step
without the start-up. ``--envs N`` steps N matches together (``gymnasium.make_vec``; a
scenario with several learner seats, which has no Gymnasium id, steps the engine,
``VectorMatchEnv``, every learner acting at random); ``--envs 0`` steps one
``gymnasium.make`` env (the issue-14 "one env" figure).
``--objects`` also splits the count per step by the shared object that ran it (the Python
interpreter, numpy, chipmunk, libm, ...). ``--floor`` also counts a 1v1 tick of the bare
pymunk prototype (``shared/bench/proto``, driven as ``floor_ratio.py`` drives it) and a
bare 1v1 match tick (no bots, observations or rewards; driven as ``alphatank bench``
drives it), 1,000 and 2,000 ticks each, and gives both the match tick and the env step as
ratios to the prototype's: the issue-14 ratios in instructions.
``--l2`` runs ``valgrind --tool=cachegrind`` instead, its last level set to one core's L2
(read from sysfs; 1 MiB, 16-way when it cannot be), and adds the L2 misses per step
(instruction fetches, data reads and writes) beside the instructions: the memory traffic
that instruction counts miss. A batched env whose matches together overflow the L2 runs
slower than its instructions say, and by how much depends on the shared L3's state.

Counts repeat to about 0.1% (hash seed fixed), where wall or CPU time on a shared
2-core VM scatter by 20% or more. Instructions are not time: a change that saves
instructions in numpy or pymunk calls saves time in proportion, one that changes memory
traffic may not, so confirm a gain with ``alphatank bench`` or ``floor_ratio.py`` where
the machine is quiet. Needs ``valgrind`` on the PATH; each run takes about a minute per
100 steps of 16 matches on a slow machine.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

WARMUP = 50
L2_EVENTS = ("ILmr", "DLmr", "DLmw")  # cachegrind's last-level misses: fetch, read, write
FLOOR, TICK = "floor", "tick"  # the child's names for the prototype's and a match's tick
FLOOR_TICKS = 1000


def child(scenario: str, envs: int, steps: int, observation: str | None) -> None:
    """Build the env, warm it up and step it ``steps`` times (runs under valgrind); with
    ``scenario`` FLOOR or TICK, tick the bare prototype or a bare 1v1 match instead."""
    if scenario == FLOOR:
        from alphatank.commands.benchfloor import find_floor, floor_us_per_tick

        floor_us_per_tick(find_floor(None), 2, steps)
        return
    if scenario == TICK:
        from alphatank.commands.benchenv import match_tick_us

        match_tick_us(steps, repeats=1)
        return
    import gymnasium as gym
    import numpy as np

    from alphatank.envs import gym_id, single_learner_scenarios

    rng = np.random.default_rng(0)
    kwargs = {} if observation is None else {"observation": observation}
    if envs == 0:
        env = gym.make(gym_id(scenario), **kwargs)
        env.reset(seed=0)
        for a in rng.integers((3, 3, 2), size=(WARMUP + steps, 3)):
            _, _, terminated, truncated, _ = env.step(a)
            if terminated or truncated:
                env.reset()
        return
    if scenario not in single_learner_scenarios():  # no Gymnasium id: the engine itself
        from alphatank.envs.vector import VectorMatchEnv

        engine = VectorMatchEnv(scenario, envs, **kwargs)
        engine.reset(seed=0)
        size = (WARMUP + steps, envs, engine.num_learners, 3)
        for a in rng.integers((3, 3, 2), size=size):
            engine.step(a)
        return
    venv = gym.make_vec(gym_id(scenario), num_envs=envs,
                        vectorization_mode="vector_entry_point", **kwargs)
    venv.reset(seed=0)
    for a in rng.integers((3, 3, 2), size=(WARMUP + steps, envs, 3)):
        venv.step(a)


def child_command(args: argparse.Namespace, scenario: str, envs: int, steps: int
                  ) -> tuple[list[str], dict[str, str]]:
    """The command line and environment of one child run."""
    cmd = [sys.executable, __file__, "--child", "--scenario", scenario,
           "--envs", str(envs), "--steps", str(steps)]
    if args.observation:
        cmd += ["--observation", args.observation]
    env = {**os.environ, "PYTHONHASHSEED": "0", "SDL_VIDEODRIVER": "dummy",
           "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    return cmd, env


def l2_geometry() -> tuple[int, int, int]:
    """(size in bytes, ways, line bytes) of one core's L2, from sysfs; 1 MiB, 16 ways, 64
    bytes where sysfs does not say."""
    folder = Path("/sys/devices/system/cpu/cpu0/cache")
    for index in sorted(folder.glob("index*")):
        try:
            if (index / "level").read_text().strip() != "2":
                continue
            size = (index / "size").read_text().strip().upper()
            scale = {"K": 1024, "M": 1024 ** 2}.get(size[-1:], 1)
            return (int(size.rstrip("KM")) * scale,
                    int((index / "ways_of_associativity").read_text()),
                    int((index / "coherency_line_size").read_text()))
        except (OSError, ValueError):
            break
    return 1024 ** 2, 16, 64


def valgrind_summary(out: Path) -> dict[str, int]:
    """Event totals of a callgrind or cachegrind file (its ``events:`` names, its
    ``summary:`` line)."""
    events: list[str] = []
    for line in out.read_text(encoding="utf-8", errors="replace").splitlines():
        if line.startswith("events:"):
            events = line.split()[1:]
        elif line.startswith("summary:"):
            return dict(zip(events, map(int, line.split()[1:]), strict=True))
    raise ValueError(f"{out}: no summary line; the valgrind run did not finish")


def count(args: argparse.Namespace, scenario: str, envs: int, steps: int, folder: Path
          ) -> tuple[dict[str, int], Path]:
    """Event totals of one child run of ``steps`` timed steps (``Ir``, the instructions;
    with ``--l2`` cachegrind's other events too), and its valgrind file."""
    out = folder / f"valgrind.{scenario}.{steps}.out"
    cmd, env = child_command(args, scenario, envs, steps)
    if args.l2:
        size, ways, line = l2_geometry()
        tool = ["--tool=cachegrind", "--cache-sim=yes", "--branch-sim=no",
                f"--LL={size},{ways},{line}", f"--cachegrind-out-file={out}"]
    else:
        tool = ["--tool=callgrind", "--cache-sim=no", f"--callgrind-out-file={out}"]
    run = subprocess.run(["valgrind", *tool, *cmd], env=env, capture_output=True, text=True,
                         check=False)
    try:
        if run.returncode != 0:
            raise ValueError(f"exit {run.returncode}")
        return valgrind_summary(out), out
    except (OSError, ValueError) as exc:
        sys.exit(f"instructions: the valgrind run failed ({exc}):\n" + run.stderr[-2000:])


def measure(args: argparse.Namespace, scenario: str, envs: int, steps: int
            ) -> tuple[float, list[int], dict[str, float]]:
    """Instructions per step (runs of ``steps`` and twice as many, the difference over
    ``steps x max(envs, 1)``), both runs' totals, and the per-object split (``--objects``)
    or, with ``--l2``, the L2 misses per step of each of :data:`L2_EVENTS`."""
    divisor = steps * max(envs, 1)
    # A first run fills numba's cache of compiled kernels for the CPU valgrind presents
    # (not this machine's), so that both counted runs load them, not the first compiling.
    cmd, env = child_command(args, scenario, envs, 1)
    subprocess.run(["valgrind", "--tool=none", *cmd], env=env, capture_output=True, check=True)
    with tempfile.TemporaryDirectory() as tmp:
        short, short_out = count(args, scenario, envs, steps, Path(tmp))
        long, long_out = count(args, scenario, envs, 2 * steps, Path(tmp))
        objects: dict[str, float] = {}
        if args.objects:
            a, b = by_object(short_out), by_object(long_out)
            objects = {k: (b.get(k, 0) - a.get(k, 0)) / divisor for k in set(a) | set(b)}
        elif args.l2:
            objects = {k: (long[k] - short[k]) / divisor for k in L2_EVENTS}
    return (long["Ir"] - short["Ir"]) / divisor, [short["Ir"], long["Ir"]], objects


def report(title: str, per_step: float, objects: dict[str, float]) -> None:
    """One figure, then its split per object (each over 0.1% of it), largest first, or
    its L2 misses (``objects`` keyed by :data:`L2_EVENTS`)."""
    print(title)
    if set(objects) == set(L2_EVENTS):
        misses = sum(objects.values())
        print(f"  {misses:12,.0f}  L2 misses per step ({1000 * misses / per_step:.2f} per "
              "1,000 instructions): " + ", ".join(
                  f"{objects[k]:,.0f} {what}" for k, what in
                  zip(L2_EVENTS, ("instruction fetch", "data read", "data write"),
                      strict=True)))
        return
    for name, n in sorted(objects.items(), key=lambda kv: -kv[1]):
        if abs(n) >= 0.001 * per_step:
            print(f"  {n:12,.0f}  {100 * n / per_step:5.1f}%  {name}")


def by_object(out: Path) -> dict[str, int]:
    """Instructions of a callgrind file per shared object (file name only): every cost
    line's own count, not the inclusive cost recorded after each ``calls=`` line."""
    names: dict[str, str] = {}
    totals: dict[str, int] = {}
    obj, skip = "???", False
    with open(out, encoding="utf-8", errors="replace") as f:
        for line in f:
            if line.startswith(("ob=", "cob=")):  # "(id) name" names an id once
                m = re.match(r"c?ob=(\(\d+\))?\s*(.*)", line.rstrip("\n"))
                key, name = m.group(1), m.group(2)
                if key and name:
                    names[key] = name
                if line.startswith("ob="):
                    obj = Path(name or names.get(key, "???")).name
            elif line.startswith("calls="):
                skip = True
            elif line[:1].isdigit() or line[:1] in "+-*":
                if not skip:
                    parts = line.split()
                    if len(parts) > 1:
                        totals[obj] = totals.get(obj, 0) + int(parts[1])
                skip = False
    return totals


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scenario", default="vs_smart",
                   help="a shipped scenario with learner seats (default: vs_smart); one with "
                   "several steps the engine, VectorMatchEnv, every learner at random")
    p.add_argument("--envs", type=int, default=16,
                   help="matches stepped together; 0: one gymnasium.make env (default: 16)")
    p.add_argument("--steps", type=int, default=100,
                   help="timed steps of the shorter run; the longer runs twice as many")
    p.add_argument("--observation", default=None, help="observation kind (default: the "
                   "scenario's)")
    how = p.add_mutually_exclusive_group()
    how.add_argument("--objects", action="store_true",
                     help="also split the count per shared object")
    how.add_argument("--l2", action="store_true",
                     help="count with cachegrind, its last level one core's L2, and also "
                     "give the L2 misses per step")
    p.add_argument("--floor", action="store_true",
                   help="also count the bare pymunk prototype's 1v1 tick (the floor) and a "
                   "bare 1v1 match tick")
    p.add_argument("--json", type=Path, default=None, help="also write the figures here")
    p.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.envs < 0 or args.steps < 1:
        p.error("--envs must be >= 0 and --steps >= 1")
    if args.child:
        child(args.scenario, args.envs, args.steps, args.observation)
        return
    from alphatank.envs import single_learner_scenarios
    from alphatank.game.scenarios import load_scenario, shipped_scenarios

    names = [n for n in shipped_scenarios() if load_scenario(n).learner_seats]
    if args.scenario not in names:
        p.error(f"--scenario {args.scenario!r}: not a shipped scenario with learner seats; "
                f"valid: {', '.join(names)}")
    if args.envs == 0 and args.scenario not in single_learner_scenarios():
        p.error(f"--envs 0 (one gymnasium.make env) needs a scenario with one learner seat; "
                f"{args.scenario!r} has several: give --envs N")
    if shutil.which("valgrind") is None:
        sys.exit("instructions: valgrind is not on the PATH (apt install valgrind)")
    if args.floor:
        from alphatank.commands.benchfloor import find_floor

        if find_floor(None) is None:
            sys.exit("instructions: --floor: the prototype (shared/bench/proto) was not "
                     "found above the project or the working folder")
    per_step, runs, objects = measure(args, args.scenario, args.envs, args.steps)
    what = "one gymnasium.make env" if args.envs == 0 else f"{args.envs} matches"
    report(f"{args.scenario}, {what}: {per_step:,.0f} instructions per env step "
           f"({runs[0]:,} and {runs[1]:,} in runs of {args.steps} and {2 * args.steps} "
           "steps)", per_step, objects)
    split = "l2_misses" if args.l2 else "per_object"  # the JSON key of each split
    figures = {"scenario": args.scenario, "envs": args.envs, "steps": args.steps,
               "observation": args.observation, "instructions_per_step": per_step,
               "instructions": runs, split: objects}
    if args.floor:
        floor, _, floor_objects = measure(args, FLOOR, 0, FLOOR_TICKS)
        report(f"bare pymunk floor, 1v1: {floor:,.0f} instructions per tick; the env step "
               f"is {per_step / floor:.2f}x the floor", floor, floor_objects)
        tick, _, tick_objects = measure(args, TICK, 0, FLOOR_TICKS)
        report(f"bare match tick, 1v1: {tick:,.0f} instructions per tick, "
               f"{tick / floor:.2f}x the floor", tick, tick_objects)
        figures.update({"floor_per_tick": floor, "over_floor": per_step / floor,
                        f"floor_{split}": floor_objects, "match_tick": tick,
                        "match_tick_over_floor": tick / floor,
                        f"match_tick_{split}": tick_objects})
    if args.json is not None:
        from alphatank.files import write_text_atomic
        write_text_atomic(args.json, json.dumps(figures, indent=2) + "\n")


if __name__ == "__main__":
    main()

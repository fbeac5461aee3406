"""CPU instructions per env step, counted by valgrind: a speed figure that other programs
on the machine do not move, for comparing two versions of the code on a noisy machine.

    python tools/instructions.py [--scenario vs_smart] [--envs 16] [--steps 100]
                                 [--observation paper] [--json FILE]

Runs this file twice under ``valgrind --tool=callgrind`` (no cache simulation), each run
building the env, stepping it 50 warm-up steps and then ``--steps`` or twice that many
timed steps with random actions drawn in advance (seeded); the difference of the two
runs' instruction counts, divided by ``--steps x --envs``, is the count per env step
without the start-up. ``--envs N`` steps N matches together (``gymnasium.make_vec``);
``--envs 0`` steps one ``gymnasium.make`` env (the issue-14 "one env" figure).

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


def child(scenario: str, envs: int, steps: int, observation: str | None) -> None:
    """Build the env, warm it up and step it ``steps`` times (runs under valgrind)."""
    import gymnasium as gym
    import numpy as np

    from alphatank.envs import gym_id

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
    venv = gym.make_vec(gym_id(scenario), num_envs=envs,
                        vectorization_mode="vector_entry_point", **kwargs)
    venv.reset(seed=0)
    for a in rng.integers((3, 3, 2), size=(WARMUP + steps, envs, 3)):
        venv.step(a)


def count(args: argparse.Namespace, steps: int, folder: Path) -> int:
    """Instructions of one child run of ``steps`` timed steps."""
    out = folder / f"callgrind.{steps}.out"
    cmd = ["valgrind", "--tool=callgrind", "--cache-sim=no", f"--callgrind-out-file={out}",
           sys.executable, __file__, "--child", "--scenario", args.scenario,
           "--envs", str(args.envs), "--steps", str(steps)]
    if args.observation:
        cmd += ["--observation", args.observation]
    env = {**os.environ, "PYTHONHASHSEED": "0", "SDL_VIDEODRIVER": "dummy",
           "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    run = subprocess.run(cmd, env=env, capture_output=True, text=True, check=False)
    found = re.search(r"Collected\s*:\s*(\d+)", run.stderr)
    if run.returncode != 0 or found is None:
        sys.exit(f"instructions: the valgrind run failed (exit {run.returncode}):\n"
                 + run.stderr[-2000:])
    return int(found.group(1))


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scenario", default="vs_smart",
                   help="a scenario with one learner seat (default: vs_smart)")
    p.add_argument("--envs", type=int, default=16,
                   help="matches stepped together; 0: one gymnasium.make env (default: 16)")
    p.add_argument("--steps", type=int, default=100,
                   help="timed steps of the shorter run; the longer runs twice as many")
    p.add_argument("--observation", default=None, help="observation kind (default: the "
                   "scenario's)")
    p.add_argument("--json", type=Path, default=None, help="also write the figures here")
    p.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.envs < 0 or args.steps < 1:
        p.error("--envs must be >= 0 and --steps >= 1")
    if args.child:
        child(args.scenario, args.envs, args.steps, args.observation)
        return
    from alphatank.envs import single_learner_scenarios

    if args.scenario not in (names := single_learner_scenarios()):
        p.error(f"--scenario {args.scenario!r}: not a shipped scenario with one learner "
                f"seat; valid: {', '.join(names)}")
    if shutil.which("valgrind") is None:
        sys.exit("instructions: valgrind is not on the PATH (apt install valgrind)")
    with tempfile.TemporaryDirectory() as tmp:
        short = count(args, args.steps, Path(tmp))
        long = count(args, 2 * args.steps, Path(tmp))
    per_step = (long - short) / (args.steps * max(args.envs, 1))
    what = "one gymnasium.make env" if args.envs == 0 else f"{args.envs} matches"
    print(f"{args.scenario}, {what}: {per_step:,.0f} instructions per env step "
          f"({short:,} and {long:,} in runs of {args.steps} and {2 * args.steps} steps)")
    if args.json is not None:
        from alphatank.files import write_text_atomic
        write_text_atomic(args.json, json.dumps({
            "scenario": args.scenario, "envs": args.envs, "steps": args.steps,
            "observation": args.observation, "instructions_per_step": per_step,
            "instructions": [short, long]}, indent=2) + "\n")


if __name__ == "__main__":
    main()

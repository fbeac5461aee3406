"""Env-runner throughput on Ray against local worker processes, Ray's start-up, and what
one PPO learner absorbs (docs/distributed.md).

    python tools/raybench.py [--envs 16] [--steps 400] [--repeats 3] [--counts 1,2]
                             [--json FILE]

Env steps/s (random actions drawn in advance, seeded; no learner) for: one process,
``--workers N`` (SubprocVectorMatchEnv) and ``--env-runners N`` (RayVectorMatchEnv on a
local instance) for each N of ``--counts``, measured round-robin ``--repeats`` times
(medians); Ray's start-up (``ray.init`` of a local instance) and the first runners'
start; PPO updates/s of the shipped ``ppo_vs_aggressive`` learner (128 steps x 16 envs x
4 epochs) and of Table 7 as is (512 steps x 60 epochs) on one thread, and of the first
taking rollout fragments; training env steps/s of that run with N worker processes and N
env runners, acting step by step and in fragments (``--fragments``).
"""

from __future__ import annotations

import argparse
import json
import statistics
import time

import numpy as np

SCENARIO = "vs_aggressive"


def actions(num_envs: int, steps: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.stack([rng.integers(0, n, (steps, num_envs, 1)) for n in (3, 3, 2)], -1)


def steps_per_s(env, acts: np.ndarray, warmup: int = 20) -> float:
    env.reset(seed=1)
    for a in acts[:warmup]:
        env.step(a)
    t0 = time.perf_counter()
    for a in acts[warmup:]:
        env.step(a)
    return (len(acts) - warmup) * env.num_envs / (time.perf_counter() - t0)


def learner_rate(num_envs: int, repeats: int, **ppo: int) -> dict[str, float]:
    """A PPO learner's own time on one thread (rollout of real observations): seconds per
    update, and acting + observing per vector step; what it absorbs when envs are free."""
    import dataclasses

    from alphatank.envs.vector import VectorMatchEnv
    from alphatank.training.learners import make_learner
    from alphatank.training.presets import get_preset
    from alphatank.training.threads import limit_threads

    limit_threads(1)
    spec = get_preset("ppo_vs_aggressive").learners[0]
    spec = dataclasses.replace(spec, config=dataclasses.replace(spec.config, **ppo))
    env = VectorMatchEnv(SCENARIO, num_envs, seed=0)
    lr = make_learner(spec, env.obs_dim, num_envs, seed=0)
    obs = env.reset(seed=0)[:, 0]
    updates, acting = [], []
    for _ in range(repeats):
        spent = 0.0
        for _ in range(lr.rollout_steps):
            t0 = time.perf_counter()
            act = lr.act(obs)
            spent += time.perf_counter() - t0
            nxt, rew, term, trunc, info = env.step(act[:, None])
            t0 = time.perf_counter()
            lr.observe(nxt[:, 0], rew[:, 0], term, trunc, info["final_obs"][:, 0])
            spent += time.perf_counter() - t0
            obs = nxt[:, 0]
        acting.append(spent)
        t0 = time.perf_counter()
        lr.update(obs)
        updates.append(time.perf_counter() - t0)
    upd, act_s = statistics.median(updates), statistics.median(acting)
    steps = lr.rollout_steps * num_envs
    return {"num_steps": lr.rollout_steps, "update_epochs": spec.config.update_epochs,
            "update_s": upd, "acting_s": act_s, "updates_per_s": 1.0 / (upd + act_s),
            "env_steps_per_update": steps, "absorbs_env_steps_per_s": steps / (upd + act_s)}


def fragment_learner_rate(num_envs: int, repeats: int) -> dict[str, float]:
    """The same learner taking rollouts acted elsewhere (``--fragments``): seconds to
    record one fragment and to update; what it absorbs when envs are free."""
    from alphatank.envs.vector import VectorMatchEnv
    from alphatank.training.fragments import FrozenLearners, ingest_fragment
    from alphatank.training.learners import make_learner
    from alphatank.training.presets import get_preset
    from alphatank.training.threads import limit_threads

    limit_threads(1)
    spec = get_preset("ppo_vs_aggressive").learners[0]
    env = VectorMatchEnv(SCENARIO, num_envs, seed=0)
    lr = make_learner(spec, env.obs_dim, num_envs, seed=0)
    learners, cols = {"ppo": lr}, {"ppo": [0]}
    obs = env.reset(seed=0)
    updates, ingests = [], []
    for k in range(repeats):
        frag = env.rollout(FrozenLearners.of(learners, cols, k), obs, lr.rollout_steps)
        t0 = time.perf_counter()
        ingest_fragment(frag, learners, cols, None)
        ingests.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        lr.update(frag.next_obs[:, 0])
        updates.append(time.perf_counter() - t0)
        obs = frag.next_obs
    upd, ing = statistics.median(updates), statistics.median(ingests)
    steps = lr.rollout_steps * num_envs
    return {"update_s": upd, "ingest_s": ing, "env_steps_per_update": steps,
            "absorbs_env_steps_per_s": steps / (upd + ing)}


def training_rate(iterations: int, tmp: str, counts: list[int]) -> dict[str, float]:
    """Training env steps/s (median over the iterations after the first) of the shipped
    ``ppo_vs_aggressive`` run (16 envs, PPO 128 x 4) with N worker processes and with N
    env runners, N in ``counts``, each acting step by step on the learner and in rollout
    fragments (``--fragments``)."""
    import dataclasses

    from alphatank.training.presets import get_preset
    from alphatank.training.runner import Trainer

    base = get_preset("ppo_vs_aggressive")
    out = {}
    for n in counts:
        for fragments in (False, True):
            for ray in (False, True):
                cfg = dataclasses.replace(base, name=f"bench-{n}-{ray}-{fragments}",
                                          num_workers=n, wandb="disabled", checkpoint_every=0,
                                          total_steps=iterations * 128 * base.num_envs,
                                          time_limit_s=0.0)
                tr = Trainer(cfg, f"{tmp}/{cfg.name}", progress=False,
                             env_runners=n if ray else 0, fragments=fragments)
                tr.train()
                key = f"{'ray runners' if ray else 'workers'}={n}{' fragments' * fragments}"
                out[key] = statistics.median(h["charts/sps"] for h in tr.history[1:])
    return out


def head_node_start() -> dict[str, float]:
    """Seconds of ``ray start --head`` (2 CPUs, 127.0.0.1) and of a driver joining it."""
    import os
    import secrets
    import socket
    import subprocess
    import sys

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    env = {**os.environ, "RAY_AUTH_MODE": "token", "RAY_AUTH_TOKEN": secrets.token_hex(16),
           "RAY_USAGE_STATS_ENABLED": "0"}
    ray_cli = [sys.executable, "-m", "ray.scripts.scripts"]
    t0 = time.perf_counter()
    subprocess.run([*ray_cli, "start", "--head", "--node-ip-address", "127.0.0.1", "--port",
                    str(port), "--num-cpus", "2", "--include-dashboard", "false"],
                   check=True, capture_output=True, env=env)
    start = time.perf_counter() - t0
    try:
        join = subprocess.run(
            [sys.executable, "-c", "from alphatank.cluster import connect; "
             f"print(connect('127.0.0.1:{port}').seconds)"],
            check=True, capture_output=True, text=True, env=env)
    finally:
        subprocess.run([*ray_cli, "stop", "--force"], capture_output=True, env=env)
    return {"ray_start_head_s": start, "join_s": float(join.stdout.strip().splitlines()[-1])}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--envs", type=int, default=16)
    p.add_argument("--steps", type=int, default=400, help="vector steps per measurement")
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--train-iterations", type=int, default=4,
                   help="PPO iterations per training measurement (0: none)")
    p.add_argument("--no-learner", action="store_true", help="skip the learner rates")
    p.add_argument("--head", action="store_true",
                   help="also time `ray start --head` and a driver joining it")
    p.add_argument("--counts", default="1,2",
                   help="comma-separated numbers of worker processes and of env runners")
    p.add_argument("--json", metavar="FILE")
    args = p.parse_args()
    counts = [int(n) for n in args.counts.split(",")]

    from alphatank.cluster import connect
    from alphatank.envs.ray_vector import RayVectorMatchEnv
    from alphatank.envs.vector import SubprocVectorMatchEnv, VectorMatchEnv

    acts = actions(args.envs, args.steps)
    # logical CPUs: every runner lives at once (only one set steps at a time)
    conn = connect(num_cpus=sum(counts) + 1)
    out: dict[str, float | dict] = {"ray_start_s": conn.seconds}
    envs = {"process": VectorMatchEnv(SCENARIO, args.envs, seed=0)}
    for n in counts:
        t0 = time.perf_counter()
        envs[f"workers={n}"] = SubprocVectorMatchEnv(SCENARIO, args.envs, num_workers=n)
        out.setdefault("workers_start_s", time.perf_counter() - t0)
    for n in counts:
        t0 = time.perf_counter()
        envs[f"ray runners={n}"] = RayVectorMatchEnv(SCENARIO, args.envs, num_runners=n)
        out.setdefault("first_runner_start_s", time.perf_counter() - t0)
    rates: dict[str, list[float]] = {k: [] for k in envs}
    try:
        for _ in range(args.repeats):
            for name, env in envs.items():
                rates[name].append(steps_per_s(env, acts))
    finally:
        for env in envs.values():
            env.close()
        conn.close()
    med = {k: statistics.median(v) for k, v in rates.items()}
    out["steps_per_s"] = med
    out["ray_overhead"] = {n: 1.0 - med[f"ray runners={n}"] / med[f"workers={n}"]
                           for n in counts}
    if not args.no_learner:
        out["learner"] = learner_rate(args.envs, args.repeats)
        out["learner_table7"] = learner_rate(args.envs, 1, num_steps=512, update_epochs=60)
        out["learner_fragments"] = fragment_learner_rate(args.envs, args.repeats)
    if args.train_iterations:
        import tempfile

        conn = connect(num_cpus=max(counts))
        with tempfile.TemporaryDirectory() as tmp:
            out["train_steps_per_s"] = train = training_rate(args.train_iterations, tmp, counts)
        conn.close()
        for name, val in train.items():
            print(f"training, {name:14s} {val:6.0f} env steps/s")
        for n in counts:
            for mode in ("", " fragments"):
                share = 1 - train[f"ray runners={n}{mode}"] / train[f"workers={n}"]
                print(f"training: ray overhead with {n} runner(s){mode} vs {n} worker(s): "
                      f"{100 * share:+.1f}%")
    for name, val in med.items():
        print(f"{name:14s} {val:8.0f} env steps/s  (runs: "
              f"{', '.join(f'{x:.0f}' for x in rates[name])})")
    for n, o in out["ray_overhead"].items():
        print(f"ray overhead with {n} runner(s) vs {n} worker(s): {100 * o:+.1f}%")
    print(f"ray start (local instance): {out['ray_start_s']:.1f} s; first runner up in "
          f"{out['first_runner_start_s']:.1f} s ({counts[0]} worker process(es): "
          f"{out['workers_start_s']:.1f} s)")
    for lr in (out[k] for k in ("learner", "learner_table7") if k in out):
        print(f"PPO learner {lr['num_steps']} steps x {lr['update_epochs']} epochs: "
              f"{lr['update_s']:.2f} s per update + {lr['acting_s']:.2f} s acting per "
              f"{lr['env_steps_per_update']} env steps = {lr['updates_per_s']:.2f} updates/s, "
              f"absorbs {lr['absorbs_env_steps_per_s']:.0f} env steps/s")
    if "learner_fragments" in out:
        lr = out["learner_fragments"]
        print(f"the same learner with --fragments: {lr['update_s']:.2f} s per update + "
              f"{lr['ingest_s']:.3f} s recording a fragment of {lr['env_steps_per_update']} "
              f"env steps, absorbs {lr['absorbs_env_steps_per_s']:.0f} env steps/s")
    if args.head:
        out["head"] = head = head_node_start()
        print(f"ray start --head: {head['ray_start_head_s']:.1f} s; a driver joins it in "
              f"{head['join_s']:.1f} s")
    if args.json:
        with open(args.json, "w", encoding="utf-8") as f:
            json.dump(out, f, indent=1)


if __name__ == "__main__":
    main()

"""Learner cost for ``alphatank bench --train`` and ``--sac``.

* ``--train``: training env steps/s of a preset (PPO by default) against the raw env
  steps/s of the same scenario, workers and envs with random actions, measured in
  alternating rounds so that both see the same machine load. Also the CPU seconds per
  env step of each (all processes), so the learner's own cost shows on a busy machine.
* ``--sac``: milliseconds per SAC gradient step (``SAC.update`` on a full replay buffer)
  against the floor: the bare torch work of the same step on random data (target
  forward, critic forward/backward, actor forward/backward through the critics, fused
  Adam steps) with nothing else; and the env steps/s of SAC training at several
  update-to-data ratios.

Also runs alone: ``python -m alphatank.commands.benchtrain --help``.
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import sys
import tempfile
import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from alphatank.commands.argtypes import match_count, positive_int
from alphatank.errors import one_line

DEFAULT_HP = ("ppo.update_epochs=4,ppo.num_steps=128",)  # for presets with PPO learners


def _cpu_seconds(pids: Sequence[int] = ()) -> float:
    """CPU seconds of this process and ``pids`` (Linux /proc; others count 0)."""
    tick = os.sysconf("SC_CLK_TCK")
    total = time.process_time()
    for pid in pids:
        try:
            with open(f"/proc/{pid}/stat", encoding="ascii") as f:
                fields = f.read().rsplit(")", 1)[1].split()
            total += (int(fields[11]) + int(fields[12])) / tick
        except OSError:
            pass
    return total


# ---- SAC: gradient step against its floor ------------------------------------------------

def sac_floor_step(obs_dim: int, hidden: int = 256, batch: int = 256, seed: int = 0) -> Any:
    """A function doing the bare torch work of one SAC gradient step on fixed random
    tensors: Table 8 nets (actor, twin critics, twin targets), target forward without
    gradients, critic MSE forward/backward and fused Adam step, actor (reparameterised
    sample) forward/backward through both critics (no critic weight gradients) and fused
    Adam step."""
    import torch

    from alphatank.training.sac import SquashedGaussianActor, TwinQNetwork

    torch.manual_seed(seed)
    act_dim = 3
    actor = SquashedGaussianActor(obs_dim, act_dim, hidden)
    q, target_q = TwinQNetwork(obs_dim, act_dim, hidden), TwinQNetwork(obs_dim, act_dim, hidden)
    q_opt = torch.optim.Adam(q.parameters(), lr=3e-4, fused=True)
    a_params = list(actor.parameters())
    a_opt = torch.optim.Adam(a_params, lr=3e-4, fused=True)
    obs, nxt = torch.randn(batch, obs_dim), torch.randn(batch, obs_dim)
    act, rew = torch.rand(batch, act_dim), torch.randn(batch)

    gen = torch.Generator().manual_seed(seed)

    def step() -> None:
        with torch.no_grad():
            a2, logp2 = actor.sample(nxt, gen)
            target = rew + 0.99 * (target_q(nxt, a2).amin(0) - 0.2 * logp2)
        loss = ((q(obs, act) - target) ** 2).mean(1).sum()
        q_opt.zero_grad(set_to_none=True)
        loss.backward()
        q_opt.step()
        pi, logp = actor.sample(obs, gen)
        a_loss = (0.2 * logp - q(obs, pi).amin(0)).mean()
        for p, g in zip(a_params, torch.autograd.grad(a_loss, a_params), strict=True):
            p.grad = g
        a_opt.step()

    return step


def sac_learner(obs_dim: int, cfg: Any = None, seed: int = 0, fill: int = 20_000) -> Any:
    """A SAC learner (Table 8 defaults) with ``fill`` random transitions in its replay."""
    from alphatank.training.sac import SAC, SACConfig

    sac = SAC(obs_dim, 16, cfg or SACConfig(), seed=seed)
    rng = np.random.default_rng(seed)
    for _ in range(fill // 16):
        obs = rng.standard_normal((16, obs_dim), dtype=np.float32)
        sac.act(obs)
        sac.observe(rng.standard_normal((16, obs_dim), dtype=np.float32),
                    rng.standard_normal(16).astype(np.float32), np.zeros(16, bool),
                    np.zeros(16, bool))
    return sac


def sac_step_bench(obs_dim: int = 201, steps: int = 64, repeats: int = 5,
                   verbose: bool = True) -> dict[str, float]:
    """Median CPU ms per gradient step of ``SAC.update`` (``steps`` per round) and of
    :func:`sac_floor_step`, alternated ``repeats`` times; one torch thread."""
    import torch

    from alphatank.training.threads import limit_threads

    limit_threads(1)
    sac = sac_learner(obs_dim)
    floor = sac_floor_step(obs_dim)
    for _ in range(5):
        floor()
    sac.since_update = 16
    sac.update()
    sac_ms, floor_ms = [], []
    for _ in range(repeats):
        sac.since_update = steps
        grad0, t = sac.grad_steps, time.process_time()
        sac.update()
        sac_ms.append(1e3 * (time.process_time() - t) / (sac.grad_steps - grad0))
        t = time.process_time()
        for _ in range(steps):
            floor()
        floor_ms.append(1e3 * (time.process_time() - t) / steps)
    out = {"floor_ms": round(statistics.median(floor_ms), 2),
           "update_ms": round(statistics.median(sac_ms), 2), "torch": torch.__version__}
    out["ratio"] = round(out["update_ms"] / out["floor_ms"], 3)
    if verbose:
        print(f"SAC gradient step, Table 8 nets (256-256), batch 256, obs {obs_dim}, 1 thread, "
              f"CPU ms (median of {repeats} alternating rounds of {steps} steps):")
        print(f"  floor (bare torch forward/backward + fused Adam) {out['floor_ms']:7.2f}")
        print(f"  SAC.update per gradient step                     {out['update_ms']:7.2f}"
              f"   ({out['ratio']:.2f}x the floor)")
    return out


# ---- training against raw env steps -------------------------------------------------------

def _raw_round(env: Any, actions: np.ndarray, steps: int) -> tuple[float, float]:
    """(env steps/s wall, CPU s per env step) of ``steps`` random vector steps."""
    pids = [p.pid for p in getattr(env, "_procs", [])]
    t, c = time.perf_counter(), _cpu_seconds(pids)
    for k in range(steps):
        env.step(actions[k % len(actions)])
    n = steps * env.num_envs
    return n / (time.perf_counter() - t), (_cpu_seconds(pids) - c) / n


class TrainBench:
    """Training steps/s of ``preset`` (``hp``: ``--hp`` strings) against raw env steps/s of
    the same scenario, workers and envs, alternating ``rounds`` rounds; each training
    round runs ``iterations`` iterations (after one warm-up iteration), each raw round
    the same number of vector steps. Medians; CPU s per step counts all processes.
    ``hp`` None: :data:`DEFAULT_HP` when the preset trains PPO learners, else none.
    ``torch_threads``: the run's torch threads (PPO's updates; rollouts use numpy).
    ``fragments``: the workers act the rollouts (``alphatank train --fragments``);
    ``overlap``: and the next one during each update (``train --overlap``), except after
    a round's last iteration, so that no rollout runs into the raw round.

    Making one builds the run and the raw env, so every setting is checked as
    ``alphatank train`` checks it (ValueError) before anything is measured;
    :meth:`measure` then measures once and closes them (:meth:`close` without measuring).
    """

    def __init__(self, preset: str = "ppo_vs_smart", workers: int = 2, num_envs: int = 32,
                 hp: Sequence[str] | None = None, rounds: int = 3, iterations: int = 3,
                 seed: int = 0, torch_threads: int = 1, fragments: bool = False,
                 overlap: bool = False):
        from alphatank.training.presets import get_preset, parse_hp, run_scenario, with_hp

        # the settings first: a bad one is refused before torch and the runner load
        cfg = get_preset(preset)
        scenario = run_scenario(cfg)
        if hp is None:
            hp = DEFAULT_HP if "ppo" in {s.algo for s in cfg.learners} or not cfg.learners else ()
        cfg = with_hp(cfg, parse_hp([("--hp", h) for h in hp]), len(scenario.learner_seats))
        from alphatank.envs.vector import make_vector_env
        from alphatank.training.runner import Trainer
        from alphatank.training.threads import limit_threads

        limit_threads(1)
        cfg = cfg.with_overrides(num_envs=num_envs, num_workers=workers, wandb="disabled",
                                 checkpoint_every=0, eval_every=0, video_every=0, seed=seed,
                                 time_limit_s=0.0, total_steps=10**12, name="bench",
                                 torch_threads=torch_threads)
        self.settings = {"preset": preset, "workers": workers, "num_envs": num_envs,
                         "hp": list(hp), "torch_threads": torch_threads}
        self.rounds, self.iterations, self.seed = rounds, iterations, seed
        self.closed = False
        self.tmp = tempfile.mkdtemp(prefix="alphatank-bench-")
        try:
            self.trainer = Trainer(cfg, os.path.join(self.tmp, "run"), progress=False,
                                   fragments=fragments, overlap=overlap)
        except BaseException:
            shutil.rmtree(self.tmp, ignore_errors=True)
            raise
        self.fragments, self.overlap = self.trainer.fragments, overlap
        try:
            # the raw env does what the training env does: game and reward overrides, and
            # the learners' extra inputs (MAPPO's agent-specific states)
            self.env = make_vector_env(
                scenario, num_envs, seed=seed, num_workers=workers,
                observation=cfg.observation, game_overrides=cfg.game or None,
                reward_overrides=cfg.rewards or None, action_repeat=cfg.action_repeat,
                **({"inputs": self.trainer.inputs} if self.trainer.inputs else {}))
        except BaseException:
            self._close_trainer()
            raise

    def _close_trainer(self) -> None:
        self.trainer.logger.close()
        self.trainer.env.close()
        shutil.rmtree(self.tmp, ignore_errors=True)

    def close(self) -> None:
        """Close the raw env and the run (its worker processes and folder); once."""
        if not self.closed:
            self.closed = True
            self.env.close()
            self._close_trainer()

    def measure(self, verbose: bool = True) -> dict[str, Any]:
        """Measure the rounds, close, and return the figures (printed if ``verbose``)."""
        trainer, env, fragments = self.trainer, self.env, self.fragments
        rounds, iterations, seed = self.rounds, self.iterations, self.seed

        def collect(obs: np.ndarray, last: bool) -> tuple[np.ndarray, dict[str, float]]:
            if fragments:
                return trainer._collect_fragment(obs, last_round=last)
            return trainer._collect(obs)
        rng = np.random.default_rng(seed)
        actions = rng.integers(0, [3, 3, 2],
                               size=(256, env.num_envs, env.num_learners, 3))
        vector_steps = trainer.rollout_steps * iterations
        pids = [p.pid for p in getattr(trainer.env, "_procs", [])]
        raw, train, raw_cpu, train_cpu = [], [], [], []
        try:
            env.reset(seed)
            _raw_round(env, actions, 32)
            obs = trainer._segment_reset()
            obs, _ = collect(obs, True)  # warm-up iteration
            for _ in range(rounds):
                sps, cpu = _raw_round(env, actions, vector_steps)
                raw.append(sps)
                raw_cpu.append(cpu)
                t, c, s0 = time.perf_counter(), _cpu_seconds(pids), trainer.global_step
                for k in range(iterations):
                    obs, _ = collect(obs, k == iterations - 1)
                n = trainer.global_step - s0
                train.append(n / (time.perf_counter() - t))
                train_cpu.append((_cpu_seconds(pids) - c) / n)
        finally:
            self.close()
        s = self.settings
        out = {**s, "fragments": fragments, "overlap": self.overlap, "iterations": iterations,
               "raw_steps_per_s": round(statistics.median(raw)),
               "train_steps_per_s": round(statistics.median(train)),
               "raw_cpu_us_per_step": round(1e6 * statistics.median(raw_cpu), 1),
               "train_cpu_us_per_step": round(1e6 * statistics.median(train_cpu), 1),
               "load_average": os.getloadavg()[0] if hasattr(os, "getloadavg") else None}
        out["ratio"] = round(out["train_steps_per_s"] / out["raw_steps_per_s"], 3)
        out["cpu_ratio"] = round(out["raw_cpu_us_per_step"] / out["train_cpu_us_per_step"], 3)
        if verbose:
            print(f"{s['preset']} ({' '.join(s['hp']) or 'preset hyperparameters'}), "
                  f"{s['workers']} workers{' acting in fragments' if fragments else ''}"
                  f"{' overlapping the updates' if self.overlap else ''}, {s['num_envs']} "
                  f"envs, {s['torch_threads']} torch threads; {rounds} alternating rounds of "
                  f"{vector_steps} vector steps "
                  f"(load average {out['load_average']:.1f}):")
            print(f"  raw env, random actions {out['raw_steps_per_s']:9,} steps/s  "
                  f"{out['raw_cpu_us_per_step']:6.1f} CPU us/step")
            print(f"  training                {out['train_steps_per_s']:9,} steps/s  "
                  f"{out['train_cpu_us_per_step']:6.1f} CPU us/step")
            print(f"  training / raw: {out['ratio']:.1%} of the steps/s, "
                  f"{out['cpu_ratio']:.1%} of the CPU per step")
        return out


def sac_train_bench(preset: str = "sac_vs_aggressive", ratios: Sequence[float] = (1.0, 0.25),
                    steps: int = 4096, num_envs: int = 16, seed: int = 0,
                    verbose: bool = True) -> dict[str, dict[str, float]]:
    """Env steps/s of SAC training (after ``update_after``) per update-to-data ratio, with
    the time share of gradient steps; one process, one torch thread."""
    from alphatank.training.presets import get_preset, parse_hp, run_scenario, with_hp
    from alphatank.training.runner import Trainer

    results: dict[str, dict[str, float]] = {}
    for ratio in ratios:
        cfg = get_preset(preset)
        n = len(run_scenario(cfg).learner_seats)
        cfg = with_hp(cfg, parse_hp([("--hp", f"sac.utd_ratio={ratio}")]), n)
        cfg = cfg.with_overrides(num_envs=num_envs, num_workers=1, wandb="disabled",
                                 checkpoint_every=0, seed=seed, rollout_steps=64,
                                 total_steps=10**12, name="bench")
        tmp = tempfile.mkdtemp(prefix="alphatank-bench-")
        trainer = Trainer(cfg, os.path.join(tmp, "run"), progress=False)
        try:
            obs = trainer._segment_reset()
            warm = max(s.config.update_after for s in trainer.specs) + 64 * num_envs
            while trainer.global_step < warm:
                obs, _ = trainer._collect(obs)
            grads0 = sum(lr.grad_steps for lr in trainer.learners.values())
            t, s0 = time.perf_counter(), trainer.global_step
            while trainer.global_step - s0 < steps:
                obs, _ = trainer._collect(obs)
            dt = time.perf_counter() - t
            grads = sum(lr.grad_steps for lr in trainer.learners.values()) - grads0
        finally:
            trainer.logger.close()
            trainer.env.close()
            shutil.rmtree(tmp, ignore_errors=True)
        done = trainer.global_step - s0
        results[str(ratio)] = {"env_steps_per_s": round(done / dt, 1),
                               "grad_steps_per_env_step": round(grads / done, 3),
                               "ms_per_grad_step_all_in": round(1e3 * dt / max(grads, 1), 2)}
        if verbose:
            r = results[str(ratio)]
            print(f"  {preset} utd_ratio {ratio:<5g} {r['env_steps_per_s']:8,.0f} env steps/s "
                  f"({r['grad_steps_per_env_step']:.2f} gradient steps per env step, "
                  f"{r['ms_per_grad_step_all_in']:.1f} ms of wall time per gradient step "
                  f"all included)")
    return results


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--train", action="store_true", help="training vs raw env steps/s")
    p.add_argument("--sac", action="store_true", help="SAC gradient step vs its floor, and "
                   "SAC training steps/s per update-to-data ratio")
    p.add_argument("--preset", default="ppo_vs_smart")
    p.add_argument("--workers", type=positive_int, default=2)
    p.add_argument("--num-envs", type=match_count, default=32)
    p.add_argument("--hp", action="append", default=None)
    p.add_argument("--rounds", type=positive_int, default=3)
    p.add_argument("--torch-threads", type=positive_int, default=1)


def run(args: argparse.Namespace) -> int:
    """A setting ``alphatank train`` refuses (--preset, --hp) is one line, exit 2, before
    anything is measured; so is asking for neither bench."""
    if not (args.train or args.sac):
        print("error: nothing to measure: give --train, --sac or both", file=sys.stderr)
        return 2
    if args.train:
        try:
            bench = TrainBench(args.preset, args.workers, args.num_envs, args.hp, args.rounds,
                               torch_threads=args.torch_threads)
        except ValueError as exc:
            print(f"error: --preset {args.preset}: {one_line(exc)}", file=sys.stderr)
            return 2
        bench.measure()
    if args.sac:
        sac_step_bench()
        sac_train_bench()
    return 0


if __name__ == "__main__":
    from alphatank.cli import Parser  # errors in one line, exit 2

    parser = Parser(description=__doc__)
    add_arguments(parser)
    raise SystemExit(run(parser.parse_args()))

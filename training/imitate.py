"""Behaviour cloning warm start (run-file key ``imitate``): before RL, a bot plays the
learner seats while the learners copy it.

A rule-based bot already aims, hunts and dodges; a fresh policy does none of it, and in a
hard line-up (two learners against three bots that shoot exactly) it never wins a game to
learn from. Cloning the bot first starts RL from a policy about as good as the bot
(``alphatank eval bot:NAME --scenario S`` measures that level in the same games).

:func:`imitate` plays ``steps`` vector steps of the run's scenario (each scenario of a
mixed run in its own envs), its opponents at full strength, the bot (a seat spec such as
``smart``) in every learner seat, recording each live seat's observation (the run's kind)
and the bot's action. Each PPO learner then fits
its actor to its seats' actions (cross-entropy on every action head) and its critic to
the discounted returns of the same games under the run's rewards, normalised as PPO
normalises them; its observation and return statistics start from the demonstrations.
The time it takes counts in the run's wall time (``time_limit_s``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from alphatank.envs.core import MatchSet
from alphatank.game.scenarios import Scenario
from alphatank.sim.episode import episode_seeds, reset_controllers
from alphatank.sim.policy import NOOP
from alphatank.training.fields import build, hp, validate
from alphatank.training.ppo import PPO, evaluate_actions


@dataclass(frozen=True)
class ImitateConfig:
    """The ``imitate`` table of a run file (empty: no warm start)."""

    bot: str = hp("smart", "seat spec of the bot to copy (e.g. smart, smart@0.8)")
    steps: int = hp(4096, "vector steps of demonstration games (each steps every env)", gt=0)
    epochs: int = hp(8, "passes over the demonstrations", gt=0)
    minibatch: int = hp(2048, "samples per gradient step", gt=0)
    learning_rate: float = hp(1e-3, "Adam learning rate of the cloning", gt=0)

    def __post_init__(self) -> None:
        validate(self)


def imitate_config(data: dict[str, Any]) -> ImitateConfig | None:
    """The config of a run's ``imitate`` table (its bot checked); None when it is empty."""
    if not data:
        return None
    from alphatank.game.lineup import spec_seat

    cfg = build(ImitateConfig, data, "imitate.")
    spec_seat(cfg.bot, where=f"imitate.bot {cfg.bot!r}")
    return cfg


@dataclass
class Demonstrations:
    """What the bot did: ``obs`` (T, E, L, D) float32 of the learner seats, ``actions``
    (T, E, L, 3), ``alive`` (T, E, L) (only live seats' actions are copied), per-step
    ``rewards`` (T, E, L) under the run's rewards and episode ends ``done`` (T, E)."""

    obs: np.ndarray
    actions: np.ndarray
    alive: np.ndarray
    rewards: np.ndarray
    done: np.ndarray
    wins: int
    games: int


def collect(scenario: Scenario, cfg: ImitateConfig, num_envs: int, seed: int,
            observation: str | None, game: dict[str, Any], rewards: dict[str, Any],
            driven: list[int], stop: Callable[[], bool] = bool) -> Demonstrations:
    """Play ``cfg.steps`` vector steps with ``cfg.bot`` in the learner seats ``driven``
    (indices into the scenario's learner seats); fewer when ``stop()`` turns true."""
    from alphatank.game.lineup import spec_seat
    from alphatank.game.seats import make_controller

    core = MatchSet(scenario, num_envs, observation=observation, game_overrides=game or None,
                    reward_overrides=rewards or None, driven=driven)
    seats = [scenario.learner_seats[d] for d in driven]
    team = scenario.seats[seats[0]].team
    stand = spec_seat(cfg.bot, team, where=f"imitate.bot {cfg.bot!r}")
    bots = [[make_controller(stand) for _ in seats] for _ in range(num_envs)]
    seeds = np.random.default_rng(seed)
    T, E, L = cfg.steps, num_envs, len(seats)
    out = Demonstrations(np.zeros((T, E, L, core.obs_dim), dtype=np.float32),
                         np.zeros((T, E, L, 3), dtype=np.int64), np.zeros((T, E, L), bool),
                         np.zeros((T, E, L)), np.zeros((T, E), bool), 0, 0)

    def start(e: int) -> None:
        s = int(seeds.integers(2**31))
        core.reset_env(e, s)
        played: list[Any] = [None] * len(scenario.seats)
        for bot, seat in zip(bots[e], seats, strict=True):
            played[seat] = bot
        reset_controllers(core.matches[e], played, episode_seeds(s, len(scenario.seats)))

    for e in range(E):
        start(e)
    obs = core.obs.build()
    acts = np.empty((E, L, 3), dtype=np.int64)
    for t in range(T):
        if stop():
            return Demonstrations(out.obs[:t], out.actions[:t], out.alive[:t],
                                  out.rewards[:t], out.done[:t], out.wins, out.games)
        out.obs[t] = obs
        for e, m in enumerate(core.matches):
            for k, (bot, seat) in enumerate(zip(bots[e], seats, strict=True)):
                live = bool(m.alive[seat])
                out.alive[t, e, k] = live
                acts[e, k] = bot.act(m, seat) if live else NOOP
        out.actions[t] = acts
        terms, obs = core.step(acts)
        out.rewards[t] = core.rewards(terms)
        ended = [e for e, m in enumerate(core.matches) if m.done]
        for e in ended:
            out.done[t, e] = True
            out.games += 1
            out.wins += core.matches[e].winner == team
            start(e)
        if ended:  # the new episodes' first observations
            obs = core.obs.build()
    return out


def discounted_returns(rewards: np.ndarray, done: np.ndarray, gamma: float) -> np.ndarray:
    """Per-stream discounted returns of (T, B) rewards, cut where ``done`` (T, B); a game
    still running at the end is cut there too."""
    ret = np.zeros_like(rewards)
    acc = np.zeros(rewards.shape[1])
    for t in range(len(rewards) - 1, -1, -1):
        acc = rewards[t] + gamma * acc * ~done[t]
        ret[t] = acc
    return ret


def clone(learner: PPO, obs: np.ndarray, actions: np.ndarray, alive: np.ndarray,
          rewards: np.ndarray, done: np.ndarray, cfg: ImitateConfig, seed: int,
          stop: Callable[[], bool] = bool) -> dict[str, float]:
    """Fit ``learner`` to its streams' demonstrations: ``obs`` (T, B, D), ``actions``
    (T, B, 3), ``alive`` / ``rewards`` / ``done`` (T, B), B = its num_streams (the
    order of its rollout streams); stops early when ``stop()`` turns true. Returns the
    last minibatch's losses and the share of live samples whose most likely action
    (every head) is the bot's."""
    if not isinstance(learner, PPO) or learner.algo != "ppo":
        raise ValueError(f"imitate: warm starts PPO learners only, not {learner.algo!r}")
    T, B, D = obs.shape
    # the statistics PPO keeps, started from the demonstrations
    x = torch.from_numpy(learner.obs_norm(obs.reshape(T * B, D), update=True))
    scaled = np.stack([learner.ret_norm(rewards[t], done[t]) for t in range(T)])
    returns = discounted_returns(scaled, done, learner.cfg.gamma)
    a = torch.from_numpy(actions.reshape(T * B, 3))
    live = torch.from_numpy(alive.reshape(T * B))
    y = torch.from_numpy(returns.reshape(T * B).astype(np.float32))
    net = learner.net
    opt = torch.optim.Adam(net.parameters(), lr=cfg.learning_rate)
    gen = torch.Generator().manual_seed(seed)
    n = T * B
    stats: dict[str, float] = {}
    for _ in range(cfg.epochs):
        order = torch.randperm(n, generator=gen)
        for lo in range(0, n, cfg.minibatch):
            if stop():
                break
            idx = order[lo:lo + cfg.minibatch]
            logits = net.logits(x[idx])
            logprob, _ = evaluate_actions(logits, a[idx], net.nvec)
            m = live[idx].float()
            policy_loss = -(logprob * m).sum() / m.sum().clamp(min=1.0)
            value_loss = 0.5 * ((net.value(x[idx]) - y[idx]) ** 2).mean()
            opt.zero_grad()
            (policy_loss + value_loss).backward()
            torch.nn.utils.clip_grad_norm_(net.parameters(), learner.cfg.max_grad_norm * 10)
            opt.step()
            stats = {"policy_loss": policy_loss.item(), "value_loss": value_loss.item()}
    learner.mirror.sync(net)
    with torch.no_grad():
        heads = torch.stack([h.argmax(-1) for h in torch.split(net.logits(x[live]),
                                                                list(net.nvec), dim=-1)], -1)
        stats["action_accuracy"] = float((heads == a[live]).all(-1).float().mean())
    return stats


def imitate(trainer: Any, cfg: ImitateConfig) -> dict[str, float]:
    """Warm start every learner of ``trainer`` (a fresh run) by cloning ``cfg.bot``,
    heeding ``trainer.stop``; returns metrics (``imitate/...``)."""
    tc, env = trainer.cfg, trainer.env
    driven = sorted(s for spec in trainer.specs for s in spec.seats)
    # a mixed env (training.mixed) plays its scenarios in contiguous blocks of env ids:
    # demonstrations come the same way, so stream order matches the learners'
    blocks = (list(zip(env.scenarios, (b.stop - b.start for b in env.slices), strict=True))
              if hasattr(env, "slices") else [(trainer.scenario, trainer.E)])
    parts = [collect(sc, cfg, n, tc.seed + 7919 + k, tc.observation, tc.game, tc.rewards,
                     driven, trainer.stop) for k, (sc, n) in enumerate(blocks)]
    T = min(len(p.done) for p in parts)
    if not T:
        return {}
    demo = Demonstrations(*(np.concatenate([getattr(p, f)[:T] for p in parts], axis=1)
                            for f in ("obs", "actions", "alive", "rewards", "done")),
                          sum(p.wins for p in parts), sum(p.games for p in parts))
    metrics = {"imitate/bot_win_rate": demo.wins / max(demo.games, 1),
               "imitate/games": float(demo.games), "imitate/samples": float(demo.alive.sum())}
    E = demo.done.shape[1]
    for k, spec in enumerate(trainer.specs):
        cols = trainer.cols[spec.name]  # its streams: env-major, then its seats
        B = E * len(cols)
        done = np.repeat(demo.done, len(cols), axis=1)
        stats = clone(trainer.learners[spec.name], demo.obs[:, :, cols].reshape(T, B, -1),
                      demo.actions[:, :, cols].reshape(T, B, 3),
                      demo.alive[:, :, cols].reshape(T, B),
                      demo.rewards[:, :, cols].reshape(T, B), done, cfg, tc.seed + k,
                      trainer.stop)
        metrics.update({f"imitate/{spec.name}/{key}": v for key, v in stats.items()})
    return metrics

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
A MAPPO learner fits its actor the same way (each seat with its one-hot); its critic reads
a global state the demonstrations do not record, so ``critic_warmup_updates`` train it
first.
The time it takes counts in the run's wall time (``time_limit_s``).

``teachers`` names a different teacher per scenario of a mixed run (any seat spec: a bot,
``checkpoint:PATH``, ``agent:NAME``), so one learner can copy several specialists, each in
the setting it mastered (policy distillation, as in kickstarting: Schmitt et al. 2018).

A clone drifts off the bot's states: one wrong turn and it stands where the bot never
stood, with no example to follow. ``dagger`` rounds (DAgger, Ross et al. 2011) fix that:
the learners play ``dagger_steps`` vector steps themselves (sampling, as PPO will), the
bot labels every live seat's state with what it would do there, and each learner is
refit (``dagger_epochs`` passes, from where it stands) on everything gathered so far.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from alphatank.envs.core import MatchSet
from alphatank.errors import InputError
from alphatank.game.scenarios import Scenario
from alphatank.sim.episode import episode_seeds, reset_controllers
from alphatank.sim.policy import NOOP, BatchPolicy
from alphatank.training.buffers import check_memory
from alphatank.training.fields import FieldError
from alphatank.training.hparams import ImitateConfig
from alphatank.training.mappo import MAPPO
from alphatank.training.ppo import PPO, evaluate_actions, head_log_probs

Clonable = PPO | MAPPO


def teacher(cfg: ImitateConfig, scenario: str, scenarios: list[str]) -> str:
    """The seat spec copied in ``scenario`` (one of the run's ``scenarios``): its entry in
    ``cfg.teachers``, else ``cfg.bot``; a teacher for a scenario the run lacks is refused."""
    unknown = sorted(set(cfg.teachers) - set(scenarios))
    if unknown:
        raise FieldError("imitate", "teachers", f"names no scenario of this run: "
                         f"{', '.join(map(repr, unknown))}; its scenarios: "
                         f"{', '.join(scenarios)}")
    return cfg.teachers.get(scenario, cfg.bot)


def check_teachers(cfg: ImitateConfig, scenarios: list[Scenario], driven: list[int],
                   game: dict[str, Any]) -> None:
    """FieldError naming the field (``imitate.bot``, ``imitate.teachers.NAME``) of a teacher
    that cannot play the learner seats ``driven`` of its scenario on each of its maps (a
    checkpoint of another tank count or team size, or with no room for a map's walls):
    said before the run starts, not once its folder is made and the cloning begins."""
    from alphatank.game.lineup import check_fit, spec_seat
    from alphatank.game.seats import make_controller

    names = [sc.name for sc in scenarios]
    for sc in scenarios:
        spec = teacher(cfg, sc.name, names)
        field = f"teachers.{sc.name}" if sc.name in cfg.teachers else "bot"
        seats = [sc.learner_seats[d] for d in driven]
        stand = spec_seat(spec, sc.seats[seats[0]].team, where=f"imitate.{field} {spec!r}")
        if stand.controller == "bot":  # a bot plays any seat of any map
            continue
        try:
            check_fit(sc, [(seat, make_controller(stand)) for seat in seats], game)
        except InputError as exc:
            raise FieldError("imitate", field, f"{spec!r} cannot play the learner seats "
                             f"{seats} of scenario {sc.name!r}: {exc}") from None


def check_demonstrations_memory(cfg: ImitateConfig, num_envs: int, seats: int,
                                obs_dim: int) -> None:
    """ValueError before the run starts when the demonstrations (with every DAgger round's,
    all kept for the refits) would not fit in the memory available: at their peak the
    learners' flat copies of them double it (the arrays were allocated at the cloning's
    start, a traceback for too many steps, or filled lazily until the machine ran out)."""
    steps = cfg.steps + cfg.dagger * cfg.dagger_steps
    rounds = (f" and {cfg.dagger} DAgger round{'s' if cfg.dagger > 1 else ''} of "
              f"{cfg.dagger_steps:,}" if cfg.dagger else "")
    check_memory(2 * steps * num_envs * seats * (4 * obs_dim + 37),
                 f"imitate: the demonstrations of {cfg.steps:,} vector steps{rounds} x "
                 f"{num_envs} matches x {seats} learner seats x {obs_dim} inputs",
                 "lower imitate.steps" + (" or imitate.dagger_steps" if cfg.dagger else "")
                 + " (vector steps: each steps all the run's matches)")


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


Drive = Callable[[np.ndarray], np.ndarray]


def collect(scenario: Scenario, cfg: ImitateConfig, num_envs: int, seed: int,
            observation: str | None, game: dict[str, Any], rewards: dict[str, Any],
            driven: list[int], stop: Callable[[], bool] = bool, steps: int | None = None,
            drive: Drive | None = None, action_repeat: int = 1,
            bot: str | None = None) -> Demonstrations:
    """Play ``steps`` (default ``cfg.steps``) vector steps with ``bot`` (default
    ``cfg.bot``) in the learner seats ``driven`` (indices into the scenario's learner
    seats); fewer when ``stop()`` turns true. With ``drive`` (observations (E, L, D) ->
    actions (E, L, 3)) the learners play instead and the bot's actions are only recorded,
    as labels. With ``action_repeat`` k a step's action (the bot's decision) is held for k
    ticks, as the learners will hold theirs. A batch policy (a checkpoint) fills every
    seat of every env as one object, deciding for all of them in one call."""
    from alphatank.game.lineup import spec_seat
    from alphatank.game.seats import make_controller

    core = MatchSet(scenario, num_envs, observation=observation, game_overrides=game or None,
                    reward_overrides=rewards or None, driven=driven,
                    action_repeat=action_repeat)
    seats = [scenario.learner_seats[d] for d in driven]
    team = scenario.seats[seats[0]].team
    bot = bot or cfg.bot
    stand = spec_seat(bot, team, where=f"imitate teacher {bot!r}")
    shared = make_controller(stand)
    if not isinstance(shared, BatchPolicy):
        shared = None
    bots = [[shared or make_controller(stand) for _ in seats] for _ in range(num_envs)]
    seeds = np.random.default_rng(seed)
    T, E, L = steps or cfg.steps, num_envs, len(seats)
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
            out.alive[t, e] = m.alive[seats]
            if shared is None:
                for k, (ctrl, seat) in enumerate(zip(bots[e], seats, strict=True)):
                    acts[e, k] = ctrl.act(m, seat) if out.alive[t, e, k] else NOOP
        if shared is not None:  # dead seats get NOOP from the policy itself
            pairs = [(m, seat) for m in core.matches for seat in seats]
            acts[:] = shared.act_batch(pairs).reshape(E, L, 3)
        out.actions[t] = acts
        terms, obs = core.step(acts if drive is None else drive(obs))
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


@dataclass
class Samples:
    """One learner's cloning data, flat: raw observations (N, D), the bot's actions
    (N, 3), which samples are of live seats (N,) and the critic's targets (N,)."""

    obs: np.ndarray
    actions: np.ndarray
    alive: np.ndarray
    returns: np.ndarray

    def __add__(self, other: Samples) -> Samples:
        return Samples(*(np.concatenate([a, b]) for a, b in zip(
            (self.obs, self.actions, self.alive, self.returns),
            (other.obs, other.actions, other.alive, other.returns), strict=True)))


def samples(learner: Clonable, obs: np.ndarray, actions: np.ndarray, alive: np.ndarray,
            rewards: np.ndarray, done: np.ndarray) -> Samples:
    """Flatten one batch of a learner's streams, ``obs`` (T, B, D), ``actions`` (T, B, 3),
    ``alive`` / ``rewards`` / ``done`` (T, B), B = its num_streams (the order of its
    rollout streams), folding the observations and rewards into the statistics the
    learner keeps; the targets are the discounted returns of the scaled rewards, cut at
    the batch's end."""
    if not (isinstance(learner, MAPPO) or isinstance(learner, PPO) and learner.algo == "ppo"):
        raise ValueError(f"imitate: warm starts PPO and MAPPO learners only, not "
                         f"{learner.algo!r}")
    T, B, D = obs.shape
    flat = obs.reshape(T * B, D)
    learner.obs_norm.update(flat)
    scaled = np.stack([learner.ret_norm(rewards[t], done[t]) for t in range(T)])
    returns = discounted_returns(scaled, done, learner.cfg.gamma)
    return Samples(flat, actions.reshape(T * B, 3), alive.reshape(T * B),
                   returns.reshape(T * B).astype(np.float32))


def fit(learner: Clonable, data: Samples, cfg: ImitateConfig, seed: int,
        stop: Callable[[], bool] = bool, epochs: int | None = None) -> dict[str, float]:
    """Fit ``learner``'s actor to ``data``'s actions (cross-entropy on every head, live
    samples only; with ``label_smoothing`` e each head's target is 1 - e on the bot's
    choice plus e spread evenly over the head's choices) and its critic to the targets for
    ``epochs`` (default ``cfg.epochs``) passes; stops early when ``stop()`` turns true.
    A MAPPO critic reads a global state the demonstrations do not hold: only its actor is
    fitted (its ``critic_warmup_updates`` then train the critic first).
    Returns the last minibatch's losses and the share of live samples whose most likely
    action (every head) is the bot's."""
    x = torch.from_numpy(learner.actor_input(data.obs))
    fit_critic = not isinstance(learner, MAPPO)
    a = torch.from_numpy(data.actions)
    live = torch.from_numpy(data.alive)
    y = torch.from_numpy(data.returns)
    net = learner.net
    opt = torch.optim.Adam(net.parameters(), lr=cfg.learning_rate)
    gen = torch.Generator().manual_seed(seed)
    n = len(x)
    eps = cfg.label_smoothing
    # each head's uniform target over its own choices (0 on the padding of narrower heads)
    k = torch.tensor(net.nvec, dtype=torch.float32)[:, None]
    uniform = (torch.arange(max(net.nvec))[None, :] < k) / k
    stats: dict[str, float] = {}
    for _ in range(epochs or cfg.epochs):
        if stop():
            break
        order = torch.randperm(n, generator=gen)
        for lo in range(0, n, cfg.minibatch):
            if stop():
                break
            idx = order[lo:lo + cfg.minibatch]
            logits = net.logits(x[idx])
            logprob, _ = evaluate_actions(logits, a[idx], net.nvec)
            nll = -logprob
            if eps:
                logp = head_log_probs(logits, net.nvec)
                spread = -(torch.where(uniform > 0, logp, 0.0) * uniform).sum((-2, -1))
                nll = (1 - eps) * nll + eps * spread
            m = live[idx].float()
            policy_loss = (nll * m).sum() / m.sum().clamp(min=1.0)
            loss = policy_loss
            if fit_critic:
                value_loss = 0.5 * ((net.value(x[idx]) - y[idx]) ** 2).mean()
                loss = loss + value_loss
            opt.zero_grad()
            loss.backward()
            torch.nn.utils.clip_grad_norm_(net.parameters(), learner.cfg.max_grad_norm * 10)
            opt.step()
            stats = {"policy_loss": policy_loss.item()}
            if fit_critic:
                stats["value_loss"] = value_loss.item()
    learner.sync_mirror()
    if not stop():  # a stopped run clones again on resume: no need to measure this clone
        stats["action_accuracy"] = agreement(learner, data)
    return stats


def agreement(learner: Clonable, data: Samples) -> float:
    """Share of ``data``'s live samples whose most likely action (every head) is the
    bot's."""
    with torch.no_grad():
        x = torch.from_numpy(learner.actor_input(data.obs)[data.alive])
        heads = torch.stack([h.argmax(-1) for h in torch.split(
            learner.net.logits(x), list(learner.net.nvec), dim=-1)], -1)
    return float((heads == torch.from_numpy(data.actions[data.alive])).all(-1)
                 .float().mean()) if len(x) else 0.0


def gather(trainer: Any, cfg: ImitateConfig, steps: int, seed: int,
           drive: Callable[[int], Drive] | None = None) -> Demonstrations:
    """One batch of games in the run's envs: a mixed env (training.mixed) plays its
    scenarios in contiguous blocks of env ids, and its demonstrations come the same way,
    so stream order matches the learners'. ``drive(n)``: the learners' player for a block
    of ``n`` envs (None: the bot plays)."""
    tc, env = trainer.cfg, trainer.env
    driven = sorted(s for spec in trainer.specs for s in spec.seats)
    blocks = (list(zip(env.scenarios, (b.stop - b.start for b in env.slices), strict=True))
              if hasattr(env, "slices") else [(trainer.scenario, trainer.E)])
    names = [sc.name for sc, _ in blocks]
    parts = [collect(sc, cfg, n, seed + k, tc.observation, tc.game, tc.rewards, driven,
                     trainer.stop, steps, None if drive is None else drive(n),
                     tc.action_repeat, teacher(cfg, sc.name, names))
             for k, (sc, n) in enumerate(blocks)]
    T = min(len(p.done) for p in parts)
    return Demonstrations(*(np.concatenate([getattr(p, f)[:T] for p in parts], axis=1)
                            for f in ("obs", "actions", "alive", "rewards", "done")),
                          sum(p.wins for p in parts), sum(p.games for p in parts))


def imitate(trainer: Any, cfg: ImitateConfig) -> dict[str, float]:
    """Warm start every learner of ``trainer`` (a fresh run) by cloning ``cfg.bot``, then
    ``cfg.dagger`` DAgger rounds, heeding ``trainer.stop``; returns metrics
    (``imitate/...``; ``imitate/dagger<r>/...`` per round: the learners' win rate and,
    per learner, how often it agreed with the bot on its own states before the refit)."""
    tc, specs = trainer.cfg, trainer.specs
    learners = [trainer.learners[spec.name] for spec in specs]
    rng = np.random.default_rng(tc.seed + 104729)  # the learners' samples in DAgger rounds

    def split(demo: Demonstrations) -> list[Samples]:
        """Each learner's share of ``demo`` (its streams: env-major, then its seats)."""
        T, E = demo.done.shape
        out = []
        for spec, learner in zip(specs, learners, strict=True):
            cols = trainer.cols[spec.name]
            B = E * len(cols)
            out.append(samples(learner, demo.obs[:, :, cols].reshape(T, B, -1),
                               demo.actions[:, :, cols].reshape(T, B, 3),
                               demo.alive[:, :, cols].reshape(T, B),
                               demo.rewards[:, :, cols].reshape(T, B),
                               np.repeat(demo.done, len(cols), axis=1)))
        return out

    def drive(n: int) -> Drive:
        def play(obs: np.ndarray) -> np.ndarray:
            acts = np.empty((n, obs.shape[1], 3), dtype=np.int64)
            for spec, learner in zip(specs, learners, strict=True):
                cols = trainer.cols[spec.name]
                acts[:, cols] = learner.policy_actions(
                    obs[:, cols].reshape(n * len(cols), -1), rng=rng).reshape(n, len(cols), 3)
            return acts
        return play

    demo = gather(trainer, cfg, cfg.steps, tc.seed + 7919)
    if not len(demo.done):
        return {}
    metrics = {"imitate/bot_win_rate": demo.wins / max(demo.games, 1),
               "imitate/games": float(demo.games), "imitate/samples": float(demo.alive.sum())}
    data = split(demo)
    for r in range(cfg.dagger + 1):
        if r:
            demo = gather(trainer, cfg, cfg.dagger_steps, tc.seed + 7919 + 1000 * r, drive)
            if not len(demo.done):
                break
            metrics[f"imitate/dagger{r}/win_rate"] = demo.wins / max(demo.games, 1)
            fresh = split(demo)
            for spec, learner, more in zip(specs, learners, fresh, strict=True):
                metrics[f"imitate/dagger{r}/{spec.name}/agreement"] = agreement(learner, more)
            data = [a + b for a, b in zip(data, fresh, strict=True)]
        for k, (spec, learner) in enumerate(zip(specs, learners, strict=True)):
            stats = fit(learner, data[k], cfg, tc.seed + k + 31 * r, trainer.stop,
                        cfg.dagger_epochs if r else cfg.epochs)
            metrics.update({f"imitate/{spec.name}/{key}": v for key, v in stats.items()})
    return metrics

"""Hyperparameter dataclasses of the learners and of a run's behaviour cloning
(``imitate``), one line of help and the allowed range per field (no torch import:
presets, ``alphatank train --list`` and the CLI list and validate them cheaply). An
algorithm's config class is named in its registry line
(:mod:`alphatank.training.algorithms`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from alphatank.training.fields import FieldError, build, hp, validate

# Widest hidden layer: 32x the paper's 128. The networks' memory grows with its square
# (parameters, gradients and two Adam moments: about 16 bytes each), so a wider one would
# fail in the middle of the set-up on many machines; at 4,096 they take about 0.5 GiB
# (PPO) to 1.3 GiB (SAC's actor, critics and target critics).
HIDDEN_MAX = 4096
# Most SAC gradient steps per collected transition, far above the 1 to 20 of the
# literature (at ~20 ms a step, 1,000 take 20 s per transition). Unbounded, a huge ratio
# made an update round endless (the steps owed no longer drop by 1 past 2**53) or
# infinite (near 1e308), and the checkpoint a stop then saved could not be loaded.
UTD_RATIO_MAX = 1000.0


@dataclass(frozen=True)
class PPOConfig:
    """PPO hyperparameters. Defaults: the paper's Table 7; the rest CleanRL's defaults."""

    learning_rate: float = hp(3e-4, "Adam step size", gt=0)
    gamma: float = hp(0.99, "discount factor", ge=0, le=1)
    gae_lambda: float = hp(0.95, "GAE lambda (bias/variance of the advantage)", ge=0, le=1)
    clip_coef: float = hp(0.2, "clip range of the probability ratio (and value change)", gt=0)
    ent_coef: float = hp(0.01, "weight of the entropy bonus", ge=0)
    vf_coef: float = hp(0.3, "weight of the value loss", ge=0)
    max_grad_norm: float = hp(0.3, "gradient norm clip", gt=0)
    num_steps: int = hp(512, "rollout length per stream (vector steps per update)", gt=0)
    update_epochs: int = hp(60, "passes over each rollout", gt=0)
    # not in Table 7: CleanRL defaults
    num_minibatches: int = hp(4, "minibatches per epoch", gt=0)
    norm_adv: bool = hp(True, "normalise advantages per minibatch")
    clip_vloss: bool = hp(True, "clip the value loss like the policy ratio")
    anneal_lr: bool = hp(False, "decay the learning rate linearly to 0 over the run")
    target_kl: float | None = hp(None, "stop an update's epochs once the approximate KL "
                                 "exceeds this (none: never)", gt=0)
    hidden: int = hp(128, "units per hidden layer (two tanh layers, actor and critic)",
                     gt=0, le=HIDDEN_MAX)
    anchor_kl: float = hp(0.0, "weight of KL(start || policy) in the loss, start being the "
                          "policy RL began from (the imitate clone or the init_from "
                          "checkpoint): keeps what the warm start knew; 0: off", ge=0)
    norm_obs: bool = hp(True, "normalise observations by running mean/std (saved)")
    norm_reward: bool = hp(True, "scale rewards by the running std of the discounted return")
    obs_clip: float = hp(10.0, "clip of normalised observations", gt=0)
    reward_clip: float = hp(10.0, "clip of scaled rewards", gt=0)
    adam_eps: float = hp(1e-5, "Adam epsilon", gt=0)

    def __post_init__(self) -> None:
        validate(self)


@dataclass(frozen=True)
class SACConfig:
    """SAC hyperparameters; defaults are the paper's Tables 8 and 9."""

    policy_lr: float = hp(3e-4, "actor learning rate", gt=0)
    q_lr: float = hp(3e-4, "critic learning rate", gt=0)
    alpha_lr: float = hp(3e-4, "entropy-coefficient learning rate (autotune)", gt=0)
    gamma: float = hp(0.99, "discount factor", ge=0, le=1)
    tau: float = hp(0.005, "Polyak factor of the target critics", gt=0, le=1)
    batch_size: int = hp(256, "transitions per gradient step", gt=0)
    buffer_size: int = hp(1_000_000, "replay buffer capacity (transitions, per learner)", gt=0)
    start_steps: int = hp(1000, "uniform random actions before this many transitions", ge=0)
    update_after: int = hp(1000, "transitions collected before the first update", ge=0)
    update_every: int = hp(50, "transitions between update rounds", gt=0)
    utd_ratio: float = hp(1.0, "gradient steps per collected transition", gt=0,
                          le=UTD_RATIO_MAX)
    hidden: int = hp(256, "units per hidden layer (two ReLU layers)", gt=0,
                     le=HIDDEN_MAX)
    autotune: bool = hp(True, "tune the entropy coefficient towards target_entropy")
    alpha: float = hp(0.2, "initial (or, without autotune, fixed) entropy coefficient", gt=0)
    target_entropy: float | None = hp(None, "entropy target of autotune (none: -action dims)")
    norm_obs: bool = hp(True, "normalise observations by running mean/std (saved)")
    obs_clip: float = hp(10.0, "clip of normalised observations", gt=0)
    reward_scale: float = hp(1.0, "multiplier of stored rewards", gt=0)

    def __post_init__(self) -> None:
        validate(self)


@dataclass(frozen=True)
class MAPPOConfig:
    """MAPPO hyperparameters. Defaults: MAPPO's published ones (Yu et al. 2022: clip 0.2,
    10 epochs, 2 minibatches, lr 5e-4, entropy 0.01, grad norm 10, Huber value loss with
    delta 10, value normalisation); network as PPO's (two 128-unit tanh layers) so 1v1 PPO
    checkpoints can warm-start its actor."""

    learning_rate: float = hp(5e-4, "actor Adam step size", gt=0)
    critic_learning_rate: float = hp(5e-4, "critic Adam step size", gt=0)
    gamma: float = hp(0.99, "discount factor", ge=0, le=1)
    gae_lambda: float = hp(0.95, "GAE lambda (bias/variance of the advantage)", ge=0, le=1)
    clip_coef: float = hp(0.2, "clip range of the probability ratio (and value change)", gt=0)
    ent_coef: float = hp(0.01, "weight of the entropy bonus", ge=0)
    vf_coef: float = hp(1.0, "weight of the value loss", ge=0)
    max_grad_norm: float = hp(10.0, "gradient norm clip, per network (actor, critic)", gt=0)
    num_steps: int = hp(128, "rollout length per stream (vector steps per update)", gt=0)
    update_epochs: int = hp(10, "passes over each rollout", gt=0)
    num_minibatches: int = hp(2, "minibatches per epoch", gt=0)
    value_norm: bool = hp(True, "critic predicts returns normalised by running mean/std")
    huber_delta: float = hp(10.0, "Huber delta of the value loss on normalised errors "
                            "(0: squared error)", ge=0)
    clip_vloss: bool = hp(True, "clip the value loss like the policy ratio")
    norm_adv: bool = hp(True, "normalise advantages over the live rows of the rollout")
    anneal_lr: bool = hp(False, "decay the learning rates linearly to 0 over the run")
    target_kl: float | None = hp(None, "stop an update's epochs once the approximate KL "
                                 "exceeds this (none: never)", gt=0)
    hidden: int = hp(128, "units per hidden layer (two tanh layers, actor and critic)",
                     gt=0, le=HIDDEN_MAX)
    norm_obs: bool = hp(True, "normalise observations by running mean/std (saved)")
    norm_state: bool = hp(True, "normalise the critic's global state by running mean/std")
    norm_reward: bool = hp(False, "scale rewards by the running std of the discounted return "
                           "(value normalisation makes it unnecessary)")
    obs_clip: float = hp(10.0, "clip of normalised observations and states", gt=0)
    reward_clip: float = hp(10.0, "clip of scaled rewards", gt=0)
    adam_eps: float = hp(1e-5, "Adam epsilon", gt=0)
    bootstrap_timeouts: bool = hp(False, "bootstrap time-limit ends from the critic (false: "
                                  "max_steps ends the game; time is in the state)")
    critic_warmup_updates: int = hp(0, "first updates train only the critic (warm starts)",
                                    ge=0)

    def __post_init__(self) -> None:
        validate(self)


# ---- behaviour cloning (the imitate table of a run) ----------------------------------------

@dataclass(frozen=True)
class ImitateConfig:
    """The ``imitate`` table of a run file (empty: no warm start)."""

    bot: str = hp("smart", "seat spec of the bot to copy (e.g. smart, smart@0.8)")
    steps: int = hp(4096, "vector steps of demonstration games (each steps every env)", gt=0)
    epochs: int = hp(8, "passes over the demonstrations", gt=0)
    minibatch: int = hp(2048, "samples per gradient step", gt=0)
    learning_rate: float = hp(1e-3, "Adam learning rate of the cloning", gt=0)
    label_smoothing: float = hp(0.0, "share of each head's target spread evenly over its "
                                     "choices (a clone that keeps exploring)", ge=0, lt=1)
    dagger: int = hp(0, "DAgger rounds after the first fit: the learners play, the bot "
                        "labels their states, the fit is redone on all the data", ge=0)
    dagger_steps: int = hp(2048, "vector steps of each DAgger round", gt=0)
    dagger_epochs: int = hp(4, "passes over all the data in each DAgger round's refit", gt=0)
    teachers: dict[str, str] = hp({}, "per scenario of the run, the seat spec copied there "
                                      "instead of bot (e.g. { vs_smart = "
                                      "\"checkpoint:runs/smart\" }: distil specialists)")

    def __post_init__(self) -> None:
        validate(self)


def imitate_config(data: dict[str, Any]) -> ImitateConfig | None:
    """The config of a run's ``imitate`` table (its bot checked); None when it is empty."""
    if not data:
        return None
    cfg = build(ImitateConfig, data, "imitate.")
    _check_teacher(cfg.bot, "bot")
    for name, spec in cfg.teachers.items():
        if not isinstance(spec, str):
            raise FieldError("imitate", f"teachers.{name}", "must be a seat spec string "
                             f"(smart, checkpoint:PATH, agent:NAME), got {spec!r}")
        _check_teacher(spec, f"teachers.{name}")
    return cfg


def _check_teacher(spec: str, field: str) -> None:
    """A seat spec that plays by itself (a bot, checkpoint, agent, ...): not a learner
    seat, which has nothing to copy, nor a player at a keyboard."""
    from alphatank.game.lineup import spec_seat
    from alphatank.game.seats import plays_by_itself

    if not plays_by_itself(spec_seat(spec, where=f"imitate.{field} {spec!r}")):
        raise FieldError("imitate", field, f"must be a seat that plays by itself (smart, "
                         f"checkpoint:PATH, agent:NAME), got {spec!r}")

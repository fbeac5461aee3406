"""PPO (clipped surrogate, GAE, minibatches) for one learner over many (env, seat) streams.

Network and defaults follow the paper's Table 7 (CleanRL-style): separate actor and
critic MLPs of two 128-unit tanh layers, one categorical head per action dimension.
Rollout inference runs on a numpy mirror of the network with Gumbel-max sampling from
the learner's own generator, so a run is reproducible and resumable bit for bit.
"""

from __future__ import annotations

import copy
import functools
import math
from typing import Any

import numpy as np
import torch
from torch import nn

from alphatank.training.buffers import OnPolicyPlumbing, RolloutBuffer, compute_gae
from alphatank.training.hparams import PPOConfig
from alphatank.training.normalize import ObsNormalizer, ReturnNormalizer
from alphatank.training.stopping import check_interrupt

NVEC = (3, 3, 2)  # rotate, move, fire — the one action layout (RULES.md)
MASKED_LOGIT = -1e8  # exp() of this is exactly 0 in float32, and 0 * it stays finite


def layer_init(layer: nn.Linear, std: float = math.sqrt(2)) -> nn.Linear:
    nn.init.orthogonal_(layer.weight, std)
    nn.init.constant_(layer.bias, 0.0)
    return layer


class _NumpyTanh(torch.autograd.Function):
    """tanh through numpy's vectorised kernel (torch 2.13's CPU tanh costs ~10x more:
    ~500 vs ~50 us for a 1024 x 128 minibatch activation), torch's backward."""

    @staticmethod
    def forward(ctx: Any, x: torch.Tensor) -> torch.Tensor:
        y = torch.from_numpy(np.tanh(x.detach().numpy()))
        ctx.save_for_backward(y)
        return y

    @staticmethod
    def backward(ctx: Any, grad: torch.Tensor) -> torch.Tensor:
        (y,) = ctx.saved_tensors
        return torch.ops.aten.tanh_backward(grad, y)


class Tanh(nn.Module):
    """``nn.Tanh`` computed by numpy (same values as the numpy rollout mirror's)."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return _NumpyTanh.apply(x)


def mlp(inp: int, hidden: int, out: int, out_std: float, act: type[nn.Module]) -> nn.Sequential:
    return nn.Sequential(layer_init(nn.Linear(inp, hidden)), act(),
                         layer_init(nn.Linear(hidden, hidden)), act(),
                         layer_init(nn.Linear(hidden, out), std=out_std))


Fold = tuple[torch.Tensor, torch.Tensor, torch.Tensor]


def fold_constant(x: torch.Tensor) -> tuple[torch.Tensor, Fold | None]:
    """Split the columns of ``x`` (N, D) that hold one value in every row (empty bullet,
    wall and zone slots: 83 of ppo_vs_smart's 236 over a 128 x 32 rollout) from the rest:
    returns (the varying columns (N, D'), (varying, constant, their values)), or (``x``,
    None) when no column is constant. A first layer then folds the constant columns into
    its bias (:func:`run_folded`): the same sums in another order, fewer products."""
    const = (x == x[:1]).all(dim=0)
    if not bool(const.any()):
        return x, None
    var_idx, const_idx = torch.nonzero(~const)[:, 0], torch.nonzero(const)[:, 0]
    return x.index_select(1, var_idx), (var_idx, const_idx, x[0, const_idx].clone())


def run_folded(seq: nn.Sequential, x: torch.Tensor, fold: Fold | None) -> torch.Tensor:
    """``seq(full x)`` from the varying columns ``x`` and the ``fold`` of the constant
    ones (gradients reach every weight as if the full input had been used)."""
    if fold is None:
        return seq(x)
    var_idx, const_idx, values = fold
    first = seq[0]
    bias = torch.addmv(first.bias, first.weight.index_select(1, const_idx), values)
    h = torch.nn.functional.linear(x, first.weight.index_select(1, var_idx), bias)
    for layer in seq[1:]:
        h = layer(h)
    return h


class ActorCritic(nn.Module):
    """Table 7: critic obs->128->128->1, actor obs->128->128->sum(nvec) logits (tanh)."""

    def __init__(self, obs_dim: int, hidden: int = 128, nvec: tuple[int, ...] = NVEC):
        super().__init__()
        self.nvec = tuple(nvec)
        self.critic = mlp(obs_dim, hidden, 1, 1.0, Tanh)
        self.actor = mlp(obs_dim, hidden, sum(self.nvec), 0.01, Tanh)

    def value(self, obs: torch.Tensor, fold: Fold | None = None) -> torch.Tensor:
        return run_folded(self.critic, obs, fold).squeeze(-1)

    def logits(self, obs: torch.Tensor, mask: torch.Tensor | None = None,
               fold: Fold | None = None) -> torch.Tensor:
        """``fold``: ``obs`` holds only the varying columns (see :func:`fold_constant`)."""
        logits = run_folded(self.actor, obs, fold)
        if mask is not None:
            logits = logits.masked_fill(~mask, MASKED_LOGIT)
        return logits


@functools.lru_cache(maxsize=8)
def _head_layout(nvec: tuple[int, ...]) -> tuple[int, torch.Tensor | None]:
    """Widest head ``m`` and, unless every head has ``m`` choices, the columns that lay
    the logits out as (heads, m), index ``sum(nvec)`` meaning a padding column."""
    m, total = max(nvec), sum(nvec)
    if all(n == m for n in nvec):
        return m, None
    cols: list[int] = []
    off = 0
    for n in nvec:
        cols += [*range(off, off + n), *[total] * (m - n)]
        off += n
    return m, torch.tensor(cols, dtype=torch.int64)


def _heads(logits: torch.Tensor, nvec: tuple[int, ...]) -> torch.Tensor:
    """(B, heads, m) layout of the logits, short heads padded with ``MASKED_LOGIT``."""
    m, cols = _head_layout(tuple(nvec))
    if cols is not None:
        padded = torch.nn.functional.pad(logits, (0, 1), value=MASKED_LOGIT)
        logits = padded.index_select(1, cols)
    return logits.reshape(logits.shape[0], len(nvec), m)


def head_log_probs(logits: torch.Tensor, nvec: tuple[int, ...]) -> torch.Tensor:
    """(B, heads, m) log-probabilities of every choice of every head: one log-softmax
    over the logits padded to the widest head (padding has probability 0)."""
    return torch.log_softmax(_heads(logits, nvec), dim=-1)


def evaluate_actions(logits: torch.Tensor, actions: torch.Tensor, nvec: tuple[int, ...]
                     ) -> tuple[torch.Tensor, torch.Tensor]:
    """Summed log-probability and entropy (both (B,)) of given actions."""
    logp = head_log_probs(logits, nvec)
    logprob = logp.gather(-1, actions.unsqueeze(-1)).squeeze(-1).sum(-1)
    entropy = -(logp.exp() * logp).sum((-2, -1))
    return logprob, entropy


def clipped_surrogate(logprob: torch.Tensor, old_logprob: torch.Tensor, adv: torch.Tensor,
                      w: torch.Tensor, n_w: torch.Tensor, clip: float
                      ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """PPO's clipped policy loss over the rows of a minibatch weighted by ``w`` (0: left
    out, e.g. a dead seat's; ``n_w`` their count), with the approximate KL and the share
    of clipped ratios (both without gradient)."""
    log_ratio = logprob - old_logprob
    ratio = log_ratio.exp()
    with torch.no_grad():
        approx_kl = (((ratio - 1) - log_ratio) * w).sum() / n_w
        clipfrac = (((ratio - 1.0).abs() > clip).float() * w).sum() / n_w
    pg = torch.max(-adv * ratio, -adv * torch.clamp(ratio, 1 - clip, 1 + clip))
    return (pg * w).sum() / n_w, approx_kl, clipfrac


class NumpyActorCritic:
    """Float32 numpy copy of an :class:`ActorCritic` for rollout and play inference: a
    handful of BLAS calls instead of dozens of small torch ops (the hot path). The first
    actor and critic layers are fused into one matrix product. ``sync`` after updates."""

    def __init__(self, net: ActorCritic):
        self.sync(net)

    def sync(self, net: ActorCritic) -> None:
        def wt(layer: nn.Module) -> np.ndarray:
            return np.ascontiguousarray(layer.weight.detach().numpy().T, dtype=np.float32)

        def bias(layer: nn.Module) -> np.ndarray:
            return layer.bias.detach().numpy().astype(np.float32)

        a, c = net.actor, net.critic
        self.hidden = a[0].out_features
        self.w1 = np.ascontiguousarray(np.concatenate([wt(a[0]), wt(c[0])], axis=1))
        self.b1 = np.concatenate([bias(a[0]), bias(c[0])])
        self.wa2, self.ba2, self.wc2, self.bc2 = wt(a[2]), bias(a[2]), wt(c[2]), bias(c[2])
        self.wa3, self.ba3, self.wc3, self.bc3 = wt(a[4]), bias(a[4]), wt(c[4]), bias(c[4])

    def forward(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Logits (B, sum(nvec)) and values (B,) for normalised float32 observations."""
        h = np.tanh(x @ self.w1 + self.b1)
        ha = np.tanh(h[:, :self.hidden] @ self.wa2 + self.ba2)
        hc = np.tanh(h[:, self.hidden:] @ self.wc2 + self.bc2)
        return ha @ self.wa3 + self.ba3, (hc @ self.wc3 + self.bc3)[:, 0]


class NumpyMLP:
    """Float32 numpy copy of a two-hidden-layer tanh :func:`~alphatank.training.ppo.mlp`."""

    def __init__(self, seq: nn.Sequential):
        self.sync(seq)

    def sync(self, seq: nn.Sequential) -> None:
        self.layers = [(np.ascontiguousarray(seq[k].weight.detach().numpy().T, dtype=np.float32),
                        seq[k].bias.detach().numpy().astype(np.float32)) for k in (0, 2, 4)]

    def forward(self, x: np.ndarray) -> np.ndarray:
        (w1, b1), (w2, b2), (w3, b3) = self.layers
        return np.tanh(np.tanh(x @ w1 + b1) @ w2 + b2) @ w3 + b3


def np_sample(logits: np.ndarray, nvec: tuple[int, ...], rng: np.random.Generator,
              deterministic: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Actions (B, len(nvec)) int64 and their summed log-probabilities (B,) float32 from
    logits (B, sum(nvec)): Gumbel-max sampling from ``rng`` (or the most likely choice).
    :func:`evaluate_actions` computes the same log-probabilities in torch."""
    b = logits.shape[0]
    rows = np.arange(b)
    actions = np.empty((b, len(nvec)), dtype=np.int64)
    logprob = np.zeros(b, dtype=np.float32)
    if not deterministic:
        u = np.maximum(rng.random(logits.shape, dtype=np.float32), np.float32(1e-20))
        scores = logits - np.log(-np.log(u))
    off = 0
    for i, n in enumerate(nvec):
        part = logits[:, off:off + n]
        top = part.max(axis=1)
        lse = top + np.log(np.exp(part - top[:, None]).sum(axis=1))
        a = (part if deterministic else scores[:, off:off + n]).argmax(axis=1)
        actions[:, i] = a
        logprob += part[rows, a] - lse
        off += n
    return actions, logprob


def sample_into(buf: RolloutBuffer, x: np.ndarray, logits: np.ndarray, values: np.ndarray,
                masks: np.ndarray | None, nvec: tuple[int, ...], rng: np.random.Generator
                ) -> np.ndarray:
    """Actions (B, len(nvec)) sampled from ``logits`` (the choices ``masks`` forbids masked
    in place), with the step's row of ``buf`` written: inputs ``x``, masks, actions, their
    log-probabilities and ``values``."""
    t, row = buf.step, buf.np
    if masks is not None:
        masks = np.asarray(masks, dtype=bool)
        logits[~masks] = MASKED_LOGIT
        if buf.masks is not None:
            row["masks"][t] = masks
    actions, logprob = np_sample(logits, nvec, rng)
    row["obs"][t] = x
    row["actions"][t] = actions
    row["logprobs"][t] = logprob
    row["values"][t] = values
    return actions


class FrozenPPO:
    """A PPO learner's acting side frozen for one rollout acted elsewhere
    (:mod:`alphatank.training.fragments`): its numpy network and observation statistics."""

    def __init__(self, net: NumpyActorCritic, norm: ObsNormalizer, nvec: tuple[int, ...]):
        self.net, self.norm, self.nvec = net, norm, nvec

    def act(self, obs: np.ndarray, inputs: dict[str, np.ndarray], rng: np.random.Generator
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Actions, log-probabilities and values of raw stream observations (B, D)."""
        del inputs
        logits, values = self.net.forward(self.norm(obs))
        return (*np_sample(logits, self.nvec, rng), values)

    def values(self, obs: np.ndarray, inputs: dict[str, np.ndarray]) -> np.ndarray:
        """Values (B,) of raw stream observations (bootstrap of time-limit cuts)."""
        del inputs
        return self.net.forward(self.norm(obs))[1]


class PPO(OnPolicyPlumbing):
    """One PPO learner controlling ``num_streams`` = num_envs x its seats (implements
    :class:`alphatank.training.learners.Learner`).

    Per env step the runner calls :meth:`act` with the streams' raw observations, then
    :meth:`observe` with rewards and episode flags; when :attr:`ready`, :meth:`update`.
    """

    algo = "ppo"
    inputs: tuple[str, ...] = ()
    inference_keys = ("net", "obs_norm")

    def __init__(self, obs_dim: int, num_streams: int, cfg: PPOConfig | None = None,
                 seed: int = 0, mask_dim: int = 0, num_seats: int = 1):
        del num_seats  # independent streams: PPO does not tell its seats apart
        self.cfg = cfg = cfg or PPOConfig()
        self.obs_dim, self.num_streams = obs_dim, num_streams
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(seed)
            self.net = ActorCritic(obs_dim, cfg.hidden)
        self.nvec = self.net.nvec
        self.optimizer = torch.optim.Adam(self.net.parameters(), lr=cfg.learning_rate,
                                          eps=cfg.adam_eps, fused=True)
        self.generator = torch.Generator().manual_seed(seed)  # minibatch order
        self.np_rng = np.random.default_rng(seed)  # action sampling
        self.mirror = NumpyActorCritic(self.net)
        self.obs_norm = ObsNormalizer(obs_dim, cfg.norm_obs, cfg.obs_clip)
        self.ret_norm = ReturnNormalizer(num_streams, cfg.gamma, cfg.norm_reward, cfg.reward_clip)
        self.mask_dim = mask_dim
        # the policy RL started from (see anchor()): its actor and observation statistics
        self.anchor_actor: nn.Sequential | None = None
        self.anchor_np: NumpyMLP | None = None
        self.anchor_norm: ObsNormalizer | None = None
        self.updates = 0
        self.total_updates = 0  # set by plan() for learning-rate annealing
        self.interrupt: Any = None  # set by the runner; polled between minibatches

    def make_buffer(self) -> RolloutBuffer:
        return RolloutBuffer(self.cfg.num_steps, self.num_streams, self.obs_dim,
                             self.mask_dim, sum(self.nvec) if self.cfg.anchor_kl else 0)

    # ---- acting -----------------------------------------------------------------------

    def anchor(self) -> None:
        """Keep the current policy (a warm start: the imitate clone, an init_from
        checkpoint) as the one ``anchor_kl`` pulls towards; nothing when it is 0."""
        if not self.cfg.anchor_kl:
            return
        self.anchor_actor = copy.deepcopy(self.net.actor).requires_grad_(False)
        self.anchor_np = NumpyMLP(self.anchor_actor)
        self.anchor_norm = copy.deepcopy(self.obs_norm)

    def act(self, obs: np.ndarray, masks: np.ndarray | None = None) -> np.ndarray:
        """Sample actions (num_streams, 3) for raw observations and record the step."""
        buf = self.buffer
        t = buf.step
        if buf.anchor_logits is not None:
            if self.anchor_np is None:
                raise RuntimeError("anchor_kl > 0 needs an anchor: call anchor() after the "
                                   "warm start (imitate or init_from)")
            ref = self.anchor_np.forward(self.anchor_norm(obs))
            if masks is not None:
                ref[~np.asarray(masks, dtype=bool)] = MASKED_LOGIT
            buf.np["anchor_logits"][t] = ref
        x = self.obs_norm(obs, update=True)
        logits, values = self.mirror.forward(x)
        return sample_into(buf, x, logits, values, masks, self.nvec, self.np_rng)

    def observe(self, next_obs: np.ndarray, rewards: np.ndarray, terminated: np.ndarray,
                truncated: np.ndarray, final_obs: np.ndarray | None = None,
                active: np.ndarray | None = None) -> None:
        """Record the outcome of the last :meth:`act`: rewards (B,), flags (B,), the final
        observations of ended streams (rows of ``final_obs``; others ignored) and which
        streams' actions counted (``active``, e.g. False for dead tanks). ``next_obs`` is
        unused (PPO reads it at the next :meth:`act`); it keeps one learner interface."""
        del next_obs
        buf = self.buffer
        self.record_outcome(rewards, terminated, truncated, True if active is None else active)
        boot = np.flatnonzero(np.logical_and(truncated, np.logical_not(terminated)))
        if boot.size:
            if final_obs is None:
                raise ValueError("truncated streams need final_obs to bootstrap from")
            buf.np["bootstrap"][buf.step, boot] = self.mirror.forward(
                self.obs_norm(final_obs[boot]))[1]
        buf.step += 1

    # ---- rollouts acted elsewhere (fragments) ------------------------------------------

    def frozen(self) -> FrozenPPO:
        """Copies of the acting network and observation statistics, for a rollout acted
        away from the learner (:mod:`alphatank.training.fragments`)."""
        return FrozenPPO(copy.deepcopy(self.mirror), copy.deepcopy(self.obs_norm), self.nvec)

    def ingest(self, obs: np.ndarray, actions: np.ndarray, logprobs: np.ndarray,
               values: np.ndarray, rewards: np.ndarray, terminated: np.ndarray,
               truncated: np.ndarray, bootstrap: np.ndarray, active: np.ndarray | None
               ) -> None:
        """Record rows acted by copies of :meth:`frozen` taken at the rollout's start:
        (T, B, ...) arrays of raw observations and what followed (``bootstrap``: V of
        the final observation of a time-limit cut). The observation statistics take the
        rows in after them (the copies acted with the statistics of the start)."""
        if self.buffer.anchor_logits is not None or self.buffer.masks is not None:
            raise RuntimeError("rollouts acted elsewhere carry no anchor logits or action "
                               "masks")
        for t in range(obs.shape[0]):
            self.record_acted(self.obs_norm(obs[t]), actions[t], logprobs[t], values[t],
                              rewards[t], terminated[t], truncated[t], bootstrap[t],
                              True if active is None else active[t])
        for t in range(obs.shape[0]):
            self.obs_norm.update(obs[t])

    # ---- learning ---------------------------------------------------------------------

    def update(self, next_obs: np.ndarray) -> dict[str, float]:
        """One PPO update on the full rollout; ``next_obs`` follows its last row."""
        cfg, buf, net = self.cfg, self.buffer, self.net
        if not buf.full:
            raise RuntimeError(f"rollout has {buf.step}/{buf.num_steps} steps; update when ready")
        self.anneal_learning_rates(cfg.learning_rate)
        with torch.no_grad():
            last_values = torch.from_numpy(self.mirror.forward(self.obs_norm(next_obs))[1])
            advantages, returns = compute_gae(buf.rewards, buf.values, buf.terminated,
                                              buf.truncated, buf.bootstrap, last_values,
                                              cfg.gamma, cfg.gae_lambda)
        n = buf.num_steps * buf.num_streams
        b_obs, fold = fold_constant(buf.obs.reshape(n, -1))
        b_actions = buf.actions.reshape(n, -1)
        b_logprobs, b_values = buf.logprobs.reshape(n), buf.values.reshape(n)
        b_adv, b_ret = advantages.reshape(n), returns.reshape(n)
        b_active = buf.active.reshape(n).float()
        b_masks = buf.masks.reshape(n, -1) if buf.masks is not None else None
        b_anchor = (buf.anchor_logits.reshape(n, -1) if buf.anchor_logits is not None
                    else None)
        mb_size = max(1, n // cfg.num_minibatches)
        stats: dict[str, list[float]] = {k: [] for k in
                                         ("policy_loss", "value_loss", "entropy", "approx_kl",
                                          "clipfrac", *(("anchor_kl",) if b_anchor is not None
                                                        else ()))}
        epochs_run = 0
        for _ in range(cfg.update_epochs):
            perm = torch.randperm(n, generator=self.generator)
            approx_kl = torch.zeros(())
            for start in range(0, n - mb_size + 1, mb_size):
                idx = perm[start:start + mb_size]
                check_interrupt(self.interrupt)  # the runner rewinds a cut update
                mask = b_masks.index_select(0, idx) if b_masks is not None else None
                obs = b_obs.index_select(0, idx)  # index_select: 5x cheaper than b_obs[idx]
                logits = net.logits(obs, mask, fold)
                logprob, entropy = evaluate_actions(logits, b_actions.index_select(0, idx),
                                                    self.nvec)
                value = net.value(obs, fold)
                act_w = b_active.index_select(0, idx)
                n_act = act_w.sum().clamp(min=1.0)
                adv = b_adv.index_select(0, idx)
                if cfg.norm_adv:
                    mean = (adv * act_w).sum() / n_act
                    std = (((adv - mean) ** 2 * act_w).sum() / n_act).sqrt()
                    adv = (adv - mean) / (std + 1e-8)
                pg_loss, approx_kl, clipfrac = clipped_surrogate(
                    logprob, b_logprobs.index_select(0, idx), adv, act_w, n_act, cfg.clip_coef)
                old_v, ret = b_values.index_select(0, idx), b_ret.index_select(0, idx)
                if cfg.clip_vloss:
                    v_clipped = old_v + torch.clamp(value - old_v, -cfg.clip_coef,
                                                    cfg.clip_coef)
                    v_loss = 0.5 * torch.max((value - ret) ** 2, (v_clipped - ret) ** 2).mean()
                else:
                    v_loss = 0.5 * ((value - ret) ** 2).mean()
                ent = (entropy * act_w).sum() / n_act
                loss = pg_loss - cfg.ent_coef * ent + cfg.vf_coef * v_loss
                if b_anchor is not None:  # KL(anchor || policy) over every head
                    ref = head_log_probs(b_anchor.index_select(0, idx), self.nvec)
                    kl = (ref.exp() * (ref - head_log_probs(logits, self.nvec))).sum((-2, -1))
                    anchor_kl = (kl * act_w).sum() / n_act
                    loss = loss + cfg.anchor_kl * anchor_kl
                    stats["anchor_kl"].append(float(anchor_kl.detach()))
                self.optimizer.zero_grad(set_to_none=True)
                loss.backward()
                nn.utils.clip_grad_norm_(net.parameters(), cfg.max_grad_norm)
                self.optimizer.step()
                for key, val in (("policy_loss", pg_loss), ("value_loss", v_loss),
                                 ("entropy", ent), ("approx_kl", approx_kl),
                                 ("clipfrac", clipfrac)):
                    stats[key].append(float(val.detach()))
            epochs_run += 1
            if cfg.target_kl is not None and float(approx_kl) > cfg.target_kl:
                break
        var_y = float(b_ret.var())
        explained = float("nan") if var_y == 0 else 1.0 - float((b_ret - b_values).var()) / var_y
        self.updates += 1
        buf.clear()
        self.sync_mirror()
        out = {f"losses/{k}": float(np.mean(v)) for k, v in stats.items() if v}
        out.update({"losses/explained_variance": explained, "losses/epochs": float(epochs_run),
                    "charts/learning_rate": float(self.optimizer.param_groups[0]["lr"])})
        return out

    # ---- inference and persistence ------------------------------------------------------

    def actor_input(self, obs: np.ndarray) -> np.ndarray:
        """The network's input for raw observations (B, obs_dim), frozen statistics."""
        return self.obs_norm(obs)

    def sync_mirror(self) -> None:
        """Copy the torch weights to the numpy rollout mirror (after editing ``net``)."""
        self.mirror.sync(self.net)

    def policy_actions(self, obs: np.ndarray, deterministic: bool = False,
                       rng: np.random.Generator | None = None) -> np.ndarray:
        """Actions for raw observations (B, obs_dim) with frozen statistics and no
        recording; ``rng`` (default: the learner's own) draws the samples."""
        logits, _ = self.mirror.forward(self.obs_norm(np.atleast_2d(obs)))
        return np_sample(logits, self.nvec, rng or self.np_rng, deterministic)[0]

    def state_dict(self) -> dict[str, Any]:
        state = {"net": self.net.state_dict(), "obs_norm": self.obs_norm.state_dict(),
                 **self.training_state()}
        if self.anchor_actor is not None:
            state["anchor"] = {"actor": self.anchor_actor.state_dict(),
                               "obs_norm": self.anchor_norm.state_dict()}
        return state

    def load_state_dict(self, state: dict[str, Any], weights_only: bool = False) -> None:
        """Restore a learner; ``weights_only`` restores just what inference needs."""
        self.net.load_state_dict(state["net"])
        self.sync_mirror()
        self.obs_norm.load_state_dict(state["obs_norm"])
        if weights_only:
            return
        self.load_training_state(state)
        if "anchor" in state:
            self.anchor_actor = copy.deepcopy(self.net.actor).requires_grad_(False)
            self.anchor_actor.load_state_dict(state["anchor"]["actor"])
            self.anchor_np = NumpyMLP(self.anchor_actor)
            self.anchor_norm = copy.deepcopy(self.obs_norm)
            self.anchor_norm.load_state_dict(state["anchor"]["obs_norm"])

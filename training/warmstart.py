"""Warm start: a team learner starts from a trained PPO learner (e.g. a 1v1 checkpoint).

Observation features are matched by name through both index maps
(:class:`~alphatank.game.observe.ObsLayout`). Other tanks are matched by role: the
source's teammates to the target's first teammate slots, its enemies to the target's
enemy slots (in a 1v1 ``tank[0]`` is the enemy; in a 2v1 it is ``tank[1]``, after the
teammate). The egocentric kinds map onto each other (``ORDER``); a feature one has and
the other lacks (the ``path_*`` fields, the shot and threat blocks) is new, or dropped. Kinds that
order other tanks differently (seat order against nearest first) map only from a source
with at most one teammate and one enemy: with one other tank the orders agree, and a 1v1
enemy lands on the nearest enemy's slot. Everything else
keeps its name (``self.x``, ``own_bullet[3].vx``, ``bullet[0].dist`` - the nearest other
bullet, ``wall[5].x0``, ...).

* First layer: matched input columns are copied; new inputs (teammate slots, team flags,
  the seat one-hot of MAPPO) start at zero; a source feature the target lacks (e.g. a
  wall slot of a map with more walls) is folded into the bias as the empty (all-zero)
  slot it would have been.
* Hidden and output layers are copied (the hidden sizes must agree).
* The observation normaliser's statistics are mapped the same way (new features: mean
  0, variance 1).
* The critic is copied for a PPO target (same inputs); a MAPPO critic reads the global
  state and predicts normalised values, so it starts fresh (see
  ``MAPPOConfig.critic_warmup_updates``).

So the warm-started actor gives the source's logits on any target observation, whatever
the new features hold (``tests/test_warmstart.py``).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np
import torch

from alphatank.game.observe import ObservationBuilder, ObsLayout, StateBatch
from alphatank.training.presets import TrainConfig

_TANK = re.compile(r"^tank\[(\d+)\]\.(.+)$")
# Other-tank order of the kinds that map onto each other (they differ in the path fields
# and the shot block, which map by name).
ORDER = {"egocentric": "seat", "egocentric_path": "seat", "egocentric_nearest": "nearest",
         "egocentric_aim": "nearest", "egocentric_aim_path": "nearest",
         "egocentric_full": "nearest"}


def _same_order(src: ObsLayout, src_mates: int, dst: ObsLayout) -> bool:
    """Whether two kinds' other-tank slots mean the same: the same order, or seat order
    against nearest first (e.g. ``egocentric`` and ``egocentric_nearest``) with at most one
    teammate and one enemy in the source (a 1v1 enemy is the nearest enemy)."""
    a, b = ORDER.get(src.kind), ORDER.get(dst.kind)
    if a is None or b is None:
        return False
    if a == b:
        return True
    slots = {int(m.group(1)) for m in map(_TANK.match, src.fields) if m}
    return src_mates <= 1 and len(slots) - src_mates <= 1


def feature_map(src: ObsLayout, dst: ObsLayout, src_mates: int = 0, dst_mates: int = 0
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(src_idx, dst_idx, dropped): source feature ``src_idx[i]`` feeds target feature
    ``dst_idx[i]``; ``dropped`` source features have no target. ``*_mates``: how many of
    each layout's ``tank[k]`` slots are teammates (they come first)."""
    if src.kind != dst.kind and not _same_order(src, src_mates, dst):
        raise ValueError(f"cannot map a {src.kind!r} observation onto a {dst.kind!r} one"
                         + (" (other tanks in seat order against nearest first: only a "
                            "source with at most one teammate and one enemy maps)"
                            if src.kind in ORDER and dst.kind in ORDER else ""))
    si, di, dropped = [], [], []
    for k, name in enumerate(src.fields):
        target = name
        m = _TANK.match(name)
        if m:
            slot = int(m.group(1))
            slot = slot if slot < src_mates else slot - src_mates + dst_mates
            if int(m.group(1)) < src_mates and slot >= dst_mates:
                slot = -1  # a source teammate the target has no teammate slot for
            target = f"tank[{slot}].{m.group(2)}"
        if target in dst.index:
            si.append(k)
            di.append(dst[target].start)
        else:
            dropped.append(k)
    return (np.array(si, dtype=np.int64), np.array(di, dtype=np.int64),
            np.array(dropped, dtype=np.int64))


def _first_layer(weight: torch.Tensor, bias: torch.Tensor, si: np.ndarray, di: np.ndarray,
                 dropped: np.ndarray, zero_norm: np.ndarray, width: int
                 ) -> tuple[torch.Tensor, torch.Tensor]:
    w = torch.zeros((weight.shape[0], width), dtype=weight.dtype)
    w[:, torch.from_numpy(di)] = weight[:, torch.from_numpy(si)]
    fold = weight[:, torch.from_numpy(dropped)] @ torch.from_numpy(
        zero_norm[dropped]).to(weight.dtype)
    return w, bias + fold


def _copy_mlp(dst: torch.nn.Sequential, prefix: str, net: dict[str, torch.Tensor],
              si: np.ndarray, di: np.ndarray, dropped: np.ndarray, zero_norm: np.ndarray
              ) -> None:
    src_hidden = net[f"{prefix}.0.weight"].shape[0]
    if src_hidden != dst[0].out_features:
        raise ValueError(f"warm start needs the same hidden size: source {src_hidden}, "
                         f"target {dst[0].out_features} (set hidden={src_hidden})")
    w, b = _first_layer(net[f"{prefix}.0.weight"], net[f"{prefix}.0.bias"], si, di, dropped,
                        zero_norm, dst[0].in_features)
    with torch.no_grad():
        dst[0].weight.copy_(w)
        dst[0].bias.copy_(b)
        for k in (2, 4):
            dst[k].weight.copy_(net[f"{prefix}.{k}.weight"])
            dst[k].bias.copy_(net[f"{prefix}.{k}.bias"])


WARM_STARTED = ("ppo", "mappo")  # the algorithms a warm start can fill


def check_init_from(cfg: TrainConfig, label: str) -> None:
    """ValueError ``label: problem`` unless the run's ``init_from`` names a checkpoint to
    warm-start from and the run has a learner that a warm start fills."""
    from alphatank.game.seats import checkpoint_source
    from alphatank.training.checkpoint import CheckpointError, resolve_checkpoint_dir

    try:
        resolve_checkpoint_dir(checkpoint_source(cfg.init_from))
    except (CheckpointError, ValueError) as exc:
        raise ValueError(f"{label}: {exc}") from None
    if not any(s.algo in WARM_STARTED for s in cfg.learners):
        raise ValueError(f"{label}: a warm start fills "
                         f"{' and '.join(a.upper() for a in WARM_STARTED)} learners; this "
                         f"run's {[(s.name, s.algo) for s in cfg.learners]} take none")


def warm_start(learner: Any, src_state: dict[str, Any], src_layout: ObsLayout,
               dst_layout: ObsLayout, src_mates: int = 0, dst_mates: int = 0
               ) -> dict[str, int]:
    """Load a PPO learner's ``state_dict`` (``src_state``, observations ``src_layout``)
    into ``learner`` (a fresh PPO or MAPPO learner over ``dst_layout``). Returns counts:
    mapped, new and dropped features, and whether the critic was copied."""
    if getattr(learner, "algo", None) not in WARM_STARTED:
        raise ValueError(f"warm start fills {' and '.join(a.upper() for a in WARM_STARTED)} "
                         f"learners, not {getattr(learner, 'algo', type(learner).__name__)}")
    if learner.obs_dim != dst_layout.size:
        raise ValueError(f"learner has obs_dim {learner.obs_dim}, the target layout "
                         f"{dst_layout.size}")
    norm = src_state["obs_norm"]
    mean = norm["mean"].numpy().astype(np.float64)
    var = norm["var"].numpy().astype(np.float64)
    if mean.shape != (src_layout.size,):
        raise ValueError(f"source normaliser has {mean.shape[0]} features, its layout "
                         f"{src_layout.size}")
    si, di, dropped = feature_map(src_layout, dst_layout, src_mates, dst_mates)
    enabled, clip = bool(norm["enabled"]), float(norm["clip"])
    eps = learner.obs_norm.epsilon
    zero_norm = (np.clip(-mean / np.sqrt(var + eps), -clip, clip) if enabled
                 else np.zeros_like(mean))
    net = src_state["net"]
    is_mappo = getattr(learner, "algo", "") == "mappo"
    _copy_mlp(learner.net.actor, "actor", net, si, di, dropped, zero_norm)
    if not is_mappo:
        _copy_mlp(learner.net.critic, "critic", net, si, di, dropped, zero_norm)
    d_mean = np.zeros(dst_layout.size)
    d_var = np.ones(dst_layout.size)
    d_mean[di], d_var[di] = mean[si], var[si]
    learner.obs_norm.load_state_dict({
        "mean": torch.from_numpy(d_mean), "var": torch.from_numpy(d_var),
        "count": norm["count"].clone(), "enabled": torch.tensor(enabled),
        "clip": torch.tensor(clip, dtype=torch.float64)})
    learner.sync_mirror()
    return {"mapped": int(si.size), "new": int(dst_layout.size - si.size),
            "dropped": int(dropped.size), "critic": int(not is_mappo)}


def checkpoint_layout(ckpt: Any, learner: str) -> tuple[ObsLayout, int]:
    """The observation layout a checkpoint's ``learner`` was trained on, and how many of
    its ``tank[k]`` slots are teammates."""
    meta = ckpt.meta["observation"]
    seats = [int(s) for s, name in meta["seat_learner"].items() if name == learner]
    if not seats:
        raise ValueError(f"{ckpt.path}: learner {learner!r} drives no seat")
    sc = ckpt.scenario
    game = sc.game_config(**ckpt.train_config.game)
    batch = StateBatch(game, int(meta["tanks"]), 1, int(meta["max_walls"]),
                       int(meta["max_buffs"]), int(meta["max_debuffs"]))
    builder = ObservationBuilder(meta["kind"], batch, sc.teams, [seats[0]],
                                 team_flags=bool(meta["team_flags"]))
    if builder.layout.size != int(meta["obs_dim"]):
        raise ValueError(f"{ckpt.path}: rebuilt layout has {builder.layout.size} features, "
                         f"the checkpoint says {meta['obs_dim']}")
    return builder.layout, int(builder.other_team[0].sum())


def warm_start_from_checkpoint(learner: Any, path: str | Path, dst_layout: ObsLayout,
                               dst_mates: int) -> dict[str, int]:
    """:func:`warm_start` from the first PPO learner of the checkpoint (or run directory's
    latest) at ``path`` (e.g. the PPO side of a SAC vs PPO run)."""
    from alphatank.training.checkpoint import load_checkpoint

    ckpt = load_checkpoint(path)
    name = next((s.name for s in ckpt.learner_specs if s.algo == "ppo"), None)
    if name is None:
        raise ValueError(f"{ckpt.path}: no PPO learner to warm-start from; its learners: "
                         f"{[(s.name, s.algo) for s in ckpt.learner_specs]}")
    # A file that does not fit its own saved config is damaged: its error names the tensor
    # and both shapes (a hidden-size mismatch found below is then a real one).
    ckpt.load_learner(name, weights_only=True)
    layout, mates = checkpoint_layout(ckpt, name)
    return warm_start(learner, ckpt.state(name), layout, dst_layout, mates, dst_mates)

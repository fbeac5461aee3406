"""The Learner protocol (everything the runner, evaluation and checkpoints use of a
learner) and the factory that builds one from a :class:`LearnerSpec` via the algorithm
table.

A learner drives ``num_streams`` = num_envs x its seats (env, seat) streams. Per vector
step the runner calls :meth:`Learner.act`, steps the env, calls :meth:`Learner.observe`,
and :meth:`Learner.update` whenever :attr:`Learner.ready`. Arrays are per stream: row
``e * k + j`` is env ``e``, the learner's ``j``-th seat.

Extra inputs. A learner that needs more than its observations per stream (a centralised
critic's state, alive masks, ...) lists their names in its class attribute ``inputs``.
For each name ``x`` the vector env supplies ``x`` (it has a method ``input_x()``
returning (num_envs, num_learner_seats, ...) for the current step; see
:class:`alphatank.envs.vector.VectorMatchEnv`), and the runner passes, as keywords:

* to the constructor: ``x_dim`` (features per stream, 1 for a scalar),
* to ``act``: ``x`` (rows for the observations being acted on),
* to ``observe``: ``x`` (rows for ``next_obs``) and ``final_x`` (rows of streams whose
  episode ended this step, taken before the env reset them; other rows are 0),
* to ``update``: ``x`` (rows for ``next_obs``).

The runner never asks for the algorithm: rollout length, learning-rate planning,
per-segment resets and extra checkpoint arrays are all methods below.

Stopping. While a run trains, the runner sets ``learner.interrupt`` to a zero-argument
callable that turns True when the run must stop (SIGINT, SIGTERM, time limit), and
resets it to None afterwards. Long updates poll it between gradient steps:

* a learner with a fixed rollout (:attr:`Learner.rollout_steps`) raises
  :class:`alphatank.training.stopping.StopRequested`; the runner saves its state from
  before the rollout (its buffers are empty at iteration boundaries, so
  :meth:`Learner.state_dict` is complete there) and the run collects it again;
* a learner without one returns early with its state whole after each gradient step
  (its state dict and arrays are complete after any :meth:`Learner.observe`), keeping
  the steps it still owes for its next update.
"""

from __future__ import annotations

from typing import Any, ClassVar, Protocol

import numpy as np

from alphatank.training.algorithms import get_algorithm


class Learner(Protocol):
    """What PPO, SAC and MAPPO provide (see :class:`alphatank.training.ppo.PPO`)."""

    algo: ClassVar[str]  # its name in the algorithm table
    inputs: ClassVar[tuple[str, ...]]  # extra per-stream inputs from the env (see above)
    # The state_dict entries that load_state_dict(weights_only=True) reads (inference,
    # warm starts); the rest (optimisers, target networks, generators, ...) only resumes.
    inference_keys: ClassVar[tuple[str, ...]]
    obs_dim: int
    num_streams: int
    updates: int  # updates done so far (saved in state_dict)
    interrupt: Any  # None, or set by the runner: () -> bool, True once the run must stop

    def __init__(self, obs_dim: int, num_streams: int, cfg: Any = None, seed: int = 0,
                 mask_dim: int = 0, num_seats: int = 1, **input_dims: int) -> None:
        """``cfg``: the algorithm's config dataclass; ``mask_dim`` > 0: ``act`` gets
        boolean action masks of that width (may be ignored); ``num_seats``: the learner
        seats it drives (``num_streams`` = envs x seats, env-major: stream ``i`` is seat
        ``i % num_seats``); ``x_dim`` per input."""

    @property
    def rollout_steps(self) -> int | None:
        """Vector steps between this learner's updates when it wants a fixed rollout
        (the runner's iteration is a multiple of it), else None."""

    def plan(self, total_steps: int) -> None:
        """The run will call :meth:`observe` ``total_steps`` times in all (e.g. to anneal
        the learning rate to zero); called before training and again on resume, inside
        the run's ``memory_budget`` (SAC makes its replay buffer here: a learner loaded
        for inference is never planned and needs none)."""

    def new_segment(self) -> None:
        """Every stream restarts from a fresh episode (after a checkpoint): forget
        per-episode running statistics such as discounted returns."""

    def anchor(self) -> None:
        """RL starts now from a warm start (after ``imitate``, or from ``init_from``): keep
        what it needs of the policy as it stands (PPO's ``anchor_kl``); may do nothing."""

    def drop_rollout(self) -> None:
        """Forget the unfinished rollout (a fixed-rollout learner; the runner then loads
        the state from the rollout's start): its matches were lost (an env runner died)."""

    def act(self, obs: np.ndarray, masks: np.ndarray | None = None,
            **inputs: np.ndarray) -> np.ndarray:
        """Actions (num_streams, 3) int64 for raw observations (num_streams, obs_dim)."""

    def observe(self, next_obs: np.ndarray, rewards: np.ndarray, terminated: np.ndarray,
                truncated: np.ndarray, final_obs: np.ndarray | None = None,
                active: np.ndarray | None = None, **inputs: np.ndarray) -> None:
        """Outcome of the last :meth:`act`: rewards and flags (num_streams,), the final
        observations of ended streams (rows of ``final_obs``), and ``active`` (False
        where the stream's action had no effect, e.g. a dead tank)."""

    @property
    def ready(self) -> bool:
        """True when :meth:`update` should run now."""

    def update(self, next_obs: np.ndarray, **inputs: np.ndarray) -> dict[str, float]:
        """Learn; returns metrics (``losses/*``, ``charts/*``)."""

    def policy_actions(self, obs: np.ndarray, deterministic: bool = False,
                       rng: np.random.Generator | None = None) -> np.ndarray:
        """Actions for raw observations (B, obs_dim) with frozen statistics and no
        recording (evaluation, videos, checkpoints as policies). A learner that tells its
        seats apart (MAPPO's seat one-hot) has a ``num_seats`` attribute and also takes
        ``seat=`` (each row's seat id; default: rows are (env, seat) pairs, env-major)."""

    def state_dict(self) -> dict[str, Any]:
        """Everything to resume exactly, as tensors and plain values
        (``torch.load(weights_only=True)``-safe)."""

    def load_state_dict(self, state: dict[str, Any], weights_only: bool = False) -> None:
        """Restore :meth:`state_dict`; ``weights_only`` restores what inference needs."""

    def arrays(self) -> dict[str, np.ndarray]:
        """Extra numpy arrays to checkpoint (SAC: the replay buffer); {} if none."""

    def load_arrays(self, arrays: dict[str, np.ndarray]) -> None:
        """Restore :meth:`arrays`."""


def learner_class(algo: str) -> Any:
    """The learner class registered for ``algo``."""
    return get_algorithm(algo).learner_class()


def inference_state(algo: str, state: dict[str, Any]) -> dict[str, Any]:
    """The entries of an ``algo`` learner's ``state_dict`` that inference and warm starts
    read (its class's ``inference_keys``): no optimiser, target network, generator,
    reward scaling or counter states."""
    keys = learner_class(algo).inference_keys
    return {k: v for k, v in state.items() if k in keys}


def make_learner(spec: Any, obs_dim: int, num_streams: int, seed: int, mask_dim: int = 0,
                 input_dims: dict[str, int] | None = None) -> Learner:
    """A fresh learner of ``spec`` (a :class:`LearnerSpec`) for ``num_streams`` streams;
    ``input_dims`` gives the width of each extra input the learner class names."""
    cls = learner_class(spec.algo)
    dims = input_dims or {}
    missing = [x for x in cls.inputs if x not in dims]
    if missing:
        raise ValueError(f"learner {spec.name!r} ({spec.algo}) needs inputs {missing}")
    return cls(obs_dim, num_streams, spec.config, seed=seed, mask_dim=mask_dim,
               num_seats=len(spec.seats), **{f"{x}_dim": int(dims[x]) for x in cls.inputs})

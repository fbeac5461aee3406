"""The one interface every seat controller implements: bots, checkpoints, human keys;
and the idle seat."""

from __future__ import annotations

from collections.abc import Callable, Hashable, Sequence
from typing import TYPE_CHECKING, Protocol, runtime_checkable

import numpy as np

if TYPE_CHECKING:
    from alphatank.sim.match import Match


@runtime_checkable
class Policy(Protocol):
    """Chooses one seat's action each tick from a read-only view of the match.

    ``act`` returns an int array of shape (3,): rotate {0 ccw, 1 none, 2 cw},
    move {0 back, 1 stop, 2 forward}, fire {0, 1}; it may be a shared read-only array
    (:data:`ACTIONS`), so copy it before changing it. ``reset`` is called at the start of
    every episode with a seed derived from the episode's seed.
    """

    def reset(self, match: Match, seat: int, seed: int | None = None) -> None: ...

    def act(self, match: Match, seat: int) -> np.ndarray: ...


# observe(setting, obs_dim, rows): the (len(rows), obs_dim) observations of those pairs of
# an act_batch call in an observation setting, or None where the caller cannot build them
Observe = Callable[[Hashable, int, np.ndarray], "np.ndarray | None"]


@runtime_checkable
class BatchPolicy(Policy, Protocol):
    """A Policy that can also act for many (match, seat) pairs in one call (one batched
    observation and forward pass for a network). ``act_batch`` returns the (k, 3) actions
    that ``act`` would return for each pair, whatever the other pairs of the call.
    ``observe``, when given, offers observations the caller already keeps (an env's
    :class:`~alphatank.game.observe.StateBatch`), built once for every policy that
    observes the same way."""

    def act_batch(self, pairs: Sequence[tuple[Match, int]],
                  observe: Observe | None = None) -> np.ndarray: ...


_BATCH_TYPES: dict[type, bool] = {}


def is_batch_policy(policy: Policy) -> bool:
    """``isinstance(policy, BatchPolicy)``, answered once per class: a runtime Protocol
    check costs tens of microseconds, and an env asks it for every seat at every reset."""
    kind = type(policy)
    known = _BATCH_TYPES.get(kind)
    if known is None:
        known = _BATCH_TYPES[kind] = isinstance(policy, BatchPolicy)
    return known


def _shared(rotate: int, move: int, fire: int) -> np.ndarray:
    a = np.array((rotate, move, fire), dtype=np.int64)
    a.setflags(write=False)
    return a


NOOP = _shared(1, 1, 0)
# ``ACTIONS[6 * rotate + 2 * move + fire]``: every action as one shared read-only array,
# so a controller returns its choice without allocating one per tick.
ACTIONS: tuple[np.ndarray, ...] = tuple(_shared(r, m, f) for r in range(3) for m in range(3)
                                        for f in range(2))


class NoopPolicy:
    """A seat that does nothing (a human seat with no keyboard attached)."""

    def reset(self, match: Match, seat: int, seed: int | None = None) -> None:
        return None

    def act(self, match: Match, seat: int) -> np.ndarray:
        return NOOP

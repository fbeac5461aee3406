"""Keyboard seats: a Policy driven by a human's keys (the paper's Table 5/6 bindings).

Player 1 ``wasd``: W forward, S back, A turn left, D turn right, F fire.
Player 2 ``arrows``: Up, Down, Left, Right, Space. Player 3 ``ijkl``: I, K, J, L, P.

Held keys are tracked from KEYDOWN/KEYUP events passed to :meth:`KeyboardPolicy.handle_event`
(``pygame.key.get_pressed`` is not used: it misses posted events, e.g. with SDL's dummy
driver, and keeps stale state across focus changes). A fire key pressed and released
between two ticks still fires once.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from alphatank.game.seats import KEYSETS

os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
import pygame  # noqa: E402

if TYPE_CHECKING:
    from alphatank.sim.match import Match


@dataclass(frozen=True)
class KeyLayout:
    forward: int
    back: int
    left: int
    right: int
    fire: int

    @property
    def keys(self) -> tuple[int, ...]:
        return (self.forward, self.back, self.left, self.right, self.fire)

    def describe(self) -> str:
        names = [pygame.key.name(k).upper() for k in self.keys]
        return f"{names[0]}/{names[1]} drive, {names[2]}/{names[3]} turn, {names[4]} fire"


LAYOUTS: dict[str, KeyLayout] = {
    "wasd": KeyLayout(pygame.K_w, pygame.K_s, pygame.K_a, pygame.K_d, pygame.K_f),
    "arrows": KeyLayout(pygame.K_UP, pygame.K_DOWN, pygame.K_LEFT, pygame.K_RIGHT,
                        pygame.K_SPACE),
    "ijkl": KeyLayout(pygame.K_i, pygame.K_k, pygame.K_j, pygame.K_l, pygame.K_p),
}
HUMAN_ORDER = KEYSETS  # players 1, 2, 3


class KeyboardPolicy:
    """A human seat. Feed it every pygame event; ``act`` maps held keys to an action.

    Rotate: left = counter-clockwise (0), right = clockwise (2), both or neither = 1.
    Move: forward = 2, back = 0, both or neither = 1. Fire while the fire key is held, or
    once for a tap since the last tick.
    """

    def __init__(self, keys: str = "wasd"):
        if keys not in LAYOUTS:
            raise ValueError(f"unknown key layout {keys!r}; valid: {list(LAYOUTS)}")
        self.keys = keys
        self.layout = LAYOUTS[keys]
        self._held: set[int] = set()
        self._tapped = False
        self._action = np.array([1, 1, 0], dtype=np.int64)

    def __repr__(self) -> str:
        return f"KeyboardPolicy({self.keys!r})"

    def owns(self, key: int) -> bool:
        """True if ``key`` is one of this seat's keys."""
        return key in self.layout.keys

    def handle_event(self, event: pygame.event.Event) -> bool:
        """Update held keys from one event; True if the event was one of this seat's keys."""
        if event.type in (pygame.WINDOWFOCUSLOST, pygame.WINDOWMINIMIZED):
            self.release_all()
            return False
        if event.type not in (pygame.KEYDOWN, pygame.KEYUP) or not self.owns(event.key):
            return False
        if event.type == pygame.KEYDOWN:
            self._held.add(event.key)
            if event.key == self.layout.fire:
                self._tapped = True
        else:
            self._held.discard(event.key)
        return True

    def release_all(self) -> None:
        self._held.clear()
        self._tapped = False

    def reset(self, match: Match, seat: int, seed: int | None = None) -> None:
        self._tapped = False

    def act(self, match: Match, seat: int) -> np.ndarray:
        held, lay, a = self._held, self.layout, self._action
        a[0] = 1 + (lay.right in held) - (lay.left in held)
        a[1] = 1 + (lay.forward in held) - (lay.back in held)
        a[2] = int(self._tapped or lay.fire in held)
        self._tapped = False
        return a.copy()


def keyboard_seat(seat: Any, seed: int | None = None) -> KeyboardPolicy:
    """The controller of a ``human`` seat with a keyboard attached (the line-up's "human"
    kind; without a keyboard the seat idles)."""
    return KeyboardPolicy(seat.keys or HUMAN_ORDER[0])

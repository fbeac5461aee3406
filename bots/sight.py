"""The wall queries bots make every tick, answered by the very chipmunk calls the world's
queries make, without pymunk's Python wrappers (3-5x cheaper, bit-identical answers).

``WallSight(world)`` collects the world's wall shapes once (their bounding boxes and
chipmunk pointers); then

* :meth:`WallSight.clear` is ``space.segment_query_first(a, b, r, WALLS_ONLY) is None``
  (one ``cpSpaceSegmentQueryFirst``: the quick aiming test of :meth:`Bot.clear`);
* :meth:`WallSight.ray_clear` is ``world.ray(a, b, r) is None``
  (:func:`alphatank.sim.world.first_wall_hit`: the walls whose bounding box meets the
  segment's box grown by ``r``, each asked ``cpShapeSegmentQuery``; the exact test of
  driving legs).

:func:`wall_sight` shares one per world (weakly cached). A WallSight holds chipmunk
pointers: it lives with its world and is never pickled (bots drop it, see
:meth:`Bot.__getstate__`). ``tests/test_bots.py`` checks both answers against pymunk's
public API on random segments.
"""

from __future__ import annotations

import weakref

import pymunk
from pymunk._chipmunk import ffi, lib

from alphatank.sim.world import WALLS_ONLY, World

_EVERYWHERE = pymunk.BB(-1e300, -1e300, 1e300, 1e300)
_cache: weakref.WeakKeyDictionary[World, WallSight] = weakref.WeakKeyDictionary()


def wall_sight(world: World) -> WallSight:
    """The (cached) WallSight of ``world``."""
    sight = _cache.get(world)
    if sight is None:
        sight = _cache[world] = WallSight(world)
    return sight


class WallSight:
    """Fast, exact wall queries on one world (see the module docstring)."""

    def __init__(self, world: World):
        self.world = world
        space = world.space
        self._space = space._space
        self._walls = []
        for shape in space.bb_query(_EVERYWHERE, WALLS_ONLY):
            ptr = shape._shape
            bb = lib.cpShapeGetBB(ptr)
            self._walls.append((bb.l, bb.b, bb.r, bb.t, ptr))
        self._filter = ffi.new("cpShapeFilter *", tuple(WALLS_ONLY))[0]
        self._info = ffi.new("cpSegmentQueryInfo *")
        self._null = ffi.NULL

    def clear(self, x0: float, y0: float, x1: float, y1: float, radius: float) -> bool:
        """``space.segment_query_first((x0, y0), (x1, y1), radius, WALLS_ONLY) is None``."""
        return lib.cpSpaceSegmentQueryFirst(self._space, (x0, y0), (x1, y1), radius,
                                            self._filter, self._info) == self._null

    def ray_clear(self, x0: float, y0: float, x1: float, y1: float, radius: float) -> bool:
        """``world.ray((x0, y0), (x1, y1), radius) is None``: no wall whose box meets the
        grown segment box (``cpBBIntersects``) touches the swept circle."""
        left, right = (x0, x1) if x0 <= x1 else (x1, x0)
        bottom, top = (y0, y1) if y0 <= y1 else (y1, y0)
        left, bottom, right, top = left - radius, bottom - radius, right + radius, top + radius
        query, info = lib.cpShapeSegmentQuery, self._info
        a = b = None
        for wl, wb, wr, wt, shape in self._walls:
            if wl <= right and left <= wr and wb <= top and bottom <= wt:
                if a is None:
                    a, b = (x0, y0), (x1, y1)
                if query(shape, a, b, radius, info):
                    return False
        return True

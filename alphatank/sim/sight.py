"""The wall queries bots make every tick, answered by the very chipmunk calls pymunk's
queries make, without pymunk's Python wrappers: 3-5x cheaper, bit-identical answers.

``WallSight(world)`` holds the world's chipmunk space and, per radius asked, a query-only
space of the map's walls rounded by that radius (one per map and radius, shared with the
worlds: :func:`alphatank.sim.world.shared_rounded_walls`); then

* :meth:`WallSight.clear` is ``space.segment_query_first(a, b, r, WALLS_ONLY) is None``
  (one ``cpSpaceSegmentQueryFirst``: the bots' quick aiming test);
* :meth:`WallSight.ray_clear` is ``first_wall_hit(space, a, b, r) is None``
  (:func:`alphatank.sim.world.first_wall_hit`, the exact test of driving legs) as one
  thin ``cpSpaceSegmentQueryFirst`` against the walls rounded by ``r``: chipmunk adds a
  poly's and a query's radii, so each wall answers as the swept circle against the sharp
  wall does, and a rounded wall's bounding box holds every point the circle can touch
  (the world's ``bullet_walls`` use the same construction).

:func:`wall_sight` shares one per world (kept on the world). A WallSight holds chipmunk
pointers: it lives with its world and is never pickled (bots drop theirs).
``tests/test_bots.py`` checks both answers against pymunk's public API on random
segments, corners grazed included.
"""

from __future__ import annotations

from typing import Any

import pymunk
from pymunk._chipmunk import ffi, lib

from alphatank.sim.world import WALLS_ONLY, World, shared_rounded_walls


def wall_sight(world: World) -> WallSight:
    """The WallSight of ``world``, built once and kept on the world, so it is freed with
    it (a module-level cache keyed weakly by the world kept every world alive: the sight
    refers to its world)."""
    sight = world.sight_cache
    if sight is None:
        sight = world.sight_cache = WallSight(world)
    return sight


class WallSight:
    """Fast, exact wall queries on one world (see the module docstring)."""

    def __init__(self, world: World):
        self.world = world
        self._space = world.space._space
        self._rounded: dict[float, tuple[pymunk.Space, Any]] = {}  # radius: space, pointer
        self._filter = ffi.new("cpShapeFilter *", tuple(WALLS_ONLY))[0]
        self._any = ffi.new("cpShapeFilter *", tuple(pymunk.ShapeFilter()))[0]
        self._seg = ffi.new("cpSegmentQueryInfo *")
        self._null = ffi.NULL

    def _walls_rounded(self, radius: float) -> Any:
        """Chipmunk pointer of the walls rounded by ``radius``: one query-only space per
        map and radius, shared by every world on the map (the sight keeps its own
        reference, so the space lives as long as the world)."""
        got = self._rounded.get(radius)
        if got is None:
            space = shared_rounded_walls(self.world.spec, radius)
            got = self._rounded[radius] = (space, space._space)
        return got[1]

    def clear(self, x0: float, y0: float, x1: float, y1: float, radius: float) -> bool:
        """``space.segment_query_first((x0, y0), (x1, y1), radius, WALLS_ONLY) is None``."""
        return lib.cpSpaceSegmentQueryFirst(self._space, (x0, y0), (x1, y1), radius,
                                            self._filter, self._seg) == self._null

    def ray_clear(self, x0: float, y0: float, x1: float, y1: float, radius: float) -> bool:
        """``first_wall_hit(space, x0, y0, x1, y1, radius) is None``."""
        return lib.cpSpaceSegmentQueryFirst(self._walls_rounded(radius), (x0, y0), (x1, y1),
                                            0.0, self._any, self._seg) == self._null

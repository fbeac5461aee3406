"""The wall queries bots make every tick, answered by the very chipmunk calls pymunk's
queries make, without pymunk's Python wrappers: 3-5x cheaper, bit-identical answers.

``WallSight(world)`` collects the world's wall shapes once (bounding boxes, chipmunk
pointers, grid bands); then

* :meth:`WallSight.clear` is ``space.segment_query_first(a, b, r, WALLS_ONLY) is None``
  (one ``cpSpaceSegmentQueryFirst``: the bots' quick aiming test);
* :meth:`WallSight.ray_clear` is ``first_wall_hit(space, a, b, r) is None``
  (:func:`alphatank.sim.world.first_wall_hit`: no wall whose bounding box meets the
  segment's box grown by ``r`` (``cpBBIntersects``) is touched by ``cpShapeSegmentQuery``;
  the exact test of driving legs). The box test runs over the walls of the grid bands the
  box covers (a superset, cached per band range), not over every wall.

:func:`wall_sight` shares one per world (weakly cached). A WallSight holds chipmunk
pointers: it lives with its world and is never pickled (bots drop theirs).
``tests/test_bots.py`` checks both answers against pymunk's public API on random
segments.
"""

from __future__ import annotations

import pymunk
from pymunk._chipmunk import ffi, lib

from alphatank.sim.world import WALLS_ONLY, World

_EVERYWHERE = pymunk.BB(-1e300, -1e300, 1e300, 1e300)


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
        space = world.space
        self._space = space._space
        # (left, bottom, right, top, chipmunk pointer) of every wall.
        self._walls = []
        for shape in space.bb_query(_EVERYWHERE, WALLS_ONLY):
            ptr = shape._shape
            bb = lib.cpShapeGetBB(ptr)
            self._walls.append((bb.l, bb.b, bb.r, bb.t, ptr))
        # Grid bands (int(v / cell): monotone, so band ranges of boxes that meet overlap).
        self._inv = inv = 1.0 / float(world.spec.cell)
        self._bands = [(int(wb * inv), int(wt * inv), int(wl * inv), int(wr * inv))
                       for wl, wb, wr, wt, _ in self._walls]
        self._near: dict[tuple[int, int, int, int], list] = {}
        self._filter = ffi.new("cpShapeFilter *", tuple(WALLS_ONLY))[0]
        self._seg = ffi.new("cpSegmentQueryInfo *")
        self._null = ffi.NULL

    def _candidates(self, x0: float, y0: float, x1: float, y1: float, radius: float
                    ) -> list:
        """Walls whose box meets first_wall_hit's query box, ``min(x0, x1) - radius`` ..
        ``max(y0, y1) + radius`` (cpBBIntersects)."""
        if x0 <= x1:
            left, right = x0 - radius, x1 + radius
        else:
            left, right = x1 - radius, x0 + radius
        if y0 <= y1:
            bottom, top = y0 - radius, y1 + radius
        else:
            bottom, top = y1 - radius, y0 + radius
        inv = self._inv
        key = (int(bottom * inv), int(top * inv), int(left * inv), int(right * inv))
        near = self._near.get(key)
        if near is None:  # walls sharing a band with the box in both axes: a superset
            r0, r1, c0, c1 = key
            near = self._near[key] = [w for w, (b0, b1, a0, a1) in zip(self._walls, self._bands,
                                                                       strict=True)
                                      if b0 <= r1 and r0 <= b1 and a0 <= c1 and c0 <= a1]
        if not near:
            return near
        return [w for w in near
                if w[0] <= right and left <= w[2] and w[1] <= top and bottom <= w[3]]

    def clear(self, x0: float, y0: float, x1: float, y1: float, radius: float) -> bool:
        """``space.segment_query_first((x0, y0), (x1, y1), radius, WALLS_ONLY) is None``."""
        return lib.cpSpaceSegmentQueryFirst(self._space, (x0, y0), (x1, y1), radius,
                                            self._filter, self._seg) == self._null

    def ray_clear(self, x0: float, y0: float, x1: float, y1: float, radius: float) -> bool:
        """``first_wall_hit(space, x0, y0, x1, y1, radius) is None``."""
        walls = self._candidates(x0, y0, x1, y1, radius)
        if walls:
            query, info, a, b = lib.cpShapeSegmentQuery, self._seg, (x0, y0), (x1, y1)
            for w in walls:
                if query(w[4], a, b, radius, info):
                    return False
        return True

"""Wall queries answered by the very chipmunk calls the world's queries make, without
pymunk's Python wrappers: 3-5x cheaper, bit-identical answers. Bots ask them every
tick; :func:`alphatank.sim.ballistics.predict_path` (bots' ricochet aim, the trajectory
rewards) traces through them.

``WallSight(world)`` collects the world's wall shapes once (bounding boxes, chipmunk
pointers, grid bands); then

* :meth:`WallSight.clear` is ``space.segment_query_first(a, b, r, WALLS_ONLY) is None``
  (one ``cpSpaceSegmentQueryFirst``: the bots' quick aiming test);
* :meth:`WallSight.first_hit` is :func:`alphatank.sim.world.first_wall_hit`: among the
  walls whose bounding box meets the segment's box grown by ``r`` (``cpBBIntersects``)
  and not in ``skip``, the one ``cpShapeSegmentQuery`` reaches first. When two walls tie
  for first it asks ``first_wall_hit`` itself, whose tie-break is pymunk's query order;
* :meth:`WallSight.ray_clear` is ``world.ray(a, b, r) is None`` (the exact test of
  driving legs);
* :meth:`WallSight.inside` is predict_path's muzzle test, ``point_query_nearest``.

The box tests run over the walls of the grid bands a box covers (a superset, cached per
band range), not over every wall. :func:`wall_sight` shares one per world (weakly
cached). A WallSight holds chipmunk pointers: it lives with its world and is never
pickled (bots drop theirs). ``tests/test_bots.py`` checks every answer against pymunk's
public API on random segments.
"""

from __future__ import annotations

import weakref
from collections.abc import Sequence
from typing import NamedTuple

import pymunk
from pymunk._chipmunk import ffi, lib

from alphatank.sim.world import WALLS_ONLY, World, first_wall_hit

_EVERYWHERE = pymunk.BB(-1e300, -1e300, 1e300, 1e300)
_cache: weakref.WeakKeyDictionary[World, WallSight] = weakref.WeakKeyDictionary()


def wall_sight(world: World) -> WallSight:
    """The (cached) WallSight of ``world``."""
    sight = _cache.get(world)
    if sight is None:
        sight = _cache[world] = WallSight(world)
    return sight


class WallHit(NamedTuple):
    """What :func:`alphatank.sim.world.trace` reads of a pymunk ``SegmentQueryInfo``."""

    shape: pymunk.Shape
    normal: tuple[float, float]
    alpha: float


class WallSight:
    """Fast, exact wall queries on one world (see the module docstring)."""

    def __init__(self, world: World):
        self.world = world
        space = world.space
        self._space = space._space
        # (left, bottom, right, top, chipmunk pointer, Shape) of every wall.
        self._walls = []
        for shape in space.bb_query(_EVERYWHERE, WALLS_ONLY):
            ptr = shape._shape
            bb = lib.cpShapeGetBB(ptr)
            self._walls.append((bb.l, bb.b, bb.r, bb.t, ptr, shape))
        # Grid bands (int(v / cell): monotone, so band ranges of boxes that meet overlap).
        self._inv = inv = 1.0 / float(world.spec.cell)
        self._bands = [(int(wb * inv), int(wt * inv), int(wl * inv), int(wr * inv))
                       for wl, wb, wr, wt, _, _ in self._walls]
        self._near: dict[tuple[int, int, int, int], list] = {}
        self._filter = ffi.new("cpShapeFilter *", tuple(WALLS_ONLY))[0]
        self._seg = ffi.new("cpSegmentQueryInfo *")
        self._point = ffi.new("cpPointQueryInfo *")
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
        """``world.ray((x0, y0), (x1, y1), radius) is None``."""
        walls = self._candidates(x0, y0, x1, y1, radius)
        if walls:
            query, info, a, b = lib.cpShapeSegmentQuery, self._seg, (x0, y0), (x1, y1)
            for w in walls:
                if query(w[4], a, b, radius, info):
                    return False
        return True

    def first_hit(self, space: pymunk.Space, x0: float, y0: float, x1: float, y1: float,
                  radius: float, skip: Sequence[pymunk.Shape] = ()
                  ) -> WallHit | pymunk.SegmentQueryInfo | None:
        """``first_wall_hit(space, x0, y0, x1, y1, radius, skip)`` (``space`` must be this
        world's): a :func:`alphatank.sim.world.trace` query."""
        walls = self._candidates(x0, y0, x1, y1, radius)
        if not walls:
            return None
        query, info, a, b = lib.cpShapeSegmentQuery, self._seg, (x0, y0), (x1, y1)
        best = None
        alpha = tie = 0.0
        for w in walls:
            if skip and w[5] in skip:
                continue
            if query(w[4], a, b, radius, info):
                if best is None or info.alpha < alpha:
                    best, alpha, tie = (w[5], info.normal.x, info.normal.y), info.alpha, False
                elif info.alpha == alpha:
                    tie = True
        if tie:  # first_wall_hit keeps the first of equals in pymunk's order: ask it
            return first_wall_hit(space, x0, y0, x1, y1, radius, skip)
        if best is None:
            return None
        return WallHit(best[0], (best[1], best[2]), alpha)

    def inside(self, x: float, y: float, radius: float) -> bool:
        """``q = space.point_query_nearest((x, y), radius, WALLS_ONLY)`` is not None and
        ``q.distance < radius - 1e-9``: a circle there overlaps a wall."""
        info = self._point
        hit = lib.cpSpacePointQueryNearest(self._space, (x, y), radius, self._filter, info)
        return hit != self._null and info.distance < radius - 1e-9

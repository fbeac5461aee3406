"""Direct Chipmunk calls through pymunk's cffi layer, for the tick's hot path.

pymunk's Python wrappers cost 0.5-3 us a call (argument checks, a C struct allocated per
query, result objects); the tick repeats a few of them every substep or shot. Each helper
here makes the one Chipmunk call that the pymunk method named in its docstring makes,
with the same result (tests/test_world.py compares them). It relies on pymunk 7's
internals (``pymunk._chipmunk_cffi``, ``Body._body``, ``Space._space``, the
``pymunk.batch`` call data); the project pins pymunk below 8.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import pymunk
import pymunk.batch
from pymunk._chipmunk_cffi import ffi, lib

_GET_BODIES = ffi.addressof(lib, "pmSpaceBodyGetIteratorFuncBatched")


def plain_attributes(mixin: type | None = None) -> bool:
    """Drop the two pass-through methods of pymunk 7's ``TypingAttrMixing`` (a base of
    Body, Shape and Constraint, there for mypy): ``__setattr__`` only calls the default
    one and ``__getattr__`` only re-raises through ``__getattribute__``. Every attribute
    write on a pymunk object, pymunk's own included, went through a Python call: about
    600 per World built (each reset), a fifth of its instructions, and a few per bullet
    that enters a space. Without them attribute access is the default one, so nothing
    else changes. Runs once, at import, on pymunk's class (``mixin`` None); a class whose
    methods do other work (a later pymunk) is left alone and False returned."""
    if mixin is None:
        from pymunk._typing_attr import TypingAttrMixing as mixin
    passes = {"__setattr__": ("super", "__setattr__"), "__getattr__": ("__getattribute__",)}
    found = {name: mixin.__dict__.get(name) for name in passes}
    if any(f is not None and f.__code__.co_names != passes[name]
           for name, f in found.items()):
        return False
    for name, f in found.items():
        if f is not None:
            delattr(mixin, name)
    return True


plain_attributes()


def set_position(body: pymunk.Body, x: float, y: float) -> None:
    """``body.position = (x, y)``."""
    lib.cpBodySetPosition(body._body, (x, y))


def set_velocity(body: pymunk.Body, vx: float, vy: float) -> None:
    """``body.velocity = (vx, vy)``."""
    lib.cpBodySetVelocity(body._body, (vx, vy))


def set_angular_velocity(body: pymunk.Body, w: float) -> None:
    """``body.angular_velocity = w``."""
    lib.cpBodySetAngularVelocity(body._body, w)


def space_step(space: pymunk.Space, dt: float) -> None:
    """``space.step(dt)``: Chipmunk's step with the space locked, as the wrapper makes
    it. The wrapper's bookkeeping (bodies to check, additions and removals deferred by
    callbacks, post-step callbacks) runs only when there is some: then the wrapper's
    own code finishes it."""
    if space._bodies_to_check or space.threaded:
        space.step(dt)
        return
    space._locked = True
    try:
        lib.cpSpaceStep(space._space, dt)
        space._removed_shapes.clear()
    finally:
        space._locked = False
    if space._add_later or space._remove_later or space._post_step_callbacks:
        _finish_step(space)


def _finish_step(space: pymunk.Space) -> None:
    """The end of pymunk 7's ``Space.step``: deferred additions, then deferred removals
    (each once), then the post-step callbacks."""
    space.add(*space._add_later)
    space._add_later.clear()
    removed = set()
    while space._remove_later:
        to_remove, _ = space._remove_later.popitem()
        if to_remove not in removed:
            removed.add(to_remove)
            space._remove(to_remove)
    for key in space._post_step_callbacks:
        space._post_step_callbacks[key](space)
    space._post_step_callbacks.clear()


class Hit(NamedTuple):
    """A segment query's answer: ``shape`` is Chipmunk's handle of the shape (compare
    with :func:`handle`), ``normal`` and ``alpha`` as in ``pymunk.SegmentQueryInfo``."""

    shape: object
    normal: tuple[float, float]
    alpha: float


def handle(shape: pymunk.Shape) -> object:
    """Chipmunk's handle of ``shape``, as :class:`Hit` gives it."""
    return shape._shape


class FirstHit:
    """``space.segment_query_first(start, end, radius, shape_filter)`` as a :class:`Hit`
    or None, with one result struct allocated once; shapes in ``skip`` (handles) are
    passed over (then through pymunk's all-hits query, rarely needed)."""

    def __init__(self, space: pymunk.Space, radius: float, shape_filter: pymunk.ShapeFilter):
        self._pm_space, self._space = space, space._space
        self._radius, self._filter = radius, shape_filter
        self._info = ffi.new("cpSegmentQueryInfo *")

    def __call__(self, x0: float, y0: float, x1: float, y1: float,
                 skip: Sequence[object] = ()) -> Hit | None:
        if skip:
            best = None
            for q in self._pm_space.segment_query((x0, y0), (x1, y1), self._radius,
                                                  self._filter):
                key = handle(q.shape)
                if key not in skip and (best is None or q.alpha < best.alpha):
                    best = Hit(key, tuple(q.normal), q.alpha)
            return best
        info = self._info
        shape = lib.cpSpaceSegmentQueryFirst(self._space, (x0, y0), (x1, y1), self._radius,
                                             self._filter, info)
        if shape == ffi.NULL:
            return None
        return Hit(shape, (info.normal.x, info.normal.y), info.alpha)


class NearestDistance:
    """``space.point_query_nearest(point, max_distance, shape_filter)``'s ``distance``, or
    None when it finds no shape, with one result struct allocated once."""

    def __init__(self, space: pymunk.Space, shape_filter: pymunk.ShapeFilter):
        self._space, self._filter = space._space, shape_filter
        self._info = ffi.new("cpPointQueryInfo *")

    def __call__(self, x: float, y: float, max_distance: float) -> float | None:
        info = self._info
        shape = lib.cpSpacePointQueryNearest(self._space, (x, y), max_distance, self._filter,
                                             info)
        return None if shape == ffi.NULL else info.distance


class BodyReader:
    """``pymunk.batch.get_space_bodies(space, fields, buffer)`` with its call data built
    once. The first read sizes the buffer; later reads rewrite it in place (the space's
    bodies must not change), so ``floats`` views every read while the reader lives."""

    def __init__(self, space: pymunk.Space, fields: pymunk.batch.BodyFields):
        buf = self._buffer = pymunk.batch.Buffer()
        # pymunk 7.3 never frees a Buffer's C arrays: they go with the reader.
        buf._float_arr = ffi.gc(buf._float_arr, lib.pmFloatArrayFree)
        buf._int_arr = ffi.gc(buf._int_arr, lib.pmIntArrayFree)
        pymunk.batch.get_space_bodies(space, fields, buf)
        self._space = space._space
        self._floats = self._buffer._float_arr
        self._data = ffi.new("pmBatchedData *")
        self._data.fields = fields.value
        self._data.floatArray = self._floats
        self._data.intArray = self._buffer._int_arr
        self.floats = ffi.buffer(self._floats.arr, self._floats.num * ffi.sizeof("cpFloat"))

    def read(self) -> None:
        self._floats.num = 0
        lib.cpSpaceEachBody(self._space, _GET_BODIES, self._data)

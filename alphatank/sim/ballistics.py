"""Ricochet predictor: where a bullet fired from a pose goes, bounces included.

:func:`predict_path` runs :meth:`alphatank.sim.world.World.trace`, the very routine the physics uses
to move bullets through walls (continuous thick segment queries against walls only,
elastic reflection about the surface normal), over the bullet's whole range at once. So
the predicted bounce points are the ones a real bullet records.

:func:`path_hits`, :func:`path_min_distance` and :func:`path_distances` are pure numpy
geometry on the polyline a prediction returns (no physics), cheap enough per tick.
"""

from __future__ import annotations

import math

import numpy as np

from alphatank.sim.world import World


def predict_path(world: World, x: float, y: float, angle: float,
                 max_distance: float | None = None, max_bounces: int | None = None,
                 radius: float | None = None, exact: bool = True) -> np.ndarray:
    """Polyline of a bullet's centre fired from (x, y) at ``angle`` (radians, 0 = +x,
    y down): (k, 2) array of the start, each bounce point (centre at contact), the end.

    The bullet stops at the wall contact after ``max_bounces`` ricochets or once it has
    travelled ``max_distance`` px (defaults: the world's config). Tanks are ignored (use
    :func:`path_hits` for them). ``(x, y)`` is a muzzle position (``world.muzzle(tank)``);
    if a bullet there would overlap a wall (the world fires nothing) the path is just
    ``[start, start]``.

    ``exact=True`` runs the physics' own :meth:`alphatank.sim.world.World.trace`, so at the
    bullet radius the predicted bounces are bit for bit the ones a fired bullet makes.
    ``exact=False`` traces the same way with pymunk's space-level segment query against the
    sharp walls, which can miss a wall corner grazed only by the bullet's rim (bots use it
    to search, then confirm with an exact prediction before firing).
    """
    return np.array(predict_points(world, x, y, angle, max_distance, max_bounces, radius, exact),
                    dtype=np.float64)


def predict_points(world: World, x: float, y: float, angle: float,
                   max_distance: float | None = None, max_bounces: int | None = None,
                   radius: float | None = None, exact: bool = True
                   ) -> list[tuple[float, float]]:
    """:func:`predict_path`'s polyline as a list of (x, y) points, the same floats: for
    callers that copy it into arrays of their own or read it in plain Python."""
    cfg = world.cfg
    length = cfg.bullet_max_distance if max_distance is None else float(max_distance)
    bounces = cfg.bullet_max_bounces if max_bounces is None else int(max_bounces)
    r = cfg.bullet_radius if radius is None else float(radius)
    x, y = float(x), float(y)
    inside = world.wall_distance(x, y, r)
    if inside is not None and inside < r - 1e-9:
        return [(x, y), (x, y)]
    dx, dy = math.cos(angle), math.sin(angle)
    if exact:
        f = world.trace(x, y, dx, dy, length, bounces, radius=r)
    else:
        f = world.quick_trace(x, y, dx, dy, length, bounces, r)
    return [(x, y), *[(q.x, q.y) for q in f.ricochets], (f.ex, f.ey)]


def path_distances(path: np.ndarray, targets_xy: np.ndarray) -> np.ndarray:
    """(T,) closest distance of each target point to the polyline ``path``."""
    return _seg_dist(path, targets_xy)[0].min(axis=0)


def path_min_distance(path: np.ndarray, targets_xy: np.ndarray) -> float:
    """Closest approach of the polyline ``path`` to any target point (inf if none)."""
    targets = np.asarray(targets_xy, dtype=np.float64).reshape(-1, 2)
    if len(targets) == 0:
        return math.inf
    return float(path_distances(path, targets).min())


def path_hits(path: np.ndarray, targets_xy: np.ndarray, hit_radius: float) -> int:
    """Index of the first target (in order along the path) the path passes within
    ``hit_radius`` of, or -1. A bullet stops at the first tank it hits, so the result
    tells whether a shot reaches an enemy before a friend."""
    targets = np.asarray(targets_xy, dtype=np.float64).reshape(-1, 2)
    if len(targets) == 0 or len(path) < 2:
        return -1
    return _first_reached(path, *_seg_dist(path, targets), hit_radius)


def _first_reached(path: np.ndarray, dist: np.ndarray, t: np.ndarray, hit_radius: float
                   ) -> int:
    """:func:`path_hits` from the (S, T) segment distances and closest-point params."""
    close = dist <= hit_radius
    near = close.any(axis=1)
    seg = int(near.argmax())  # first segment that comes close to anyone
    if not near[seg]:
        return -1
    cand = np.flatnonzero(close[seg])
    if cand.size == 1:
        return int(cand[0])
    # Several targets near the same leg: the one whose entry point comes first.
    d = path[seg + 1] - path[seg]
    seg_len = math.hypot(d[0], d[1])
    along = t[seg, cand] * seg_len
    half_chord = np.sqrt(np.maximum(hit_radius ** 2 - dist[seg, cand] ** 2, 0.0))
    entry = along - half_chord
    return int(cand[int(np.argmin(entry))])


def _seg_dist(path: np.ndarray, targets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distances (S, T) from each path segment to each target, and the closest-point
    parameter t in [0, 1] along each segment (:func:`segment_distances`)."""
    z = np.asarray(path, dtype=np.float64).view(np.complex128).ravel()
    w = np.ascontiguousarray(targets, dtype=np.float64).view(np.complex128).ravel()
    dist, t, _ = segment_distances(z, w)
    return dist, t


def segment_distances(z: np.ndarray, w: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Distances (..., S, T) from each leg of the polylines ``z`` (..., P) to the points
    ``w`` (..., T), both complex x + iy with broadcasting leading axes; the closest-point
    parameter t in [0, 1] along each leg; the legs (..., S, 1). Complex arithmetic: the
    fewest numpy calls."""
    a = z[..., :-1, None]
    d = z[..., 1:, None] - a
    rel = w[..., None, :] - a
    len2 = np.maximum(d.real * d.real + d.imag * d.imag, 1e-300)  # zero legs: t = 0
    t = np.minimum(np.maximum((rel * d.conj()).real / len2, 0.0), 1.0)
    return np.abs(rel - t * d), t, d


def wall_faces(rects: np.ndarray, width: float, height: float) -> np.ndarray:
    """Faces of axis-aligned wall rectangles (x0, y0, x1, y1), plus the grid's outer
    boundary: (m, 5) rows (axis, c, lo, hi, side) for the line x = c (axis 0) or
    y = c (axis 1) spanning [lo, hi] on the other axis, open towards ``side`` (+1/-1)."""
    rects = np.asarray(rects, dtype=np.float64).reshape(-1, 4)
    x0, y0, x1, y1 = rects.T
    faces = [np.stack([np.zeros_like(x0), x0, y0, y1, -np.ones_like(x0)], axis=1),
             np.stack([np.zeros_like(x0), x1, y0, y1, np.ones_like(x0)], axis=1),
             np.stack([np.ones_like(x0), y0, x0, x1, -np.ones_like(x0)], axis=1),
             np.stack([np.ones_like(x0), y1, x0, x1, np.ones_like(x0)], axis=1),
             np.array([[0, 0.0, 0.0, height, 1], [0, width, 0.0, height, -1],
                       [1, 0.0, 0.0, width, 1], [1, height, 0.0, width, -1]], dtype=np.float64)]
    return np.concatenate(faces)


def bank_angles(faces: np.ndarray, x: float, y: float, tx: float, ty: float, radius: float,
                max_distance: float) -> np.ndarray:
    """Headings of one-bounce shots from (x, y) to (tx, ty) off ``faces`` (from
    :func:`wall_faces`), by mirroring the target in each face's contact line (offset by
    the bullet ``radius``); sorted by path length, at most ``max_distance`` long. Pure
    geometry: walls in the way are not checked (confirm with :func:`predict_path`)."""
    axis, c, lo, hi, side = faces.T
    line = c + side * radius  # where the bullet centre touches the face
    vertical = axis == 0
    p = np.where(vertical, x, y)  # coordinate across the line
    q = np.where(vertical, y, x)  # coordinate along the line
    tp = np.where(vertical, tx, ty)
    tq = np.where(vertical, ty, tx)
    ok = ((p - line) * side > 0) & ((tp - line) * side > 0)  # both on the open side
    mp = 2 * line - tp  # mirrored target, across the line
    with np.errstate(divide="ignore", invalid="ignore"):
        u = (line - p) / (mp - p)
    hit_q = q + u * (tq - q)  # where the bounce lands along the face
    ok &= (hit_q >= lo - radius) & (hit_q <= hi + radius)
    length = np.hypot(mp - p, tq - q)
    ok &= length <= max_distance
    dx = np.where(vertical, mp - p, tq - q)
    dy = np.where(vertical, tq - q, mp - p)
    idx = np.flatnonzero(ok)
    idx = idx[np.argsort(length[idx], kind="stable")]
    return np.arctan2(dy[idx], dx[idx])

"""The physics world: a pymunk Space with tank, wall and bullet bodies.

The world knows nothing of agents, teams, rewards or pygame. It moves tanks from
(rotate, move) commands, spawns bullets, ricochets them elastically off walls, reports
bullet-tank hits allowed by a ``can_hit`` matrix, and reads the whole state back once per
tick with ``pymunk.batch``.

Walls never move, so a bullet's flight is traced once, exactly, when it spawns
(:meth:`World.trace`: continuous swept-circle queries against a twin of the walls rounded
by the bullet radius, no tunnelling at any speed). In the physics a bullet flies straight;
each ricochet (and its end on a wall once out of bounces, or at its range) is applied at
the end of the substep in which it happens. Bullets collide only with tank hitboxes, whose
handler tests the bullet's exact path of that substep. No Python runs for a bullet
between its events.

Body layout never changes after construction (bodies are never removed, only their
shapes), so the batch read has a fixed order: tank bodies, bullet bodies, control bodies.
Bullet slot ``b`` belongs to tank ``b // capacity``.
"""

from __future__ import annotations

import atexit
import functools
import heapq
import math
from collections import OrderedDict
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import numpy as np
import pymunk
import pymunk.batch

from alphatank.sim import cp
from alphatank.sim.config import GameConfig
from alphatank.sim.mapspec import MapSpec

WALL, TANK, BULLET, HITBOX = 1, 2, 3, 4  # collision types
CAT_WALL, CAT_TANK, CAT_BULLET, CAT_HITBOX = 0b0001, 0b0010, 0b0100, 0b1000
WALL_FILTER = pymunk.ShapeFilter(categories=CAT_WALL)
TANK_FILTER = pymunk.ShapeFilter(categories=CAT_TANK, mask=CAT_WALL | CAT_TANK)
WALLS_ONLY = pymunk.ShapeFilter(mask=CAT_WALL)
TANK_MASS = 10.0
DRIVE_ACCEL_TICKS = 2.0  # ticks a tank takes to reach full speed; bounds the drive forces
PARK = (-1000.0, -1000.0)  # where free bullet bodies wait (without their shapes)
SKIN = 1e-7  # px: step off a wall after a contact so the next query starts outside it
NEVER = np.iinfo(np.int64).max
_BODY_FIELDS = (pymunk.batch.BodyFields.POSITION | pymunk.batch.BodyFields.ANGLE
                | pymunk.batch.BodyFields.VELOCITY | pymunk.batch.BodyFields.ANGULAR_VELOCITY)
_FLOATS_PER_BODY = 6  # x, y, angle, vx, vy, angular velocity
_ANY = pymunk.ShapeFilter()


TANK_TRAVEL_PER_SUBSTEP = 3.0  # px: bound on how far any point of a tank moves per substep


def tank_travel_per_tick(cfg: GameConfig) -> float:
    """Farthest any point of a tank moves in one tick (driving plus turning)."""
    half_diagonal = math.hypot(cfg.tank_width, cfg.tank_height) / 2
    return (cfg.tank_speed + math.radians(cfg.rotation_speed) * half_diagonal) / cfg.tick_hz


def substeps_for(cfg: GameConfig, min_wall_thickness: float) -> int:
    """Physics substeps per tick: a bullet never travels past a wall's middle, and a tank
    point never moves more than TANK_TRAVEL_PER_SUBSTEP."""
    per_tick = cfg.bullet_speed / cfg.tick_hz
    bullets = math.ceil(per_tick / (0.8 * (min_wall_thickness / 2 + cfg.bullet_radius)))
    tanks = math.ceil(tank_travel_per_tick(cfg) / TANK_TRAVEL_PER_SUBSTEP)
    return max(1, bullets, tanks)


class Bounce(NamedTuple):
    bullet: int
    x: float
    y: float


class Ricochet(NamedTuple):
    """One bounce of a traced flight."""

    s: float  # distance travelled at the contact
    x: float  # centre at the contact
    y: float
    sx: float  # where the next leg starts (SKIN off the wall)
    sy: float
    dx: float  # unit direction of the next leg
    dy: float


class Flight(NamedTuple):
    """A traced bullet path: start, ricochets in order, and where it ends."""

    x: float
    y: float
    dx: float
    dy: float
    ricochets: list[Ricochet]
    end: float  # distance travelled when it ends (its range, or its last wall contact)
    ex: float  # centre and direction at the end
    ey: float
    edx: float
    edy: float
    died: bool  # ends on a wall contact with no bounces left


class _Bullet:
    """Flight bookkeeping of one live bullet (plain Python: read every few substeps)."""

    __slots__ = ("flight", "start", "due", "end_due", "done", "serial")

    def __init__(self, flight: Flight, start: int, due: list[int], end_due: int,
                 serial: int):
        self.flight = flight
        self.start = start  # world substep when it was spawned
        self.due = due  # substep at whose end each ricochet applies
        self.end_due = end_due  # substep at whose end it leaves play
        self.done = 0  # ricochets applied so far
        self.serial = serial  # tells its scheduled events from an earlier bullet's


class World:
    """Physics of one match. Build a new World to reset (bit-reproducible)."""

    def __init__(self, cfg: GameConfig, spec: MapSpec, poses: np.ndarray):
        """``poses``: (n_tanks, 3) array of x, y, angle (radians; 0 faces +x, y down)."""
        self.cfg, self.spec = cfg, spec
        self.sight_cache: Any = None  # its WallSight (alphatank.sim.sight.wall_sight)
        n = len(poses)
        cap = cfg.bullet_capacity
        self.n_tanks, self.capacity, self.n_bullets = n, cap, n * cap
        self.substeps = substeps_for(cfg, spec.min_wall_thickness())
        self.dt_sub = cfg.dt / self.substeps
        self.step_len = cfg.bullet_speed * self.dt_sub
        self.life_substeps = max(1, math.ceil(cfg.bullet_max_distance / self.step_len - 1e-9))
        self.margin = tank_travel_per_tick(cfg) / self.substeps

        space = self.space = pymunk.Space()
        space.iterations = 10
        space.collision_slop = 0.1
        # Query-only twin of the walls, rounded by the bullet radius: one C-level thin
        # segment query against it is a swept-bullet query (chipmunk adds the shape's and
        # the query's radii, so alpha and normal are bit-identical to a radius-r query
        # against the sharp walls). Shared by every world on the map.
        self.bullet_walls = shared_rounded_walls(spec, cfg.bullet_radius)
        self._add_walls()
        self._first_bullet_hit = cp.FirstHit(self.bullet_walls, 0.0, _ANY)
        self._quick: dict[float, cp.FirstHit] = {}  # quick_trace's queries, per radius
        self._wall_distance = cp.NearestDistance(self.space, WALLS_ONLY)
        self.tank_bodies: list[pymunk.Body] = []
        self.tank_shapes: list[pymunk.Poly] = []  # collision envelopes
        self.hitboxes: list[pymunk.Poly] = []  # exact boxes that bullets hit
        self.controls: list[pymunk.Body] = []
        w, h = cfg.tank_width, cfg.tank_height
        moment = pymunk.moment_for_box(TANK_MASS, (w, h))
        for i, (x, y, a) in enumerate(poses):
            body = pymunk.Body(TANK_MASS, moment)
            body.position, body.angle = (float(x), float(y)), float(a)
            # Contacts are found once shapes overlap, so a moving tank's envelope can sink
            # up to one substep's travel into a wall: the envelope's rounded margin takes
            # that, and the exact box never enters a wall.
            shape = pymunk.Poly.create_box(body, (w, h), radius=self.margin)
            shape.collision_type, shape.filter = TANK, TANK_FILTER
            shape.friction, shape.elasticity = 0.0, 0.0
            shape.slot = i
            hitbox = pymunk.Poly.create_box(body, (w, h))
            hitbox.collision_type, hitbox.sensor = HITBOX, True
            hitbox.filter = pymunk.ShapeFilter(group=self._group(i), categories=CAT_HITBOX,
                                               mask=CAT_BULLET)
            hitbox.slot = i
            space.add(body, shape, hitbox)
            self.tank_bodies.append(body)
            self.tank_shapes.append(shape)
            self.hitboxes.append(hitbox)
        self.bullet_bodies: list[pymunk.Body] = []
        self.bullet_shapes: list[pymunk.Circle] = []
        for b in range(self.n_bullets):
            body = pymunk.Body(1.0, float("inf"))
            body.position = PARK
            # Detection circle: the physics moves a bullet straight through its substep
            # and its ricochets are applied at the end, so its real path in a substep lies
            # within 2 steps of the straight end point. Any tank that path touches overlaps
            # this circle; the handler then tests the real path exactly.
            shape = pymunk.Circle(body, cfg.bullet_radius + 2 * self.step_len + 1e-3)
            shape.collision_type = BULLET
            shape.filter = pymunk.ShapeFilter(group=self._group(b // cap), categories=CAT_BULLET,
                                              mask=CAT_HITBOX)
            shape.slot = b
            space.add(body)  # the shape joins while the bullet is in play
            self.bullet_bodies.append(body)
            self.bullet_shapes.append(shape)
        # Forces just strong enough to reach full speed in DRIVE_ACCEL_TICKS: a stronger
        # drive out-muscles the contact solver and shoves tanks into walls.
        accel = cfg.tank_speed * cfg.tick_hz / DRIVE_ACCEL_TICKS
        spin = math.radians(cfg.rotation_speed) * cfg.tick_hz / DRIVE_ACCEL_TICKS
        for body in self.tank_bodies:
            control = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
            control.position, control.angle = body.position, body.angle
            pivot = pymunk.PivotJoint(control, body, (0, 0), (0, 0))
            pivot.max_bias, pivot.max_force = 0.0, TANK_MASS * accel
            gear = pymunk.GearJoint(control, body, 0.0, 1.0)
            gear.max_bias, gear.max_force = 0.0, moment * spin
            space.add(control, pivot, gear)
            self.controls.append(control)

        space.on_collision(BULLET, HITBOX, pre_solve=_bullet_tank, data=self)
        space.on_collision(TANK, WALL, begin=_tank_wall_begin, separate=_tank_wall_end,
                           data=self)

        # Game-facing state, all arrays (no attributes on pymunk objects).
        self.bullet_active = np.zeros(self.n_bullets, dtype=bool)
        self.bullet_bounces = np.zeros(self.n_bullets, dtype=np.int32)
        self.bullet_expire = np.zeros(self.n_bullets, dtype=np.int64)  # substep of expiry
        self.bullet_fired_tick = np.zeros(self.n_bullets, dtype=np.int64)
        self.bullet_owner = np.repeat(np.arange(n), cap)
        self.can_hit = ~np.eye(n, dtype=bool)  # can_hit[shooter, victim]
        self.grace_ticks = cfg.grace_ticks
        self.tank_present = np.ones(n, dtype=bool)
        self.wall_contacts = np.zeros(n, dtype=np.int64)  # walls each tank touches now
        self.contacts_changed = 0  # bumped whenever ``wall_contacts`` changes
        self.hits: list[tuple[int, int]] = []  # (bullet, victim) this tick
        self.bounces: list[Bounce] = []
        self.expired: list[int] = []  # bullets removed by the bounce or distance limit
        self.substep = 0
        self.tick = 0
        self._bullets: list[_Bullet | None] = [None] * self.n_bullets
        self._events: list[tuple[int, int, int]] = []  # heap of (substep, slot, serial)
        self._next_event = NEVER
        self._serial = 0
        self._drive = [(0.0, 0.0, 0.0)] * n  # last (vx, vy, w) given to each control body
        # The batch read: one row per body the space iterates (ours, then the static
        # body), rewritten in place by each read as bodies are never added or removed.
        # ``_batch`` views it privately (it lives and dies with the reader); ``state`` is
        # our own copy.
        self._reader = cp.BodyReader(space, _BODY_FIELDS)
        n_bodies = 2 * n + self.n_bullets
        self._batch = np.frombuffer(self._reader.floats, dtype=np.float64).reshape(
            -1, _FLOATS_PER_BODY)[:n_bodies]
        self.state = np.empty((n_bodies, _FLOATS_PER_BODY))
        self.tank_state = self.state[:n]
        self.bullet_state = self.state[n:n + self.n_bullets]
        self._tank_rows: list[list[float]] | None = None  # tank_state.tolist(), per read
        self.read_state()

    def _group(self, tank: int) -> int:
        """Shape group of a tank's hitbox and bullets: same group never collides, so
        without self-hits the physics skips a tank's own bullets entirely."""
        return 0 if self.cfg.self_hit else tank + 1

    def _add_walls(self) -> None:
        """Merged wall boxes plus a closed boundary outside the grid (:func:`wall_corners`)."""
        static = self.space.static_body
        for corners in wall_corners(self.spec):
            shape = pymunk.Poly(static, corners)
            shape.collision_type, shape.filter = WALL, WALL_FILTER
            shape.friction, shape.elasticity = 0.0, 1.0
            self.space.add(shape)

    # ---- commands -------------------------------------------------------------------

    def drive(self, tank: int, rotate: int, move: int) -> None:
        """rotate in {-1, 0, 1} (1 = clockwise on screen), move in {-1, 0, 1}; the heading
        comes from ``tank_state`` (current after construction, every step and
        read_state()). pymunk is only written when a control velocity changes."""
        cfg = self.cfg
        a = self.tank_rows()[tank][2]
        speed = cfg.tank_speed * move
        cmd = (math.cos(a) * speed, math.sin(a) * speed,
               math.radians(cfg.rotation_speed) * rotate)
        last = self._drive[tank]
        if cmd != last:
            control = self.controls[tank]
            if cmd[:2] != last[:2]:
                cp.set_velocity(control, cmd[0], cmd[1])
            if cmd[2] != last[2]:
                cp.set_angular_velocity(control, cmd[2])
            self._drive[tank] = cmd

    def muzzle(self, tank: int) -> tuple[float, float]:
        """Where a bullet fired now would appear (just clear of the tank's front)."""
        x, y, a = self.tank_rows()[tank][:3]
        d = self.cfg.tank_width / 2 + self.cfg.bullet_radius + 0.5
        return (x + math.cos(a) * d, y + math.sin(a) * d)

    def place_tank(self, tank: int, x: float, y: float, angle: float) -> None:
        """Teleport a tank (at rest) and its control body; call read_state() after."""
        for body in (self.tank_bodies[tank], self.controls[tank]):
            body.position, body.angle = (x, y), angle
            body.velocity, body.angular_velocity = (0.0, 0.0), 0.0
        self._drive[tank] = (0.0, 0.0, 0.0)
        self.space.reindex_shapes_for_body(self.tank_bodies[tank])

    def spawn_bullet(self, tank: int, x: float, y: float, angle: float) -> int:
        """Put one of ``tank``'s bullets at (x, y) flying along ``angle``; returns its slot,
        or -1 if all of the tank's slots are in use. No muzzle or cooldown checks."""
        lo = tank * self.capacity
        active = self.bullet_active
        free = active[lo:lo + self.capacity].tolist()
        if all(free):
            return -1
        b = lo + free.index(False)
        cfg, start, step = self.cfg, self.substep, self.step_len
        x, y = float(x), float(y)
        dx, dy = math.cos(angle), math.sin(angle)
        flight = self.trace(x, y, dx, dy, cfg.bullet_max_distance, cfg.bullet_max_bounces)
        due = [start + max(1, math.ceil(r.s / step)) for r in flight.ricochets]
        expire = start + self.life_substeps
        end_due = (min(expire, start + max(1, math.ceil(flight.end / step))) if flight.died
                   else expire)
        self._serial += 1
        self._bullets[b] = _Bullet(flight, start, due, end_due, self._serial)
        self._schedule(due[0] if due else end_due, b, self._serial)
        vx, vy = dx * cfg.bullet_speed, dy * cfg.bullet_speed
        body = self.bullet_bodies[b]
        cp.set_position(body, x, y)
        cp.set_velocity(body, vx, vy)
        self.space.add(self.bullet_shapes[b])
        active[b] = True
        self.bullet_bounces[b] = 0
        self.bullet_fired_tick[b] = self.tick
        self.bullet_expire[b] = expire
        self.bullet_state[b] = (x, y, 0.0, vx, vy, 0.0)
        return b

    def fire(self, tank: int) -> int:
        """Spawn a bullet from the tank's muzzle; returns its slot, or -1 if the muzzle is
        in a wall or the tank has no free bullet slot."""
        x, y, a = self.tank_rows()[tank][:3]
        mx, my = self.muzzle(tank)
        if self._first_bullet_hit(x, y, mx, my) is not None:
            return -1
        return self.spawn_bullet(tank, mx, my, a)

    def remove_tank(self, tank: int) -> None:
        """Take a dead tank out of the physics (its bullets fly on)."""
        if self.tank_present[tank]:
            self.space.remove(self.tank_shapes[tank], self.hitboxes[tank])
            self.tank_present[tank] = False
            self.drive(tank, 0, 0)

    def despawn(self, b: int) -> None:
        """Take bullet ``b`` out of play (its shape leaves the space)."""
        if self.bullet_active[b]:
            self.bullet_active[b] = False
            self._bullets[b] = None
            self.space.remove(self.bullet_shapes[b])
            body = self.bullet_bodies[b]
            cp.set_position(body, *PARK)
            cp.set_velocity(body, 0.0, 0.0)

    # ---- time -----------------------------------------------------------------------

    def step(self) -> None:
        """Advance one tick; fills ``hits``, ``bounces`` and ``expired``."""
        self.hits.clear()
        self.bounces.clear()
        self.expired.clear()
        space, dt = self.space, self.dt_sub
        for _ in range(self.substeps):
            cp.space_step(space, dt)
            self.substep += 1
            if self.substep >= self._next_event:
                self._fly()
        self.tick += 1
        self.read_state()

    def _schedule(self, substep: int, b: int, serial: int) -> None:
        heapq.heappush(self._events, (substep, b, serial))
        self._next_event = self._events[0][0]

    def _fly(self) -> None:
        """Apply the ricochets and ends due by this substep (in slot order)."""
        now, events, step = self.substep, self._events, self.step_len
        while events and events[0][0] <= now:
            _, b, serial = heapq.heappop(events)
            bullet = self._bullets[b]
            if bullet is None or bullet.serial != serial:
                continue  # hit a tank since it was scheduled
            due, k = bullet.due, bullet.done
            while k < len(due) and due[k] <= now:
                k += 1
            turned = k > bullet.done
            if turned:
                self._ricochet(b, bullet, k)
            if bullet.end_due <= now:
                self.despawn(b)
                self.expired.append(b)
                continue
            if turned:  # continue along the leg after its last ricochet
                leg = bullet.flight.ricochets[k - 1]
                t = max(0.0, (now - bullet.start) * step - leg.s)
                body, speed = self.bullet_bodies[b], self.cfg.bullet_speed
                cp.set_position(body, leg.sx + leg.dx * t, leg.sy + leg.dy * t)
                cp.set_velocity(body, leg.dx * speed, leg.dy * speed)
            heapq.heappush(events, (due[k] if k < len(due) else bullet.end_due, b, serial))
        self._next_event = events[0][0] if events else NEVER

    def _ricochet(self, b: int, bullet: _Bullet, k: int) -> None:
        """Record bullet ``b``'s ricochets up to (not including) number ``k``."""
        for r in bullet.flight.ricochets[bullet.done:k]:
            self.bounces.append(Bounce(b, r.x, r.y))
        self.bullet_bounces[b] += k - bullet.done
        bullet.done = k

    def _path_hit(self, b: int, shape: pymunk.Shape) -> int:
        """Whether bullet ``b``'s exact path in the current substep touches ``shape``:
        the number of ricochets it has made when it does, else -1."""
        bullet = self._bullets[b]
        f, step = bullet.flight, self.step_len
        m = self.substep + 1 - bullet.start  # substeps flown at the end of this one
        t, t1 = (m - 1) * step, min(m * step, f.end)
        if t > t1:
            return -1
        rics, r = f.ricochets, self.cfg.bullet_radius
        k = bullet.done
        while k < len(rics) and rics[k].s <= t:
            k += 1
        while True:
            if k:
                leg = rics[k - 1]
                x, y, dx, dy, s0 = leg.sx, leg.sy, leg.dx, leg.dy, leg.s
            else:
                x, y, dx, dy, s0 = f.x, f.y, f.dx, f.dy, 0.0
            stop = min(t1, rics[k].s) if k < len(rics) else t1
            a, z = t - s0, stop - s0
            if shape.segment_query((x + dx * a, y + dy * a), (x + dx * z, y + dy * z),
                                   r) is not None:
                return k
            if stop >= t1:
                return -1
            t = stop
            k += 1

    def read_state(self) -> None:
        """One batch read of every body into ``state`` (x, y, angle, vx, vy, w)."""
        self._reader.read()
        self.state[...] = self._batch
        self._tank_rows = None

    def tank_rows(self) -> list[list[float]]:
        """``tank_state.tolist()`` (x, y, angle, vx, vy, w per tank), made once per
        :meth:`read_state`: the bots and the rules read the tanks' poses several times a
        tick, and a list costs less than a numpy read each time. Do not modify it."""
        rows = self._tank_rows
        if rows is None:
            rows = self._tank_rows = self.tank_state.tolist()
        return rows

    # ---- queries --------------------------------------------------------------------

    def wall_hit(self, x0: float, y0: float, x1: float, y1: float, radius: float,
                 skip: Sequence[pymunk.Shape] = ()) -> pymunk.SegmentQueryInfo | None:
        """First wall touched by a circle of ``radius`` swept from (x0, y0) to (x1, y1),
        ignoring ``skip``; exact (at the bullet radius, one C-level query)."""
        if radius != self.cfg.bullet_radius:
            return first_wall_hit(self.space, x0, y0, x1, y1, radius, skip)
        if not skip:
            return self.bullet_walls.segment_query_first((x0, y0), (x1, y1), 0.0, _ANY)
        best = None
        for q in self.bullet_walls.segment_query((x0, y0), (x1, y1), 0.0, _ANY):
            if q.shape not in skip and (best is None or q.alpha < best.alpha):
                best = q
        return best

    def wall_distance(self, x: float, y: float, max_distance: float) -> float | None:
        """Distance from (x, y) to the nearest wall within ``max_distance`` (negative
        inside one), or None: ``space.point_query_nearest`` against the walls."""
        return self._wall_distance(x, y, max_distance)

    def ray(self, start: tuple[float, float], end: tuple[float, float],
            radius: float = 0.0) -> pymunk.SegmentQueryInfo | None:
        """First wall touched by a circle of ``radius`` swept along a segment."""
        return self.wall_hit(start[0], start[1], end[0], end[1], radius)

    def trace(self, x: float, y: float, dx: float, dy: float, length: float,
              bounces_left: int, radius: float | None = None) -> Flight:
        """The flight of a circle (default: a bullet) from (x, y) along unit (dx, dy) over
        ``length`` px with ``bounces_left`` ricochets: what the physics flies."""
        if radius is None or radius == self.cfg.bullet_radius:
            return trace_flight(self._first_bullet_hit, x, y, dx, dy, length, bounces_left)
        return trace_flight(
            lambda x0, y0, x1, y1, skip: first_wall_hit(self.space, x0, y0, x1, y1, radius,
                                                        skip),
            x, y, dx, dy, length, bounces_left)

    def quick_trace(self, x: float, y: float, dx: float, dy: float, length: float,
                    bounces_left: int, radius: float) -> Flight:
        """:meth:`trace` with the space-level thick segment query (one C call a leg, the
        query pymunk's ``space.segment_query_first`` makes): cheaper, but it can miss a
        wall corner grazed only by the circle's rim."""
        first = self._quick.get(radius)
        if first is None:
            first = self._quick[radius] = cp.FirstHit(self.space, radius, WALLS_ONLY)
        return trace_flight(first, x, y, dx, dy, length, bounces_left)


def wall_corners(spec: MapSpec) -> tuple[tuple[tuple[float, float], ...], ...]:
    """Corners of every wall box of a world on ``spec``: the map's merged wall rectangles
    plus a closed boundary one cell thick outside the grid (computed once per map)."""
    return _wall_corners(spec.wall_rects, spec.cell, spec.width, spec.height)


@functools.lru_cache(maxsize=64)
def _wall_corners(wall_rects: tuple[tuple[float, float, float, float], ...], t: float,
                  W: float, H: float) -> tuple[tuple[tuple[float, float], ...], ...]:
    rects = list(wall_rects) + [
        (-t, -t, W + t, 0.0), (-t, H, W + t, H + t), (-t, 0.0, 0.0, H), (W, 0.0, W + t, H)]
    return tuple(((x0, y0), (x1, y0), (x1, y1), (x0, y1)) for x0, y0, x1, y1 in rects)


def rounded_walls(spec: MapSpec, radius: float) -> pymunk.Space:
    """A query-only space of the walls of a world on ``spec`` rounded by ``radius``: a thin
    segment query against it answers as a circle of ``radius`` swept against the sharp
    walls (Chipmunk adds a poly's and a query's radii)."""
    space = pymunk.Space()
    for corners in wall_corners(spec):
        space.add(pymunk.Poly(space.static_body, corners, radius=radius))
    return space


# The walls of each map rounded per radius, shared by every world and WallSight on the map:
# query-only spaces that nothing changes, so a shared one answers as a fresh one would.
# The most recent maps are kept; freed at exit while pymunk can still free them.
_ROUNDED: OrderedDict[tuple, pymunk.Space] = OrderedDict()
_ROUNDED_SIZE = 64
atexit.register(_ROUNDED.clear)


def shared_rounded_walls(spec: MapSpec, radius: float) -> pymunk.Space:
    """:func:`rounded_walls` of ``spec`` and ``radius``, built once (read by queries only)."""
    key = (spec.wall_rects, spec.cell, spec.width, spec.height, float(radius))
    space = _ROUNDED.get(key)
    if space is None:
        space = _ROUNDED[key] = rounded_walls(spec, radius)
        if len(_ROUNDED) > _ROUNDED_SIZE:
            _ROUNDED.popitem(last=False)
    else:
        _ROUNDED.move_to_end(key)
    return space


def first_wall_hit(space: pymunk.Space, x0: float, y0: float, x1: float, y1: float,
                   radius: float, skip: Sequence[pymunk.Shape] = ()
                   ) -> pymunk.SegmentQueryInfo | None:
    """First wall touched by a circle swept from (x0, y0) to (x1, y1), ignoring ``skip``.

    Space-level thick segment queries test the thin segment against shape bounding boxes
    and miss walls only the circle's rim reaches, so gather candidates with a bounding-box
    query inflated by the radius and query each shape.
    """
    bb = pymunk.BB(min(x0, x1) - radius, min(y0, y1) - radius,
                   max(x0, x1) + radius, max(y0, y1) + radius)
    best = None
    for shape in space.bb_query(bb, WALLS_ONLY):
        if shape in skip:
            continue
        q = shape.segment_query((x0, y0), (x1, y1), radius)
        if q is not None and (best is None or q.alpha < best.alpha):
            best = q
    return best


WallHit = Callable[[float, float, float, float, Sequence[object]],
                   pymunk.SegmentQueryInfo | cp.Hit | None]


def trace_flight(hit: WallHit, x: float, y: float, dx: float, dy: float, length: float,
                 bounces_left: int) -> Flight:
    """Move a circle from (x, y) along unit (dx, dy) for ``length`` px, reflecting
    elastically off the walls ``hit`` finds (continuous: exact contact points, no
    tunnelling). ``hit(x0, y0, x1, y1, skip)`` is a swept query of the circle.

    The flight dies on a wall contact with no bounces left (it then ends there). A circle
    that starts overlapping a wall it is moving away from just leaves it.
    """
    x0, y0, dx0, dy0 = x, y, dx, dy
    ricochets: list[Ricochet] = []
    leaving: list[object] = []  # walls overlapped at the start and moved away from
    s = 0.0
    while True:
        q = hit(x, y, x + dx * length, y + dy * length, leaving)
        if q is None:
            return Flight(x0, y0, dx0, dy0, ricochets, s + length,
                          x + dx * length, y + dy * length, dx, dy, False)
        nx, ny = q.normal  # out of the wall, toward the bullet
        vn = dx * nx + dy * ny
        if vn >= 0:
            leaving.append(q.shape)
            continue
        travel = length * q.alpha
        x, y = x + dx * travel, y + dy * travel
        s += travel
        if bounces_left == 0:
            return Flight(x0, y0, dx0, dy0, ricochets, s, x, y, dx, dy, True)
        dx, dy = dx - 2 * vn * nx, dy - 2 * vn * ny
        norm = math.hypot(dx, dy)
        dx, dy = dx / norm, dy / norm
        cx, cy = x, y
        bounces_left -= 1
        length -= travel
        x, y = x + nx * SKIN, y + ny * SKIN
        ricochets.append(Ricochet(s, cx, cy, x, y, dx, dy))
        leaving.clear()


def _bullet_tank(arbiter: pymunk.Arbiter, space: pymunk.Space, world: World) -> None:
    """Bullets never push tanks; a hit allowed by ``can_hit`` removes the bullet."""
    arbiter.process_collision = False
    bullet_shape, tank_shape = arbiter.shapes
    b, victim = bullet_shape.slot, tank_shape.slot
    if not world.bullet_active[b]:
        return
    shooter = int(world.bullet_owner[b])
    if not world.can_hit[shooter, victim]:
        return
    if shooter == victim and world.tick - world.bullet_fired_tick[b] < world.grace_ticks:
        return
    k = world._path_hit(b, tank_shape)
    if k < 0:
        return
    bullet = world._bullets[b]
    if k > bullet.done:
        world._ricochet(b, bullet, k)  # the ricochets it made before the hit
    world.hits.append((b, victim))
    world.despawn(b)


def _tank_wall_begin(arbiter: pymunk.Arbiter, space: pymunk.Space, world: World) -> None:
    world.wall_contacts[arbiter.shapes[0].slot] += 1
    world.contacts_changed += 1


def _tank_wall_end(arbiter: pymunk.Arbiter, space: pymunk.Space, world: World) -> None:
    slot = getattr(arbiter.shapes[0], "slot", None)
    if slot is not None:  # None while a discarded space is being torn down
        world.wall_contacts[slot] -= 1
        world.contacts_changed += 1

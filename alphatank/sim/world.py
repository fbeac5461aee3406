"""The physics world: a pymunk Space with tank, wall and bullet bodies.

The world knows nothing of agents, teams, rewards or pygame. It moves tanks from
(rotate, move) commands, spawns bullets, ricochets them elastically off walls inside a
collision handler, reports bullet-tank hits allowed by a ``can_hit`` matrix, and reads the
whole state back once per tick with ``pymunk.batch``.

Body layout never changes after construction (bodies are never removed, only their
shapes), so the batch read has a fixed order: tank bodies, bullet bodies, control bodies.
Bullet slot ``b`` belongs to tank ``b // capacity``.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import pymunk
import pymunk.batch

from alphatank.sim.config import GameConfig
from alphatank.sim.mapspec import MapSpec

WALL, TANK, BULLET, HITBOX = 1, 2, 3, 4  # collision types
CAT_WALL, CAT_TANK, CAT_BULLET, CAT_HITBOX = 0b0001, 0b0010, 0b0100, 0b1000
WALL_FILTER = pymunk.ShapeFilter(categories=CAT_WALL)
TANK_FILTER = pymunk.ShapeFilter(categories=CAT_TANK, mask=CAT_WALL | CAT_TANK)
WALLS_ONLY = pymunk.ShapeFilter(mask=CAT_WALL)
TANK_MASS = 10.0
DRIVE_ACCEL_TICKS = 2.0  # ticks a tank takes to reach full speed; bounds the drive forces
PARK = (-1000.0, -1000.0)
SKIN = 1e-7  # px: step off a wall after a contact so the next query starts outside it
_BODY_FIELDS = (pymunk.batch.BodyFields.POSITION | pymunk.batch.BodyFields.ANGLE
                | pymunk.batch.BodyFields.VELOCITY | pymunk.batch.BodyFields.ANGULAR_VELOCITY)
_FLOATS_PER_BODY = 6  # x, y, angle, vx, vy, angular velocity


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


_BUFFERS = threading.local()


def batch_buffer() -> pymunk.batch.Buffer:
    """The calling thread's ``pymunk.batch.Buffer``, shared by every World it builds (a
    World reads its bodies through it and copies them out at once). pymunk 7.3 never frees
    a Buffer's C arrays, so one Buffer per World leaked about 1.3 kB per episode reset for
    the life of the process; one per thread bounds that to a few kB."""
    buf = getattr(_BUFFERS, "buffer", None)
    if buf is None:
        buf = _BUFFERS.buffer = pymunk.batch.Buffer()
    return buf


@dataclass(frozen=True)
class Bounce:
    bullet: int
    x: float
    y: float


class World:
    """Physics of one match. Build a new World to reset (bit-reproducible)."""

    def __init__(self, cfg: GameConfig, spec: MapSpec, poses: np.ndarray):
        """``poses``: (n_tanks, 3) array of x, y, angle (radians; 0 faces +x, y down)."""
        self.cfg, self.spec = cfg, spec
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
        self._add_walls()
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
            # Detection circle: large enough that any wall or tank touched during a
            # substep overlaps it at the substep's end; handlers then trace exactly.
            shape = pymunk.Circle(body, cfg.bullet_radius + self.step_len + 1e-3)
            shape.collision_type = BULLET
            shape.filter = pymunk.ShapeFilter(group=self._group(b // cap), categories=CAT_BULLET,
                                              mask=CAT_WALL | CAT_HITBOX)
            shape.friction, shape.elasticity = 0.0, 1.0
            shape.slot = b
            space.add(body)
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

        space.on_collision(BULLET, WALL, pre_solve=_bullet_wall, data=self)
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
        self.hits: list[tuple[int, int]] = []  # (bullet, victim) this tick
        self.bounces: list[Bounce] = []
        self.expired: list[int] = []  # bullets removed by the bounce or distance limit
        self.substep = 0
        self.tick = 0
        self._traced = np.full(self.n_bullets, -1, dtype=np.int64)
        self._next_expiry = np.iinfo(np.int64).max
        self._buffer = batch_buffer()
        n_bodies = 2 * n + self.n_bullets
        self.state = np.zeros((n_bodies, _FLOATS_PER_BODY))
        self.tank_state = self.state[:n]
        self.bullet_state = self.state[n:n + self.n_bullets]
        self.read_state()

    def _group(self, tank: int) -> int:
        """Shape group of a tank's hitbox and bullets: same group never collides, so
        without self-hits the physics skips a tank's own bullets entirely."""
        return 0 if self.cfg.self_hit else tank + 1

    def _add_walls(self) -> None:
        """Merged wall boxes plus a closed boundary outside the grid."""
        spec, static = self.spec, self.space.static_body
        t = spec.cell
        W, H = spec.width, spec.height
        rects = list(spec.wall_rects) + [
            (-t, -t, W + t, 0.0), (-t, H, W + t, H + t), (-t, 0.0, 0.0, H), (W, 0.0, W + t, H)]
        for x0, y0, x1, y1 in rects:
            shape = pymunk.Poly(static, [(x0, y0), (x1, y0), (x1, y1), (x0, y1)])
            shape.collision_type, shape.filter = WALL, WALL_FILTER
            shape.friction, shape.elasticity = 0.0, 1.0
            self.space.add(shape)

    # ---- commands -------------------------------------------------------------------

    def drive(self, tank: int, rotate: int, move: int) -> None:
        """rotate in {-1, 0, 1} (1 = clockwise on screen), move in {-1, 0, 1}."""
        cfg, body, control = self.cfg, self.tank_bodies[tank], self.controls[tank]
        a = body.angle
        speed = cfg.tank_speed * move
        control.velocity = (math.cos(a) * speed, math.sin(a) * speed)
        control.angular_velocity = math.radians(cfg.rotation_speed) * rotate

    def muzzle(self, tank: int) -> tuple[float, float]:
        """Where a bullet fired now would appear (just clear of the tank's front)."""
        x, y, a = self.tank_state[tank, :3]
        d = self.cfg.tank_width / 2 + self.cfg.bullet_radius + 0.5
        return (x + math.cos(a) * d, y + math.sin(a) * d)

    def place_tank(self, tank: int, x: float, y: float, angle: float) -> None:
        """Teleport a tank (at rest) and its control body; call read_state() after."""
        for body in (self.tank_bodies[tank], self.controls[tank]):
            body.position, body.angle = (x, y), angle
            body.velocity, body.angular_velocity = (0.0, 0.0), 0.0
        self.space.reindex_shapes_for_body(self.tank_bodies[tank])

    def spawn_bullet(self, tank: int, x: float, y: float, angle: float) -> int:
        """Put one of ``tank``'s bullets at (x, y) flying along ``angle``; returns its slot,
        or -1 if all of the tank's slots are in use. No muzzle or cooldown checks."""
        lo = tank * self.capacity
        free = np.flatnonzero(~self.bullet_active[lo:lo + self.capacity])
        if free.size == 0:
            return -1
        b = lo + int(free[0])
        body = self.bullet_bodies[b]
        speed = self.cfg.bullet_speed
        body.position = (x, y)
        body.velocity = (math.cos(angle) * speed, math.sin(angle) * speed)
        self.space.add(self.bullet_shapes[b])
        self.bullet_active[b] = True
        self.bullet_bounces[b] = 0
        self.bullet_fired_tick[b] = self.tick
        expire = self.substep + self.life_substeps
        self.bullet_expire[b] = expire
        self._next_expiry = min(self._next_expiry, expire)
        self.bullet_state[b, :2] = (x, y)
        self.bullet_state[b, 3:5] = body.velocity
        return b

    def fire(self, tank: int) -> int:
        """Spawn a bullet from the tank's muzzle; returns its slot, or -1 if the muzzle is
        in a wall or the tank has no free bullet slot."""
        x, y, a = self.tank_state[tank, :3]
        mx, my = self.muzzle(tank)
        if first_wall_hit(self.space, x, y, mx, my, self.cfg.bullet_radius):
            return -1
        return self.spawn_bullet(tank, mx, my, a)

    def remove_tank(self, tank: int) -> None:
        """Take a dead tank out of the physics (its bullets fly on)."""
        if self.tank_present[tank]:
            self.space.remove(self.tank_shapes[tank], self.hitboxes[tank])
            self.tank_present[tank] = False
            control = self.controls[tank]
            control.velocity, control.angular_velocity = (0.0, 0.0), 0.0

    def despawn(self, b: int) -> None:
        if self.bullet_active[b]:
            self.bullet_active[b] = False
            self.space.remove(self.bullet_shapes[b])
            body = self.bullet_bodies[b]
            body.position, body.velocity = PARK, (0.0, 0.0)

    # ---- time -----------------------------------------------------------------------

    def step(self) -> None:
        """Advance one tick; fills ``hits``, ``bounces`` and ``expired``."""
        self.hits.clear()
        self.bounces.clear()
        self.expired.clear()
        space, dt = self.space, self.dt_sub
        for _ in range(self.substeps):
            space.step(dt)
            self.substep += 1
            if self.substep >= self._next_expiry:
                self._expire()
        self.tick += 1
        self.read_state()

    def _expire(self) -> None:
        due = np.flatnonzero(self.bullet_active & (self.bullet_expire <= self.substep))
        for b in due:
            self.despawn(int(b))
            self.expired.append(int(b))
        live = self.bullet_expire[self.bullet_active]
        self._next_expiry = int(live.min()) if live.size else np.iinfo(np.int64).max

    def read_state(self) -> None:
        """One batch read of every body into ``state`` (x, y, angle, vx, vy, w)."""
        buf = self._buffer
        buf.clear()
        pymunk.batch.get_space_bodies(self.space, _BODY_FIELDS, buf)
        flat = np.frombuffer(buf.float_buf(), dtype=np.float64)
        self.state.reshape(-1)[:] = flat[: self.state.size]

    # ---- queries --------------------------------------------------------------------

    def ray(self, start: tuple[float, float], end: tuple[float, float],
            radius: float = 0.0) -> pymunk.SegmentQueryInfo | None:
        """First wall touched by a circle of ``radius`` swept along a segment."""
        return first_wall_hit(self.space, start[0], start[1], end[0], end[1], radius)


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


WallQuery = Callable[[pymunk.Space, float, float, float, float, float, Sequence[pymunk.Shape]],
                     pymunk.SegmentQueryInfo | None]


def trace(space: pymunk.Space, x: float, y: float, dx: float, dy: float, length: float,
          radius: float, bounces_left: int, query: WallQuery = first_wall_hit
          ) -> tuple[float, float, float, float, list[tuple[float, float]], bool]:
    """Move a circle of ``radius`` from (x, y) along unit (dx, dy) for ``length`` px,
    reflecting elastically off walls (continuous: exact contact points, no tunnelling).

    Returns the end position and direction, the centre at each ricochet, and whether the
    bullet died on a wall contact with no bounces left (it then ends at that contact).
    The physics and the ricochet predictor both use this, so they agree exactly.
    A circle that starts overlapping a wall it is moving away from just leaves it.
    """
    points: list[tuple[float, float]] = []
    leaving: list[pymunk.Shape] = []  # walls overlapped at the start and moved away from
    while True:
        q = query(space, x, y, x + dx * length, y + dy * length, radius, leaving)
        if q is None:
            return x + dx * length, y + dy * length, dx, dy, points, False
        nx, ny = q.normal  # out of the wall, toward the bullet
        vn = dx * nx + dy * ny
        if vn >= 0:
            leaving.append(q.shape)
            continue
        travel = length * q.alpha
        x, y = x + dx * travel, y + dy * travel
        if bounces_left == 0:
            return x, y, dx, dy, points, True
        dx, dy = dx - 2 * vn * nx, dy - 2 * vn * ny
        norm = math.hypot(dx, dy)
        dx, dy = dx / norm, dy / norm
        points.append((x, y))
        bounces_left -= 1
        length -= travel
        x, y = x + nx * SKIN, y + ny * SKIN
        leaving.clear()


def _bullet_wall(arbiter: pymunk.Arbiter, space: pymunk.Space, world: World) -> None:
    """Ricochet: re-trace this substep's travel continuously from where it began."""
    arbiter.process_collision = False
    shape = arbiter.shapes[0]
    b = shape.slot
    if not world.bullet_active[b] or world._traced[b] == world.substep:
        return
    world._traced[b] = world.substep
    body = shape.body
    speed, length = world.cfg.bullet_speed, world.step_len
    vx, vy = body.velocity
    dx, dy = vx / speed, vy / speed
    x1, y1 = body.position
    left = world.cfg.bullet_max_bounces - int(world.bullet_bounces[b])
    done = world.substep - (int(world.bullet_expire[b]) - world.life_substeps)
    remaining = world.cfg.bullet_max_distance - done * length  # distance limit mid-substep
    x, y, dx, dy, points, died = trace(space, x1 - dx * length, y1 - dy * length, dx, dy,
                                       min(length, remaining), world.cfg.bullet_radius, left)
    for px, py in points:
        world.bounces.append(Bounce(b, px, py))
    world.bullet_bounces[b] += len(points)
    if died:
        world.despawn(b)
        world.expired.append(b)
    elif points:
        body.position = (x, y)
        body.velocity = (dx * speed, dy * speed)


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
    body, length = bullet_shape.body, world.step_len
    x1, y1 = body.position
    vx, vy = body.velocity
    k = length / world.cfg.bullet_speed
    hit = tank_shape.segment_query((x1 - vx * k, y1 - vy * k), (x1, y1), world.cfg.bullet_radius)
    if hit is None:
        return
    world.hits.append((b, victim))
    world.despawn(b)


def _tank_wall_begin(arbiter: pymunk.Arbiter, space: pymunk.Space, world: World) -> None:
    world.wall_contacts[arbiter.shapes[0].slot] += 1


def _tank_wall_end(arbiter: pymunk.Arbiter, space: pymunk.Space, world: World) -> None:
    slot = getattr(arbiter.shapes[0], "slot", None)
    if slot is not None:  # None while a discarded space is being torn down
        world.wall_contacts[slot] -= 1

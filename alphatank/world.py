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
from dataclasses import dataclass

import numpy as np
import pymunk
import pymunk.batch

from alphatank.config import GameConfig
from alphatank.mapspec import MapSpec

WALL, TANK, BULLET = 1, 2, 3  # collision types
CAT_WALL, CAT_TANK, CAT_BULLET = 0b001, 0b010, 0b100
WALL_FILTER = pymunk.ShapeFilter(categories=CAT_WALL)
TANK_FILTER = pymunk.ShapeFilter(categories=CAT_TANK)
BULLET_FILTER = pymunk.ShapeFilter(categories=CAT_BULLET, mask=CAT_WALL | CAT_TANK)
WALLS_ONLY = pymunk.ShapeFilter(mask=CAT_WALL)
TANK_MASS = 10.0
DRIVE_FORCE = 1e6  # pivot/gear force limits: drive the tank, never push through walls
PARK = (-1000.0, -1000.0)
_BODY_FIELDS = (pymunk.batch.BodyFields.POSITION | pymunk.batch.BodyFields.ANGLE
                | pymunk.batch.BodyFields.VELOCITY | pymunk.batch.BodyFields.ANGULAR_VELOCITY)
_FLOATS_PER_BODY = 6  # x, y, angle, vx, vy, angular velocity


def substeps_for(cfg: GameConfig, min_wall_thickness: float) -> int:
    """Physics substeps per tick so a bullet never travels past a wall's middle."""
    per_tick = cfg.bullet_speed / cfg.tick_hz
    return max(1, math.ceil(per_tick / (0.8 * (min_wall_thickness / 2 + cfg.bullet_radius))))


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

        space = self.space = pymunk.Space()
        space.iterations = 10
        space.collision_slop = 0.1
        self._add_walls()
        self.tank_bodies: list[pymunk.Body] = []
        self.tank_shapes: list[pymunk.Poly] = []
        self.controls: list[pymunk.Body] = []
        w, h = cfg.tank_width, cfg.tank_height
        moment = pymunk.moment_for_box(TANK_MASS, (w, h))
        for i, (x, y, a) in enumerate(poses):
            body = pymunk.Body(TANK_MASS, moment)
            body.position, body.angle = (float(x), float(y)), float(a)
            shape = pymunk.Poly.create_box(body, (w, h))
            shape.collision_type, shape.filter = TANK, TANK_FILTER
            shape.friction, shape.elasticity = 0.0, 0.0
            shape.slot = i
            space.add(body, shape)
            self.tank_bodies.append(body)
            self.tank_shapes.append(shape)
        self.bullet_bodies: list[pymunk.Body] = []
        self.bullet_shapes: list[pymunk.Circle] = []
        for b in range(self.n_bullets):
            body = pymunk.Body(1.0, float("inf"))
            body.position = PARK
            shape = pymunk.Circle(body, cfg.bullet_radius)
            shape.collision_type, shape.filter = BULLET, BULLET_FILTER
            shape.friction, shape.elasticity = 0.0, 1.0
            shape.slot = b
            space.add(body)
            self.bullet_bodies.append(body)
            self.bullet_shapes.append(shape)
        for body in self.tank_bodies:
            control = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
            control.position, control.angle = body.position, body.angle
            pivot = pymunk.PivotJoint(control, body, (0, 0), (0, 0))
            pivot.max_bias, pivot.max_force = 0.0, DRIVE_FORCE
            gear = pymunk.GearJoint(control, body, 0.0, 1.0)
            gear.max_bias, gear.max_force = 0.0, DRIVE_FORCE * 10
            space.add(control, pivot, gear)
            self.controls.append(control)

        space.on_collision(BULLET, WALL, begin=_bullet_wall, data=self)
        space.on_collision(BULLET, TANK, begin=_bullet_tank, data=self)
        space.on_collision(TANK, WALL, pre_solve=_tank_wall, data=self)

        # Game-facing state, all arrays (no attributes on pymunk objects).
        self.bullet_active = np.zeros(self.n_bullets, dtype=bool)
        self.bullet_bounces = np.zeros(self.n_bullets, dtype=np.int32)
        self.bullet_expire = np.zeros(self.n_bullets, dtype=np.int64)  # substep of expiry
        self.bullet_fired_tick = np.zeros(self.n_bullets, dtype=np.int64)
        self.bullet_owner = np.repeat(np.arange(n), cap)
        self.can_hit = ~np.eye(n, dtype=bool)  # can_hit[shooter, victim]
        self.grace_ticks = cfg.grace_ticks
        self.tank_present = np.ones(n, dtype=bool)
        self.wall_contact = np.zeros(n, dtype=bool)
        self.hits: list[tuple[int, int]] = []  # (bullet, victim) this tick
        self.bounces: list[Bounce] = []
        self.expired: list[int] = []  # bullets removed by the bounce or distance limit
        self.substep = 0
        self.tick = 0
        self._bounce_substep = np.full(self.n_bullets, -1, dtype=np.int64)
        self._next_expiry = np.iinfo(np.int64).max
        self._buffer = pymunk.batch.Buffer()
        n_bodies = 2 * n + self.n_bullets
        self.state = np.zeros((n_bodies, _FLOATS_PER_BODY))
        self.tank_state = self.state[:n]
        self.bullet_state = self.state[n:n + self.n_bullets]
        self.read_state()

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

    def fire(self, tank: int) -> int:
        """Spawn a bullet from the tank's muzzle; returns its slot, or -1 if the muzzle is
        in a wall or the tank has no free bullet slot."""
        x, y, a = self.tank_state[tank, :3]
        mx, my = self.muzzle(tank)
        if self.space.segment_query_first((x, y), (mx, my), self.cfg.bullet_radius, WALLS_ONLY):
            return -1
        lo = tank * self.capacity
        free = np.flatnonzero(~self.bullet_active[lo:lo + self.capacity])
        if free.size == 0:
            return -1
        b = lo + int(free[0])
        body = self.bullet_bodies[b]
        body.position = (mx, my)
        speed = self.cfg.bullet_speed
        body.velocity = (math.cos(a) * speed, math.sin(a) * speed)
        self.space.add(self.bullet_shapes[b])
        self.bullet_active[b] = True
        self.bullet_bounces[b] = 0
        self.bullet_fired_tick[b] = self.tick
        expire = self.substep + self.life_substeps
        self.bullet_expire[b] = expire
        self._next_expiry = min(self._next_expiry, expire)
        self.bullet_state[b, :2] = (mx, my)
        self.bullet_state[b, 3:5] = body.velocity
        return b

    def remove_tank(self, tank: int) -> None:
        """Take a dead tank out of the physics (its bullets fly on)."""
        if self.tank_present[tank]:
            self.space.remove(self.tank_shapes[tank])
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
        """Advance one tick; fills ``hits``, ``bounces``, ``expired``, ``wall_contact``."""
        self.hits.clear()
        self.bounces.clear()
        self.expired.clear()
        self.wall_contact[:] = False
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
        """First wall hit along a segment (walls only)."""
        return self.space.segment_query_first(start, end, radius, WALLS_ONLY)


def _bullet_wall(arbiter: pymunk.Arbiter, space: pymunk.Space, world: World) -> None:
    """Exact elastic ricochet: mirror the penetration out of the wall, reflect velocity."""
    arbiter.process_collision = False
    bullet_shape = arbiter.shapes[0]
    b = bullet_shape.slot
    if not world.bullet_active[b]:
        return
    body = bullet_shape.body
    points = arbiter.contact_point_set.points
    nx, ny = arbiter.normal  # from the bullet into the wall
    vx, vy = body.velocity
    vn = vx * nx + vy * ny
    if vn <= 0:  # already moving away (second face of a junction this substep)
        return
    first = world._bounce_substep[b] != world.substep
    if first:
        if world.bullet_bounces[b] >= world.cfg.bullet_max_bounces:
            world.despawn(b)
            world.expired.append(b)
            return
        world.bullet_bounces[b] += 1
        world._bounce_substep[b] = world.substep
    depth = -min(p.distance for p in points) if points else 0.0
    px, py = body.position
    body.position = (px - 2 * depth * nx, py - 2 * depth * ny)
    vx, vy = vx - 2 * vn * nx, vy - 2 * vn * ny
    scale = world.cfg.bullet_speed / math.hypot(vx, vy)
    body.velocity = (vx * scale, vy * scale)
    if first:
        world.bounces.append(Bounce(b, px - depth * nx, py - depth * ny))


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
    world.hits.append((b, victim))
    world.despawn(b)


def _tank_wall(arbiter: pymunk.Arbiter, space: pymunk.Space, world: World) -> None:
    world.wall_contact[arbiter.shapes[0].slot] = True

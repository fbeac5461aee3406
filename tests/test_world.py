"""Physics world: no escapes, exact ricochets, limits, tanks vs walls."""

import math

import numpy as np
import pymunk
import pytest

from alphatank.sim.config import PRESETS, game_config, replace
from alphatank.sim.mapspec import CELL_RANGE, load_map, map_text, parse_map, shipped_maps
from alphatank.sim.world import WALLS_ONLY, World, first_wall_hit, substeps_for


def _world(spec, cfg, poses):
    w = World(cfg, spec, np.asarray(poses, dtype=float))
    w.can_hit[:] = False  # bullets fly through tanks: only walls matter here
    return w


def _inside_walls(xy: np.ndarray, rects: np.ndarray) -> np.ndarray:
    x, y = xy[:, None, 0], xy[:, None, 1]
    return ((x > rects[None, :, 0]) & (x < rects[None, :, 2])
            & (y > rects[None, :, 1]) & (y < rects[None, :, 3])).any(axis=1)


@pytest.mark.parametrize("preset", sorted(PRESETS))
@pytest.mark.parametrize("speed_factor", [1, 2, 4, 8])
def test_bullets_never_escape_or_enter_walls(preset, speed_factor):
    """Thousands of bullets at random angles on every shipped map: 0 escapes, 0 wall
    penetrations, constant speed."""
    base = game_config(preset)
    cfg = replace(base, bullet_speed=base.bullet_speed * speed_factor,
                  bullet_max_distance=base.bullet_max_distance * 2, max_bullets=8)
    rng = np.random.default_rng(speed_factor)
    fired = escapes = inside = 0
    worst_speed = 0.0
    for name in shipped_maps():
        spec = load_map(name)
        rects = np.array(spec.wall_rects)
        floor = spec.floor_cells()
        for _ in range(25):
            cells = [floor[i] for i in rng.choice(len(floor), 2, replace=False)]
            poses = [(*spec.cell_center(c), 0.0) for c in cells]
            w = _world(spec, cfg, poses)
            x, y = poses[0][:2]
            for a in rng.uniform(-math.pi, math.pi, size=w.capacity):
                fired += w.spawn_bullet(0, x, y, a) >= 0
            while w.bullet_active.any():
                w.step()
                xy = w.bullet_state[w.bullet_active, :2]
                escapes += int(((xy[:, 0] < 0) | (xy[:, 0] > spec.width)
                                | (xy[:, 1] < 0) | (xy[:, 1] > spec.height)).sum())
                inside += int(_inside_walls(xy, rects).sum())
                v = np.hypot(*w.bullet_state[w.bullet_active, 3:5].T)
                if v.size:
                    worst_speed = max(worst_speed, float(np.abs(v / cfg.bullet_speed - 1).max()))
    assert fired >= 1000
    assert escapes == 0 and inside == 0
    assert worst_speed < 1e-6


def test_substeps_grow_with_bullet_speed():
    spec = load_map("maze")
    slow = substeps_for(game_config(), spec.min_wall_thickness())
    fast = substeps_for(game_config("long_range", bullet_speed=4800.0), spec.min_wall_thickness())
    assert fast > slow >= 1
    cfg = game_config("long_range", bullet_speed=4800.0)
    per_substep = cfg.bullet_speed / cfg.tick_hz / fast
    assert per_substep <= 0.8 * (spec.cell / 2 + cfg.bullet_radius)


CORRIDOR = "name: corridor\n\n#######\n#.....#\n#######\n"


def test_bullet_disappears_exactly_at_bounce_limit():
    spec = parse_map(CORRIDOR)
    cfg = game_config(bullet_max_distance=1e6, bullet_max_bounces=3)
    w = _world(spec, cfg, [(105, 105, 0), (315, 105, 0)])
    b = w.spawn_bullet(0, 210.0, 105.0, 0.0)  # flies along the corridor, wall to wall
    bounces, died_on = 0, None
    for _ in range(1000):
        w.step()
        bounces += sum(1 for e in w.bounces if e.bullet == b)
        if not w.bullet_active[b]:
            died_on = w.tick
            break
    assert bounces == 3 and died_on is not None
    assert w.bullet_bounces[b] == 3


def test_bullet_disappears_exactly_at_distance_limit():
    spec = load_map("open")
    cfg = game_config(bullet_max_distance=200.0)
    w = _world(spec, cfg, [(105, 105, 0), (665, 665, 0)])
    b = w.spawn_bullet(0, 200.0, 385.0, 0.0)  # 200 px of free floor ahead
    per_tick = cfg.bullet_speed / cfg.tick_hz
    ticks = 0
    while w.bullet_active[b]:
        last_x = w.bullet_state[b, 0]
        w.step()
        ticks += 1
    assert ticks == math.ceil(200.0 / per_tick)
    assert last_x - 200.0 < 200.0 <= last_x - 200.0 + per_tick


def test_ricochet_is_a_mirror_reflection():
    spec = load_map("open")
    cfg = game_config(bullet_max_distance=400.0)
    w = _world(spec, cfg, [(105, 105, 0), (665, 665, 0)])
    angle = math.radians(-30)  # up and to the right, toward the top wall (y = 70)
    b = w.spawn_bullet(0, 385.0, 200.0, angle)
    while not w.bounces:
        w.step()
    bounce = w.bounces[0]
    assert bounce.y == pytest.approx(70 + cfg.bullet_radius, abs=1e-9)
    vx, vy = w.bullet_state[b, 3:5]
    assert math.atan2(vy, vx) == pytest.approx(-angle, abs=1e-9)


def _box_rect_depth(x, y, a, w, h, rect) -> float:
    """Separating-axis penetration depth of an oriented w x h box into a rectangle."""
    u = np.array([math.cos(a), math.sin(a)])
    v = np.array([-math.sin(a), math.cos(a)])
    corners = np.array([(x, y) + su * w / 2 * u + sv * h / 2 * v
                        for su in (-1, 1) for sv in (-1, 1)])
    x0, y0, x1, y1 = rect
    rect_corners = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
    depth = math.inf
    for axis in (np.array([1.0, 0.0]), np.array([0.0, 1.0]), u, v):
        p, q = corners @ axis, rect_corners @ axis
        overlap = min(p.max(), q.max()) - max(p.min(), q.min())
        if overlap <= 0:
            return 0.0
        depth = min(depth, overlap)
    return depth


def _max_overlap(w: World, tank: int) -> float:
    """Deepest penetration (px) of a tank's exact box into any wall or the boundary."""
    spec, t = w.spec, w.spec.cell
    W, H = spec.width, spec.height
    rects = [*spec.wall_rects, (-t, -t, W + t, 0), (-t, H, W + t, H + t), (-t, 0, 0, H),
             (W, 0, W + t, H)]
    x, y, a = w.tank_state[tank, :3]
    return max(_box_rect_depth(x, y, a, w.cfg.tank_width, w.cfg.tank_height, r) for r in rects)


@pytest.mark.parametrize("seed", range(3))
def test_tanks_never_sink_into_walls(seed):
    spec = load_map("maze")
    cfg = game_config()
    rng = np.random.default_rng(seed)
    w = _world(spec, cfg, [(105, 105, 0.3), (665, 665, 2.0)])
    worst = 0.0
    for t in range(2000):
        if t % 20 == 0:
            cmds = rng.integers(-1, 2, size=(2, 2))
        for i in range(2):
            w.drive(i, int(cmds[i, 0]), 1 if cmds[i, 1] >= 0 else -1)
        w.step()
        worst = max(worst, _max_overlap(w, 0), _max_overlap(w, 1))
    assert worst < 1.0


def test_tanks_turn_and_drive_in_corridors_of_the_smallest_cell():
    smallest = f"name: maze\ncell: {CELL_RANGE[0]:g}\n"  # a corridor maze of 39 px cells
    text = map_text(load_map("maze")).replace("name: maze\n", smallest)
    spec = parse_map(text, "small.txt")
    cfg = game_config()
    rng = np.random.default_rng(0)
    a, b = spec.cell_center((1, 1)), spec.cell_center((9, 9))
    w = _world(spec, cfg, [(*a, math.pi / 4), (*b, 0.9)])  # 0.9 rad: the box's diagonal
    worst = max(_max_overlap(w, 0), _max_overlap(w, 1))
    for t in range(600):
        if t % 20 == 0:
            cmds = rng.integers(-1, 2, size=(2, 2))
        for i in range(2):
            w.drive(i, int(cmds[i, 0]), 1 if cmds[i, 1] >= 0 else -1)
        w.step()
        worst = max(worst, _max_overlap(w, 0), _max_overlap(w, 1))
    assert worst < 1.0


def test_a_tank_cannot_push_another_through_a_wall():
    spec = load_map("open")
    cfg = game_config()
    # B sits against the right wall (x = 700); A drives into B from the left.
    w = _world(spec, cfg, [(600, 385, 0.0), (680, 385, 0.0)])
    for _ in range(300):
        w.drive(0, 0, 1)
        w.drive(1, 0, 0)
        w.step()
    bx = w.tank_state[1, 0]
    assert bx + cfg.tank_width / 2 <= 700 + 1.0
    assert _max_overlap(w, 1) < 1.0
    assert w.tank_state[0, 0] < bx  # A did not pass through B either


def test_rounded_wall_twin_answers_like_the_sharp_walls():
    """Swept-bullet queries against the walls rounded by the bullet radius give the very
    alpha and normal of radius-r queries against the sharp walls (bit for bit)."""
    spec = load_map("maze")
    cfg = game_config()
    w = _world(spec, cfg, [(105, 105, 0), (665, 665, 0)])
    rng = np.random.default_rng(5)
    hits = 0
    for _ in range(3000):
        x0, y0 = rng.uniform(-10, spec.width + 10, size=2)
        a, length = rng.uniform(-math.pi, math.pi), rng.uniform(0, 400)
        x1, y1 = x0 + math.cos(a) * length, y0 + math.sin(a) * length
        fast = w.wall_hit(x0, y0, x1, y1, cfg.bullet_radius)
        slow = first_wall_hit(w.space, x0, y0, x1, y1, cfg.bullet_radius)
        assert (fast is None) == (slow is None)
        if fast is not None and slow.alpha > 0:  # alpha 0: starts inside, normal is moot
            assert (fast.alpha, tuple(fast.normal)) == (slow.alpha, tuple(slow.normal))
            hits += 1
    assert hits > 800


def test_state_matches_every_body_after_steps():
    """``state`` rows equal every body's pymunk attributes after steps, shots and kills."""
    spec = load_map("maze")
    cfg = game_config()
    w = World(cfg, spec, np.array([(105, 105, 0.3), (665, 665, 2.0), (385, 385, 1.0)]))
    rng = np.random.default_rng(0)
    for t in range(200):
        for i in range(3):
            w.drive(i, int(rng.integers(-1, 2)), int(rng.integers(-1, 2)))
            if t % 7 == 0:
                w.fire(i)
        if t == 100:
            w.remove_tank(2)
        w.step()
    bodies = w.tank_bodies + w.bullet_bodies + w.controls
    expect = [(*b.position, b.angle, *b.velocity, b.angular_velocity) for b in bodies]
    assert np.array_equal(w.state, np.array(expect))
    assert w.bullet_active.any()


def test_tank_rows_follow_every_read_of_the_state():
    """``tank_rows()`` (the bots' per-read list of the tanks' poses) equals
    ``tank_state`` after every tick, and after a teleport once the state is read again."""
    spec = load_map("maze")
    w = World(game_config(), spec, np.array([(105, 105, 0.3), (665, 665, 2.0)]))
    rng = np.random.default_rng(1)
    for t in range(60):
        w.tank_rows()  # read before the tick, as the bots do
        for i in range(2):
            w.drive(i, int(rng.integers(-1, 2)), int(rng.integers(-1, 2)))
        w.step()
        assert w.tank_rows() == w.tank_state.tolist(), t
    before = w.tank_rows()
    w.place_tank(0, 385.0, 385.0, 1.0)
    w.read_state()
    assert w.tank_rows()[0][:3] == [385.0, 385.0, 1.0] != before[0][:3]
    assert w.tank_rows() == w.tank_state.tolist()


def _box_hit(shape, path: np.ndarray, radius: float) -> bool:
    return any(shape.segment_query(tuple(a), tuple(b), radius) is not None
               for a, b in zip(path[:-1], path[1:], strict=True))


@pytest.mark.parametrize("map_name", ["open", "maze"])
def test_bullets_hit_exactly_the_tanks_their_path_touches(map_name):
    """A still tank is hit iff the bullet's exact path (ricochets included, also inside
    the substep of a ricochet) passes within the bullet radius of its box; the
    ricochets made before the hit are reported."""
    from alphatank.sim.ballistics import predict_path

    spec = load_map(map_name)
    cfg = game_config()
    rng = np.random.default_rng(1)
    floor = spec.floor_cells()
    hits = after_bounce = checked = 0
    for _ in range(150):
        cells = [floor[i] for i in rng.choice(len(floor), 2, replace=False)]
        target = (*spec.cell_center(cells[1]), float(rng.uniform(-math.pi, math.pi)))
        w = World(cfg, spec, np.array([(*spec.cell_center(cells[0]), 0.0), target]))
        w.can_hit[0, 1] = True
        box = w.hitboxes[1]
        for _ in range(4):
            x, y = np.array(spec.cell_center(cells[1])) + rng.uniform(-35, 35, size=2)
            a = float(rng.uniform(-math.pi, math.pi))
            if (box.point_query((x, y)).distance < 2 * cfg.bullet_radius
                    or w.wall_hit(x, y, x, y, cfg.bullet_radius) is not None):
                continue
            path = predict_path(w, x, y, a)
            b = w.spawn_bullet(0, x, y, a)
            bounces, hit = 0, False
            while w.bullet_active[b]:
                w.step()
                bounces += sum(1 for e in w.bounces if e.bullet == b)
                hit = hit or any(h == (b, 1) for h in w.hits)
            assert hit == _box_hit(box, path, cfg.bullet_radius), (x, y, a)
            if hit:  # ricochets before the hit are the predicted ones before the box
                before = next(k for k in range(1, len(path))
                              if _box_hit(box, path[k - 1:k + 1], cfg.bullet_radius))
                assert bounces == before - 1
            checked += 1
            hits += hit
            after_bounce += hit and bounces > 0
    assert checked > 300 and hits > 30 and after_bounce > 5


def test_a_ricochet_and_a_hit_in_the_same_substep():
    """A bullet that grazes past a tank into a wall and comes back off it within one
    substep hits the tank in that substep, after the bounce is recorded."""
    spec = load_map("open")  # the right wall's face is x = 700
    cfg = game_config()
    w = World(cfg, spec, np.array([(105.0, 105.0, 0.0), (684.0, 385.0, 0.0)]))
    # Tank 1's box spans x 669..699, y 373..397. The bullet flies up-right at 45 degrees
    # and touches the wall 0.5 px below the box's reach, 0.1 px into its third substep.
    a, s = -math.pi / 4, 0.1 + 2 * w.step_len
    cx, cy = 700 - cfg.bullet_radius, 397 + cfg.bullet_radius + 0.5
    b = w.spawn_bullet(0, cx - s * math.cos(a), cy - s * math.sin(a), a)
    w.step()
    assert w.bullet_active[b] and not w.bounces and not w.hits
    w.step()
    assert [(e.bullet, e.x, e.y) for e in w.bounces] == [
        (b, pytest.approx(cx, abs=1e-9), pytest.approx(cy, abs=1e-9))]
    assert w.hits == [(b, 1)] and not w.bullet_active[b] and w.bullet_bounces[b] == 1


def test_direct_chipmunk_calls_match_pymunk():
    """alphatank.sim.cp makes the very calls of the pymunk methods it stands for."""
    import pymunk

    from alphatank.sim import cp

    spec = load_map("maze")
    w = _world(spec, game_config(), [(105, 105, 0), (665, 665, 0)])
    first = cp.FirstHit(w.bullet_walls, 0.0, pymunk.ShapeFilter())
    rng = np.random.default_rng(2)
    for _ in range(500):
        x0, y0, x1, y1 = rng.uniform(-10, spec.width + 10, size=4)
        fast, slow = first(x0, y0, x1, y1), w.bullet_walls.segment_query_first(
            (x0, y0), (x1, y1), 0.0, pymunk.ShapeFilter())
        assert (fast is None) == (slow is None)
        if slow is not None:
            assert fast == (cp.handle(slow.shape), tuple(slow.normal), slow.alpha)
    near, found = cp.NearestDistance(w.space, WALLS_ONLY), 0
    for _ in range(500):
        x, y = rng.uniform(-10, spec.width + 10, size=2)
        r = float(rng.choice([0.0, 4.0, 30.0]))
        slow = w.space.point_query_nearest((x, y), r, WALLS_ONLY)
        assert near(x, y, r) == (None if slow is None else slow.distance)
        found += slow is not None
    assert found
    body = w.controls[0]
    cp.set_position(body, 1.5, -2.5)
    cp.set_velocity(body, 3.25, 4.0)
    cp.set_angular_velocity(body, -0.75)
    assert (body.position, body.velocity, body.angular_velocity) == ((1.5, -2.5), (3.25, 4.0),
                                                                      -0.75)


def test_direct_space_step_matches_pymunk_with_deferred_work():
    """cp.space_step steps a space as pymunk's Space.step does: the first step checks
    new bodies, removals and additions made by callbacks wait for the end of the step,
    post-step callbacks run once, and the trajectories are bit-identical."""
    import pymunk

    from alphatank.sim import cp

    def scene(stepper):
        space = pymunk.Space()
        log = []
        ball = pymunk.Body(1.0, 10.0)
        ball.position, ball.velocity = (0.0, 0.0), (30.0, 7.0)
        disc = pymunk.Circle(ball, 2.0)
        disc.collision_type = 1
        wall = pymunk.Segment(space.static_body, (20.0, -50.0), (20.0, 50.0), 1.0)
        wall.collision_type, wall.elasticity, disc.elasticity = 2, 1.0, 1.0
        late = pymunk.Circle(space.static_body, 1.0, (100.0, 100.0))

        def begin(arbiter, space, data):
            log.append(("begin", space._locked))
            space.remove(wall)  # deferred until the step ends
            space.add(late)
            space.add_post_step_callback(lambda s, key: log.append((key, len(s.shapes))), "post")

        space.on_collision(1, 2, begin=begin)
        space.add(ball, disc, wall)
        path = []
        for _ in range(60):
            stepper(space, 0.05)
            path.append((*ball.position, *ball.velocity, len(space.shapes), space._locked))
        return path, log

    fast = scene(cp.space_step)
    slow = scene(lambda space, dt: space.step(dt))
    assert fast == slow
    assert fast[1] == [("begin", True), ("post", 2)]  # the wall gone, the late disc in


def test_pymunk_attribute_hooks_are_dropped_only_when_they_pass_through():
    import pickle

    import pymunk
    from pymunk._typing_attr import TypingAttrMixing

    from alphatank.sim.cp import plain_attributes

    # pymunk's own mixin lost its pass-through hooks at import; attributes behave as before
    assert "__setattr__" not in TypingAttrMixing.__dict__
    assert "__getattr__" not in TypingAttrMixing.__dict__
    body = pymunk.Body(1.0, 2.0)
    shape = pymunk.Circle(body, 3.0)
    shape.collision_type, shape.slot = 7, 4
    assert (shape.collision_type, shape.slot, shape.body is body) == (7, 4, True)
    with pytest.raises(AttributeError, match="no_such"):
        _ = shape.no_such
    copy = pickle.loads(pickle.dumps(shape))
    assert (copy.collision_type, copy.radius, copy.slot) == (7, 3.0, 4)

    class PassThrough:
        def __setattr__(self, name, value):
            super().__setattr__(name, value)

        def __getattr__(self, name):
            return self.__getattribute__(name)

    class Busy:  # a hook with work of its own: kept
        writes: list[str] = []

        def __setattr__(self, name, value):
            type(self).writes.append(name)
            super().__setattr__(name, value)

    assert plain_attributes(PassThrough) is True
    assert "__setattr__" not in PassThrough.__dict__ and "__getattr__" not in PassThrough.__dict__
    assert plain_attributes(Busy) is False
    Busy().x = 1
    assert Busy.writes == ["x"]


def test_worlds_on_one_map_share_its_rounded_walls_and_answer_as_fresh_ones():
    """The query-only rounded walls are built once per map and radius: worlds on one map
    share them (the bots' sight too), another map or radius gets its own, and a shared
    space answers every swept query exactly as a freshly built one."""
    from alphatank.sim.sight import wall_sight
    from alphatank.sim.world import rounded_walls

    cfg, maze = game_config(), load_map("maze")
    a = _world(maze, cfg, [(105, 105, 0), (665, 665, 0)])
    for _ in range(3):
        _world(load_map("open"), cfg, [(105, 105, 0), (300, 300, 0)])
    b = _world(maze, cfg, [(175, 105, 1.0), (665, 595, 2.0)])
    assert a.bullet_walls is b.bullet_walls
    assert _world(load_map("open"), cfg, [(105, 105, 0)]).bullet_walls is not a.bullet_walls
    sight = wall_sight(b)
    sight._walls_rounded(cfg.bullet_radius)
    assert sight._rounded[cfg.bullet_radius][0] is b.bullet_walls
    assert sight._walls_rounded(9.0) != sight._walls_rounded(cfg.bullet_radius)
    fresh = rounded_walls(maze, cfg.bullet_radius)
    rng = np.random.default_rng(5)
    for _ in range(300):
        x0, y0, x1, y1 = rng.uniform(-10, maze.width + 10, size=4)
        got = b.wall_hit(x0, y0, x1, y1, cfg.bullet_radius)
        want = fresh.segment_query_first((x0, y0), (x1, y1), 0.0, pymunk.ShapeFilter())
        assert (got is None) == (want is None)
        if want is not None:
            assert (tuple(got.point), tuple(got.normal), got.alpha) == (
                tuple(want.point), tuple(want.normal), want.alpha)

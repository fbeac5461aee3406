"""Observations: index map, hand-placed tanks and bullets, rays against known walls,
digests pinned per env version."""

from __future__ import annotations

import hashlib
import math
from collections.abc import Iterator

import numpy as np
import pytest

from alphatank.envs.core import MatchSet
from alphatank.envs.ids import ENV_VERSION
from alphatank.game.observe import (
    DEFAULT_RAY_LENGTH,
    OBS_KINDS,
    GlobalState,
    ObservationBuilder,
    StateBatch,
    constant,
    room_misfit,
    slot_counts,
)
from alphatank.game.scenarios import load_scenario, parse_scenario
from alphatank.sim.config import hit_radius
from alphatank.sim.match import Match

W = H = 770.0
DIAG = math.hypot(W, H)


def duel(kind: str, map_name: str = "open", teams: tuple[str, ...] = ("A", "B")) -> MatchSet:
    seats = [{"team": t, "controller": "learner"} for t in teams]
    sc = parse_scenario({"name": "duel", "map": map_name, "observation": kind, "seats": seats})
    ms = MatchSet(sc, 1)
    ms.reset_env(0, 1)
    return ms


def place(ms: MatchSet, poses, bullets=()) -> np.ndarray:
    """Put tanks at (x, y, angle) and bullets (owner, slot, x, y, vx, vy); return obs."""
    m = ms.matches[0]
    w = m.world
    for i, (x, y, a) in enumerate(poses):
        body = w.tank_bodies[i]
        body.position, body.angle, body.velocity = (x, y), a, (0.0, 0.0)
        w.controls[i].position, w.controls[i].angle = (x, y), a
    w.bullet_active[:] = False
    for owner, slot, x, y, vx, vy in bullets:
        b = owner * w.capacity + slot
        w.bullet_active[b] = True
        w.bullet_bodies[b].position, w.bullet_bodies[b].velocity = (x, y), (vx, vy)
    w.read_state()
    ms.batch.gather(0, m)
    return ms.obs.build()


def feat(ms: MatchSet, obs: np.ndarray, name: str, learner: int = 0) -> float:
    return float(obs[0, learner, ms.obs.layout[name]][0])


@pytest.mark.parametrize("kind", OBS_KINDS)
def test_index_map_is_complete_and_contiguous(kind):
    ms = duel(kind, "arena4", ("A", "A", "B", "B"))
    lay = ms.obs.layout
    assert lay.size == ms.obs_dim == ms.obs.out.shape[-1]
    assert len(lay.fields) == lay.size == len(set(lay.fields))
    for k, name in enumerate(lay.fields):
        assert lay[name] == slice(k, k + 1)
    blocks = lay.blocks()
    assert lay[blocks[0]].start == 0 and lay[blocks[-1]].stop == lay.size
    for a, b in zip(blocks, blocks[1:], strict=False):
        assert lay[a].stop == lay[b].start
    assert "tank[2].team" in lay and "bullet[0].team" in lay  # team scenario flags
    assert all(b in lay.describe() for b in blocks)
    with pytest.raises(KeyError, match="blocks"):
        lay["self.colour"]
    obs = ms.obs.build()
    assert obs.dtype == np.float32 and np.abs(obs).max() <= 1.0


def test_paper_features_equal_hand_computed_values():
    ms = duel("paper")
    x0, y0, a0 = 200.0, 300.0, 0.3
    x1, y1, a1 = 500.0, 600.0, -2.0
    obs = place(ms, [(x0, y0, a0), (x1, y1, a1)],
                bullets=[(0, 2, 250.0, 310.0, 300.0, 0.0),  # own bullet in slot 2
                         (1, 0, 480.0, 300.0, 0.0, -300.0),  # enemy bullets: far ...
                         (1, 3, 220.0, 330.0, -300.0, 0.0)])  # ... and near
    f = lambda name: feat(ms, obs, name)  # noqa: E731
    assert f("self.x") == pytest.approx(2 * x0 / W - 1, abs=1e-6)
    assert f("self.y") == pytest.approx(2 * y0 / H - 1, abs=1e-6)
    assert f("self.sin") == pytest.approx(math.sin(a0), abs=1e-6)
    assert f("self.cos") == pytest.approx(math.cos(a0), abs=1e-6)
    assert f("self.alive") == 1.0
    # Front-left corner (eq. 2): centre + R(angle) @ (w/2, -h/2).
    cx = x0 + math.cos(a0) * 15 - math.sin(a0) * -12
    cy = y0 + math.sin(a0) * 15 + math.cos(a0) * -12
    assert f("self.c0x") == pytest.approx(2 * cx / W - 1, abs=1e-6)
    assert f("self.c0y") == pytest.approx(2 * cy / H - 1, abs=1e-6)
    assert f("tank[0].x") == pytest.approx(2 * x1 / W - 1, abs=1e-6)
    assert f("tank[0].rel_x") == pytest.approx((x1 - x0) / W, abs=1e-6)
    assert f("tank[0].rel_y") == pytest.approx((y1 - y0) / W, abs=1e-6)
    assert f("tank[0].dist") == pytest.approx(math.hypot(x1 - x0, y1 - y0) / DIAG, abs=1e-6)
    assert f("tank[0].sin") == pytest.approx(math.sin(a1), abs=1e-6)
    # Own bullets stay in their slot; empty slots are all zero.
    assert f("own_bullet[2].mask") == 1.0
    assert f("own_bullet[2].x") == pytest.approx(2 * 250 / W - 1, abs=1e-6)
    assert f("own_bullet[2].vx") == pytest.approx(1.0, abs=1e-6)
    assert not obs[0, 0, ms.obs.layout["own_bullet[0]"]].any()
    # Enemy bullets nearest first, with relative position and distance.
    assert f("bullet[0].mask") == f("bullet[1].mask") == 1.0
    assert f("bullet[0].rel_x") == pytest.approx((220 - x0) / W, abs=1e-6)
    assert f("bullet[0].dist") == pytest.approx(math.hypot(20, 30) / DIAG, abs=1e-6)
    assert f("bullet[0].vx") == pytest.approx(-1.0, abs=1e-6)
    assert f("bullet[1].rel_x") == pytest.approx((480 - x0) / W, abs=1e-6)
    assert f("bullet[1].vy") == pytest.approx(-1.0, abs=1e-6)
    assert not obs[0, 0, ms.obs.layout["bullet[2]"]].any()
    # Walls (static): the first merged rectangle of the open map is its top row.
    assert f("wall[0].mask") == 1.0
    assert [f(f"wall[0].{k}") for k in ("x0", "y0", "x1", "y1")] == pytest.approx(
        [-1.0, -1.0, 1.0, 2 * 70 / H - 1], abs=1e-6)
    # Once the bullets are gone their slots are zero again.
    obs = place(ms, [(x0, y0, a0), (x1, y1, a1)])
    lay = ms.obs.layout
    assert not obs[0, 0, lay["bullet"]].any() and not obs[0, 0, lay["own_bullet"]].any()


def test_zones_and_flags():
    ms = duel("paper", "arena4")
    m = ms.matches[0]
    (br, bc), = m.buffs
    bx, by = m.spec.cell_center((br, bc))
    obs = place(ms, [(bx, by, 0.0), (100.0, 100.0, 0.0)])
    m._update_zones(report=False)
    ms.batch.gather(0, m)
    obs = ms.obs.build()
    assert feat(ms, obs, "buff[0].mask") == 1.0
    assert feat(ms, obs, "buff[0].x") == pytest.approx(2 * bx / m.spec.width - 1, abs=1e-6)
    assert feat(ms, obs, "zone.in_buff") == 1.0 and feat(ms, obs, "zone.in_debuff") == 0.0


def test_team_flags_and_order_teammates_first():
    ms = duel("paper", "arena4", ("A", "B", "A", "B"))
    obs = ms.obs.build()
    # Seat 0's others: seat 2 (mate), then seats 1 and 3.
    assert [feat(ms, obs, f"tank[{k}].team") for k in range(3)] == [1.0, 0.0, 0.0]
    xs = ms.matches[0].tank_xy[:, 0]
    assert feat(ms, obs, "tank[0].x") == pytest.approx(2 * xs[2] / ms.matches[0].spec.width - 1,
                                                       abs=1e-6)
    assert [feat(ms, obs, f"tank[{k}].team", learner=1) for k in range(3)] == [1.0, 0.0, 0.0]


def test_nearest_kind_is_the_egocentric_one_with_tanks_nearest_first():
    teams = ("A", "B", "A", "B", "B")
    poses = [(385.0, 385.0, 0.3), (600.0, 385.0, 1.0), (100.0, 100.0, 2.0),
             (385.0, 300.0, -1.0), (150.0, 600.0, 0.5)]
    ego, near = duel("egocentric", "arena8", teams), duel("egocentric_nearest", "arena8", teams)
    for ms in (ego, near):
        ms.matches[0].alive[3] = False  # the nearest enemy of seat 0 is dead
    a, b = place(ego, poses), place(near, poses)
    lay = ego.obs.layout
    assert near.obs.layout.fields == lay.fields
    w = lay.widths["tank"]
    tanks = lambda obs, o: obs[0, o, lay["tank"]].reshape(-1, w)  # noqa: E731
    # Seat 0 (learner 0): others by seat are [mate 2, enemies 1, 3, 4]; nearest first among
    # the living enemies: 1 (215 px), 4 (~302 px), then the dead 3.
    assert np.array_equal(tanks(b, 0), tanks(a, 0)[[0, 1, 3, 2]])
    assert feat(near, b, "tank[1].dist") < feat(near, b, "tank[2].dist")
    assert feat(near, b, "tank[3].alive") == 0.0
    # Every observer's slots are a permutation of its egocentric slots, teammates first.
    for o in range(len(teams)):
        ta, tb = tanks(a, o), tanks(b, o)
        assert sorted(map(tuple, ta)) == sorted(map(tuple, tb))
        assert np.array_equal(ta[:, lay.column("tank", "team")],
                              tb[:, lay.column("tank", "team")])
    # Outside the tank block the two kinds agree.
    rest = np.ones(lay.size, dtype=bool)
    rest[lay["tank"]] = False
    assert np.array_equal(a[..., rest], b[..., rest])
    # A 1v1 has one other tank: the kinds are the same observation.
    poses2 = poses[:2]
    assert np.array_equal(place(duel("egocentric"), poses2),
                          place(duel("egocentric_nearest"), poses2))


def test_aim_kind_adds_the_shot_of_a_bullet_fired_now():
    teams = ("A", "A", "B", "B")
    near, aim = duel("egocentric_nearest", "open", teams), duel("egocentric_aim", "open", teams)
    # Seat 0 at the centre facing +x; enemy 2 straight ahead, enemy 3 and mate 1 far off.
    poses = [(385.0, 385.0, 0.0), (150.0, 150.0, 0.0), (560.0, 385.0, 0.0),
             (150.0, 620.0, 0.0)]
    a, b = place(near, poses), place(aim, poses)
    lay = aim.obs.layout
    assert lay.fields[:near.obs.layout.size] == near.obs.layout.fields  # the shot comes last
    assert np.array_equal(a, b[..., :near.obs.layout.size])
    f = lambda obs, name, o=0: feat(aim, obs, name, learner=o)  # noqa: E731
    assert (f(b, "shot.enemy"), f(b, "shot.friend"), f(b, "shot.miss")) == (1.0, 0.0, 0.0)
    # The mate steps into the line of fire: the bullet would reach it first.
    poses[1] = (470.0, 385.0, 0.0)
    b = place(aim, poses)
    assert (f(b, "shot.enemy"), f(b, "shot.friend")) == (0.0, 1.0)
    # Both near the same leg: the enemy's centre comes first along it, but 15 px off the
    # line, and the bullet enters the centred mate's reach first.
    g = aim.matches[0].cfg
    r, start = hit_radius(g), 385.0 + g.tank_width / 2 + g.bullet_radius + 0.5
    enemy_x = start + 100.0
    mate_x = enemy_x + 6.0  # enters at 106 - r, the enemy at 100 - sqrt(r^2 - 15^2)
    assert mate_x - r < enemy_x - math.sqrt(r * r - 15.0 ** 2)
    poses[1], poses[2] = (mate_x, 385.0, 0.0), (enemy_x, 400.0, 0.0)
    b = place(aim, poses)
    assert (f(b, "shot.enemy"), f(b, "shot.friend")) == (0.0, 1.0)
    poses[1] = (mate_x + 20.0, 385.0, 0.0)  # the mate further on: the enemy is reached
    b = place(aim, poses)
    assert (f(b, "shot.enemy"), f(b, "shot.friend")) == (1.0, 0.0)
    poses[2] = (560.0, 385.0, 0.0)
    # Turned a quarter away (down the screen): the bullet hits the wall 315 px below, after
    # 300 px of travel at most; the closest it gets to enemy 2 is from its start.
    poses[0] = (385.0, 385.0, math.pi / 2)
    poses[1] = (150.0, 150.0, 0.0)
    b = place(aim, poses)
    assert (f(b, "shot.enemy"), f(b, "shot.friend")) == (0.0, 0.0)
    assert f(b, "shot.miss") == pytest.approx(
        min(math.hypot(175.0, start - 385.0), 175.0 * math.sqrt(2)) / g.bullet_max_distance,
        abs=1e-4)
    # A dead observer sees no shot.
    aim.matches[0].alive[0] = False
    b = place(aim, poses)
    assert b[0, 0, lay["shot"]].tolist() == [0.0, 0.0, 0.0]


def test_aim_kind_agrees_with_the_bots_shot_prediction():
    """In played positions (ricochets included) ``shot.enemy`` is the bots' own test of a
    shot fired now (``Bot.shot_hits``, search grade) for every live learner."""
    from bots.registry import make_bot

    teams = ("A", "A", "B", "B", "B")
    ms = duel("egocentric_aim", "arena8", teams)
    m = ms.matches[0]
    bot = make_bot("smart", seed=0)
    players = [make_bot("smart", seed=k) for k in range(5)]  # they aim: shots that hit
    for k, p in enumerate(players):
        p.reset(m, k)
    seen = {0.0: 0, 1.0: 0}
    for t in range(400):
        m.step(np.stack([p.act(m, k) for k, p in enumerate(players)]))
        if m.done:
            break
        ms.batch.gather(0, m)
        obs = ms.obs.build()
        for o in range(5):
            if m.alive[o]:
                bot.reset(m, o)
                want = float(bot.shot_hits(m, o, exact=False)[0])
                assert feat(ms, obs, "shot.enemy", learner=o) == want, (t, o)
                seen[want] += 1
    assert seen[1.0] > 0 and seen[0.0] > 0


def test_shots_of_many_envs_are_each_paths_own_reach():
    """The shot block of a batch of envs, reached for every env and seat at once, is
    what :func:`path_hits` and :func:`path_distances` give on each seat's own predicted
    path in its own match (dead seats and teammates in the way included)."""
    from alphatank.sim.ballistics import path_distances, path_hits, predict_path

    sc = load_scenario("team_vs_four_bots")
    ms = MatchSet(sc, 3, observation="egocentric_aim")
    obs = ms.reset_all([5, 6, 7])
    lay, rng = ms.obs.layout, np.random.default_rng(3)
    cols = [lay[f"shot.{k}"].start for k in ("enemy", "friend", "miss")]
    seen = np.zeros(3)  # enemy, friend, dead observers
    for _ in range(300):
        for e, m in enumerate(ms.matches):
            g, r = m.cfg, hit_radius(m.cfg)
            for o, seat in enumerate(sc.learner_seats):
                got = obs[e, o, cols].tolist()
                if not m.alive[seat]:
                    assert got == [0.0, 0.0, 0.0]
                    seen[2] += 1
                    continue
                path = predict_path(m.world, *m.world.muzzle(seat),
                                    float(m.tank_angle[seat]), exact=False)
                others = np.flatnonzero(m.alive)
                others = others[others != seat]
                k = path_hits(path, m.tank_xy[others], r)
                mate = m.team_index[others] == m.team_index[seat]
                foes = others[~mate]
                miss = (min(path_distances(path, m.tank_xy[foes]).min()
                            / g.bullet_max_distance, 1.0) if len(foes) else 1.0)
                want = [float(k >= 0 and not mate[k]), float(k >= 0 and mate[k])]
                assert got[:2] == want and got[2] == pytest.approx(miss, rel=1e-6)
                seen[:2] += want
        acts = rng.integers((3, 3, 2), size=(3, len(sc.learner_seats), 3))
        _, obs = ms.step(acts)
        for e in range(3):
            if ms.terminated[e] or ms.truncated[e]:
                ms.reset_env(e, 100 + e)
        obs = ms.obs.build()
    assert seen.min() > 0


def test_aim_path_kind_is_the_aim_kind_with_the_way_to_each_tank():
    """``egocentric_aim_path``: every feature of ``egocentric_aim`` (slots nearest first,
    the shot block) plus ``egocentric_path``'s way to each tank, moved with its slot."""
    teams = ("A", "B", "A", "B", "B")
    poses = [(105.0, 105.0, 0.3), (665.0, 385.0, 1.0), (385.0, 665.0, 2.0),
             (245.0, 105.0, -1.0), (525.0, 525.0, 0.5)]
    kinds = ("egocentric_aim", "egocentric_path", "egocentric_aim_path")
    aim, path, both = (place(duel(k, "maze", teams), poses) for k in kinds)
    lay_aim, lay_path, lay = (duel(k, "maze", teams).obs.layout for k in kinds)
    assert set(lay.fields) == set(lay_aim.fields) | set(lay_path.fields)
    for name in lay_aim.fields:
        assert np.array_equal(both[..., lay[name]], aim[..., lay_aim[name]]), name
    # Path fields follow their tank: match egocentric_path's seat-order slots by position.
    where = lambda obs, lay, k: tuple(obs[0, o, lay[f"tank[{k}].{f}"]][0]  # noqa: E731
                                      for f in ("fwd", "side"))
    for o in range(len(teams)):
        for k in range(len(teams) - 1):
            j = [i for i in range(len(teams) - 1)
                 if where(path, lay_path, i) == where(both, lay, k)]
            assert len(j) == 1
            for f in ("path_fwd", "path_side", "path_dist"):
                assert (both[0, o, lay[f"tank[{k}].{f}"]][0]
                        == path[0, o, lay_path[f"tank[{j[0]}].{f}"]][0])
    assert np.abs(both[..., lay["tank[0].path_fwd"]]).max() > 0


def test_full_kind_adds_the_closest_incoming_bullet():
    """``threat``: the other tanks' bullet that will pass closest within the horizon,
    straight lines (hand-computed), nothing for bullets flying away or too far off."""
    full, path = duel("egocentric_full"), duel("egocentric_aim_path")
    me, foe = (385.0, 385.0, 0.0), (600.0, 600.0, 0.0)
    # Coming from ahead, passing 10 px to my right (+y on screen) in 200 / 300 s; a second
    # one passes farther (30 px) and sooner: the closer pass is the threat.
    bullets = [(1, 0, 585.0, 395.0, -300.0, 0.0), (1, 1, 415.0, 355.0, 0.0, 300.0)]
    obs = place(full, [me, foe], bullets)
    lay, r = full.obs.layout, hit_radius(full.matches[0].cfg)
    got = [feat(full, obs, f"threat.{f}") for f in ("near", "eta", "dir_fwd", "dir_side")]
    assert got == pytest.approx([1 - 10 / (4 * r), 1 - 200 / 300, 0.0, 1.0], abs=1e-6)
    # Everything else is the aim_path observation.
    base = place(path, [me, foe], bullets)
    rest = [k for k, name in enumerate(lay.fields) if not name.startswith("threat.")]
    assert np.array_equal(obs[..., rest], base)
    # Turned a quarter to the right, the pass point lies straight ahead.
    obs = place(full, [(385.0, 385.0, math.pi / 2), foe], bullets)
    assert feat(full, obs, "threat.dir_fwd") == pytest.approx(1.0, abs=1e-6)
    # Flying away, or closing in after the horizon: no threat.
    for b in [(1, 0, 585.0, 395.0, 300.0, 0.0), (1, 0, 700.0, 395.0, -300.0, 0.0)]:
        obs = place(full, [me, foe], [b])
        assert obs[0, 0, lay["threat"]].tolist() == [0.0, 0.0, 0.0, 0.0]
    full.matches[0].alive[0] = False
    obs = place(full, [me, foe], bullets)
    assert obs[0, 0, lay["threat"]].tolist() == [0.0, 0.0, 0.0, 0.0]


def test_fire_kind_adds_every_other_tanks_line_of_fire():
    """``tank[k].aimed / aim_near / ready``: a bullet the other tank fired now reaches me
    first, how close it passes me, whether its gun is ready; they move with the tank's
    slot, and everything else is ``egocentric_full``'s."""
    teams = ("A", "A", "B", "B")
    fire, full = duel("egocentric_fire", "open", teams), duel("egocentric_full", "open", teams)
    lay, r = fire.obs.layout, hit_radius(fire.matches[0].cfg)
    extra = ("aimed", "aim_near", "ready")
    # Seat 0 at the centre; enemy 2 to its right facing it, 10 px off its centre line;
    # enemy 3 farther off, facing sideways (its ricochets stay 275 px away); the mate far
    # off, facing away.
    poses = [(385.0, 385.0, 0.0), (150.0, 150.0, math.pi), (560.0, 395.0, math.pi),
             (385.0, 660.0, 0.0)]
    obs, base = place(fire, poses), place(full, poses)
    rest = [k for k, name in enumerate(lay.fields) if name.split(".")[-1] not in extra]
    assert np.array_equal(obs[..., rest], base)
    f = lambda name, o=0: feat(fire, obs, name, learner=o)  # noqa: E731
    # Nearest first: tank[0] the mate, tank[1] enemy 2 (175 px), tank[2] enemy 3 (275 px).
    assert f("tank[1].fwd") == pytest.approx(175.0 / W)
    assert (f("tank[1].aimed"), f("tank[1].ready")) == (1.0, 1.0)
    assert f("tank[1].aim_near") == pytest.approx(1 - 10.0 / (4 * r), abs=1e-6)
    assert [f(f"tank[{k}].{x}") for k in (0, 2) for x in extra[:2]] == [0.0] * 4
    assert (f("tank[0].ready"), f("tank[2].ready")) == (1.0, 1.0)
    # Enemy 2 seen by the mate (seat 1): its shot reaches seat 0, not the mate.
    assert feat(fire, obs, "tank[1].aimed", learner=1) == 0.0
    # Enemy 3 comes nearer than enemy 2 and faces seat 0: the slots swap, the fields go
    # with their tank; enemy 2 reloading is not ready.
    m = fire.matches[0]
    m.cooldown[2] = 5
    poses[3] = (385.0, 485.0, -math.pi / 2)
    obs = place(fire, poses)
    assert f("tank[1].side") == pytest.approx(100.0 / W)
    assert (f("tank[1].aimed"), f("tank[1].aim_near"), f("tank[1].ready")) == (1.0, 1.0, 1.0)
    assert (f("tank[2].aimed"), f("tank[2].ready")) == (1.0, 0.0)
    # Enemy 3 at its bullet limit is not ready either; the mate in enemy 3's line of fire
    # takes the shot: it no longer reaches seat 0 first.
    m.bullets_alive[3] = m.cfg.max_bullets
    poses[1] = (385.0, 435.0, 0.0)
    obs = place(fire, poses)
    assert (f("tank[1].aimed"), f("tank[1].ready")) == (0.0, 0.0)
    assert feat(fire, obs, "tank[1].aimed", learner=1) == 1.0  # the mate sees it aimed
    # Dead tanks aim at no one, and a dead observer sees no line of fire.
    m.alive[2] = False
    obs = place(fire, poses)
    assert [f(f"tank[2].{x}") for x in extra] == [0.0, 0.0, 0.0]
    m.alive[2], m.alive[0] = True, False
    obs = place(fire, poses)
    assert [f(f"tank[{k}].{x}") for k in range(3) for x in extra[:2]] == [0.0] * 6


def test_advice_kind_adds_what_the_smart_bot_would_do():
    """``advice``: the one-hot action a smart bot kept for the seat takes on each
    observation (the same as a smart bot playing the seat decides on that state); every
    other feature is ``egocentric_full``'s; a dead seat's advice is all zeros."""
    from alphatank.game.seats import Seat, make_controller

    runs = {k: MatchSet("team_vs_def_smart", 2, observation=k, action_repeat=2)
            for k in ("egocentric_advice", "egocentric_full")}
    obs = {k: ms.reset_all([3, 4]) for k, ms in runs.items()}
    ms = runs["egocentric_advice"]
    lay, full = ms.obs.layout, runs["egocentric_full"].obs.layout
    assert lay.fields == full.fields + [f"advice.{f}" for f in (
        "rot_ccw", "rot_none", "rot_cw", "back", "stop", "forward", "fire")]
    seats = ms.driven
    players = [[make_controller(Seat("A", "bot", bot="smart"), 0) for _ in seats]
               for _ in range(2)]
    for e, m in enumerate(ms.matches):
        for bot, seat in zip(players[e], seats, strict=True):
            bot.reset(m, seat, 0)
    advised, seen = 0, set()
    for _ in range(40):
        acts = np.ones((2, len(seats), 3), dtype=np.int64)
        for e, m in enumerate(ms.matches):
            for k, (bot, seat) in enumerate(zip(players[e], seats, strict=True)):
                advice = obs["egocentric_advice"][e, k, lay["advice"]]
                if not m.alive[seat]:
                    assert not advice.any()
                    continue
                acts[e, k] = bot.act(m, seat)
                rot, move, fire = acts[e, k].tolist()
                want = np.zeros(7)
                want[rot] = want[3 + move] = 1.0
                want[6] = fire
                assert advice.tolist() == want.tolist()
                advised += 1
                seen.add((rot, move, fire))
        for k, run in runs.items():
            _, obs[k] = run.step(acts)
        assert np.array_equal(obs["egocentric_advice"][..., :full.size], obs["egocentric_full"])
        assert not (ms.terminated | ms.truncated).any()
    assert advised > 100 and len(seen) >= 4  # the bot turns, drives and stops
    m = ms.matches[0]
    m.alive[seats[0]] = False
    ms.batch.gather(0, m)
    assert not ms.obs.build()[0, 0, lay["advice"]].any()


def test_egocentric_frame_and_rays_against_known_walls():
    ms = duel("egocentric")
    # Facing +y (down the screen); the enemy 100 px to the tank's left on screen (+x).
    obs = place(ms, [(385.0, 385.0, math.pi / 2), (485.0, 385.0, math.pi)],
                bullets=[(1, 0, 385.0, 485.0, 0.0, -300.0)])
    f = lambda name: feat(ms, obs, name)  # noqa: E731
    assert f("tank[0].fwd") == pytest.approx(0.0, abs=1e-6)
    assert f("tank[0].side") == pytest.approx(-100 / W, abs=1e-6)
    assert f("tank[0].dist") == pytest.approx(100 / DIAG, abs=1e-6)
    assert f("tank[0].sin") == pytest.approx(math.sin(math.pi / 2), abs=1e-6)  # heading diff
    # Enemy bullet straight ahead, coming at the tank.
    assert f("bullet[0].fwd") == pytest.approx(100 / W, abs=1e-6)
    assert f("bullet[0].side") == pytest.approx(0.0, abs=1e-6)
    assert f("bullet[0].v_fwd") == pytest.approx(-1.0, abs=1e-6)
    # The open map's inner wall faces are at 70 and 700 px: 315 px from the centre.
    R = ms.obs.rays
    assert f("ray[0].dist") == pytest.approx(315 / DEFAULT_RAY_LENGTH, abs=1e-6)  # ahead
    assert f(f"ray[{R // 4}].dist") == pytest.approx(315 / DEFAULT_RAY_LENGTH, abs=1e-6)
    assert f(f"ray[{R // 8}].dist") == 1.0  # diagonal: beyond the ray length


def test_path_features_follow_the_maze_to_each_tank():
    """``tank[k].path_*`` against NavGrid.path (the per-cell route the bots use): the
    direction to the route's cell two steps ahead (the tank itself when one step away), in
    the own frame, and the route's length over the map's longest one; zeros once dead."""
    from alphatank.sim.navigation import nav_grid

    ms = duel("egocentric_path", "maze")
    m = ms.matches[0]
    nav = nav_grid(m.spec)
    floor = m.spec.floor_cells()
    rng = np.random.default_rng(11)
    turned = 0
    for _ in range(25):
        a, b = (floor[int(k)] for k in rng.choice(len(floor), 2, replace=False))
        (x0, y0), (x1, y1) = m.spec.cell_center(a), m.spec.cell_center(b)
        heading = float(rng.uniform(-math.pi, math.pi))
        obs = place(ms, [(x0, y0, heading), (x1, y1, 0.0)])
        route = nav.path(a, b)
        tx, ty = (x1, y1) if len(route) <= 2 else m.spec.cell_center(route[2])
        dx, dy = tx - x0, ty - y0
        norm = math.hypot(dx, dy)
        c, s = math.cos(heading), math.sin(heading)
        f = lambda name, obs=obs: feat(ms, obs, name)  # noqa: E731
        assert f("tank[0].path_fwd") == pytest.approx((dx * c + dy * s) / norm, abs=1e-5)
        assert f("tank[0].path_side") == pytest.approx((dy * c - dx * s) / norm, abs=1e-5)
        assert f("tank[0].path_dist") == pytest.approx((len(route) - 1) / nav.diameter,
                                                       abs=1e-6)
        # The way differs from the straight line when walls are in between.
        straight = math.atan2(y1 - y0, x1 - x0)
        turned += abs(math.remainder(math.atan2(dy, dx) - straight, 2 * math.pi)) > 0.5
    assert turned >= 5
    m.alive[1] = False
    ms.batch.gather(0, m)
    obs = ms.obs.build()
    assert [feat(ms, obs, f"tank[0].path_{k}") for k in ("fwd", "side", "dist")] == [0, 0, 0]


def test_rays_match_pymunk_segment_queries():
    ms = duel("egocentric", "maze")
    m = ms.matches[0]
    rng = np.random.default_rng(3)
    floor = m.spec.floor_cells()
    L = 2000.0
    for _ in range(20):
        cell = floor[int(rng.integers(len(floor)))]
        x, y = m.spec.cell_center(cell)
        x += rng.uniform(-20, 20)
        y += rng.uniform(-20, 20)
        a = rng.uniform(-math.pi, math.pi)
        ms.obs.ray_length = L
        ours = ms.obs.ray_distances(np.array([[[x, y]]]), np.array([[a]]))[0, 0]
        for r, d in enumerate(ours):
            ang = a + 2 * math.pi * r / ms.obs.rays
            end = (x + L * math.cos(ang), y + L * math.sin(ang))
            hit = m.world.ray((x, y), end)
            assert hit is not None
            assert d == pytest.approx(hit.alpha * L, abs=1e-6)


def test_global_state_layout():
    ms = duel("paper", "arena4", ("A", "A", "B", "B"))
    st = ms.global_state.build()[0]
    lay = ms.global_state.layout
    assert st.shape == (lay.size,) == ms.state_space().shape
    m = ms.matches[0]
    assert st[lay["tank[3].x"]][0] == pytest.approx(2 * m.tank_xy[3, 0] / m.spec.width - 1,
                                                     abs=1e-6)
    assert st[lay["tank[3].team"]][0] == 1.0 and st[lay["tank[0].team"]][0] == 0.0
    assert st[lay["time.t"]][0] == 0.0


def test_dead_tank_alive_flag():
    ms = duel("paper")
    m = ms.matches[0]
    m.alive[1] = False
    ms.batch.gather(0, m)
    obs = ms.obs.build()
    assert feat(ms, obs, "tank[0].alive") == 0.0 and feat(ms, obs, "self.alive") == 1.0
    assert feat(ms, obs, "tank[0].alive", learner=1) == 1.0
    assert feat(ms, obs, "self.alive", learner=1) == 0.0


@pytest.mark.parametrize("kind", OBS_KINDS)
def test_a_game_without_bullets_observes_zero_bullets(kind):
    """Every bullet limit 0 (nobody can fire; the match runs): observations build and
    read no bullets, instead of dividing by the capacity 0."""
    seats = [{"team": t, "controller": "learner"} for t in ("A", "B")]
    game = {"max_bullets": 0, "buff_max_bullets": 0, "debuff_max_bullets": 0}
    sc = parse_scenario({"name": "unarmed", "map": "open", "observation": kind,
                         "seats": seats, "game": game})
    ms = MatchSet(sc, 1)
    ms.reset_env(0, 1)
    _, obs = ms.step(np.array([[[2, 2, 1], [0, 2, 1]]]))
    assert np.isfinite(obs).all()
    assert feat(ms, obs, "self.bullets") == 0.0 and not ms.matches[0].bullet_active.any()


# sha256 (first 16 hex digits) of observations built from seeded synthetic states, per env
# version. Observations are part of the env's definition: a change that alters them must
# bump ENV_VERSION (alphatank/envs/ids.py) and pin the new digests under the new version.
PINNED_OBS = {0: {
    ("vs_smart", "paper"): "92f8af6d19caa86a", ("vs_smart", "egocentric"): "ba0044fa90355dbd",
    ("team", "paper"): "e66c5cbd51dfb1f0", ("team", "egocentric"): "8b2e0fc82bb7b131",
    ("mixed_teams", "paper"): "44df475de4411a94",
    ("mixed_teams", "egocentric"): "d3b5b1945c0f6cda",
    ("vs_smart", "egocentric_path"): "5434918d2c16c85e",
    ("mixed_teams", "egocentric_path"): "78131bc73be9bae3",
    ("mixed_teams", "egocentric_nearest"): "e5c6b475bbcc5d2b",
    ("mixed_teams", "egocentric_aim"): "489aa654eb225f24",
    ("mixed_teams", "egocentric_aim_path"): "3d8c7b9688e78470",
    ("mixed_teams", "egocentric_full"): "39f53a118ceb6a4d",
    ("mixed_teams", "egocentric_fire"): "d12a78cdf3c82e2c",
}}


def synthetic_states(scenario: str, kind: str, steps: int = 12, num_envs: int = 3
                     ) -> Iterator[tuple[StateBatch, ObservationBuilder]]:
    """Seeded random tank, bullet and flag states on the scenario's map, one per step, with
    the builder of ``kind`` over them: the builder alone, independent of physics and bots.
    Inactive bullet slots keep their stale random positions, as a match leaves them."""
    sc = load_scenario(scenario)
    game, spec = sc.game_config(), sc.map_specs()[0]
    n = len(sc.teams)
    batch = StateBatch(game, n, num_envs, *slot_counts(game, [spec]))
    builder = ObservationBuilder(kind, batch, sc.teams, range(n), team_flags=sc.team_mode)
    for e in range(num_envs):
        batch.set_static(e, Match(game, spec, sc.teams, seed=e))
        builder.set_static(e)
    rng = np.random.default_rng(7)
    for k in range(steps):
        batch.raw[...] = rng.uniform(-1, 1, batch.raw.shape) * 400.0
        batch.raw[..., 0] += spec.width / 2
        batch.raw[..., 1] += spec.height / 2
        batch.raw[..., 2] *= np.pi / 400.0
        batch.flags[...] = rng.random(batch.flags.shape) < 0.6
        # every fourth step no other bullet flies (the builder's shortcut path)
        batch.bullet_active[...] = (rng.random(batch.bullet_active.shape) < 0.5) & (k % 4 != 0)
        batch.counts[...] = rng.integers(0, game.bullet_capacity + 1, batch.counts.shape)
        batch.tick[...] = k
        yield batch, builder


def synthetic_digest(scenario: str, kind: str, steps: int = 12, num_envs: int = 3) -> str:
    """Digest of the observations of every seat in :func:`synthetic_states`."""
    digest = hashlib.sha256()
    for _, builder in synthetic_states(scenario, kind, steps, num_envs):
        digest.update(builder.build().tobytes())
    return digest.hexdigest()[:16]


@pytest.mark.parametrize("case", sorted(PINNED_OBS[0]))
def test_observations_are_pinned_for_this_env_version(case):
    assert ENV_VERSION in PINNED_OBS, f"pin the observation digests of env v{ENV_VERSION}"
    assert synthetic_digest(*case) == PINNED_OBS[ENV_VERSION][case], (
        f"{case}: observations changed; if intended, bump ENV_VERSION and pin the new digest")


@pytest.mark.parametrize("kind", OBS_KINDS)
def test_no_observation_or_critic_state_holds_a_negative_zero(kind):
    """A masked-out feature is 0 whatever stale value sits under the mask: +0.0, never
    -0.0, so the bits of an observation hang on the state alone (not on other envs of the
    batch or an earlier episode: a run split over worker processes stays bit-identical)."""
    scenario = "mixed_teams" if kind != "egocentric_advice" else "vs_smart"
    for batch, builder in synthetic_states(scenario, kind, steps=8):
        obs = builder.build()
        state = GlobalState(batch, load_scenario(scenario).teams).build()
        for name, x in (("observation", obs), ("critic state", state)):
            zeros = x[x == 0]
            assert zeros.size and not np.signbit(zeros).any(), (kind, name)


def test_layout_columns_and_markdown():
    ms = duel("paper", "arena4", ("A", "A", "B", "B"))
    lay = ms.obs.layout
    assert lay.column("tank", "team") == 0 and lay.column("tank", "alive") == 1
    assert lay.span("tank", "rel_x", "rel_y") == slice(17, 19)
    assert lay.slot_fields["bullet"][:2] == ("mask", "team")
    with pytest.raises(KeyError, match="its fields"):
        lay.column("tank", "colour")
    with pytest.raises(ValueError, match="not adjacent"):
        lay.span("tank", "rel_y", "rel_x")
    table = lay.markdown().splitlines()
    assert table[0].startswith("| block | slots |") and len(table) == 2 + len(lay.blocks())
    assert f"| `tank[k]` | 3 | {3 * lay.widths['tank']} | {lay['tank'].start}:" in table[4]


def test_constant_operands_are_read_only_and_give_the_scalars_results():
    """The 0-d operands of the per-step ufunc calls: read-only, of their dtype, and the
    same bits as the Python number they stand for (float32 stays float32)."""
    one32, inf = constant(1.0, np.float32), constant(np.inf)
    assert one32.shape == () and one32.dtype == np.float32 and inf.dtype == np.float64
    with pytest.raises(ValueError):
        one32[...] = 2.0
    x = np.random.default_rng(0).normal(scale=2.0, size=50).astype(np.float32)
    got = np.minimum(x, one32)
    assert got.dtype == np.float32 and np.array_equal(got, np.minimum(x, 1.0))
    d = np.random.default_rng(1).random(8)
    mask = d > 0.5
    assert np.array_equal(np.where(mask, d, inf), np.where(mask, d, np.inf))


def test_room_misfit_names_each_overflow_and_walls_only_for_the_paper_kind():
    """Maps beyond an observation's padded room: walls count for the 'paper' kind only
    (the others read walls through rays), zones for every kind; a map that fits is fine."""
    room, maps = (11, 1, 1), "map 'm' has"
    assert room_misfit("paper", room, (11, 1, 0), maps) == []
    assert room_misfit("paper", room, (15, 1, 1), maps) == [
        "map 'm' has 15 wall rectangles; its 'paper' observation has room for 11"]
    assert room_misfit("egocentric_full", room, (15, 1, 1), maps) == []
    assert room_misfit("egocentric_full", room, (4, 1, 2), maps) == [
        "map 'm' has 1 buff and 2 debuff zones; it has room for 1 and 1"]
    assert len(room_misfit("paper", room, (12, 2, 0), maps)) == 2

"""Match rules: kills, cooldowns, bullet limits, zones, muzzle, friendly fire, self-hit."""

import math

import numpy as np
import pytest

from alphatank.sim.config import ConfigError, GameConfig, RewardConfig, from_dict, game_config
from alphatank.sim.mapspec import MapError, load_map, parse_map
from alphatank.sim.match import Match

IDLE, FIRE = (1, 1, 0), (1, 1, 1)

ZONES = """\
name: zones

#########
#1......#
#.+...-.#
#......2#
#########
"""


OPEN = parse_map("name: plain\n\n" + "#" * 11 + "\n" + ("#" + "." * 9 + "#\n") * 9 + "#" * 11)


def _match(teams=("A", "B"), spec=None, seed=0, **cfg) -> Match:
    """A match on an 11x11 walled ring without zones unless a map is given."""
    return Match(game_config(**cfg), spec or OPEN, list(teams), seed=seed)


def _act(m: Match, *rows) -> np.ndarray:
    acts = np.tile(np.array(IDLE), (m.n, 1))
    for i, row in enumerate(rows):
        acts[i] = row
    return acts


def test_one_hit_kills_and_ends_the_match():
    m = _match()
    m.place_tank(0, 200, 385, 0.0)
    m.place_tank(1, 400, 385, 0.0)
    ev = m.step(_act(m, FIRE))
    assert [e.tank for e in ev.fired] == [0]
    for _ in range(60):
        ev = m.step(_act(m))
        if ev.hits:
            break
    assert [(h.shooter, h.victim, h.friendly) for h in ev.hits] == [(0, 1, False)]
    assert [(k.victim, k.shooter) for k in ev.kills] == [(1, 0)]
    assert not m.alive[1] and m.terminated and m.winner == "A"
    assert m.score[0] == 1 and m.bullets_alive[0] == 0
    with pytest.raises(RuntimeError, match="reset"):
        m.step(_act(m))


def test_cooldown_in_ticks_spaces_shots():
    m = _match(bullet_max_distance=2000.0, max_bullets=50)
    m.place_tank(0, 100, 385, 0.0)
    m.place_tank(1, 600, 150, 0.0)
    fired_at = [t for t in range(60) if m.step(_act(m, FIRE)).fired]
    gaps = set(np.diff(fired_at).tolist())
    assert gaps == {m.cfg.cooldown_ticks}
    assert m.cfg.cooldown_ticks == math.ceil(0.3 * 30)


def test_max_bullets_limit_holds():
    m = _match(bullet_cooldown_ms=1.0, bullet_max_distance=5000.0, max_bullets=4, immortal=True)
    m.place_tank(0, 385, 385, 0.3)
    m.place_tank(1, 105, 105, 0.0)
    most = 0
    for _ in range(100):
        m.step(_act(m, FIRE))
        most = max(most, int(m.bullet_active[: m.capacity].sum()))
        assert m.bullets_alive[0] == m.bullet_active[: m.capacity].sum()
    assert most == 4


@pytest.mark.parametrize(("cell", "limit"), [((2, 2), 10), ((2, 6), 1), ((3, 4), 4)])
def test_buff_and_debuff_change_bullet_limit(cell, limit):
    spec = parse_map(ZONES)
    m = _match(spec=spec, bullet_cooldown_ms=1.0, bullet_max_distance=5000.0, max_bullets=4,
               buff_max_bullets=10, debuff_max_bullets=1, immortal=True)
    x, y = spec.cell_center(cell)
    m.place_tank(0, x, y, math.pi / 2 + 0.2)
    m.place_tank(1, 105, 105, 0.0)
    assert m.bullet_limit(0) == limit
    most = 0
    for _ in range(60):
        m.step(_act(m, FIRE))
        most = max(most, int(m.bullets_alive[0]))
    assert most == limit


def test_zone_entered_event_and_flags():
    spec = parse_map(ZONES)
    m = _match(spec=spec)
    x, y = spec.cell_center((2, 1))
    m.place_tank(0, x, y, 0.0)  # facing the buff cell to the right
    m.place_tank(1, 455, 245, 0.0)
    entered = []
    for _ in range(40):
        entered += m.step(_act(m, (1, 2, 0))).zones_entered
        if entered:
            break
    assert [(e.tank, e.kind) for e in entered] == [(0, "buff")]
    assert m.in_buff[0] and not m.in_debuff[0]


def test_muzzle_in_wall_fires_nothing():
    m = _match()
    m.place_tank(0, 700 - 16, 385, 0.0)  # front 1 px from the right wall
    m.place_tank(1, 200, 385, 0.0)
    ev = m.step(_act(m, FIRE))
    assert not ev.fired and m.bullets_alive[0] == 0


@pytest.mark.parametrize("friendly_fire", [True, False])
def test_friendly_fire_follows_config(friendly_fire):
    m = _match(teams=("A", "A", "B"), friendly_fire=friendly_fire)
    m.place_tank(0, 150, 385, 0.0)
    m.place_tank(1, 300, 385, 0.0)
    m.place_tank(2, 600, 150, 0.0)
    m.step(_act(m, FIRE))
    hits = []
    for _ in range(30):
        hits += m.step(_act(m)).hits
    if friendly_fire:
        assert [(h.shooter, h.victim, h.friendly) for h in hits] == [(0, 1, True)]
        assert not m.alive[1] and m.score[0] == 0
    else:
        assert hits == [] and m.alive[1]


@pytest.mark.parametrize(("self_hit", "gap", "expect_hit"),
                         [(True, 60, True), (False, 60, False), (True, 8, False)])
def test_self_hit_option_and_grace_period(self_hit, gap, expect_hit):
    """A shot straight at a wall comes back at its shooter. It kills only with self_hit on,
    and never within the grace period (a wall a few px away returns it too soon)."""
    m = _match(self_hit=self_hit)
    front = 700 - gap
    m.place_tank(0, front - m.cfg.tank_width / 2, 385, 0.0)
    m.place_tank(1, 150, 150, 0.0)
    m.step(_act(m, FIRE))
    hits = []
    for _ in range(40):
        if m.done:
            break
        hits += m.step(_act(m)).hits
    assert bool(hits) == expect_hit
    if expect_hit:
        assert (hits[0].shooter, hits[0].victim, hits[0].friendly) == (0, 0, True)
        assert m.winner == "B"


def test_immortal_mode_scores_hits_and_cuts_at_max_steps():
    m = _match(immortal=True, max_steps=60)
    m.place_tank(0, 200, 385, 0.0)
    m.place_tank(1, 400, 385, 0.0)
    hits = 0
    while not m.done:
        hits += len(m.step(_act(m, FIRE)).hits)
    assert hits >= 2 and m.alive.all()
    assert m.truncated and not m.terminated and m.tick == 60
    assert m.score[0] == hits and m.winner == "A"


def test_truncation_without_a_winner_is_a_draw():
    m = _match(max_steps=10)
    for _ in range(10):
        m.step(_act(m))
    assert m.truncated and m.winner is None


def test_bounces_and_wall_contacts_are_events():
    m = _match()
    m.place_tank(0, 560, 385, 0.0)
    m.place_tank(1, 150, 150, 0.0)
    m.step(_act(m, FIRE))
    bounced = []
    contacts = []
    for _ in range(60):
        ev = m.step(_act(m, (1, 2, 0)))
        bounced += ev.bounced
        contacts += ev.wall_contacts
    assert bounced and bounced[0].owner == 0
    assert bounced[0].x == pytest.approx(700 - m.cfg.bullet_radius)
    assert {c.tank for c in contacts} == {0}


def test_flag_and_count_rows_stay_views_and_wall_follows_contacts():
    """``alive``/``wall``/``in_buff``/``in_debuff`` are rows of ``flags`` and the counters
    rows of ``counts`` (a batch copies each in one go), through resets and kills; ``wall``
    is each tank's wall contact after every tick, leaving the wall included."""
    m = _match()
    for episode in range(2):
        m.reset(episode)
        assert np.shares_memory(m.alive, m.flags) and np.shares_memory(m.wall, m.flags)
        assert np.shares_memory(m.cooldown, m.counts)
        m.place_tank(0, 560, 385, 0.0)
        m.place_tank(1, 150, 150, 0.0)
        touched = released = False
        for t in range(80):
            m.step(_act(m, (1, 2, 0) if t < 50 else (1, 0, 0)))
            assert np.array_equal(m.wall, m.world.wall_contacts > 0)
            touched |= bool(m.wall[0])
            released |= touched and not m.wall[0]
        assert touched and released
        assert np.array_equal(m.flags, [m.alive, m.wall, m.in_buff, m.in_debuff])
        assert np.array_equal(m.counts, [m.cooldown, m.bullets_alive])


def test_tanks_bigger_than_the_cells_are_refused_naming_map_and_sizes():
    spec = parse_map("cell: 50\n\n#####\n#1.2#\n#####\n", "small.txt")
    Match(game_config(tank_width=40.0, tank_height=30.0), spec, ["A", "B"], seed=0)  # 50 px
    with pytest.raises(MapError) as info:
        Match(game_config(tank_width=40.0, tank_height=40.0), spec, ["A", "B"], seed=0)
    assert str(info.value) == (
        "small.txt: cells of 50 px are too small for tanks of 40 x 40 px (tank_width, "
        "tank_height): a tank spawns and turns in one cell, which needs cells of at least its "
        "diagonal, 56.6 px")


@pytest.mark.parametrize("seed, why", [(-1, r"must be in \[0, inf\], got -1"),
                                       (1.5, "must be an integer, got 1.5")])
def test_a_bad_seed_is_named(seed, why):
    with pytest.raises(ValueError, match=f"^seed {why}"):
        Match(game_config("paper"), load_map("maze"), ["A", "B"], seed=seed)


def test_config_rejects_unknown_keys_and_slow_bullets():
    with pytest.raises(ConfigError, match="unknown GameConfig key.*'bulet_speed'.*valid keys"):
        from_dict(GameConfig, {"bulet_speed": 3})
    with pytest.raises(ConfigError, match="unknown RewardConfig"):
        from_dict(RewardConfig, {"victry": 1})
    with pytest.raises(ConfigError, match="must exceed tank_speed"):
        game_config(bullet_speed=50.0)
    with pytest.raises(ConfigError, match="unknown preset 'fast'.*long_range"):
        game_config("fast")


def test_presets_keep_table5_defaults():
    cfg = game_config("paper")
    assert (cfg.max_bullets, cfg.bullet_max_bounces, cfg.bullet_max_distance) == (6, 6, 300.0)
    assert (cfg.tank_width, cfg.tank_height, cfg.bullet_cooldown_ms) == (30.0, 24.0, 300.0)
    lr = game_config("long_range")
    assert lr.bullet_max_distance == 800.0 and lr.bullet_speed == 4 * cfg.bullet_speed
    assert RewardConfig().victory == 200.0 and RewardConfig().hit_penalty == -50.0


def test_spawns_fill_missing_slots_on_reachable_floor():
    m = _match(teams=("A", "B", "C", "D"), spec=load_map("maze"), seed=5)
    spec = m.spec
    assert m.spawn_cells[:2] == [spec.spawns[1], spec.spawns[2]]
    assert len(set(m.spawn_cells)) == 4
    assert all(not spec.walls[c] for c in m.spawn_cells)


def test_random_spawns_ignore_the_map_slots_and_follow_the_seed():
    bf = load_map("battlefield")
    draws = [_match(teams=("A", "A", "B", "B", "B"), spec=bf, seed=s, random_spawns=True)
             for s in range(6)]
    again = _match(teams=("A", "A", "B", "B", "B"), spec=bf, seed=3, random_spawns=True)
    assert again.spawn_cells == draws[3].spawn_cells
    for m in draws:
        assert len(set(m.spawn_cells)) == 5
        assert all(not bf.walls[c] for c in m.spawn_cells)
    firsts = {m.spawn_cells[0] for m in draws}
    assert len(firsts) > 1 and firsts != {bf.spawns[1]}
    fixed = _match(teams=("A", "A", "B", "B", "B"), spec=bf, seed=3)
    assert fixed.spawn_cells[:2] == [bf.spawns[1], bf.spawns[2]]


def test_benched_tanks_are_out_from_the_start_and_the_rest_play_to_the_end():
    m = _match(teams=("A", "B", "B"), seed=2)
    m.bench([1])
    assert m.alive.tolist() == [True, False, True] and not m.events.kills
    assert not m.world.tank_present[1]
    with pytest.raises(ValueError, match="leave a team with no tank"):
        m.bench([2])
    m.place_tank(0, 200.0, 385.0, 0.0)
    m.place_tank(2, 420.0, 385.0, math.pi)
    for _ in range(120):
        m.step(_act(m, FIRE))
        if m.done:
            break
    assert m.terminated and m.winner == "A"  # the one tank B fielded is down
    assert [k.victim for k in m.events.kills] == [2]
    with pytest.raises(RuntimeError, match="before the first tick"):
        m.bench([1])


def test_random_zones_come_from_the_seed():
    maze = load_map("maze")
    a, b, c = _match(spec=maze, seed=1), _match(spec=maze, seed=1), _match(spec=maze, seed=2)
    assert a.buffs == b.buffs and a.debuffs == b.debuffs
    assert len(a.buffs) == 2 and len(a.debuffs) == 2
    assert (a.buffs, a.debuffs) != (c.buffs, c.debuffs)


@pytest.mark.parametrize("actions, error, message", [
    ([[5, 1, 0], [1, 1, 0]], ValueError, r"tank 0: action \[5, 1, 0\] out of range"),
    ([[1, 1, 0], [1, 10, 0]], ValueError, r"tank 1: action \[1, 10, 0\] out of range"),
    ([[1, 1, 0], [1, 1, 2]], ValueError, r"tank 1: .*fire 0\.\.1"),
    ([[1, 1, 0], [-1, 1, 0]], ValueError, r"tank 1: .*rotate 0\.\.2"),
    ([[1, 1.5, 0], [1, 1, 0]], TypeError, r"integers .*got dtype float64"),
    ([[1, np.nan, 0], [1, 1, 0]], TypeError, r"integers .*got dtype float64"),
    ([[1, 1, 0]], ValueError, r"shape \(2, 3\).*got \(1, 3\)"),
    ([[1, 1], [1, 1]], ValueError, r"shape \(2, 3\).*got \(2, 2\)"),
])
def test_step_rejects_bad_actions_and_changes_nothing(actions, error, message):
    m = _match()
    m.step(_act(m, FIRE, FIRE))
    before = m.state_hash()
    with pytest.raises(error, match=message):
        m.step(actions)
    assert m.state_hash() == before and m.tick == 1


def test_step_accepts_any_integer_array_or_list():
    m = _match()
    for acts in ([[2, 2, 1], [0, 0, 1]], np.array([[2, 2, 1], [0, 0, 1]], dtype=np.uint8),
                 np.array([[1, 1, True], [1, 1, False]]), np.array([[2, 2, 0], [0, 0, 0]])):
        m.step(acts)
    assert m.tick == 4 and m.events.fired == []

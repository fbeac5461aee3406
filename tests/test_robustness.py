"""Bad input at the library level: config fields checked by type and range, map and
scenario files in any encoding, untrusted replays, checkpoints with NaN weights, the
PettingZoo env's misuse errors, the World's freed C buffers, and a short soak."""

from __future__ import annotations

import dataclasses
import gc
import json
import math

import numpy as np
import pytest

from alphatank.commands.benchsoak import (
    SoakError,
    SoakResult,
    heap_mb,
    min_soak_steps,
    slope_per_million,
    soak,
    soak_scenario,
)
from alphatank.errors import InputError
from alphatank.game.lineup import build_lineup
from alphatank.game.scenarios import ScenarioError, load_scenario, parse_scenario, seats_scenario
from alphatank.mapgen import EditorModel, describe
from alphatank.sim.config import (
    ConfigError,
    GameConfig,
    RewardConfig,
    bounded,
    check_fields,
    from_dict,
    game_config,
)
from alphatank.sim.mapspec import MapError, load_map, parse_map
from alphatank.sim.match import Match
from alphatank.sim.world import substeps_for
from alphatank.ui.replay import (
    MAX_BODY_SUBSTEPS,
    MAX_SUBSTEPS,
    ReplayError,
    ReplayPolicy,
    ReplayRecorder,
    check_replay_room,
    load_replay,
    save_replay,
    simulate,
)
from alphatank.ui.video import record_match

SCENARIO = ('name = "t"\nmap = "open"\n[[seats]]\nteam = "A"\ncontroller = "learner"\n'
            '[[seats]]\nteam = "B"\ncontroller = "bot"\nbot = "random"\n')


# ---- configs -------------------------------------------------------------------------

@pytest.mark.parametrize(("field", "value", "why"), [
    ("friendly_fire", "no", "must be true or false, got 'no'"),
    ("friendly_fire", 0, "must be true or false"),
    ("max_steps", True, "must be an integer, got True"),
    ("max_steps", 0, "must be in [1, 10000000]"),
    ("max_bullets", 2.5, "must be an integer, got 2.5"),
    ("tick_hz", 0.5, "must be an integer"),
    ("tick_hz", 0, "must be in [1, 240]"),
    ("bullet_cooldown_ms", -1.0, "must be in [0, 60000]"),
    ("random_buff_zones", 100000, "must be in [0, 64]"),
    ("bullet_speed", math.inf, "must be a finite number, got inf"),
    ("bullet_speed", 3e9, "must be in [1, 10000]"),
    ("tank_width", "30", "must be a number, got '30'"),
])
def test_game_config_checks_every_field(field, value, why):
    with pytest.raises(ConfigError) as info:
        game_config(where="x.toml: [game]", **{field: value})
    assert str(info.value).startswith(f"x.toml: [game].{field}: {why}")
    assert info.value.key == field and isinstance(info.value, InputError)


@pytest.mark.parametrize(("field", "value", "why"), [
    ("victory", math.nan, "must be a finite number, got nan"),
    ("victory", "lots", "must be a number, got 'lots'"),
    ("stationary_ticks", 0, "must be in [1, 10000000], got 0"),
    ("trajectory_close_px", 0.0, "must be in [1, 100000], got 0.0"),
])
def test_reward_config_checks_every_field(field, value, why):
    with pytest.raises(ConfigError) as info:
        from_dict(RewardConfig, {field: value}, where="r.toml: [rewards]")
    assert str(info.value) == f"r.toml: [rewards].{field}: {why}"


def test_configs_normalise_numbers_and_keep_defaults_valid():
    cfg = GameConfig(tank_speed=100, bullet_speed=np.float64(400.0), max_steps=np.int64(50))
    assert type(cfg.tank_speed) is float and type(cfg.bullet_speed) is float
    assert type(cfg.max_steps) is int and cfg.max_steps == 50
    assert GameConfig() == game_config("paper") and RewardConfig(victory=1).victory == 1.0
    game_config("long_range")


def test_fields_added_later_are_checked_by_their_type():
    """Other parts add reward weights: the validator covers a new field with no extra code."""
    @dataclasses.dataclass(frozen=True)
    class Extended(RewardConfig):
        team_outcome: float = 0.0
        time_cost_ticks: int = bounded(10, 1, 100)
        shaped: bool = False

    assert Extended(team_outcome=2).team_outcome == 2.0
    for kw, why in ((dict(team_outcome=math.inf), "finite"), (dict(shaped="yes"), "true or false"),
                    (dict(time_cost_ticks=0), "[1, 100]")):
        with pytest.raises(ConfigError, match=why):
            Extended(**kw)
    with pytest.raises(ConfigError, match="victory"):
        Extended(victory=math.nan)
    cfg = Extended()
    object.__setattr__(cfg, "team_outcome", "x")  # what a frozen dataclass cannot stop
    with pytest.raises(ConfigError, match="team_outcome: must be a number"):
        check_fields(cfg)


@pytest.mark.parametrize(("table", "line", "where"), [
    ("[game]\nfriendly_fire = \"no\"\n", "[game].friendly_fire", "true or false, got 'no'"),
    ("[game]\nmax_steps = true\n", "[game].max_steps", "integer"),
    ("[game]\nvictory = 1\n", "[game]", "unknown GameConfig key"),
    ("[rewards]\nvictory = \"lots\"\n", "[rewards].victory", "number, got 'lots'"),
    ("[rewards]\nvictory = nan\n", "[rewards].victory", "finite"),
    ("[rewards]\nteam_win_time_decay = 2\n", "[rewards].team_win_time_decay",
     "must be in [0, 1], got 2.0"),
    ("[rewards]\nteam_draw = 5\nteam_loss = -5\n", "[rewards].team_draw",
     "(5.0) must not exceed team_loss (-5.0)"),
])
def test_scenario_files_name_file_and_field(tmp_path, table, line, where):
    p = tmp_path / "x.toml"
    p.write_text(SCENARIO + table)
    with pytest.raises(ScenarioError) as info:
        load_scenario(p)
    assert str(info.value).startswith(f"{p}: {line}") and where in str(info.value)


def test_bot_options_and_checkpoint_paths_are_checked_when_the_scenario_loads(tmp_path):
    p = tmp_path / "x.toml"
    p.write_text(SCENARIO.replace('bot = "random"', 'bot = "smart"\noptions = {ricochet = "no"}'))
    with pytest.raises(ScenarioError, match=r"seats\[1\]\.options: .*ricochet.*true or false"):
        load_scenario(p)
    p.write_text(SCENARIO.replace('controller = "bot"\nbot = "random"',
                                  'controller = "checkpoint"\npath = "runs/x"'))
    with pytest.raises(ScenarioError, match=r"seats\[1\]\.path: runs/x: no such checkpoint"):
        load_scenario(p)
    run = tmp_path / "runs" / "x"
    run.mkdir(parents=True)
    (run / "latest").write_text("checkpoints/step_1\n")
    (run / "checkpoints" / "step_1").mkdir(parents=True)
    (run / "checkpoints" / "step_1" / "meta.json").write_text("{}")  # checked, not loaded
    sc = load_scenario(p)  # relative to the scenario's folder, like maps
    assert sc.seats[1].path == str(run)


def test_scenario_file_encodings(tmp_path):
    p = tmp_path / "bom.toml"
    p.write_bytes(b"\xef\xbb\xbf" + SCENARIO.encode())
    assert load_scenario(p).name == "t"
    p.write_bytes(SCENARIO.encode("utf-16"))
    with pytest.raises(ScenarioError, match="not a UTF-8 text file.*UTF-16"):
        load_scenario(p)


# ---- maps ----------------------------------------------------------------------------

MAP = "name: m\n\n#####\n#1..#\n#.#.#\n#..2#\n#####\n"


def test_map_encodings(tmp_path):
    p = tmp_path / "m.txt"
    p.write_bytes(b"\xef\xbb\xbf" + MAP.encode())
    assert load_map(p).name == "m"  # a BOM is dropped, not an unknown header key
    assert parse_map("\ufeff" + MAP).name == "m"
    for data, kind in ((MAP.replace("m\n", "caf\xe9\n").encode("latin-1"), "not UTF-8"),
                       (MAP.encode("utf-16"), "UTF-16"), (bytes(range(256)), "binary")):
        p.write_bytes(data)
        with pytest.raises(MapError, match=f"{p}: not a UTF-8 text file \\({kind}"):
            load_map(p)


@pytest.mark.parametrize("cell", ["inf", "nan", "0.001", "-3", "1e9", "x", "16", "38.9"])
def test_cell_size_must_be_sane(cell):
    with pytest.raises(MapError, match=r"'cell' must be a positive number of px in \[39, 400\]"):
        parse_map(f"cell: {cell}\n\n#####\n#1.2#\n#####\n", "c.txt")


def test_room_for_tanks_is_checked_early(tmp_path):
    with pytest.raises(MapError, match="spawn slots go up to 4 but only 3 tank"):
        parse_map("#####\n#1.+#\n###4#\n#####\n", "r.txt")
    p = tmp_path / "r.txt"
    p.write_text("######\n#1..+#\n######\n#....#\n######\n")  # 3 cells by spawn 1
    seats = [{"team": "AB"[i % 2], "controller": "learner"} for i in range(4)]
    with pytest.raises(ScenarioError, match="map 'r' has room for 3 tank"):
        parse_scenario({"name": "x", "map": str(p), "seats": seats}, "s.toml")
    parse_scenario({"name": "x", "map": str(p), "seats": seats[:3]}, "s.toml")


def test_maps_without_spawns_never_place_tanks_in_a_small_pocket():
    spec = parse_map("#######\n#.#...#\n###...#\n#######\n")  # a 1-cell pocket + 6 cells
    assert spec.tank_room(3) == 6
    for seed in range(40):  # the pocket is drawn for some seeds: the match then moves on
        m = Match(GameConfig(), spec, ["A", "B", "C"], seed=seed)
        assert (1, 1) not in m.spawn_cells


def test_editor_names_maps_after_their_file(tmp_path):
    m = EditorModel.blank(5, 7)
    m.paint(1, 1, "1")
    m.paint(3, 5, "2")
    m.save(tmp_path / "arena_x.txt")
    assert (tmp_path / "arena_x.txt").read_text().startswith("name: arena_x\n")
    assert load_map(tmp_path / "arena_x.txt").name == "arena_x"


def test_describe_a_map_without_interior():
    with np.errstate(all="raise"):
        assert "no interior" in describe(parse_map("1.2\n"))


# ---- replays -------------------------------------------------------------------------

@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    lineup = build_lineup(seats_scenario("smart,defensive", "maze", {"max_steps": 90}))
    ep = lineup.start(3)
    rec = ReplayRecorder(ep.match, match_seed=ep.seeds.match_seed, seed=3,
                         policies=lineup.controllers, labels=lineup.labels)
    video = record_match(ep.match, lineup.controllers, keep_frames=True, recorder=rec,
                         labels=lineup.labels, scale=0.5)
    path = save_replay(rec.finish(), tmp_path_factory.mktemp("rep") / "r.npz")
    return path, video


def test_replay_video_matches_the_original_with_the_bots_paths(recording):
    path, video = recording
    rep = load_replay(path)
    assert (rep.routes[:, :, 0] >= 0).any()  # the bots planned routes, and they were kept
    again = record_match(rep.new_match(), rep.policies(), keep_frames=True, labels=rep.labels,
                         max_ticks=rep.ticks, scale=0.5)
    assert np.array_equal(again.kept, video.kept)  # pixel for pixel, path overlay included
    bare = record_match(rep.new_match(), [ReplayPolicy(rep.actions)] * 2, keep_frames=True,
                        labels=rep.labels, max_ticks=rep.ticks, scale=0.5)
    assert not np.array_equal(bare.kept, video.kept)  # without routes: no paths drawn


def _respoil(path, tmp_path, name, **changes):
    """A copy of the replay with meta fields changed and the digest NOT recomputed."""
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    meta = json.loads(arrays.pop("meta").tobytes())
    meta.update(changes)
    out = tmp_path / name
    np.savez_compressed(out, meta=np.frombuffer(json.dumps(meta).encode(), np.uint8), **arrays)
    return out


@pytest.mark.parametrize(("changes", "fragment"), [
    ({"version": 1}, "replay version 1 is not supported: this AlphaTank reads version 2"),
    ({"match_seed": -5}, "meta.match_seed: must be in [0, 18446744073709551615], got -5"),
    ({"match_seed": 1.5}, "meta.match_seed: must be an integer"),
    ({"teams": None}, "meta.teams: must be a list of 2 to 64 team names"),
    ({"teams": ["A", "A"]}, "meta.teams: need at least 2 different teams"),
    ({"winner": "Z"}, "meta.winner: must be one of the teams ['A', 'B'] or null"),
    ({"labels": ["x"]}, "meta.labels: must be a list of 2 strings"),
    ({"final_hash": "abc"}, "meta.final_hash: must be 64 lowercase hex digits"),
    ({"config": {"bullet_speed": 3e9}}, "meta.config.bullet_speed: must be in [1, 10000]"),
    ({"config": {"max_steps": 10}}, "meta.ticks: 90 ticks exceed the config's max_steps (10)"),
    ({"map_text": "cell: inf\n\n###\n#1#\n#2#\n###\n"}, "'cell' must be a positive number"),
    ({"ticks": 3}, "meta.ticks: is 3 but the file holds 90 ticks"),
    ({"map_text": None}, "meta.map_text: must be a string"),
    ({"winner": "A"}, "meta.digest: does not match the file's contents"),
])
def test_untrusted_replay_fields_are_checked(recording, tmp_path, changes, fragment):
    path = _respoil(recording[0], tmp_path, "bad.npz", **changes)
    with pytest.raises(ReplayError) as info:
        load_replay(path)
    assert str(info.value).startswith(str(path)) and fragment in str(info.value)


def test_a_digest_binds_every_byte_of_meaning(recording, tmp_path):
    rep = load_replay(recording[0])
    edited = _respoil(recording[0], tmp_path, "m.npz",
                      map_text=rep.map_text + "; an ignored comment\n")
    with pytest.raises(ReplayError, match="meta.digest"):
        load_replay(edited)  # the re-simulation alone would not notice this edit


def test_recorded_winner_is_compared_with_the_resimulated_one(recording, tmp_path):
    rep = load_replay(recording[0])
    claimed = "A" if rep.winner != "A" else "B"
    liar = dataclasses.replace(rep, winner=claimed)
    path = save_replay(liar, tmp_path / "liar.npz")  # a consistent file that lies
    with pytest.raises(ReplayError, match=f"re-simulated winner is .*claims team {claimed}"):
        simulate(load_replay(path))


def test_resimulation_work_is_capped(recording, tmp_path):
    rep = load_replay(recording[0])
    cfg = {**rep.config, "max_steps": 10_000_000, "bullet_speed": 10_000.0}
    ticks = MAX_SUBSTEPS // 5
    big = dataclasses.replace(rep, config=cfg, actions=np.ones((ticks, 2, 3), np.int8),
                              routes=None)
    with pytest.raises(ReplayError, match="big.npz: not saved, it would not load: .*physics "
                                          "substeps; a replay may ask for at most"):
        save_replay(big, tmp_path / "big.npz")  # reads back what it would write
    path = tmp_path / "big.npz"  # the same file, made by hand
    blob = np.frombuffer(json.dumps(big.meta()).encode(), np.uint8)
    np.savez_compressed(path, **big.arrays(), meta=blob)
    with pytest.raises(ReplayError, match="physics substeps; a replay may ask for at most"):
        load_replay(path)


def test_resimulation_work_counts_the_bullets(recording, tmp_path):
    rep = load_replay(recording[0])
    cfg = {**rep.config, "max_steps": 10_000_000, "max_bullets": 64, "buff_max_bullets": 64}
    ticks = MAX_BODY_SUBSTEPS // (2 * 65) + 1  # under MAX_SUBSTEPS: loaded before
    assert ticks * substeps_for(from_dict(GameConfig, cfg), rep.map_spec()
                                .min_wall_thickness()) <= MAX_SUBSTEPS
    busy = dataclasses.replace(rep, config=cfg, actions=np.ones((ticks, 2, 3), np.int8),
                               routes=None)
    path = tmp_path / "busy.npz"
    np.savez_compressed(path, **busy.arrays(),
                        meta=np.frombuffer(json.dumps(busy.meta()).encode(), np.uint8))
    with pytest.raises(ReplayError, match=r"busy\.npz: meta\.config: re-simulating .* ticks "
                                          r"would take .* physics substeps of up to 130 bodies "
                                          r"\(2 tanks and 64 bullets each\)"):
        load_replay(path)
    with pytest.raises(InputError, match="--replay: a game of up to 1,000,000 ticks .* 130 bodies"):
        check_replay_room(GameConfig(max_steps=1_000_000, max_bullets=64), [rep.map_spec()],
                          2, "--replay")
    check_replay_room(GameConfig(max_steps=1_000_000), [rep.map_spec()], 2, "--replay")


def test_a_config_whose_tanks_do_not_fit_the_maps_cells_is_refused_on_load(recording,
                                                                        tmp_path):
    rep = load_replay(recording[0])  # a consistent file (digest and all), made by hand
    wide = dataclasses.replace(rep, config={**rep.config, "tank_width": 500.0})
    path = tmp_path / "wide.npz"
    np.savez_compressed(path, **wide.arrays(),
                        meta=np.frombuffer(json.dumps(wide.meta()).encode(), np.uint8))
    with pytest.raises(ReplayError) as info:
        load_replay(path)  # before: loaded, then simulate's MapError named no file
    assert str(info.value).startswith(f"{path}: meta.config: does not fit meta.map_text: "
                                      "cells of 70 px are too small for tanks of 500 x")
    with pytest.raises(ReplayError, match="not saved, it would not load: meta.config"):
        save_replay(wide, tmp_path / "again.npz")


# ---- checkpoints and envs ------------------------------------------------------------

def test_non_finite_tensors_are_named():
    import torch

    from alphatank.training.checkpoint import non_finite

    state = {"net": {"a.weight": torch.ones(3), "b.bias": torch.tensor([0.0, math.inf])},
             "steps": torch.tensor(3), "buffer": [np.zeros(2), np.array([np.nan])]}
    assert non_finite(state) == "net.b.bias"
    del state["net"]["b.bias"]
    assert non_finite(state) == "buffer.1"
    state["buffer"].pop()
    assert non_finite(state) is None


def test_pettingzoo_refuses_scenarios_without_learners_and_non_dict_steps():
    from alphatank.envs import env, parallel_env

    for make in (parallel_env, env):
        with pytest.raises(ScenarioError, match="bot_teams.toml: no learner seats"):
            make(scenario="bot_teams")
    p = parallel_env(scenario="team")
    p.reset(seed=0)
    for bad in (np.ones(3, dtype=np.int64), None, [1, 1, 0]):
        with pytest.raises(TypeError, match=r"dict agent -> action .*tank_0"):
            p.step(bad)


# ---- memory --------------------------------------------------------------------------

@pytest.mark.skipif(heap_mb is None, reason="needs glibc's mallinfo2")
def test_match_resets_do_not_leak_c_memory():
    """pymunk 7.3's batch buffers were never freed: 1.3 kB per reset, ~1.6 MB here."""
    m = Match(GameConfig(), load_map("battlefield"), ["A", "B"], seed=0)
    for k in range(300):
        m.reset(k)
    gc.collect()
    before = heap_mb()
    for k in range(1200):
        m.reset(k)
    gc.collect()
    assert heap_mb() - before < 0.4


def test_short_soak_sees_no_nan():
    res = soak_scenario("vs_random", 3000, every=1000)
    assert res.bad_obs == 0 and res.bad_rewards == 0
    assert [s[0] for s in res.samples] == [1000, 2000, 3000]
    assert all(s[1] > 0 for s in res.samples)
    assert slope_per_million([0, 1e6], [1.0, 3.0]) == pytest.approx(2.0)


def test_min_soak_steps_is_the_shortest_soak_that_measures():
    """The bench refuses fewer steps per scenario than min_soak_steps: one step less fits
    no growth."""
    for every in (1, 5):
        need = min_soak_steps(every)
        assert soak_scenario("vs_random", need, every=every).measured
        assert not soak_scenario("vs_random", need - 1, every=every).measured
    assert min_soak_steps(10_000) == 10_001


def test_soak_refuses_too_few_steps_before_running(capsys):
    """soak() from Python with too few steps to measure a growth: an InputError naming
    the arguments, before anything runs (it ran them and reported 'soak FAILED')."""
    with pytest.raises(SoakError, match=r"^steps must be >= 10001 with every 10000 and 1 "
                                        r"scenario\(s\) \(each needs .*\), got 3000$"):
        soak(["vs_random"], 3000)
    assert issubclass(SoakError, InputError) and capsys.readouterr().out == ""
    with pytest.raises(SoakError, match=r"^steps must be >= 12 with every 5 and 2 scenario"):
        soak(["vs_random", "team"], 5, every=5, verbose=False)


@pytest.mark.parametrize("kwargs, message", [
    ({"every": 0}, r"^every must be an integer >= 1, got 0$"),
    ({"every": -5}, r"^every must be an integer >= 1, got -5$"),
    ({"scenarios": []}, r"^scenarios: need at least one scenario, got none$")])
def test_soak_refuses_every_below_one_and_no_scenarios(kwargs, message, capsys):
    """soak() from Python with every < 1 or no scenario: a SoakError naming the argument,
    before anything runs (ZeroDivisionError)."""
    with pytest.raises(SoakError, match=message):
        soak(**{"scenarios": ["vs_random"], "steps": 100, **kwargs})
    assert capsys.readouterr().out == ""


def test_a_short_soak_cannot_fail_on_a_page_of_noise():
    """One 4 kB page over 50 steps is 78 MB per 10^6 steps: within noise, not a leak; a
    real leak (2 kB a step) fails a short soak too."""
    page = 4096 / 2**20
    noise = SoakResult("s", 100, 0, 1.0, [(50, 175.8, 0.0), (100, 175.8 + page, 0.0)], 20)
    assert noise.rss_growth > 70 and noise.rss_rise < 0.01 and noise.passed()
    leak = SoakResult("s", 150_000, 0, 1.0, [(k, 100 + k * 2048 / 2**20, 0.0)
                                             for k in range(30_000, 150_001, 10_000)], 30_000)
    assert leak.rss_growth == pytest.approx(1953, rel=1e-3) and not leak.passed()
    # one sample after warm-up fits no growth: not measured, which is not a pass
    short = SoakResult("s", 10, 0, 1.0, [(10, 175.8, 0.0)], 2)
    assert not short.measured and not short.passed()
    assert short.verdict() == "not measured (too few steps)"

"""Scenarios: shipped files, validation errors, map folders, seat controllers."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from alphatank.bots import BOT_NAMES
from alphatank.envs.core import MatchSet
from alphatank.envs.vector import VectorMatchEnv
from alphatank.game.lineup import build_lineup
from alphatank.game.scenarios import (
    NoopPolicy,
    ScenarioError,
    Seat,
    load_scenario,
    parse_scenario,
    seats_scenario,
    shipped_scenarios,
)
from alphatank.game.seats import make_controller
from alphatank.sim.config import RewardConfig
from alphatank.sim.policy import NOOP

TABLE6 = ("team", "pair", "team_vs_bot", "team_vs_bot_hard", "team_vs_def_bot", "bot_teams",
          "mixed_teams")
VERSUS = {"vs_random": "random", "vs_aggressive": "aggressive", "vs_defensive": "defensive",
          "vs_dodge": "dodge", "vs_smart": "smart"}
MAPS = Path(__file__).resolve().parents[1] / "maps"


def test_shipped_scenarios_cover_the_paper():
    names = set(shipped_scenarios())
    assert set(TABLE6) | set(VERSUS) | {"selfplay_1v1", "team_vs_def_smart",
                                        "team_vs_four_bots"} <= names
    assert set(VERSUS.values()) == set(BOT_NAMES)


def test_table6_seats_match_the_paper():
    hard = load_scenario("team_vs_bot_hard")
    assert hard.teams == ["A", "A", "B", "B", "B"]
    assert [s.bot for s in hard.seats[2:]] == ["aggressive", "smart", "defensive"]
    mixed = load_scenario("mixed_teams")
    assert [s.controller for s in mixed.seats] == [
        "human", "bot", "learner", "human", "bot", "learner", "bot", "bot"]
    assert [s.keys for s in mixed.seats if s.controller == "human"] == ["wasd", "ijkl"]
    assert mixed.teams == ["A", "A", "A", "B", "B", "B", "C", "C"]
    assert load_scenario("bot_teams").learner_seats == []
    assert load_scenario("selfplay_1v1").learner_seats == [0, 1]


@pytest.mark.parametrize("name,bot", sorted(VERSUS.items()))
def test_versus_scenarios(name, bot):
    sc = load_scenario(name)
    assert [s.controller for s in sc.seats] == ["learner", "bot"] and sc.seats[1].bot == bot
    # The paper's Table 2: dodge and defensive bots train with long-range bullets.
    assert sc.preset == ("long_range" if bot in ("dodge", "defensive") else "paper")
    assert sc.game_config().bullet_max_distance == (800.0 if sc.preset == "long_range"
                                                    else 300.0)


@pytest.mark.parametrize("name", TABLE6)
def test_table6_scenario_runs_1000_random_steps(name):
    env = VectorMatchEnv(name, 1, seed=7)
    obs = env.reset()
    rng = np.random.default_rng(0)
    lengths = []
    for _ in range(1000):
        acts = rng.integers(0, [3, 3, 2], size=(1, env.num_learners, 3))
        obs, rew, term, trunc, info = env.step(acts)
        assert obs.shape == (1, env.num_learners, env.obs_dim) and np.isfinite(obs).all()
        assert np.isfinite(rew).all()
        lengths += [ep["length"] for ep in info["episodes"]]
    # Every tick is accounted for: finished episodes plus the running one.
    assert sum(lengths) + env.core.matches[0].tick == 1000


def _write(tmp_path: Path, text: str, name: str = "s.toml") -> Path:
    p = tmp_path / name
    p.write_text(text, encoding="utf-8")
    return p


BASE = '''name = "t"
map = "open"
[[seats]]
team = "A"
controller = "learner"
[[seats]]
team = "B"
controller = "bot"
bot = "random"
'''


@pytest.mark.parametrize("text,field,hint", [
    (BASE + 'colour = "red"\n', "colour", "valid keys"),
    (BASE.replace('map = "open"', 'map = "nowhere"'), "map", "shipped maps"),
    (BASE.replace('name = "t"\n', 'name = "t"\npreset = "fast"\n'), "preset", "long_range"),
    (BASE.replace('name = "t"\n', 'name = "t"\npreset = ["paper"]\n'), "preset", "long_range"),
    (BASE.replace('name = "t"\n', 'name = "t\\nu"\n'), "name", "U+000A is a control character"),
    (BASE.replace('name = "t"\n', 'name = "t"\nobservation = "pixels"\n'), "observation",
     "egocentric"),
    (BASE.replace('bot = "random"', 'bot = "genius"'), "seats[1].bot", "smart"),
    (BASE.replace('bot = "random"', 'bot = "random"\nweakness = 1.5'), "seats[1].weakness",
     "[0, 1]"),
    (BASE.replace('bot = "random"', 'bot = "random"\noptions = { hold_min = 0 }'),
     "seats[1].options", "need 1 <= hold_min <= hold_max, got hold_min=0"),
    (BASE.replace('controller = "learner"', 'controller = "robot"'), "seats[0].controller",
     "checkpoint"),
    (BASE.replace('controller = "learner"', 'controller = "human"\nkeys = "zqsd"'),
     "seats[0].keys", "arrows"),
    (BASE.replace('controller = "learner"', 'controller = "learner"\nbot = "smart"'),
     "seats[0].bot", "not used by a 'learner' seat"),
    (BASE.replace('team = "B"', 'team = "A"'), "seats", "2 teams"),
    (BASE + '[game]\nbullet_sped = 3.0\n', "[game]", "bullet_speed"),
    (BASE + '[rewards]\nvictroy = 1.0\n', "[rewards]", "victory"),
    (BASE + '[game]\nbullet_speed = 10.0\n', "[game]", "must exceed tank_speed"),
    ('name = "t"\nmap = "open"\n[[seats]]\nteam = "A"\ncontroller = "learner"\n', "seats",
     "at least 2"),
    (BASE.replace('controller = "bot"\nbot = "random"', 'controller = "checkpoint"'),
     "seats[1].path", "checkpoint folder"),
])
def test_invalid_scenarios_name_file_and_field(tmp_path, text, field, hint):
    p = _write(tmp_path, text)
    with pytest.raises(ScenarioError) as err:
        load_scenario(p)
    msg = str(err.value)
    assert str(p) in msg and field in msg and hint in msg


def test_invalid_toml_and_unknown_name(tmp_path, monkeypatch):
    p = _write(tmp_path, "name = \n")
    with pytest.raises(ScenarioError, match="invalid TOML"):
        load_scenario(p)
    with pytest.raises(ScenarioError, match="vs_smart"):
        load_scenario("no_such_scenario")
    monkeypatch.chdir(tmp_path)  # a shipped name with .toml is a path: say so
    with pytest.raises(ScenarioError, match=r"^vs_smart\.toml: no such scenario file \(the "
                                            r"shipped scenario is 'vs_smart', without \.toml\)$"):
        load_scenario("vs_smart.toml")


def test_a_shipped_name_is_not_hidden_by_a_folder_or_file_of_that_name(tmp_path, monkeypatch):
    """A folder 'team' or a file 'pair' in the working folder made load_scenario('team')
    fail ('team: a folder, not a scenario file'), and with it `import alphatank.envs`,
    which loads every shipped scenario by name to register its ids."""
    from alphatank.envs.ids import single_learner_scenarios

    monkeypatch.chdir(tmp_path)
    (tmp_path / "team").mkdir()
    (tmp_path / "pair").write_text("not toml [", encoding="utf-8")
    assert load_scenario("team").source == "scenarios/team.toml"
    assert len(load_scenario("pair").learner_seats) == 2
    assert "vs_smart" in single_learner_scenarios()
    with pytest.raises(ScenarioError, match="team: a folder, not a scenario file"):
        load_scenario(tmp_path / "team")  # a path is a path


def test_a_shipped_map_is_not_hidden_by_a_folder_of_that_name(tmp_path, monkeypatch):
    """A folder 'battlefield' in the working folder made every scenario on battlefield fail
    ('folder 'battlefield' holds no .txt maps': `import alphatank.envs` too), and a folder
    'arena4' of maps silently replaced the shipped arena4 of `team`."""
    from alphatank.envs.ids import single_learner_scenarios

    monkeypatch.chdir(tmp_path)
    (tmp_path / "battlefield").mkdir()
    (tmp_path / "arena4").mkdir()
    shutil.copy(MAPS / "maze.txt", tmp_path / "arena4" / "maze.txt")
    assert "vs_smart" in single_learner_scenarios()
    assert load_scenario("vs_smart").maps == ("pkg:battlefield.txt",)
    assert load_scenario("team").maps == ("pkg:arena4.txt",)
    assert seats_scenario("smart,smart", "train/maze_0000").maps == ("pkg:train/maze_0000.txt",)
    for local in ("./arena4", "arena4/"):  # the folder here, named as a path
        assert seats_scenario("smart,smart", local).maps == (str(Path("arena4/maze.txt")),)
    # a scenario file's own folder is still read first (docs: relative map paths)
    own = _write(tmp_path, BASE.replace('map = "open"', 'map = "arena4"'))
    assert load_scenario(own).maps == (str(tmp_path / "arena4" / "maze.txt"),)


def test_overrides_reach_the_configs():
    sc = parse_scenario({"name": "x", "map": "open", "game": {"max_steps": 77},
                         "rewards": {"victory": 5.0},
                         "seats": [{"team": "A", "controller": "learner"},
                                   {"team": "B", "controller": "learner"}]})
    assert sc.game_config().max_steps == 77
    assert sc.reward_config() == RewardConfig(victory=5.0)
    with pytest.raises(ScenarioError, match="max_stepz"):
        sc.game_config(max_stepz=3)


def test_map_folder_is_sampled_per_episode_and_reported(tmp_path):
    folder = tmp_path / "pool"
    folder.mkdir()
    for name in ("open", "battlefield", "maze"):
        shutil.copy(MAPS / f"{name}.txt", folder / f"{name}.txt")
    p = _write(tmp_path, BASE.replace('map = "open"', 'map = "pool"').replace(
        'controller = "bot"\nbot = "random"', 'controller = "learner"'))
    sc = load_scenario(p)  # relative to the scenario file's folder
    assert len(sc.maps) == 3
    env = VectorMatchEnv(sc, 4, seed=3)
    env.reset()
    seen = {env.core.map_name(e) for e in range(4)}
    for seed in range(4, 12):
        env.reset(seed)
        seen |= {env.core.map_name(e) for e in range(4)}
    assert seen == {"open", "battlefield", "maze"}
    # Fixed size across maps: walls padded to the largest map, with a mask.
    lay = env.layout
    masks = env.reset(0)[:, 0, [lay[f"wall[{k}].mask"].start for k in range(
        sum(1 for f in lay.fields if f.endswith(".x0")))]]
    assert masks.shape[1] == max(len(s.wall_rects) for s in sc.map_specs())
    # Same seed, same maps.
    a = [env.core.map_name(e) for e in range(4)]
    env.reset(0)
    assert a == [env.core.map_name(e) for e in range(4)]


def test_make_controller_resolves_controllers():
    assert make_controller(Seat("A", "learner")) is None
    human = make_controller(Seat("A", "human", keys="wasd"))
    assert isinstance(human, NoopPolicy)
    assert np.array_equal(human.act(None, 0), NOOP)
    bot = make_controller(Seat("B", "bot", bot="smart", weakness=0.5), seed=1)
    assert hasattr(bot, "act") and hasattr(bot, "reset")


def test_human_seats_idle_without_keyboard():
    ms = MatchSet("mixed_teams", 1)
    ms.reset_env(0, 5)
    start = ms.matches[0].tank_xy[[0, 3]].copy()
    for _ in range(30):
        ms.step(np.ones((1, 2, 3), dtype=np.int64))
    assert np.allclose(ms.matches[0].tank_xy[[0, 3]], start)
    assert (ms.joint[0, [0, 3]] == NOOP).all()


@pytest.mark.parametrize("name", ["team_vs_def_smart", "team_vs_four_bots"])
def test_nododge_scenarios_are_the_paper_rows_with_bots_that_do_not_dodge(name):
    full, calm = load_scenario(name), load_scenario(f"{name}_nododge")
    assert (calm.map, calm.preset, calm.game) == (full.map, full.preset, full.game)
    assert [(s.controller, s.team, s.bot) for s in calm.seats] == [
        (s.controller, s.team, s.bot) for s in full.seats]
    for scenario, dodging in ((full, True), (calm, False)):
        lineup = build_lineup(scenario, learner="bot:random")
        lineup.start(3)
        for seat, ctrl in zip(scenario.seats, lineup.controllers, strict=True):
            if seat.bot in ("smart", "defensive"):
                bot = getattr(ctrl, "bot", ctrl)  # weakness wrapper or the bot itself
                assert (bot.evader is not None) is dodging, (scenario.name, seat.bot)

"""Evaluation: exact counts, symmetric tables, Wilson intervals, Table-3 layout, CSV/JSON."""

import argparse
import csv
import json

import numpy as np
import pytest
import torch

from alphatank.bots import make_bot
from alphatank.cli import main
from alphatank.commands import eval as eval_cmd
from alphatank.envs.core import MatchSet
from alphatank.game.scenarios import load_scenario, parse_scenario
from alphatank.stats import wilson_interval
from alphatank.training.evaluate import (
    EvalResult,
    evaluate_checkpoint,
    evaluate_stand_in,
    format_table,
    game_seed,
    play_games,
    rate_games,
    results_league,
    row_opponents,
    write_csv,
    write_json,
)
from alphatank.training.ppo import PPOConfig
from alphatank.training.presets import LearnerSpec, TrainConfig
from alphatank.training.runner import Trainer

torch.set_num_threads(1)


def duel(max_steps: int) -> object:
    """Two learner seats on the open map (filled with policies by the tests)."""
    return parse_scenario({"name": "duel", "map": "open", "game": {"max_steps": max_steps},
                           "seats": [{"team": "A", "controller": "learner"},
                                     {"team": "B", "controller": "learner"}]})


def bots(w: float) -> dict:
    return {0: make_bot("aggressive", weakness=w, seed=1),
            1: make_bot("aggressive", weakness=w, seed=2)}


def evaluate_policies(sc, policies: dict, team: str, games: int, seed: int = 0,
                      num_envs: int = 8) -> EvalResult:
    """Count games of ``sc`` whose learner seats are filled by ``policies``."""
    core = MatchSet(sc, min(num_envs, games), driven=[], seat_policies=policies)
    return play_games(core, team, games, seed, None,
                      EvalResult(name=sc.name, opponent=core.describe_opponents(0)))


def test_idle_bots_draw_every_game_exactly():
    res = evaluate_policies(duel(20), bots(0.0), team="A", games=13, num_envs=4)
    assert (res.wins, res.losses, res.draws, res.games) == (0, 0, 13, 13)
    assert res.lengths == [20] * 13
    assert res.interval == wilson_interval(0, 13)


def test_bot_against_itself_gives_a_symmetric_table():
    sc = duel(600)
    a = evaluate_policies(sc, bots(1.0), team="A", games=40, num_envs=8, seed=3)
    b = evaluate_policies(sc, bots(1.0), team="B", games=40, num_envs=8, seed=3)
    assert a.games == b.games == 40
    assert (a.wins, a.losses, a.draws) == (b.losses, b.wins, b.draws)  # same games, mirrored
    assert max(a.lengths) < 600 and a.wins > 0  # every game ends in combat (draw: both die)
    assert abs(a.wins - a.losses) <= 8  # identical bots: no side wins by much


def test_counts_do_not_depend_on_how_games_are_split_over_envs():
    sc = duel(300)
    r4 = evaluate_policies(sc, bots(1.0), team="A", games=10, num_envs=4, seed=9)
    r7 = evaluate_policies(sc, bots(1.0), team="A", games=10, num_envs=7, seed=9)
    assert (r4.wins, r4.losses, r4.draws) == (r7.wins, r7.losses, r7.draws)
    assert sorted(r4.lengths) == sorted(r7.lengths)


def test_bot_parity_plays_the_learner_seats_in_the_same_games(tmp_path, capsys):
    """bot:NAME puts the bot in every learner seat: the same games as evaluate_policies
    with that bot there, whatever num_envs; idle opponents lose every game to it."""
    sc = duel(300)
    ref = evaluate_policies(sc, bots(1.0), team="A", games=10, num_envs=4, seed=9)
    tmp = tmp_path / "duel_bots.toml"
    tmp.write_text('name = "duel_bots"\nmap = "open"\n[game]\nmax_steps = 300\n'
                   '[[seats]]\nteam = "A"\ncontroller = "learner"\n'
                   '[[seats]]\nteam = "B"\ncontroller = "bot"\nbot = "aggressive"\n')
    for n_env in (3, 7):
        (par,) = evaluate_stand_in("aggressive", tmp, [None], games=10, seed=9,
                                   num_envs=n_env)
        assert par.outcomes == ref.outcomes and par.lengths == ref.lengths
    assert par.name == "Aggressive Bot vs Aggressive Bot" and par.agent == "bot:aggressive"
    (idle,) = evaluate_stand_in("smart", "vs_smart", ["dodge"], games=4, weakness=0.0)
    assert (idle.wins, idle.games) == (4, 4) and idle.opponent == "dodge"
    assert main(["eval", "bot:smart", "--scenario", "vs_smart", "--vs", "random",
                 "--weakness", "0", "--games", "2"]) == 0
    assert "| bot:smart  | Smart Bot vs Random Bot |" in capsys.readouterr().out
    assert main(["eval", "bot:smart", "--games", "2"]) == 2
    assert "give --scenario" in capsys.readouterr().err


def test_table_layout_wilson_and_files(tmp_path):
    rows = [EvalResult("PPO Agent vs Smart Bot", "smart", wins=60, losses=40),
            EvalResult("2 PPO Agents vs 1 Defensive + 2 Smart Bots", "x", wins=40, losses=55,
                       draws=5)]
    table = format_table(rows).splitlines()
    assert [c.strip() for c in table[0].split("|")[1:-1]] == [
        "Experiment Name", "Agent Wins", "Bot Wins", "Draws", "Agent Win Ratio", "Wilson 95% CI"]
    assert len({len(line) for line in table}) == 1  # aligned columns
    lo, hi = wilson_interval(60, 100)
    assert "| 60% " in table[2] and f"[{100 * lo:.1f}%, {100 * hi:.1f}%]" in table[2]
    assert "| 40%" in table[3] and "| 5 " in table[3]
    write_csv(rows, tmp_path / "t.csv")
    write_json(rows, tmp_path / "t.json")
    with open(tmp_path / "t.csv") as f:
        got = list(csv.DictReader(f))
    assert got[1]["wins"] == "40" and got[1]["draws"] == "5" and got[1]["games"] == "100"
    data = json.loads((tmp_path / "t.json").read_text())
    assert data[0]["win_rate"] == 0.6 and data[0]["ci95_low"] == round(lo, 4)


def test_a_win_ratio_never_reads_none_or_all_when_it_is_not():
    """The table's whole percent rounded 1 win of 200 to '0%' and 199 of 200 to '100%'
    (beside '1' and '199' wins and a Wilson interval that excludes them); such a ratio
    gets the decimals it takes. Whole games stay whole percent, as in the paper."""
    rows = [EvalResult("a", "smart", wins=1, losses=199), EvalResult("b", "smart", wins=199,
                                                                    draws=1),
            EvalResult("c", "smart", wins=1, losses=29999), EvalResult("d", "smart", wins=0,
                                                                      losses=7),
            EvalResult("e", "smart", wins=7), EvalResult("f", "smart", wins=3, losses=497)]
    ratios = [line.split("|")[5].strip() for line in format_table(rows).splitlines()[2:]]
    assert ratios == ["0.5%", "99.5%", "0.003%", "0%", "100%", "1%"]


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory):
    run = tmp_path_factory.mktemp("runs") / "ev"
    cfg = TrainConfig("ev", "vs_aggressive", total_steps=128, num_envs=4, wandb="disabled",
                      game={"max_steps": 60},
                      learners=(LearnerSpec("ppo", "ppo", (0,),
                                            config=PPOConfig(num_steps=16, update_epochs=1)),))
    Trainer(cfg, run, progress=False).train()
    return run


def test_checkpoint_against_several_bots(checkpoint):
    res = evaluate_checkpoint(checkpoint, ["random", "aggressive"], games=6, num_envs=3)
    assert [r.name for r in res] == ["PPO Agent vs Random Bot", "PPO Agent vs Aggressive Bot"]
    assert all(r.games == 6 for r in res)
    again = evaluate_checkpoint(checkpoint, ["random", "aggressive"], games=6, num_envs=3)
    assert [(r.wins, r.losses, r.draws) for r in res] == \
        [(r.wins, r.losses, r.draws) for r in again]


def test_eval_command_prints_table_and_writes_files(checkpoint, tmp_path, capsys):
    parser = argparse.ArgumentParser()
    eval_cmd.add_arguments(parser)
    args = parser.parse_args([str(checkpoint), "--vs", "aggressive", "--games", "4",
                              "--num-envs", "2", "--csv", str(tmp_path / "e.csv"),
                              "--json", str(tmp_path / "e.json")])
    assert eval_cmd.run(args) == 0
    out = capsys.readouterr().out
    assert "| PPO Agent vs Aggressive Bot |" in out and "Wilson 95% CI" in out
    assert json.loads((tmp_path / "e.json").read_text())[0]["games"] == 4
    assert main(["eval", str(tmp_path / "missing")]) == 2
    assert "alphatank eval: error: " in (err := capsys.readouterr().err)
    assert "no such checkpoint" in err


def test_eval_pool_adds_up_the_rows_against_each_opponent(capsys):
    args = ["eval", "bot:aggressive", "bot:smart", "--scenario", "vs_aggressive", "--games",
            "6", "--num-envs", "3", "--seed", "4"]
    assert main(args) == 0
    rows = capsys.readouterr().out
    assert main(args + ["--pool"]) == 0
    out = capsys.readouterr().out
    assert out.startswith(rows)  # the same table, then one pooled line
    (line,) = [x for x in out.splitlines() if x.startswith("pooled vs ")]
    counts = [x.split("|")[3:6] for x in rows.splitlines() if x.startswith("| bot:")]
    w, lo, d = (sum(int(c[k]) for c in counts) for k in range(3))
    assert f"(2 rows): {w}/{lo}/{d} (W/L/D) of 12 games" in line and "permutation p = " in line
    # the legend says how to read p whatever its value (it read "(small: ...)" after p = 1)
    assert line.endswith("(a small p says the rows differ more than chance)")
    assert main(["eval", "bot:smart", "--scenario", "vs_aggressive", "--pool"]) == 2
    assert "--pool needs two or more checkpoints" in capsys.readouterr().err


def test_eval_game_settings_override_the_checkpoints_own(checkpoint, capsys, tmp_path):
    """--game changes the game played over the one the checkpoint trained in (here its
    60-tick limit) and nothing else; bad keys and values are one-line errors."""
    own = evaluate_checkpoint(checkpoint, ["random"], games=6, num_envs=3)[0]
    short = evaluate_checkpoint(checkpoint, ["random"], games=6, num_envs=3,
                                game={"max_steps": 20})[0]
    assert max(own.lengths) > 20 >= max(short.lengths)
    same = evaluate_checkpoint(checkpoint, ["random"], games=6, num_envs=3,
                               game={"max_steps": 60})[0]
    assert (same.outcomes, same.lengths) == (own.outcomes, own.lengths)
    assert main(["eval", str(checkpoint), "--vs", "random", "--games", "6", "--num-envs",
                 "3", "--game", "max_steps=20", "--json", str(tmp_path / "g.json")]) == 0
    capsys.readouterr()
    assert json.loads((tmp_path / "g.json").read_text())[0]["wins"] == short.wins
    (bot,) = evaluate_stand_in("smart", "vs_smart", [None], games=4, game={"max_steps": 15})
    assert max(bot.lengths) <= 15
    for text, words in (("nope=1", ["--game nope: unknown game setting", "random_spawns"]),
                        ("max_steps=abc", ["--game max_steps:", "'abc'"]),
                        ("max_steps", ["--game: expected KEY=VALUE"]),
                        ("max_steps=0", ["--game max_steps: must be in [1, 10000000], got 0"]),
                        ("tank_speed=nan", ["--game tank_speed: must be a finite number"]),
                        ("bullet_speed=50", ["--game bullet_speed: (50) must exceed tank_speed"]),
                        # more bullets per tank than its observations hold (it crashed as
                        # "expects N observation features ... another layout")
                        ("max_steps=20,buff_max_bullets=20", ["--game buff_max_bullets: lets a "
                         "tank have up to 20 bullets alive", "trained with 10", "most at 10"])):
        assert main(["eval", str(checkpoint), "--games", "2", "--game", text]) == 2
        err = capsys.readouterr().err
        assert all(w in err for w in words) and len(err.strip().splitlines()) == 1, err




@pytest.fixture(scope="module")
def long_games(tmp_path_factory):
    """A barely trained (near-uniform, sampled) policy whose games run long enough to end
    in combat."""
    run = tmp_path_factory.mktemp("runs") / "long"
    cfg = TrainConfig("long", "vs_aggressive", total_steps=64, num_envs=4, wandb="disabled",
                      game={"max_steps": 400},
                      learners=(LearnerSpec("ppo", "ppo", (0,),
                                            config=PPOConfig(num_steps=16, update_epochs=1)),))
    Trainer(cfg, run, progress=False).train()
    return run


def test_sampled_policy_games_do_not_depend_on_num_envs(long_games):
    """Game i depends only on (seed, i): sampled actions come from that game's generator,
    whichever env plays it and however many envs run together."""
    runs = [evaluate_checkpoint(long_games, ["aggressive"], games=8, seed=4, num_envs=n)[0]
            for n in (1, 3, 8)]
    assert len(runs[0].outcomes) == 8 and len(set(runs[0].lengths)) > 1
    for r in runs[1:]:
        assert (r.wins, r.losses, r.draws) == (runs[0].wins, runs[0].losses, runs[0].draws)
        assert r.outcomes == runs[0].outcomes and r.lengths == runs[0].lengths
    # the sampled actions matter: the most likely actions give other games
    greedy = evaluate_checkpoint(long_games, ["aggressive"], games=8, seed=4, num_envs=3,
                                 deterministic=True)[0]
    assert greedy.lengths != runs[0].lengths


def test_rows_are_labelled_and_columns_name_what_plays(checkpoint, tmp_path, capsys):
    parser = argparse.ArgumentParser()
    eval_cmd.add_arguments(parser)
    args = parser.parse_args([str(checkpoint), f"checkpoint:{checkpoint}", "--vs", "random",
                              "--games", "3", "--num-envs", "3", "--ratings",
                              "--csv", str(tmp_path / "e.csv"), "--json", str(tmp_path / "e.json")])
    assert eval_cmd.run(args) == 0
    out = capsys.readouterr().out
    head, _, first, second = out.splitlines()[:4]
    assert [c.strip() for c in head.split("|")[1:4]] == ["Checkpoint", "Experiment Name",
                                                         "Agent Wins"]
    assert "Bot Wins" in head
    assert first.split("|")[1].strip() == str(checkpoint)
    assert second.split("|")[1].strip() == f"checkpoint:{checkpoint}"
    assert "openskill" in out and "| random" in out  # the bot is rated beside the agents
    with open(tmp_path / "e.csv") as f:
        labels = [row["checkpoint"] for row in csv.DictReader(f)]
    assert labels == [str(checkpoint), f"checkpoint:{checkpoint}"]
    rows = json.loads((tmp_path / "e.json").read_text())
    assert [r["checkpoint"] for r in rows] == labels and len(rows[0]["outcomes"]) == 3
    # an opponent that is not a bot: the column says so
    agent_row = EvalResult("PPO Agent vs PPO Agent", "B:ppo", wins=1, sides=("Agent", "Agent"))
    assert "Opponent Wins" in format_table([agent_row]).splitlines()[0]
    assert "Bot Wins" not in format_table([agent_row]).splitlines()[0]


def test_rate_games_puts_agents_and_bots_in_one_table():
    league = rate_games([("agent_a", "smart", ["win"] * 8 + ["loss"] * 2),
                         ("agent_b", "smart", ["loss"] * 8 + ["draw"] * 2)])
    mu = {name: m for name, m, *_ in league.table()}
    assert set(mu) == {"agent_a", "agent_b", "smart"}
    assert mu["agent_a"] > mu["smart"] > mu["agent_b"]  # 8-2 over smart; smart 8-0 over b



def test_ratings_do_not_depend_on_the_order_of_the_rows():
    """Three runs with the same results get the same rating, whichever is listed first
    (rated game by game in row order, the first listed came out lowest)."""
    same = ["loss"] * 9 + ["draw"]
    rows = [(name, "smart", same) for name in ("run_a", "run_b", "run_c")]
    rows.append(("run_d", "defensive", ["win"] * 6))
    tables = [{n: (round(m, 9), round(s, 9)) for n, m, s, _ in rate_games(order).table()}
              for order in (rows, rows[::-1], rows[1:] + rows[:1])]
    assert tables[0] == tables[1] == tables[2]
    assert tables[0]["run_a"] == tables[0]["run_b"] == tables[0]["run_c"]


def test_a_row_where_the_checkpoint_drives_every_seat_is_against_itself():
    from alphatank.game.scenarios import load_scenario

    assert row_opponents(load_scenario("team"), [None, "smart"]) == ["itself", "smart"]
    assert row_opponents(load_scenario("team_vs_bot"), [None]) == ["B:smart(w=1), B:smart(w=1)"]


def test_self_play_rows_are_not_rated_against_a_shared_player():
    """Two self-play checkpoints were both rated against one player 'itself', which
    linked their ratings; a checkpoint against itself says nothing of its skill."""
    rows = [EvalResult("a", "itself", wins=4, agent="runs/a", outcomes=["win"] * 4),
            EvalResult("b", "itself", losses=4, agent="runs/b", outcomes=["loss"] * 4),
            EvalResult("a", "smart", wins=3, agent="runs/a", outcomes=["win"] * 3)]
    names = {n for n, *_ in results_league(rows).table()}
    assert names == {"runs/a", "smart"}


def test_an_evaluation_seed_is_checked_by_name():
    with pytest.raises(ValueError, match="seed must be an integer >= 0, got -1"):
        game_seed(-1, 0)
    assert game_seed(np.int64(7), 3) == game_seed(7, 3)



def test_a_checkpoint_plays_maps_with_fewer_walls_as_its_seat_does():
    """An agent trained with room for 11 wall rectangles (battlefield) on arena4 (fewer):
    evaluation pads its observation as play and arena do, and plays the very games its
    checkpoint seat plays (it was refused: 'expects 236 observation features ... gives
    215'); a map with more walls than its room says so."""
    from alphatank.training.checkpoint import agent_path, load_policy
    from alphatank.training.evaluate import with_map

    path = agent_path("ppo_vs_smart")
    res = evaluate_checkpoint(path, [None], games=2, seed=4, map_name="arena4",
                              deterministic=True, num_envs=2)[0]
    seat = evaluate_policies(with_map(load_scenario("vs_smart"), "arena4"),
                             {0: load_policy(path, deterministic=True)}, "A", games=2, seed=4,
                             num_envs=2)
    assert res.games == 2 and (res.outcomes, res.lengths) == (seat.outcomes, seat.lengths)
    with pytest.raises(ValueError, match=r"gives 256 \(its maps have up to 15 wall rectangles; "
                                         r"its 'paper' observation has room for 11\)"):
        evaluate_checkpoint(path, [None], games=1, map_name="maze")
    with pytest.raises(ValueError, match=r"\(the match has 4 tanks; it trained with 2\)"):
        evaluate_checkpoint(path, [None], games=1, scenario="team_vs_bot")

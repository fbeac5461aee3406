"""Team training end to end: MAPPO through ``alphatank train`` (save, exact resume,
checkpoints as policies in eval, arena and play seats), one policy object in several
seats and envs, the self-play pool driving per-env opponents, warm starts."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch

from alphatank.cli import main
from alphatank.envs.core import MatchSet
from alphatank.game.lineup import build_lineup
from alphatank.game.scenarios import load_scenario, parse_scenario, team_misfit, team_shape
from alphatank.training.checkpoint import (
    CheckpointError,
    LivePolicy,
    load_checkpoint,
    load_policy,
)
from alphatank.training.evaluate import evaluate_checkpoint
from alphatank.training.hparams import MAPPOConfig, PPOConfig
from alphatank.training.presets import LearnerSpec, TrainConfig, load_run
from alphatank.training.runner import Trainer, resume_trainer
from alphatank.training.selfplay import opponent_name

torch.set_num_threads(1)

RUN = """
scenario = "team_vs_bot"
[game]
max_steps = 40
[rewards]
team_win = 100.0
team_loss = -50.0
team_draw = -60.0
engagement = 10.0
step_cost = -0.1
[[learners]]
name = "team"
algo = "mappo"
seats = [0, 1]
[learners.config]
num_steps = 16
update_epochs = 2
hidden = 32
"""
E = 2
ITER = 16 * E


def _train(tmp_path, *args: str) -> int:
    where = [] if "--resume" in args else ["--runs", str(tmp_path)]  # a resumed run's own
    return main(["train", *where, "--num-envs", str(E), "--wandb", "disabled",
                 "--no-progress", "--checkpoint-every", "2", *args])


@pytest.fixture(scope="module")
def team_runs(tmp_path_factory):
    """The same tiny MAPPO run twice: 4 iterations in one go, and 2 + a resume to 4."""
    root = tmp_path_factory.mktemp("team")
    cfg = root / "team.toml"
    cfg.write_text(RUN)
    assert _train(root, "--config", str(cfg), "--name", "full", "--total-steps",
                  str(4 * ITER)) == 0
    assert _train(root, "--config", str(cfg), "--name", "half", "--total-steps",
                  str(2 * ITER)) == 0
    assert _train(root, "--resume", str(root / "half"), "--total-steps", str(4 * ITER)) == 0
    return root


def test_mappo_run_saves_and_resumes_bit_for_bit(team_runs):
    full, half = load_checkpoint(team_runs / "full"), load_checkpoint(team_runs / "half")
    assert full.meta["progress"]["global_step"] == half.meta["progress"]["global_step"] == 4 * ITER
    assert full.learner_specs[0].algo == "mappo" and full.meta["input_dims"] == {
        "alive": 1, "state": 69}
    a, b = full.state("team"), half.state("team")
    assert int(a["updates"]) == 4 and int(a["num_seats"]) == 2
    for key in a["net"]:
        assert torch.equal(a["net"][key], b["net"][key]), key
    assert a["value_norm"]["mean"] == b["value_norm"]["mean"]


def test_mappo_checkpoint_plays_in_eval_arena_and_play_seats(team_runs):
    run = team_runs / "full"
    res = evaluate_checkpoint(run, [None, "random"], games=4, seed=5, num_envs=2)
    assert [r.games for r in res] == [4, 4]
    assert res[0].name == "2 MAPPO Agents vs 2 Smart Bots"
    # scenario seats of controller "checkpoint" (the arena's and play's seat kinds)
    sc = parse_scenario({"name": "t", "map": "arena4", "game": {"max_steps": 60}, "seats": [
        {"team": "A", "controller": "checkpoint", "path": str(run)},
        {"team": "A", "controller": "checkpoint", "path": str(run)},
        {"team": "B", "controller": "bot", "bot": "random"},
        {"team": "B", "controller": "bot", "bot": "random"}]})
    ep = build_lineup(sc).play(seed=3)
    assert ep.match.done and ep.ticks > 0
    # play / record: the scenario's learner seats taken by the checkpoint
    lineup = build_lineup("team_vs_bot", learner=f"checkpoint:{run}")
    assert [c.seat_id(ep.match, s, "team", 2) for s, c in enumerate(lineup.controllers[:2])] \
        == [0, 1]
    assert main(["eval", str(run), "--games", "2", "--num-envs", "2"]) == 0


def one_vs_random(policy, map_name: str) -> MatchSet:
    """A 1v1 on ``map_name`` with ``policy`` in seat 0 against the random bot."""
    sc = parse_scenario({"name": "t", "map": map_name, "seats": [
        {"team": "A", "controller": "learner"}, {"team": "B", "controller": "bot",
                                                 "bot": "random"}]})
    return MatchSet(sc, 1, driven=[], seat_policies={0: policy})


def test_a_checkpoint_of_another_team_size_says_what_fits(team_runs):
    core = one_vs_random(load_policy(team_runs / "full"), "arena4")
    with pytest.raises(CheckpointError, match=r"gives 226.*fits seats of matches with 4 tanks"
                                              r".*'team_vs_bot'"):
        core.reset_env(0, 1)


def test_a_team_checkpoint_in_teams_of_other_sizes_says_where_it_trained(team_runs, tmp_path):
    """Four tanks as in training, but split 1 vs 3 or 2 vs 1 vs 1: the observation has the
    same size and other meanings, so the seat is refused with the place it trained in."""
    pol = load_policy(team_runs / "full")
    sc = parse_scenario({"name": "t", "map": "arena4", "seats": [
        {"team": "A", "controller": "learner"},
        *({"team": "B", "controller": "bot", "bot": "random"} for _ in range(3))]})
    core = MatchSet(sc, 1, driven=[], seat_policies={0: pol})
    with pytest.raises(CheckpointError, match=r"seat 0 of this match \(teams \['A', 'B', 'B', "
                       r"'B'\]\) plays alone against a team of 3; it trained in a team of 2 "
                       r"against a team of 2, in its training scenario 'team_vs_bot'"):
        core.reset_env(0, 1)
    lineup = {"name": "t", "map": "arena4", "seats": [
        {"team": "A", "controller": "learner"}, {"team": "A", "controller": "learner"},
        {"team": "B", "controller": "bot", "bot": "random"},
        {"team": "C", "controller": "bot", "bot": "random"}]}
    file = tmp_path / "split.toml"
    file.write_text("\n".join(
        ['name = "split"', 'map = "arena4"']
        + [f'[[seats]]\nteam = "{s["team"]}"\ncontroller = "{s["controller"]}"'
           + (f'\nbot = "{s["bot"]}"' if "bot" in s else "") for s in lineup["seats"]]))
    with pytest.raises(ValueError, match=r"scenario 'split': seat 0 of this match .* plays in "
                       r"a team of 2 against teams of 1 and 1; it trained in a team of 2 "
                       r"against a team of 2"):
        evaluate_checkpoint(team_runs / "full", [None], games=1, scenario=str(file))
    # the place it trained in plays from other seats, with other bots
    swapped = parse_scenario({"name": "t", "map": "arena4", "seats": [
        {"team": "B", "controller": "bot", "bot": "smart"},
        {"team": "B", "controller": "bot", "bot": "dodge"},
        {"team": "A", "controller": "learner"}, {"team": "A", "controller": "learner"}]})
    core = MatchSet(swapped, 1, driven=[], seat_policies={2: pol, 3: pol})
    core.reset_env(0, 1)
    core.step(np.zeros((1, 0, 3), dtype=np.int64))


def test_team_shape_reads_own_and_other_team_sizes():
    assert team_shape(["A", "A", "B"], 2) == (1, (2,))
    assert team_shape(["A", "B", "C", "C"], 2) == (2, (1, 1))
    assert team_misfit(["A", "A", "B"], [0, 1], ["B", "A", "A"], 2) is None
    assert team_misfit(["A", "B"], [0], ["A", "B", "C"], 0) == (
        "seat 0 of this match (teams ['A', 'B', 'C']) plays alone against teams of 1 and 1; "
        "it trained alone against a team of 1")
    assert team_misfit([], [0], ["A", "B", "C"], 0) is None


def _play(core: MatchSet, ticks: int) -> np.ndarray:
    for e in range(core.num_envs):
        core.reset_env(e, 100 + e)
    for _ in range(ticks):
        core.step(np.zeros((core.num_envs, 0, 3), dtype=np.int64))
    return np.stack([m.tank_xy.copy() for m in core.matches])


def test_one_policy_object_in_two_seats_of_two_envs_acts_per_seat(team_runs):
    """One object in both team seats of two envs plays exactly like four objects."""
    shared = load_policy(team_runs / "full")
    own = {s: load_policy(team_runs / "full") for s in (0, 1)}
    sc = dataclasses.replace(load_scenario("team_vs_bot"), seats=(
        *load_scenario("team_vs_bot").seats[:2],
        *[dataclasses.replace(s, bot="random") for s in load_scenario("team_vs_bot").seats[2:]]))
    one = _play(MatchSet(sc, 2, driven=[], seat_policies={0: shared, 1: shared}), 40)
    four = _play(MatchSet(sc, 2, driven=[], seat_policies=own), 40)
    assert np.array_equal(one, four)
    assert not np.array_equal(one[0], one[1])  # the two envs play different games


TINY = MAPPOConfig(num_steps=16, update_epochs=1, hidden=32)


def selfplay_config(name: str, iterations: int) -> TrainConfig:
    return TrainConfig(
        name=name, scenario="team", total_steps=iterations * 16 * 4, num_envs=4, seed=1,
        wandb="disabled", checkpoint_every=2, game={"max_steps": 30},
        rewards={"team_win": 50.0, "team_loss": -20.0, "team_draw": -20.0},
        learners=(LearnerSpec("team", "mappo", (0, 1), TINY),),
        selfplay={"window": 2, "every": 64, "latest_share": 0.5})


def test_selfplay_pool_drives_per_env_opponents_and_resumes(tmp_path):
    tr = Trainer(selfplay_config("sp", 4), tmp_path / "sp", progress=False)
    assert tr.env.learner_seats == [0, 1]  # the pool plays seats 2 and 3
    tr.train()
    sp, core = tr.selfplay, tr.env.core
    pool = sp.pool
    assert [s.step for s in pool.snapshots] == [128, 192]  # every 64 steps, window 2
    assert pool.next_id == 4 and sum(pool.games.values()) == tr.episodes > 0
    for e in range(4):
        # the env's next episode plays the snapshot chosen for it from (seed, env, episode)
        assert sp.next[e] == pool.opponent_for(e, int(sp.games[e]))
        assert core.env_opponent[e] == opponent_name(sp.next[e])
        # ... and its current episode the one chosen before it started
        cur = core.opponents[opponent_name(sp.current[e])]
        assert core.controllers[e][2] is cur and core.controllers[e][3] is cur
        assert isinstance(cur, LivePolicy)
    assert {"selfplay/mu", "selfplay/rated_games"} <= set(tr.history[-1])
    assert "charts/win_rate_vs/selfplay" in tr.history[-1]
    # a run stopped at iteration 2 and resumed plays the same games and learns the same
    Trainer(selfplay_config("half", 2), tmp_path / "half", progress=False).train()
    res = resume_trainer(tmp_path / "half", progress=False, total_steps=4 * 64)
    res.train()
    assert res.selfplay.pool.games == pool.games
    assert [s.id for s in res.selfplay.pool.snapshots] == [s.id for s in pool.snapshots]
    a, b = tr.learners["team"].state_dict(), res.learners["team"].state_dict()
    for key in a["net"]:
        assert torch.equal(a["net"][key], b["net"][key]), key


def test_selfplay_settings_are_checked(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('scenario = "team"\n[selfplay]\nwindow = 0\n[[learners]]\nname = "t"\n'
                   'algo = "mappo"\nseats = [0, 1]\n')
    with pytest.raises(ValueError, match=r"bad.toml: selfplay: snapshot pool needs window >= 1"):
        load_run(bad)
    bad.write_text('scenario = "team"\n[selfplay]\nlearner = "x"\n[[learners]]\nname = "t"\n'
                   'algo = "mappo"\nseats = [0, 1]\n')
    with pytest.raises(ValueError, match=r"selfplay.learner: 'x' is not one of"):
        load_run(bad)
    cfg = dataclasses.replace(selfplay_config("x", 1), learners=(
        LearnerSpec("a", "mappo", (0, 1), TINY), LearnerSpec("b", "mappo", (2, 3), TINY)))
    with pytest.raises(ValueError, match="leave the others to the snapshot pool"):
        Trainer(cfg, tmp_path / "x", progress=False)


def test_warm_start_from_a_1v1_run(tmp_path, capsys):
    one = TrainConfig(name="one", scenario="vs_smart", total_steps=64, num_envs=2,
                      wandb="disabled", learners=(LearnerSpec(
                          "ppo", "ppo", (0,), PPOConfig(num_steps=16, update_epochs=1,
                                                        hidden=32)),))
    Trainer(one, tmp_path / "one", progress=False).train()
    cfg = tmp_path / "team.toml"
    cfg.write_text(RUN)
    assert _train(tmp_path, "--config", str(cfg), "--name", "warm", "--total-steps", "32",
                  "--init-from", str(tmp_path / "one")) == 0
    out = capsys.readouterr().out
    assert "warm start team from" in out and "critic fresh" in out
    assert load_checkpoint(tmp_path / "warm").train_config.init_from == str(tmp_path / "one")
    assert _train(tmp_path, "--config", str(cfg), "--name", "w2", "--init-from",
                  "agent:nobody") == 2
    assert "unknown agent 'nobody'; shipped agents:" in capsys.readouterr().err


def test_a_checkpoint_in_a_match_of_another_tank_count_is_told_so_before_the_map():
    """A 4-tank team agent in a 1v1 on a map with more walls than its room: the tank count
    fits no map, so that is what it is told (it was told the map's walls, and on a map
    with room then the tank count)."""
    from alphatank.training.checkpoint import agent_path

    core = one_vs_random(load_policy(agent_path("team_vs_2smart")), "maze")
    with pytest.raises(CheckpointError, match=r"seat 0 of this match \(2 tanks, teams \['A', "
                       r"'B'\]\) gives \d+; it fits seats of matches with 4 tanks"):
        core.reset_env(0, 1)

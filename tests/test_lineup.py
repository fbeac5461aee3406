"""One line-up: the same (scenario, seed) is the same game through the env, the arena,
`alphatank record` and `alphatank play`; the seat grammar, controller kinds resolved late
(a registered kind, shipped agents, checkpoints) and the episode hooks."""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from alphatank.cli import main
from alphatank.commands import arena as arena_cmd
from alphatank.commands import eval as eval_cmd
from alphatank.commands import play, record
from alphatank.commands.lineup_options import lineup_from_args
from alphatank.envs.core import MatchSet
from alphatank.game import seats
from alphatank.game.arena import run_arena
from alphatank.game.lineup import build_lineup, lineup_scenario
from alphatank.game.scenarios import ScenarioError, seats_scenario
from alphatank.game.seats import (
    SeatError,
    checkpoint_source,
    parse_seat_list,
    register_controller,
    resolve,
    shipped_agents,
)
from alphatank.sim.episode import EpisodeHook, episode_seeds
from alphatank.sim.policy import NoopPolicy
from alphatank.ui.replay import load_replay

MAPS = Path(__file__).resolve().parents[1] / "maps"
SEATS, MAP, STEPS, SEED = "smart,aggressive", "battlefield", 400, 7


def _args(module, *argv: str) -> argparse.Namespace:
    p = argparse.ArgumentParser()
    module.add_arguments(p)
    return p.parse_args(list(argv))


def env_game(sc, seed: int) -> tuple[str, int, str | None]:
    """Final state hash, length and winner of the env episode of ``seed`` (every seat a
    bot)."""
    core = MatchSet(sc, 1, driven=[])
    core.reset_env(0, seed)
    nobody = np.zeros((1, 0, 3), dtype=np.int64)
    m = core.matches[0]
    while not m.done:
        core.step(nobody)
    return m.state_hash(), m.tick, m.winner


def test_one_scenario_and_seed_is_one_game_everywhere(tmp_path, capsys):
    sc = seats_scenario(SEATS, MAP, {"max_steps": STEPS})
    env, ticks, winner = env_game(sc, SEED)
    arena: list[str] = []
    run_arena(SEATS.split(","), MAP, games=1, seed=SEED, game={"max_steps": STEPS},
              on_game=lambda a, b, ep: arena.append(ep.match.state_hash()))
    common = ("--seats", SEATS, "--map", MAP, "--max-steps", str(STEPS), "--seed", str(SEED))
    assert record.run(_args(record, *common, "--out", str(tmp_path / "r.mp4"), "--every",
                            "60", "--scale", "0.25", "--replay", str(tmp_path / "r.npz"))) == 0
    assert play.run(_args(play, *common, "--headless-test", "--fps", "30", "--max-frames",
                          str(STEPS + 5), "--save-replay", str(tmp_path / "p.npz"))) == 0
    recorded, played = load_replay(tmp_path / "r.npz"), load_replay(tmp_path / "p.npz")
    lineup = build_lineup(sc).play(SEED).match.state_hash()
    assert env == arena[0] == recorded.final_hash == played.final_hash == lineup
    assert f"final state hash: {env}" in capsys.readouterr().out
    # a real fight, ended by a kill before the step limit
    assert 30 < ticks == recorded.ticks == played.ticks < STEPS and winner is not None
    assert recorded.winner == played.winner == winner and recorded.actions[..., 2].any()
    assert env_game(sc, SEED + 1)[0] != env  # the seed matters


def test_the_public_envs_reset_seed_starts_the_game_of_that_seed():
    """``reset(seed=S)`` of the Gymnasium and PettingZoo envs is the game ``record
    --seed S`` plays (the first tick's state, random spawns included); later resets
    without a seed go on from S's generator, and numpy seeds are the same seeds."""
    import gymnasium

    import alphatank.envs  # noqa: F401  (registers the ids)
    from alphatank.envs import parallel_env

    for seed in (0, 7, np.int64(123)):
        want = build_lineup("vs_smart", stand_in="smart").start(int(seed)).match
        env = gymnasium.make("AlphaTank/VsSmart-v0")
        env.reset(seed=seed)
        assert env.unwrapped.match.state_hash() == want.state_hash()
        team = build_lineup("team_vs_def_smart", stand_in="smart").start(int(seed)).match
        pz = parallel_env(scenario="team_vs_def_smart")
        pz.reset(seed=seed)
        assert pz.core.matches[0].state_hash() == team.state_hash()
    env.reset()
    again = gymnasium.make("AlphaTank/VsSmart-v0")
    again.reset(seed=123)
    again.reset()
    assert env.unwrapped.match.state_hash() == again.unwrapped.match.state_hash()
    assert env.unwrapped.match.state_hash() != want.state_hash()


def test_the_map_of_an_episode_comes_from_its_seed():
    sc = seats_scenario(SEATS, "train")  # a folder of maps: one drawn per episode
    core, lineup = MatchSet(sc, 1, driven=[]), build_lineup(sc)
    names = set()
    for seed in range(8):
        core.reset_env(0, seed)
        ep = lineup.start(seed)
        assert ep.seeds == episode_seeds(seed, 2, len(sc.maps))
        assert ep.match.spec.name == core.map_name(0)
        assert ep.match.state_hash() == core.matches[0].state_hash()
        names.add(core.map_name(0))
    assert len(names) > 2


def test_max_steps_keeps_a_scenario_maps_relative_to_its_file(tmp_path, monkeypatch):
    """``record``/``play --scenario FILE --max-steps N``: a map named relative to the
    scenario file's folder was looked up from the working folder ('unknown map')."""
    folder = tmp_path / "duel"
    folder.mkdir()
    shutil.copy(MAPS / "maze.txt", folder / "mine.txt")
    (folder / "s.toml").write_text('name = "s"\nmap = "mine.txt"\n[game]\nmax_steps = 900\n'
                                   '[[seats]]\nteam = "A"\ncontroller = "learner"\n'
                                   '[[seats]]\nteam = "B"\ncontroller = "bot"\nbot = "smart"\n',
                                   encoding="utf-8")
    monkeypatch.chdir(tmp_path)
    args = _args(record, "--scenario", str(folder / "s.toml"), "--max-steps", "5")
    lineup = lineup_from_args(args, interactive=False)
    assert lineup.scenario.maps == (str(folder / "mine.txt"),)
    assert lineup.scenario.game_config().max_steps == 5
    assert lineup.play(0).match.tick == 5
    with pytest.raises(ScenarioError, match=r"s\.toml: \[game\]\.max_steps: must be in"):
        lineup_scenario(str(folder / "s.toml"), game={"max_steps": 0})


def test_episode_hooks_see_start_every_tick_and_the_end_once():
    class Log(EpisodeHook):
        def __init__(self):
            self.calls = []

        def on_start(self, episode):
            self.calls.append(("start", episode.match.tick))

        def on_tick(self, episode, events):
            self.calls.append(("tick", episode.match.tick))

        def on_end(self, episode):
            self.calls.append(("end", episode.match.tick))

    log = Log()
    lineup = build_lineup(seats_scenario("smart,random", "open", {"max_steps": 50}))
    ep = lineup.start(2, [log], tick_limit=20).run()
    ep.end()
    ep.run()
    assert log.calls == [("start", 0), *(("tick", t) for t in range(1, 21)), ("end", 20)]
    assert ep.over and ep.ticks == 20 and not ep.match.done


def test_seat_list_grammar():
    tables = parse_seat_list("A=smart:ricochet=false@0.5,B=checkpoint:runs/a:b@2,human,"
                             "agent:ace,bot:dodge:evade=off,human")
    assert tables[0] == {"team": "A", "controller": "bot", "bot": "smart",
                         "options": {"ricochet": False}, "weakness": 0.5}
    assert tables[1] == {"team": "B", "controller": "checkpoint", "path": "runs/a:b@2"}
    assert tables[2] == {"team": "C", "controller": "human", "keys": "wasd"}
    assert tables[3] == {"team": "D", "controller": "agent", "agent": "ace"}
    assert tables[4]["bot"] == "dodge" and tables[4]["options"] == {"evade": False}
    assert tables[5]["keys"] == "arrows"
    sc = seats_scenario("A=smart:ricochet=false@0.5,B=human:ijkl", "open")
    assert [s.describe() for s in sc.seats] == ["smart(w=0.5,ricochet=False)", "human:ijkl"]
    again = seats_scenario("B=human:ijkl,A=random", "open")  # describe() reads back
    assert again.seats[0] == sc.seats[1]
    # a human seat without keys gets the first set no other seat names
    assert [t["keys"] for t in parse_seat_list("human:arrows,human")] == ["arrows", "wasd"]
    assert [t.get("keys") for t in parse_seat_list("human,smart,human:wasd")] == [
        "arrows", None, "wasd"]
    # after Z: AA, AB, ... (the 28th seat got '\\', the 64th the control character U+007F)
    teams = [t["team"] for t in parse_seat_list(",".join(["random"] * 64))]
    assert teams[24:29] == ["Y", "Z", "AA", "AB", "AC"] and teams[-1] == "BL"
    assert len(set(teams)) == 64 and seats_scenario(",".join(["random"] * 64), "open")


@pytest.mark.parametrize("text,hint", [
    ("human,robot", "neither a seat kind (learner, human, checkpoint, agent) nor a valid "
                    "bot spec: unknown bot 'robot'; valid bots"),
    ("human,smart:=", "nor a valid bot spec: bot spec 'smart:=': option '=' must be "
                      "KEY=VALUE; valid options of 'smart': ['ricochet', 'evade']"),
    ("human,learner:x", "a 'learner' seat takes no ':' argument"),
    ("human,checkpoint:", "needs the checkpoint folder"),
    ("human,smart:speed=3", "seats[1].options: bot 'smart' has no option(s) ['speed']; "
                            "valid options: ['ricochet', 'evade'] (weakness: NAME@W"),
    ("human,smart@2", "seats[1].weakness: must be a number in [0, 1]"),
    ("human,random:hold_min=40", "seats[1].options: RandomBot: need 1 <= hold_min <= "
                                 "hold_max, got hold_min=40, hold_max=30"),
    ("human,smart:fast", "must be KEY=VALUE"),
    ("human,human:zqsd", "seats[1].keys: got 'zqsd'; valid: ['wasd', 'arrows', 'ijkl']"),
    ("human,checkpoint:/no/such/run", "seats[1].path: /no/such/run: no such checkpoint"),
    ("smart", "at least 2 seats"),
])
def test_bad_seats_name_the_seat_and_what_is_allowed(text, hint):
    with pytest.raises(ScenarioError) as err:
        seats_scenario(text, "open")
    assert hint in str(err.value)


def test_more_players_than_key_sets_is_said_so():
    """Four human seats at one keyboard: the error said two seats 'use the ijkl keys' and
    to give each player its own of the three sets."""
    sc = seats_scenario("human,human,human,human,smart", "arena8")
    with pytest.raises(ScenarioError, match=r"^--seats: seats \[0, 1, 2, 3\] are 4 players at "
                                            r"one keyboard, which has 3 key sets"):
        build_lineup(sc, interactive=True)
    assert len(build_lineup(sc, stand_in="smart").controllers) == 5  # no keyboard: stand-ins


def test_unknown_agents_list_the_shipped_ones(tmp_path, monkeypatch):
    monkeypatch.setattr(seats, "agents_root", lambda: tmp_path)
    assert shipped_agents() == []
    with pytest.raises(ScenarioError, match="unknown agent 'ace'; shipped agents: none yet"):
        seats_scenario("agent:ace,smart", "open")
    with pytest.raises(SeatError, match="none yet"):
        checkpoint_source("agent:ace")
    assert checkpoint_source("checkpoint:runs/x") == checkpoint_source("runs/x") == "runs/x"


def still_seat(seat, seed=None) -> NoopPolicy:
    """Factory of the test's registered ``still`` kind."""
    return NoopPolicy()


def test_a_registered_kind_fills_seats(monkeypatch):
    monkeypatch.setattr(seats, "CONTROLLER_KINDS", dict(seats.CONTROLLER_KINDS))
    register_controller("still", f"{__name__}:still_seat", keys=(), arg=None)
    sc = lineup_scenario(seats="smart,B=still", game={"max_steps": 30})
    assert sc.seats[1].controller == "still" and sc.seats[1].describe() == "still"
    ep = build_lineup(sc).play(3)
    assert isinstance(ep.controllers[1], NoopPolicy) and ep.ticks > 0
    with pytest.raises(ValueError, match="other than 'learner' and 'bot'"):
        register_controller("bot", f"{__name__}:still_seat")
    with pytest.raises(ValueError, match="not 'module:attribute'"):
        register_controller("odd", "still_seat")
    with pytest.raises(SeatError, match="cannot be loaded"):
        resolve("alphatank.nowhere:thing")


def test_the_game_layer_resolves_kinds_late():
    """Scenarios and env episodes with bot seats load the bots, never training, torch or
    pygame (the kinds' modules are imported on first use, by name)."""
    code = ("import sys, numpy as np; from alphatank.envs.core import MatchSet; "
            "m = MatchSet('bot_teams', 1, driven=[]); m.reset_env(0, 1); "
            "m.step(np.zeros((1, 0, 3), dtype=np.int64)); "
            "print(sorted({n.split('.')[0] if not n.startswith('alphatank') else "
            "'.'.join(n.split('.')[:2]) for n in sys.modules} & {'torch', 'pygame', "
            "'alphatank.training', 'alphatank.bots'}))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "['alphatank.bots']"


# ---- checkpoints and shipped agents as seats ------------------------------------------

@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """A tiny PPO run on vs_aggressive, and an agents folder holding its save as 'tiny'."""
    import torch

    from alphatank.training.checkpoint import resolve_checkpoint_dir
    from alphatank.training.ppo import PPOConfig
    from alphatank.training.presets import LearnerSpec, TrainConfig
    from alphatank.training.runner import Trainer

    torch.set_num_threads(1)
    root = tmp_path_factory.mktemp("lineup")
    cfg = TrainConfig("tiny", "vs_aggressive", total_steps=64, num_envs=2, num_workers=1,
                      wandb="disabled", game={"max_steps": 40},
                      learners=(LearnerSpec("ppo", "ppo", (0,),
                                            config=PPOConfig(num_steps=16, update_epochs=1)),))
    Trainer(cfg, root / "run", progress=False).train()
    shutil.copytree(resolve_checkpoint_dir(root / "run"), root / "agents" / "tiny")
    return root / "run", root / "agents"


def test_arena_seats_can_be_checkpoints_and_agents(trained, monkeypatch, capsys):
    run, agents = trained
    monkeypatch.setattr(seats, "agents_root", lambda: agents)
    names = [f"checkpoint:{run}", "agent:tiny", "random"]
    res = run_arena(names, "open", games=2, seed=1, game={"max_steps": 30})
    assert res.names == names and all(res.games(i, j) == 2 for i in range(3) for j in range(3)
                                       if i != j)
    assert [row[0] for row in res.league.table()] != [] and "agent:tiny" in res.table()
    assert arena_cmd.run(_args(arena_cmd, "--seats", "agent:tiny,random", "--map", "open",
                               "--games", "2", "--max-steps", "30")) == 0
    out = capsys.readouterr().out
    assert any(line.startswith("agent:tiny") for line in out.splitlines())
    assert main(["arena", "--seats", "agent:nobody,random"]) == 2
    assert "shipped agents: tiny" in capsys.readouterr().err


def test_arena_fits_every_seat_to_the_map_before_the_first_game():
    """The shipped agent fits battlefield, not maze: the arena fails before smart-vs-dodge
    is played (it used to play that pair, then fail, losing its results)."""
    from alphatank.training.checkpoint import CheckpointError

    played: list[str] = []
    with pytest.raises(CheckpointError, match="map 'maze' has 15 wall rectangles"):
        run_arena(["smart", "dodge", "agent:ppo_vs_smart"], "maze", games=1,
                  on_game=lambda a, b, ep: played.append(a))
    assert played == []


def test_eval_accepts_checkpoint_and_agent_arguments(trained, monkeypatch, capsys):
    run, agents = trained
    monkeypatch.setattr(seats, "agents_root", lambda: agents)
    assert eval_cmd.run(_args(eval_cmd, f"checkpoint:{run}", "agent:tiny", "--vs", "random",
                              "--games", "2", "--num-envs", "1")) == 0
    rows = [ln.split("|")[1:] for ln in capsys.readouterr().out.splitlines()
            if "vs Random Bot" in ln]
    assert [r[0].strip() for r in rows] == [f"checkpoint:{run}", "agent:tiny"]  # labelled
    assert len(rows) == 2 and rows[0][1:] == rows[1][1:]  # the same checkpoint, same games
    assert main(["eval", "agent:nobody"]) == 2
    assert "shipped agents: tiny" in capsys.readouterr().err


def test_learner_seats_take_an_agent(trained, monkeypatch):
    run, agents = trained
    monkeypatch.setattr(seats, "agents_root", lambda: agents)
    lineup = build_lineup("vs_aggressive", learner="agent:tiny")
    assert lineup.seats[0] == "agent:tiny" and lineup.labels == ["tiny", "aggressive"]
    ep = lineup.play(4)
    assert ep.over and type(ep.controllers[0]).__name__ == "CheckpointPolicy"
    with pytest.raises(ScenarioError, match="learner seat"):
        build_lineup("vs_aggressive")
    with pytest.raises(ScenarioError, match="agent:tiny: --seats has no learner seat for it"):
        build_lineup(seats_scenario("smart,random", "open"), learner="agent:tiny")


def test_checkpoint_seats_are_labelled_by_their_folder(trained, monkeypatch, tmp_path):
    """Each checkpoint seat is labelled by its run folder (a save inside one: RUN/step_N),
    so two checkpoints in one match can be told apart; shipped agents keep their names."""
    run, agents = trained
    monkeypatch.setattr(seats, "agents_root", lambda: agents)
    other = tmp_path / "rival"
    shutil.copytree(run, other)
    save = sorted((run / "checkpoints").iterdir())[-1]
    lineup = build_lineup(seats_scenario(f"checkpoint:{run}/,checkpoint:{other},"
                                         f"checkpoint:{save},agent:tiny", "arena4"))
    assert lineup.labels == ["run", "rival", f"run/{save.name}", "tiny"]

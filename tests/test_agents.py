"""Shipped agents: every Table 3 row ships, loads with weights_only=True and plays a game
in its own scenario; export strips training state; unknown names list the shipped ones."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
import torch

from alphatank.cli import main
from alphatank.game.lineup import build_lineup, lineup_scenario
from alphatank.game.seats import SeatError, agent_path, shipped_agents
from alphatank.training.algorithms import ALGORITHMS
from alphatank.training.checkpoint import CheckpointError, load_checkpoint, load_policy
from alphatank.training.hparams import MAPPOConfig, PPOConfig, SACConfig
from alphatank.training.learners import learner_class
from alphatank.training.presets import LearnerSpec, TrainConfig
from alphatank.training.runner import Trainer
from alphatank.training.warmstart import warm_start_from_checkpoint

TABLE3 = ("ppo_vs_smart", "ppo_vs_aggressive", "ppo_vs_dodge", "ppo_vs_defensive",
          "team_vs_2smart", "team_vs_def", "team_vs_def_2smart", "team_vs_four_bots")


def test_every_table3_row_ships_in_under_10_mb():
    assert set(TABLE3) <= set(shipped_agents())
    size = sum(f.stat().st_size for name in shipped_agents()
               for f in Path(agent_path(name)).iterdir())
    assert size < 10e6


@pytest.mark.parametrize("name", shipped_agents())
def test_shipped_agent_loads_weights_only_and_plays_its_scenario(name):
    path = Path(agent_path(name))
    for pt in path.glob("*.pt"):
        state = torch.load(pt, weights_only=True)
        assert "optimizer" not in state and "net" in state
    ckpt = load_checkpoint(path)
    assert ckpt.meta["agent"]["progress"]["global_step"] > 0
    lineup = build_lineup(ckpt.scenario, learner=f"agent:{name}")
    ep = lineup.start(seed=1, tick_limit=120).run()
    assert ep.ticks > 0
    assert all(type(c).__name__ == "CheckpointPolicy"
               for s, c in zip(ckpt.scenario.seats, lineup.controllers, strict=True)
               if s.controller == "learner")


def test_the_shipped_agents_hold_the_inference_keys_and_only_known_extras():
    """Exported before export kept only the inference keys, the shipped agents' files also
    hold ``updates`` (and the league agent ``anchor``), which loading ignores; nothing
    else (the module doc names both)."""
    extra = {}
    for name in shipped_agents():
        ckpt = load_checkpoint(agent_path(name))
        for spec in ckpt.learner_specs:
            state = torch.load(Path(agent_path(name)) / f"{spec.name}.pt", weights_only=True)
            keys = set(learner_class(spec.algo).inference_keys)
            assert keys <= set(state)
            for key in set(state) - keys:
                extra.setdefault(key, set()).add(name)
    assert set(extra) <= {"updates", "anchor"} and extra.get("anchor", set()) <= {"league"}


def test_an_egocentric_agent_plays_a_map_with_more_walls_than_it_trained_on():
    # ppo_cycle_full trained on battlefield and open (11 and 4 wall rectangles); maze has
    # 15. Its observation has no wall block, so it plays there; a paper agent says why not.
    paper = "15 wall rectangles; its 'paper' observation has room for 11"
    for name, want in (("ppo_cycle_full", None), ("ppo_vs_smart", paper)):
        sc = lineup_scenario(seats=f"smart,agent:{name}", map_name="maze")
        assert len(sc.map_specs()[0].wall_rects) == 15
        lineup = build_lineup(sc)
        if want is None:
            ep = lineup.start(seed=2, tick_limit=60).run()
            assert ep.ticks == 60 or ep.over
        else:
            with pytest.raises(CheckpointError, match=want):
                lineup.start(seed=2, tick_limit=60)


def test_unknown_agent_lists_the_shipped_ones():
    with pytest.raises(SeatError, match="unknown agent 'nobody'; shipped agents: "):
        agent_path("nobody")


def test_export_strips_training_state_and_lists(tmp_path, capsys):
    cfg = TrainConfig(name="one", scenario="vs_aggressive", total_steps=64, num_envs=2,
                      wandb="disabled", game={"max_steps": 40}, learners=(LearnerSpec(
                          "ppo", "ppo", (0,), PPOConfig(num_steps=16, update_epochs=1)),))
    Trainer(cfg, tmp_path / "one", progress=False).train()
    row = {"checkpoint": str(tmp_path / "one"), "win_rate": 0.5, "ci95_low": 0.1,
           "ci95_high": 0.9, "games": 2}
    export = ["agents", "export", str(tmp_path / "one"), str(tmp_path / "agent"),
              "--description", "tiny", "--eval", str(tmp_path / "e.json")]
    for bad, why in (({**row, "checkpoint": "agent:ppo_vs_smart"},
                      "row 0 evaluated 'agent:ppo_vs_smart', not the exported checkpoint"),
                     ({"win_rate": 0.5, "games": 2}, "row 0 is not a row of `alphatank eval")):
        (tmp_path / "e.json").write_text(json.dumps([bad]))  # another's, or not a row
        assert main(export) == 2 and why in capsys.readouterr().err
        assert not (tmp_path / "agent").exists()
    (tmp_path / "e.json").write_text(json.dumps([row]))
    assert main(export) == 0
    state = torch.load(tmp_path / "agent" / "ppo.pt", weights_only=True)
    assert set(state) == {"net", "obs_norm"}
    meta = load_checkpoint(tmp_path / "agent").meta
    assert meta["agent"]["description"] == "tiny" and meta["agent"]["eval"][0]["games"] == 2
    assert "windows" not in meta
    pol = load_policy(tmp_path / "agent")
    assert pol.learners["ppo"].obs_dim == load_checkpoint(tmp_path / "one").obs_dim
    assert main(["agents"]) == 0
    out = capsys.readouterr().out
    assert all(name in out for name in shipped_agents()) or "no shipped agents" in out
    cycle = next(line for line in out.splitlines() if line.startswith("ppo_cycle_full"))
    assert all(f"vs {bot} " in cycle for bot in ("random", "aggressive", "defensive", "dodge"))


def test_the_listing_shows_each_agent_s_training_seed(capsys):
    """The seed column is the run's own ``seed`` (the README's shipped seeds: the defensive
    row's best seed 2, the cycle agent's seed 1)."""
    assert main(["agents"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].split()[:4] == ["agent", "scenario", "seed", "steps"]
    rows = {line.split()[0]: line.split() for line in lines[1:]}
    for name in shipped_agents():
        assert rows[name][2] == str(load_checkpoint(agent_path(name)).train_config.seed)
    assert rows["ppo_vs_defensive"][2] == "2" and rows["ppo_cycle_full"][2] == "1"


def test_a_shipped_agent_s_saved_description_names_its_schedule():
    """A row built on a preset inherited the preset's description: the fixed-order cycle
    agent read "(adaptive)", the league agent "PPO vs smart bot". Their meta.json (not
    hashed: it holds the weights' digests) says what they trained."""
    for name in shipped_agents():
        cfg = load_checkpoint(agent_path(name)).train_config
        kind = cfg.schedule.get("kind")
        if kind == "cycle":
            mode = cfg.schedule.get("mode", "fixed")
            other = "adaptive" if mode == "fixed" else "fixed"
            assert mode in cfg.description and other not in cfg.description, name
        elif kind == "league":
            assert "league" in cfg.description.lower(), name


TINY = {"ppo": ("vs_aggressive", PPOConfig(num_steps=16, update_epochs=1)),
        "sac": ("vs_aggressive", SACConfig(hidden=16, batch_size=16, start_steps=16,
                                           update_after=16, update_every=16,
                                           buffer_size=1000)),
        "mappo": ("team_vs_bot", MAPPOConfig(num_steps=16, update_epochs=1, hidden=16))}


@pytest.mark.parametrize("algo", sorted(ALGORITHMS))
def test_export_keeps_only_the_inference_state_of_every_algorithm(algo, tmp_path):
    """No optimiser, target network or other training-only state (SAC's q_target and
    three optimisers included); the agent still loads weights-only, plays its scenario
    and, for PPO, warm-starts a new learner."""
    scenario, hp = TINY[algo]
    seats = (0, 1) if algo == "mappo" else (0,)
    cfg = TrainConfig(name="one", scenario=scenario, total_steps=64, num_envs=2,
                      wandb="disabled", game={"max_steps": 40},
                      learners=(LearnerSpec(algo, algo, seats, hp),))
    run = Trainer(cfg, tmp_path / "one", progress=False)
    run.train()
    trained = run.learners[algo].state_dict()
    assert main(["agents", "export", str(tmp_path / "one"), str(tmp_path / "agent")]) == 0
    state = torch.load(tmp_path / "agent" / f"{algo}.pt", weights_only=True)
    assert set(state) == set(learner_class(algo).inference_keys) < set(trained)
    assert not any("optim" in k or "target" in k for k in state)
    ckpt = load_checkpoint(tmp_path / "agent")
    ckpt.load_learner(algo, weights_only=True)
    lineup = build_lineup(ckpt.scenario, learner=f"checkpoint:{tmp_path / 'agent'}")
    assert lineup.start(seed=1, tick_limit=60).run().ticks > 0
    if algo == "ppo":  # --init-from reads the same entries
        fresh = learner_class("ppo")(run.env.layout.size, 1, hp)
        info = warm_start_from_checkpoint(fresh, tmp_path / "agent", run.env.layout, 0)
        assert info["mapped"] == run.env.layout.size


def test_export_replaces_only_an_agent_folder(tmp_path, capsys):
    """An agent exported from a shipped one (``agent:NAME``) replaces an earlier export;
    a folder or file that is not an agent is refused and left as it was."""
    keep = tmp_path / "keep"
    keep.mkdir()
    (keep / "notes.txt").write_text("precious")
    name = shipped_agents()[0]
    assert main(["agents", "export", f"agent:{name}", str(keep)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("alphatank agents: error: ") and "not an agent folder" in err
    assert [p.name for p in keep.iterdir()] == ["notes.txt"]
    assert main(["agents", "export", f"agent:{name}", str(keep / "notes.txt")]) == 2
    assert (keep / "notes.txt").read_text() == "precious"
    dest = tmp_path / "agent"
    for text in ("first", "second"):
        assert main(["agents", "export", f"agent:{name}", str(dest), "--description", text,
                     "--command", f"made {text}"]) == 0
    record = load_checkpoint(dest).meta["agent"]
    assert record["description"] == "second" and record["commands"] == ["made second"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["agent", "keep"]  # no leftovers
    long = tmp_path / ("a" * 250)  # the temporary and old folders' names are cut short
    for _ in range(2):
        assert main(["agents", "export", f"agent:{name}", str(long)]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == [long.name, "agent", "keep"]
    (tmp_path / "e.json").write_text("{bad")
    assert main(["agents", "export", f"agent:{name}", str(dest), "--eval",
                 str(tmp_path / "e.json")]) == 2
    assert "alphatank agents: error: --eval: " in capsys.readouterr().err
    assert load_checkpoint(dest).meta["agent"]["description"] == "second"
    (dest / "NOTES.md").write_text("mine")  # an agent folder with a file of the user's
    assert main(["agents", "export", f"agent:{name}", str(dest)]) == 2
    assert "NOTES.md, which replacing it would delete" in capsys.readouterr().err
    assert (dest / "NOTES.md").read_text() == "mine"
    assert load_checkpoint(dest).meta["agent"]["description"] == "second"


def test_an_export_that_fails_leaves_nothing_behind(tmp_path, capsys):
    """A damaged learner file is found before anything is written: no temporary folder
    (it was left as .NAME.tmp-PID) and no parent folder made for it."""
    src = tmp_path / "src"
    shutil.copytree(agent_path(shipped_agents()[0]), src)
    pt = next(src.glob("*.pt"))
    pt.write_bytes(pt.read_bytes()[:1000])
    assert main(["agents", "export", str(src), str(tmp_path / "out" / "agent")]) == 2
    assert f"{pt}: corrupt or truncated" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["src"]

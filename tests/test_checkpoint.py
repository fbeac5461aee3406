"""Checkpoints: atomic save, Policy in any seat, exact resume, clear errors on bad files."""

import dataclasses
import json
import resource
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch

import alphatank.maps
from alphatank.envs.core import MatchSet
from alphatank.game.scenarios import ScenarioError, load_scenario, parse_scenario
from alphatank.game.seats import make_controller
from alphatank.sim.episode import start_episode
from alphatank.sim.policy import Policy
from alphatank.training.checkpoint import (
    CheckpointError,
    SaveFailed,
    load_checkpoint,
    load_policy,
    non_finite,
    npz_arrays,
    save_checkpoint,
)
from alphatank.training.hparams import MAPPOConfig
from alphatank.training.ppo import PPOConfig
from alphatank.training.presets import LearnerSpec, TrainConfig
from alphatank.training.runner import Trainer, resume_trainer
from alphatank.training.sac import SACConfig

torch.set_num_threads(1)

PPO_TINY = PPOConfig(num_steps=16, update_epochs=2, num_minibatches=2)
SAC_TINY = SACConfig(batch_size=32, start_steps=32, update_after=32, update_every=16,
                     buffer_size=4096, hidden=32)
E = 4
ITER = 16 * E  # env steps per iteration


def tiny_config(name: str, iterations: int, **kw) -> TrainConfig:
    base = dict(name=name, scenario="vs_aggressive", total_steps=iterations * ITER,
                num_envs=E, num_workers=1, seed=3, wandb="disabled", checkpoint_every=2,
                game={"max_steps": 40}, learners=(LearnerSpec("ppo", "ppo", (0,), PPO_TINY),))
    base.update(kw)
    return TrainConfig(**base)


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    run = tmp_path_factory.mktemp("runs") / "tiny"
    Trainer(tiny_config("tiny", 3, wandb="offline", video_every=3), run, progress=False).train()
    return run


def test_run_folder_has_offline_wandb_metrics_and_video(trained):
    assert list((trained / "wandb").glob("offline-run-*/run-*.wandb"))  # no account needed
    rows = [json.loads(line) for line in (trained / "metrics.jsonl").read_text().splitlines()]
    assert [r["step"] for r in rows] == [ITER, 2 * ITER, 3 * ITER]
    assert {"charts/sps", "losses/policy_loss", "losses/entropy"} <= set(rows[-1])
    video = trained / "videos" / f"step_{3 * ITER:010d}.mp4"
    assert video.stat().st_size > 1000


def test_save_layout_is_complete_and_atomic(trained):
    ckpts = sorted(p.name for p in (trained / "checkpoints").iterdir())
    assert ckpts == [f"step_{2 * ITER:010d}", f"step_{3 * ITER:010d}"]  # every 2 + final
    assert (trained / "latest").read_text().strip() == f"checkpoints/step_{3 * ITER:010d}"
    ck = load_checkpoint(trained)  # run dir resolves to the latest save
    assert ck.meta["progress"]["global_step"] == 3 * ITER
    assert set(ck.meta["files"]) == {"ppo.pt"}
    assert ck.meta["env"] == "AlphaTank/VsAggressive-v0"  # the env (and version) trained on
    assert ck.scenario.name == "vs_aggressive" and ck.train_config.num_envs == E
    state = torch.load(ck.path / "ppo.pt", weights_only=True)
    assert {"net", "optimizer", "obs_norm", "ret_norm", "generator"} <= set(state)
    assert state["obs_norm"]["count"] > 3 * ITER - 1  # the normaliser is saved
    assert not [p for p in (trained / "checkpoints").iterdir() if p.name.startswith(".")]


def test_checkpoint_is_a_policy_in_any_seat(trained):
    pol = load_policy(trained)
    assert isinstance(pol, Policy)
    for seat in (0, 1):  # trained in seat 0; also plays seat 1 against the bot
        seats = [{"team": "A", "controller": "bot", "bot": "aggressive"},
                 {"team": "B", "controller": "bot", "bot": "aggressive"}]
        seats[seat] = {"team": "AB"[seat], "controller": "learner"}
        sc = parse_scenario({"name": "t", "map": "open", "seats": seats})
        core = MatchSet(sc, 1, driven=[], seat_policies={seat: pol})
        core.reset_env(0, 11)
        m = core.matches[0]
        for _ in range(60):
            if m.done:
                break
            core.step(np.zeros((1, 0, 3), dtype=np.int64))
        assert m.tick > 0
    # a scenario seat of controller "checkpoint" loads it by path
    sc = parse_scenario({"name": "t", "map": "open", "seats": [
        {"team": "A", "controller": "checkpoint", "path": str(trained)},
        {"team": "B", "controller": "bot", "bot": "aggressive", "weakness": 0.0}]})
    core = MatchSet(sc, 1, driven=[])
    core.reset_env(0, 5)
    a = core.controllers[0][0].act(core.matches[0], 0)
    assert a.shape == (3,) and a.dtype == np.int64


def test_one_policy_in_many_envs_plays_each_env_as_it_would_alone(tmp_path):
    """A checkpoint asked for many matches at once (one observation build, one forward
    pass) samples and acts in each exactly as when it plays that match alone."""
    run = tmp_path / "full"
    Trainer(tiny_config("full", 1, observation="egocentric_full", checkpoint_every=0), run,
            progress=False).train()

    def play(core: MatchSet, seeds: list[int]) -> np.ndarray:
        for e, seed in enumerate(seeds):
            core.reset_env(e, seed)
        path = []
        for _ in range(50):
            core.step(np.zeros((core.num_envs, 0, 3), dtype=np.int64))
            path.append([m.tank_xy.copy() for m in core.matches])
        return np.array(path).transpose(1, 0, 2, 3)  # (env, tick, tank, xy)

    seeds = [21, 22, 23, 24, 25]
    many = play(MatchSet("vs_aggressive", 5, driven=[], seat_policies={0: load_policy(run)}),
                seeds)
    alone = [play(MatchSet("vs_aggressive", 1, driven=[], seat_policies={0: load_policy(run)}),
                  [s])[0] for s in seeds]
    assert np.array_equal(many, np.array(alone))
    assert not np.array_equal(many[0], many[1])  # different games
    # the env serves the policy observations from its own batch; asked one match at a
    # time (an episode loop), the policy builds its own: the same game (greedy, so that
    # the actions follow the observations, not the sampling noise)
    sc = load_scenario("vs_aggressive")
    greedy_set = MatchSet(sc, 2, driven=[],
                          seat_policies={0: load_policy(run, deterministic=True)})
    greedy = play(greedy_set, seeds[:2])
    for e in range(2):
        ep = start_episode(sc.game_config(), sc.map_specs(), sc.teams,
                           [load_policy(run, deterministic=True),
                            make_controller(sc.seats[1], 0)], seeds[e])
        path = []
        for _ in range(50):
            ep.tick()
            path.append(ep.match.tank_xy.copy())
        assert np.array_equal(np.array(path), greedy[e])


def test_checkpoint_policy_rejects_a_match_it_cannot_observe(trained):
    pol = load_policy(trained)
    sc = parse_scenario({"name": "t", "map": "arena4", "seats": [
        {"team": "A", "controller": "learner"}, {"team": "A", "controller": "bot", "bot": "random"},
        {"team": "B", "controller": "bot", "bot": "random"}]})
    core = MatchSet(sc, 1, driven=[], seat_policies={0: pol})
    with pytest.raises(CheckpointError, match="observation features|wall rectangles"):
        core.reset_env(0, 1)


def test_resume_continues_exactly_like_an_uninterrupted_run(tmp_path):
    spec_sac = LearnerSpec("sac", "sac", (1,), config=SAC_TINY)
    spec_ppo = LearnerSpec("ppo", "ppo", (0,), PPO_TINY)
    cfg = tiny_config("pair", 4, scenario="pair", learners=(spec_ppo, spec_sac),
                      game={"max_steps": 30})
    full = Trainer(cfg, tmp_path / "full", progress=False)
    full.train()
    half = Trainer(dataclasses.replace(cfg, total_steps=2 * ITER), tmp_path / "half",
                   progress=False)
    half.train()
    resumed = resume_trainer(tmp_path / "half", progress=False, total_steps=4 * ITER)
    assert resumed.global_step == 2 * ITER and resumed.iteration == 2
    resumed.train()
    # the update right after resuming (iteration 3) and the one after are identical
    assert resumed.history[0]["step"] == full.history[2]["step"]
    for key in ("losses/policy_loss/ppo", "losses/value_loss/ppo", "losses/qf_loss/sac"):
        assert resumed.history[0][key] == full.history[2][key], key
    # and so are the rolling windows: win rates (per opponent too), returns, lengths
    rolling = [k for k in full.history[2] if k.startswith("charts/")
               and k not in ("charts/sps", "charts/elapsed_s")]
    assert {"charts/episode_length", "charts/win_rate/ppo"} <= set(rolling)
    assert any(k.startswith("charts/win_rate_vs/") for k in rolling), rolling
    assert {k: resumed.history[0][k] for k in rolling} == {k: full.history[2][k]
                                                            for k in rolling}
    for name in ("ppo", "sac"):
        a, b = full.learners[name].state_dict(), resumed.learners[name].state_dict()
        net = "net" if name == "ppo" else "actor"
        for k in a[net]:
            assert torch.equal(a[net][k], b[net][k]), (name, k)
    assert len(resumed.learners["sac"].replay) == len(full.learners["sac"].replay)


def test_a_sac_checkpoint_whose_replay_does_not_fit_plays_but_does_not_resume(tmp_path,
                                                                             capsys):
    """Loading a SAC checkpoint to play built its learner with the full replay buffer: one
    whose buffer_size exceeds this machine's memory was refused by eval, play, record and
    load_policy, which need only the actor. Now the buffer is made when training needs it:
    the checkpoint plays, and resuming it is still refused before training starts."""
    from alphatank.cli import main

    run = tmp_path / "sac"
    spec = LearnerSpec("sac", "sac", (0,), config=SAC_TINY)
    cfg = tiny_config("sac", 1, learners=(spec,), rollout_steps=16, checkpoint_every=0)
    Trainer(cfg, run, progress=False).train()
    meta = load_checkpoint(run).path / "meta.json"
    text = meta.read_text(encoding="utf-8")
    assert text.count('"buffer_size": 4096') == 2  # the learner's spec and the run's
    meta.write_text(text.replace('"buffer_size": 4096', f'"buffer_size": {10**12}'),
                    encoding="utf-8")
    assert load_checkpoint(run).learner_specs[0].config.buffer_size == 10**12
    assert main(["eval", str(run), "--games", "2"]) == 0
    assert "SAC Agent vs Aggressive Bot" in capsys.readouterr().out
    core = MatchSet("vs_aggressive", 1, driven=[], seat_policies={0: load_policy(run)})
    core.reset_env(0, 1)
    for _ in range(5):
        core.step(np.zeros((1, 0, 3), dtype=np.int64))
    assert main(["train", "--resume", str(run), "--total-steps", str(2 * ITER),
                 "--wandb", "disabled", "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "buffer_size = 1,000,000,000,000 transitions" in err[0], err
    assert "lower buffer_size" in err[0]
    assert load_checkpoint(run).meta["progress"]["global_step"] == ITER  # nothing trained


@pytest.mark.parametrize("agent", ["ppo_vs_smart", "team_vs_def"])  # PPO, MAPPO
def test_a_checkpoint_whose_rollout_does_not_fit_plays_but_does_not_train(agent, tmp_path):
    """PPO and MAPPO learners loaded to play made their rollout buffer (num_steps rows per
    seat) and the memory check refused one too large for this machine: they need only the
    networks. Now the buffer is made when training needs it (plan, act, ingest)."""
    src = Path(alphatank.__file__).parent / "data" / "agents" / agent
    ck = tmp_path / agent
    shutil.copytree(src, ck)
    meta = ck / "meta.json"
    text = meta.read_text(encoding="utf-8")
    meta.write_text(text.replace('"num_steps": 128', f'"num_steps": {10**12}'), encoding="utf-8")
    checkpoint = load_checkpoint(ck)
    spec = checkpoint.learner_specs[0]
    assert spec.config.num_steps == 10**12
    learner = checkpoint.load_learner(spec.name, weights_only=True)
    assert learner._buffer is None
    policy = load_policy(ck)
    core = MatchSet(checkpoint.scenario, 1, driven=[],
                    seat_policies=dict.fromkeys(spec.seats, policy))
    core.reset_env(0, 1)
    for _ in range(5):
        core.step(np.zeros((1, 0, 3), dtype=np.int64))
    with pytest.raises(ValueError, match=r"a rollout of num_steps = 1,000,000,000,000 x "):
        learner.plan(10**13)


def _copy(trained, tmp_path):
    dst = tmp_path / "ck"
    shutil.copytree(load_checkpoint(trained).path, dst)
    return dst


def test_corrupt_checkpoint_file_gives_a_clear_error(trained, tmp_path):
    ck = _copy(trained, tmp_path)
    data = bytearray((ck / "ppo.pt").read_bytes())
    data[len(data) // 2] ^= 0xFF
    (ck / "ppo.pt").write_bytes(bytes(data))
    with pytest.raises(CheckpointError, match=r"ppo\.pt: corrupt or truncated"):
        load_policy(ck)


def test_truncated_checkpoint_without_checksum_gives_a_clear_error(trained, tmp_path):
    ck = _copy(trained, tmp_path)
    meta = json.loads((ck / "meta.json").read_text())
    meta["files"] = {}
    (ck / "meta.json").write_text(json.dumps(meta))
    data = (ck / "ppo.pt").read_bytes()
    (ck / "ppo.pt").write_bytes(data[: len(data) // 3])
    with pytest.raises(CheckpointError, match=r"ppo\.pt: cannot be loaded"):
        load_policy(ck)


def test_hand_edited_learner_files_give_one_line_naming_the_file(trained, tmp_path):
    """A .pt holding other Python objects names the one the weights-only load refused
    (not torch's advice to load it with weights_only=False, with terminal escapes); one
    whose values have other types says it does not fit (it raised a TypeError)."""
    ck = _copy(trained, tmp_path)
    meta = json.loads((ck / "meta.json").read_text())
    meta["files"] = {}  # edited without their digests
    (ck / "meta.json").write_text(json.dumps(meta))
    state = torch.load(ck / "ppo.pt", weights_only=True)
    torch.save({**state, "where": Path("/")}, ck / "ppo.pt")
    with pytest.raises(CheckpointError) as err:
        load_policy(ck)
    assert str(err.value) == (f"{ck / 'ppo.pt'}: holds more than tensors and plain data, "
                              f"which a checkpoint never does (Unsupported global: GLOBAL "
                              f"pathlib.PosixPath); it was not saved by alphatank or was "
                              f"altered")
    torch.save({**state, "net": 5}, ck / "ppo.pt")
    with pytest.raises(CheckpointError, match=r"ppo\.pt: does not fit a ppo learner .* "
                                              r"TypeError: Expected state_dict to be dict-like"):
        load_policy(ck)


def test_a_hand_edited_self_play_pool_is_named_on_resume(tmp_path):
    """extra/selfplay.pt edited (its digest dropped) without a key the pool reads: one
    line naming it, not a KeyError traceback."""
    mappo = MAPPOConfig(num_steps=16, update_epochs=1, hidden=32)
    cfg = TrainConfig(name="sp", scenario="team", total_steps=64, num_envs=4, seed=1,
                      wandb="disabled", game={"max_steps": 30},
                      learners=(LearnerSpec("team", "mappo", (0, 1), mappo),),
                      selfplay={"window": 2, "every": 64})
    run = tmp_path / "sp"
    Trainer(cfg, run, progress=False).train()
    ck = load_checkpoint(run).path
    meta = json.loads((ck / "meta.json").read_text())
    del meta["files"]["extra/selfplay.pt"]
    (ck / "meta.json").write_text(json.dumps(meta))
    state = torch.load(ck / "extra" / "selfplay.pt", weights_only=True)
    del state["pool"]["league"]
    torch.save(state, ck / "extra" / "selfplay.pt")
    with pytest.raises(CheckpointError) as err:
        resume_trainer(run, progress=False, total_steps=128)
    assert str(err.value) == (f"{ck / 'extra' / 'selfplay.pt'}: does not fit the run's "
                              f"self-play pool: KeyError: 'league'")


def test_truncated_meta_and_missing_files_are_named(trained, tmp_path):
    ck = _copy(trained, tmp_path)
    text = (ck / "meta.json").read_text()
    (ck / "meta.json").write_text(text[: len(text) // 2])
    with pytest.raises(CheckpointError, match=r"meta\.json: invalid JSON"):
        load_checkpoint(ck)
    (ck / "meta.json").write_text(text)
    (ck / "ppo.pt").unlink()
    with pytest.raises(CheckpointError, match=r"ppo\.pt: missing"):
        load_policy(ck)
    with pytest.raises(CheckpointError, match="no such checkpoint"):
        load_checkpoint(tmp_path / "nope")
    with pytest.raises(CheckpointError, match="not a checkpoint"):
        load_checkpoint(tmp_path)


def test_a_latest_naming_a_removed_save_lists_the_runs_saves(trained, tmp_path):
    """The newest save removed by hand (to go back to an earlier one): latest says which
    saves the run has and how to use one; a latest of two lines says it names one."""
    run = tmp_path / "run"
    shutil.copytree(trained, run)
    newest = load_checkpoint(run).path.name
    (run / "latest").write_text("checkpoints/step_0000999999\n")
    with pytest.raises(CheckpointError) as err:
        load_checkpoint(run)
    saves = ", ".join(p.name for p in sorted((run / "checkpoints").iterdir()))
    assert str(err.value) == (
        f"{run / 'latest'}: points at {run / 'checkpoints' / 'step_0000999999'}, which does "
        f"not exist; the run's saves: {saves} (give one, e.g. {run / 'checkpoints' / newest}, "
        f"or write checkpoints/{newest} into {run / 'latest'})")
    (run / "latest").write_text(f"checkpoints/{newest}\ncheckpoints/{newest}\n")
    with pytest.raises(CheckpointError, match=r"latest: holds 2 lines; it names one save"):
        load_checkpoint(run)


def test_a_run_folder_without_latest_says_what_it_has(trained, tmp_path):
    """latest removed: the run's saves are listed; no save yet: said so. Both read 'not a
    run directory'."""
    run = tmp_path / "run"
    shutil.copytree(trained, run)
    (run / "latest").unlink()
    saves = sorted((run / "checkpoints").iterdir())
    with pytest.raises(CheckpointError) as err:
        load_checkpoint(run)
    assert str(err.value) == (
        f"{run}: a run folder without its 'latest' file; the run's saves: "
        f"{', '.join(p.name for p in saves)} (give one, e.g. {saves[-1]}, or write "
        f"checkpoints/{saves[-1].name} into {run / 'latest'})")
    shutil.rmtree(run / "checkpoints")
    with pytest.raises(CheckpointError, match=r"run: a run folder with no save yet \(a run "
                                              r"saves after every checkpoint_every iterations"):
        load_checkpoint(run)
    meta = json.loads((load_checkpoint(trained).path / "meta.json").read_text())
    ck = _copy(trained, tmp_path)
    (ck / "meta.json").write_text(json.dumps({**meta, "version": "1"}))
    with pytest.raises(CheckpointError, match=r"meta\.json: version: must be an integer "
                                              r"\(this alphatank reads version 1\), got '1'"):
        load_checkpoint(ck)


def test_meta_fields_that_resuming_reads_are_checked_at_load(trained, tmp_path):
    """progress is required and typed; its later fields (cut, clone_pending) get their
    defaults in an older checkpoint; windows maps learner names to numbers."""
    ck = _copy(trained, tmp_path)
    meta = json.loads((ck / "meta.json").read_text())
    old = {**meta, "progress": {k: v for k, v in meta["progress"].items()
                                if k not in ("cut", "clone_pending")}}
    (ck / "meta.json").write_text(json.dumps(old))
    assert load_checkpoint(ck).meta["progress"] == {**old["progress"], "cut": 0,
                                                    "clone_pending": False}
    for edit, error in (({"progress": {**meta["progress"], "elapsed": "long"}},
                         r"meta\.json: progress\.elapsed: must be a number, got 'long'"),
                        ({"windows": {"returns": {"ppo": ["x"]}}},
                         r"meta\.json: windows\.returns: must map learner names \['ppo'\]"),
                        ({"windows": {"outcomes": []}}, r"windows\.outcomes"),
                        ({"schedule": [1]}, r"meta\.json: schedule: must be an object"),
                        ({"scenario": "vs_smart"},
                         r"meta\.json: scenario: must be an object, got 'vs_smart'"),
                        ({"scenario": {**meta["scenario"], "seats": "A,B"}},
                         r"meta\.json: scenario\.seats: must be a list of seat objects, "
                         r"got 'A,B'"),
                        ({"observation": {**meta["observation"], "kind": "bogus"}},
                         r"meta\.json: observation\.kind: unknown observation kind 'bogus'"),
                        ({"observation": {**meta["observation"],
                                          "seat_learner": {"0": "nobody"}}},
                         r"meta\.json: observation\.seat_learner: must map seat numbers to "
                         r"learner names \['ppo'\]")):
        (ck / "meta.json").write_text(json.dumps({**meta, **edit}))
        with pytest.raises(CheckpointError, match=error):
            load_checkpoint(ck)


def test_mismatched_checkpoint_gives_a_clear_error(trained, tmp_path):
    ck = _copy(trained, tmp_path)
    meta = json.loads((ck / "meta.json").read_text())
    meta["observation"]["obs_dim"] += 7  # weights no longer fit the declared observation
    (ck / "meta.json").write_text(json.dumps(meta))
    with pytest.raises(CheckpointError, match=r"ppo\.pt: does not fit a ppo learner"):
        load_policy(ck)
    meta["version"] = 99
    (ck / "meta.json").write_text(json.dumps(meta))
    with pytest.raises(CheckpointError, match="version 99"):
        load_checkpoint(ck)


def test_pruning_removes_only_the_runs_own_older_saves(tmp_path):
    mine = tmp_path / "checkpoints" / "important"
    mine.mkdir(parents=True)
    (mine / "data.txt").write_text("precious")
    state = {"ppo": {"w": torch.zeros(2)}}
    for step in (300, 20, 1000):  # out of order on purpose: pruning goes by step
        save_checkpoint(tmp_path, f"step_{step:010d}", {}, state, keep=2)
    assert sorted(p.name for p in (tmp_path / "checkpoints").iterdir()) == [
        "important", f"step_{300:010d}", f"step_{1000:010d}"]
    assert (mine / "data.txt").read_text() == "precious"


def test_train_command_runs_resumes_and_refuses_to_overwrite(tmp_path, capsys):
    import argparse

    from alphatank.commands import train as train_cmd
    from alphatank.errors import InputError

    parser = argparse.ArgumentParser()
    train_cmd.add_arguments(parser)
    common = ["--runs", str(tmp_path), "--num-envs", "2", "--wandb", "disabled",
              "--no-progress"]
    args = parser.parse_args(["--preset", "ppo_vs_aggressive", "--name", "cli",
                              "--total-steps", "64", "--ppo", "num_steps=16,update_epochs=1",
                              *common])
    assert train_cmd.run(args) == 0
    assert load_checkpoint(tmp_path / "cli").meta["progress"]["global_step"] == 64
    with pytest.raises(InputError, match="--resume"):  # the run exists: resume it instead
        train_cmd.run(args)
    resume = parser.parse_args(["--resume", str(tmp_path / "cli"), "--total-steps", "128",
                                *common[2:]])  # a resumed run keeps its folder: no --runs
    assert train_cmd.run(resume) == 0
    ck = load_checkpoint(tmp_path / "cli")
    assert ck.meta["progress"]["global_step"] == 128
    assert ck.learner_specs[0].config.num_steps == 16  # the run keeps its own settings
    bad = parser.parse_args(["--preset", "ppo_vs_aggressive", "--name", "x",
                             "--ppo", "num_stepz=3", *common])
    with pytest.raises(InputError, match="num_stepz"):  # alphatank.cli prints it, exit 2
        train_cmd.run(bad)
    assert train_cmd.run(parser.parse_args(["--list"])) == 0
    assert "team_ppo_vs_ppo" in capsys.readouterr().out


def test_a_run_on_a_map_file_evaluates_and_resumes_after_the_file_is_gone(tmp_path, capsys):
    """A checkpoint carries the text of maps not shipped with the package (map_texts):
    moving the run to another machine, or the map away, loses nothing."""
    from alphatank.cli import main

    (tmp_path / "sc").mkdir()
    (tmp_path / "sc" / "mine.txt").write_text(
        (Path(alphatank.maps.__file__).parent / "maze.txt").read_text())
    (tmp_path / "sc" / "my.toml").write_text(
        'name = "mine"\nmap = "mine.txt"\n[[seats]]\nteam = "A"\ncontroller = "learner"\n'
        '[[seats]]\nteam = "B"\ncontroller = "bot"\nbot = "aggressive"\n')
    common = ["--wandb", "disabled", "--no-progress"]
    assert main(["train", "--preset", "ppo_vs_aggressive", "--scenario",
                 str(tmp_path / "sc" / "my.toml"), "--num-envs", "2", "--total-steps", "128",
                 "--runs", str(tmp_path / "runs"), "--name", "r",
                 "--hp", "ppo.num_steps=32,ppo.update_epochs=1", *common]) == 0
    walls = load_checkpoint(tmp_path / "runs" / "r").scenario.map_specs()[0].walls
    shutil.rmtree(tmp_path / "sc")
    assert main(["eval", str(tmp_path / "runs" / "r"), "--games", "2", "--seed", "5"]) == 0
    assert main(["train", "--resume", str(tmp_path / "runs" / "r"), "--total-steps", "256",
                 *common]) == 0
    ckpt = load_checkpoint(tmp_path / "runs" / "r")
    assert ckpt.meta["progress"]["global_step"] == 256
    assert (ckpt.scenario.map_specs()[0].walls == walls).all()
    with pytest.raises(ScenarioError, match="map_texts: must be a list of"):
        parse_scenario({**ckpt.meta["scenario"], "map_texts": [["a\nb", "x"]]})


def test_a_new_trainer_never_writes_into_a_run_and_a_trainer_trains_once(tmp_path):
    from alphatank.errors import InputError

    cfg = tiny_config("once", 2)
    tr = Trainer(cfg, tmp_path / "once", progress=False)
    tr.train()
    with pytest.raises(RuntimeError, match="has trained; continue the run with resume_trainer"):
        tr.train()
    before = {p.name: p.stat().st_mtime_ns for p in (tmp_path / "once").rglob("*")}
    with pytest.raises(InputError, match="already holds a run; continue it with resume_trainer"):
        Trainer(dataclasses.replace(cfg, seed=5), tmp_path / "once", progress=False)
    assert {p.name: p.stat().st_mtime_ns for p in (tmp_path / "once").rglob("*")} == before
    resume_trainer(tmp_path / "once", progress=False, total_steps=3 * ITER).train()



def _wrong_shape(trained: Path, tmp_path: Path) -> Path:
    """A copy of the run's checkpoint with a 3 x 5 ``critic.0.weight`` (and its SHA-256 in
    meta.json updated, so it passes the digest check)."""
    import hashlib

    ck = _copy(trained, tmp_path)
    state = torch.load(ck / "ppo.pt", weights_only=True)
    state["net"]["critic.0.weight"] = torch.zeros(3, 5)
    torch.save(state, ck / "ppo.pt")
    meta = json.loads((ck / "meta.json").read_text())
    meta["files"]["ppo.pt"] = hashlib.sha256((ck / "ppo.pt").read_bytes()).hexdigest()
    (ck / "meta.json").write_text(json.dumps(meta))
    return ck


def test_a_tensor_of_the_wrong_shape_is_named_with_both_shapes(trained, tmp_path):
    """torch puts the tensor and its shapes on the lines after its heading: the one-line
    error keeps them."""
    ck = _wrong_shape(trained, tmp_path)
    wrong = r"ppo\.pt: does not fit a ppo learner .*size mismatch for critic\.0\.weight: .*\[3, 5\]"
    with pytest.raises(CheckpointError, match=wrong) as info:
        load_policy(ck)
    assert "\n" not in str(info.value)


def test_init_from_a_damaged_checkpoint_names_the_tensor_not_the_hidden_size(trained, tmp_path,
                                                                            capsys):
    """A weight of the wrong shape is the file's fault: the error names the file, the tensor
    and both shapes before any run folder is made (it advised hidden=3)."""
    from alphatank.cli import main

    ck = _wrong_shape(trained, tmp_path)
    runs = tmp_path / "runs"
    assert main(["train", "--preset", "ppo_vs_aggressive", "--init-from", str(ck), "--runs",
                 str(runs), "--num-envs", "2", "--total-steps", "128", "--wandb", "disabled",
                 "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "hidden" not in err
    assert f"{ck / 'ppo.pt'}: does not fit a ppo learner" in err
    assert "critic.0.weight: copying a param with shape torch.Size([3, 5])" in err
    assert "the shape in current model is torch.Size([128, " in err
    assert not any(runs.glob("*"))  # no run folder (nor a lock file) is left


def test_a_save_that_fails_leaves_no_temporary_folder(tmp_path):
    """A save cut short (an error, or a Ctrl-C that could not wait) removes its folder."""
    with pytest.raises(Exception):  # noqa: B017 (whatever pickle raises for a lambda)
        save_checkpoint(tmp_path, "step_0000000001", {}, {"ppo": {"f": lambda: 0}})
    assert list((tmp_path / "checkpoints").iterdir()) == []
    assert not (tmp_path / "latest").exists()


def test_a_save_on_a_full_disk_says_so_and_keeps_the_previous_save(tmp_path):
    """A write that fails (here a file-size limit, as a full disk) ends the run with one
    line naming the save and the cause; the previous save and latest stay as they were."""
    run = tmp_path / "run"
    trainer = Trainer(tiny_config("full", 1), run, progress=False)
    trainer.train()
    before = (run / "latest").read_text()
    trainer = resume_trainer(run, progress=False, total_steps=2 * ITER)
    soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
    resource.setrlimit(resource.RLIMIT_FSIZE, (100_000, hard))  # ppo.pt is larger
    try:
        with pytest.raises(SaveFailed) as err:
            trainer.train()
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
    assert str(err.value) == (
        f"{run / 'checkpoints' / f'step_{2 * ITER:010d}'}: the checkpoint cannot be written "
        f"(File too large); nothing of it is kept, and the run's earlier saves are as they "
        f"were; continue from step {ITER} with alphatank train --resume {run} once it can "
        f"be written")
    assert (run / "latest").read_text() == before
    assert [p.name for p in (run / "checkpoints").iterdir()] == [f"step_{ITER:010d}"]
    load_policy(run)  # intact


def _anonymous_rss() -> int:
    """This process's resident anonymous memory in bytes (Linux /proc)."""
    with open("/proc/self/status") as f:
        return 1024 * int(next(x for x in f if x.startswith("RssAnon:")).split()[1])


@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="Linux /proc")
def test_a_saved_replay_is_mapped_not_read_into_memory(tmp_path):
    """A replay buffer's arrays as a resume reads them: the same values, dtypes, shapes and
    orders, the big ones mapped from the file, so the buffer filled from them is the only
    copy in memory (the file was read whole first: twice the buffer at the peak, and a
    buffer over half the machine's memory passed the check, then was killed on resume)."""
    rng = np.random.default_rng(0)
    saved = {"obs": rng.random((200_000, 200), dtype=np.float32),  # 160 MB
             "fortran": np.asfortranarray(rng.random((3000, 120))), "pos": np.array(7),
             "empty": np.zeros((0, 5), np.float32)}
    np.savez(tmp_path / "r.replay.npz", **saved)
    before = _anonymous_rss()
    arrays = npz_arrays(tmp_path / "r.replay.npz")
    assert non_finite(arrays) is None
    assert _anonymous_rss() - before < 40_000_000  # not the 160 MB of obs
    for key, want in saved.items():
        got = arrays[key]
        assert (got.dtype, got.shape, got.flags.f_contiguous) == (
            want.dtype, want.shape, want.flags.f_contiguous)
        assert np.array_equal(got, want)
    spoiled = np.array(arrays["obs"])
    spoiled[150_000, 3] = np.inf  # past the first block of the check
    assert non_finite({"obs": spoiled}) == "obs"

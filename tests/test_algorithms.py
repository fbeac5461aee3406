"""The algorithm table, the Learner protocol and its extra-inputs hook, typed
hyperparameters and --hp overrides, and per-opponent metrics of agent-vs-agent runs."""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import subprocess
import sys

import numpy as np
import pytest

from alphatank.envs.vector import VectorMatchEnv, make_vector_env
from alphatank.training.algorithms import ALGORITHMS, get_algorithm, register
from alphatank.training.checkpoint import load_checkpoint
from alphatank.training.fields import describe
from alphatank.training.hparams import PPOConfig, SACConfig
from alphatank.training.learners import make_learner
from alphatank.training.ppo import PPO
from alphatank.training.presets import (
    LearnerSpec,
    TrainConfig,
    get_preset,
    parse_hp,
    with_hp,
)
from alphatank.training.runner import Trainer, opposing_learners, resume_trainer

TINY = PPOConfig(num_steps=16, update_epochs=1, num_minibatches=2)
TINY_SAC = SACConfig(hidden=16, batch_size=16, start_steps=16, update_after=16, update_every=16,
                     buffer_size=1000)


# ---- a new algorithm: its module (here: this one) + one registry line ---------------------

@dataclasses.dataclass(frozen=True)
class ProbeConfig:
    """A config of its own proves the table carries it (fields like PPO's, fewer)."""

    num_steps: int = 16


class AliveProbe(PPO):
    """PPO that also asks the env for the 'alive' input and records what it is given."""

    algo = "alive_probe"
    inputs = ("alive",)

    def __init__(self, obs_dim, num_streams, cfg=None, seed=0, mask_dim=0, num_seats=1,
                 alive_dim=0):
        super().__init__(obs_dim, num_streams, TINY, seed=seed, mask_dim=mask_dim)
        self.probe_cfg, self.alive_dim, self.num_seats = cfg, alive_dim, num_seats
        self.acted, self.observed, self.finals, self.updated = [], [], [], []

    def act(self, obs, masks=None, alive=None):
        self.acted.append((obs.copy(), alive.copy()))
        return super().act(obs, masks)

    def observe(self, next_obs, rewards, terminated, truncated, final_obs=None, active=None,
                alive=None, final_alive=None):
        self.observed.append((next_obs.copy(), alive.copy()))
        ended = np.logical_or(terminated, truncated)
        self.finals.append((final_obs[ended].copy(), final_alive[ended].copy()))
        super().observe(next_obs, rewards, terminated, truncated, final_obs, active)

    def update(self, next_obs, alive=None):
        self.updated.append(alive.copy())
        return super().update(next_obs)


@pytest.fixture
def probe_algo():
    register("alive_probe", ProbeConfig, f"{__name__}:AliveProbe", "test probe")
    yield get_algorithm("alive_probe")
    ALGORITHMS.pop("alive_probe")


RANGE = """name: range
description: 5x5 firing range: the aggressive bot soon shoots the learner

#######
#.....#
#.1...#
#.....#
#...2.#
#.....#
#######
"""
SCENARIO = """name = "range"
map = "range.txt"
[[seats]]
team = "A"
controller = "learner"
[[seats]]
team = "B"
controller = "bot"
bot = "aggressive"
"""


def test_a_registered_algorithm_gets_its_inputs_and_checkpoints(probe_algo, tmp_path):
    (tmp_path / "range.txt").write_text(RANGE)
    (tmp_path / "range.toml").write_text(SCENARIO)
    cfg = TrainConfig("probe", str(tmp_path / "range.toml"), total_steps=6 * 16 * 4,
                      num_envs=4, seed=2, wandb="disabled", checkpoint_every=0,
                      game={"max_steps": 40},
                      learners=(LearnerSpec("probe", "alive_probe", (0,),
                                            ProbeConfig(num_steps=8)),))
    tr = Trainer(cfg, tmp_path / "probe", progress=False)
    lr = tr.learners["probe"]
    assert isinstance(lr, AliveProbe) and (lr.alive_dim, lr.num_seats) == (1, 1)
    assert lr.probe_cfg == ProbeConfig(num_steps=8)  # the spec's config object
    assert tr.input_dims == {"alive": 1} and tr.rollout_steps == 16  # PPO's rollout hint
    tr.train()
    col = tr.env.layout["self.alive"].start
    assert len(lr.acted) == len(lr.observed) == 6 * 16 and len(lr.updated) == 6
    for obs, alive in lr.acted + lr.observed:  # the input matches the observation's flag
        assert alive.shape == (4,) and np.array_equal(alive, obs[:, col])
    ended = [(f, a) for f, a in lr.finals if len(a)]
    assert ended  # episodes ended inside the run: finals are taken before the reset
    for final_obs, final_alive in ended:
        assert np.array_equal(final_alive, final_obs[:, col])
    assert any((a == 0).any() for _, a in ended)  # someone died: not the reset value
    ck = load_checkpoint(tmp_path / "probe")
    assert ck.meta["input_dims"] == {"alive": 1}
    again = ck.load_learner("probe", weights_only=True)
    assert isinstance(again, AliveProbe) and again.alive_dim == 1
    # the factory tells a learner how many seats share it (streams are env-major)
    two = make_learner(LearnerSpec("two", "alive_probe", (0, 1)), 12, 8, 0,
                       input_dims={"alive": 1})
    assert (two.num_seats, two.num_streams) == (2, 8)
    with pytest.raises(ValueError, match=r"'two' \(alive_probe\) needs inputs \['alive'\]"):
        make_learner(LearnerSpec("two", "alive_probe", (0, 1)), 12, 8, 0)


def test_an_env_without_the_input_is_refused(probe_algo, tmp_path):
    cfg = TrainConfig("probe", "vs_aggressive", total_steps=64, num_envs=2, wandb="disabled",
                      learners=(LearnerSpec("probe", "alive_probe", (0,)),))
    with pytest.raises(ValueError, match=r"need env inputs \['alive'\].*supplies \[\]"):
        Trainer(cfg, tmp_path / "x", env=VectorMatchEnv("vs_aggressive", 2), progress=False)


def test_a_trainer_that_fails_to_start_releases_its_folder(tmp_path):
    """Learners that do not fit the scenario, refused after the run locked its folder: the
    lock is released and the folders the run made are removed (the --runs folder and its
    lock file were left behind)."""
    cfg = TrainConfig("x", "vs_aggressive", total_steps=64, num_envs=2, wandb="disabled",
                      learners=(LearnerSpec("a", "ppo", (0,)), LearnerSpec("b", "ppo", (0,))))
    with pytest.raises(ValueError, match="seats exactly once; they drive"):
        Trainer(cfg, tmp_path / "runs" / "x", progress=False)
    assert not any(tmp_path.iterdir())


def _open_files() -> set[str]:
    """Paths of the files this process holds open (Linux: /proc/self/fd)."""
    paths = set()
    for fd in os.listdir("/proc/self/fd"):
        with contextlib.suppress(OSError):  # the listing's own descriptor, closed by now
            paths.add(os.readlink(f"/proc/self/fd/{fd}"))
    return paths


@pytest.mark.skipif(not os.path.isdir("/proc/self/fd"), reason="needs /proc/self/fd")
def test_a_trainer_that_fails_after_its_logger_closes_it(tmp_path):
    """An error after the metrics logger is made (a league schedule that snapshots a run of
    two learners, refused in schedule.bind): the logger's metrics.jsonl is closed (it stayed
    open), the folder's lock is released and the run folder it made is removed (it was left
    behind holding an empty metrics.jsonl, a run that never started)."""
    cfg = TrainConfig("x", "team_vs_bot", total_steps=64, num_envs=2, wandb="disabled",
                      learners=(LearnerSpec("a", "ppo", (0,)), LearnerSpec("b", "ppo", (1,))),
                      schedule={"kind": "league"})
    run = tmp_path / "runs" / "x"
    with pytest.raises(ValueError, match="league snapshots need one learner") as failed:
        Trainer(cfg, run, progress=False)
    # the half-made trainer, and so its logger, is still reachable from the traceback
    assert failed.traceback and str(run / "metrics.jsonl") not in _open_files()
    assert not any(tmp_path.iterdir())  # lock released (.x.lock removed), folders too


def test_env_inputs_match_in_process_and_worker_envs():
    kw = {"game_overrides": {"max_steps": 20}, "inputs": ("alive",)}
    envs = [make_vector_env("team_vs_bot", 4, seed=5, num_workers=w, **kw) for w in (1, 2)]
    try:
        rng = np.random.default_rng(0)
        for env in envs:
            env.reset(seed=5)
            assert env.input_shapes == {"alive": ()}
            assert env.inputs["alive"].shape == (4, 2) and (env.inputs["alive"] == 1).all()
        for _ in range(30):
            acts = rng.integers(0, [3, 3, 2], size=(4, 2, 3))
            (*_, info_a), (*_, info_b) = (env.step(acts) for env in envs)
            assert np.array_equal(envs[0].inputs["alive"], envs[1].inputs["alive"])
            assert np.array_equal(info_a["final_inputs"]["alive"],
                                  info_b["final_inputs"]["alive"])
    finally:
        for env in envs:
            env.close()
    with pytest.raises(ValueError, match=r"unknown env input 'bogus'; this env supplies: "
                                         r"\[.*'alive'"):
        VectorMatchEnv("vs_random", 1, inputs=("bogus",))


# ---- the table -------------------------------------------------------------------------------

def test_table_names_configs_and_lazy_learner_classes():
    assert get_algorithm("ppo").config is PPOConfig and get_algorithm("sac").config is SACConfig
    assert get_algorithm("ppo").learner_class() is PPO
    with pytest.raises(ValueError,
                       match=r"unknown algorithm 'dqn'; registered: \['mappo', 'ppo', 'sac'"):
        get_algorithm("dqn")
    with pytest.raises(ValueError, match="module:Class"):
        register("x", PPOConfig, "alphatank.training.ppo.PPO")
    with pytest.raises(ValueError, match="config must be a PPOConfig for algo 'ppo'"):
        LearnerSpec("a", "ppo", (0,), SACConfig())
    assert LearnerSpec("a", "sac").config == SACConfig()  # None: the algorithm's defaults


def test_listing_and_validating_runs_never_imports_torch():
    code = ("import sys\nfrom alphatank.cli import main\n"
            "for argv in (['train', '--list'], ['train', '--print-config', '--preset', "
            "'sac_vs_ppo', '--hp', 'ppo.clip_coef=0.3'], "
            "['train', '--print-config', '--preset', 'team_vs_four_bots']):\n"
            "    assert main(argv) == 0\n"
            "assert 'torch' not in sys.modules, 'torch imported'\n")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert "ppo.update_epochs" in res.stdout and "clip_coef = 0.3" in res.stdout


def test_every_hyperparameter_has_a_one_line_help():
    for algo in [*ALGORITHMS.values()]:
        for f in describe(algo.config):
            assert f.help and "\n" not in f.help, (algo.name, f.name)
    for f in describe(TrainConfig):
        assert f.help, f.name


# ---- typed hyperparameters and --hp -----------------------------------------------------------

def test_fields_are_typed_and_ranged_by_name():
    with pytest.raises(ValueError, match=r"PPOConfig\.gamma must be in \[0, 1\], got 1\.5"):
        PPOConfig(gamma=1.5)
    with pytest.raises(ValueError, match=r"SACConfig\.tau must be in \(0, 1\], got 0"):
        SACConfig(tau=0)
    with pytest.raises(ValueError, match=r"PPOConfig\.num_steps needs an int, got True"):
        PPOConfig(num_steps=True)
    with pytest.raises(ValueError, match=r"PPOConfig\.update_epochs needs an int, got 2\.0"):
        PPOConfig(update_epochs=2.0)
    cfg = PPOConfig(learning_rate=1)
    assert cfg.learning_rate == 1.0 and isinstance(cfg.learning_rate, float)
    assert PPOConfig(target_kl=None).target_kl is None


def test_hp_overrides_are_typed_per_algorithm():
    got = parse_hp([("--hp", "ppo.clip_coef=0.1, sac.tau=0.5"), ("--hp", "ppo.target_kl=none"),
                    ("--ppo", "update_epochs=4,anneal_lr=true"), ("--sac", ""),
                    ("--hp", "sac.buffer_size=1e5")])
    assert got == {"ppo": {"clip_coef": 0.1, "target_kl": None, "update_epochs": 4,
                           "anneal_lr": True},
                   "sac": {"tau": 0.5, "buffer_size": 100_000}}
    cfg = with_hp(get_preset("sac_vs_ppo"), got, 2)
    sac, ppo = cfg.learners
    assert ppo.config == dataclasses.replace(get_preset("sac_vs_ppo").learners[1].config,
                                             clip_coef=0.1, target_kl=None, update_epochs=4,
                                             anneal_lr=True)
    assert (sac.config.tau, sac.config.buffer_size, sac.config.batch_size) == (0.5, 100_000, 256)
    # a preset without learners gets one PPO per seat, then the override
    team = with_hp(TrainConfig("t", "team_vs_bot"), {"ppo": {"hidden": 64}}, 2)
    assert [(s.name, s.config.hidden) for s in team.learners] == [("ppo_0", 64), ("ppo_1", 64)]


@pytest.mark.parametrize("items,error", [
    ([("--hp", "ppo.clip_coef=-1")], r"^--hp ppo\.clip_coef: must be > 0, got -1\.0$"),
    ([("--hp", "ppo.update_epochs=2.5")], r"^--hp ppo\.update_epochs: needs an int, got '2\.5'"),
    ([("--hp", "ppo.norm_adv=maybe")], r"^--hp ppo\.norm_adv: needs a bool, got 'maybe'"),
    ([("--hp", "ppo.clip=1")], r"^--hp ppo\.clip: unknown ppo hyperparameter; valid: \[.*"),
    ([("--hp", "dqn.lr=1")], r"^--hp dqn\.lr: unknown algorithm 'dqn'; registered"),
    ([("--hp", "clip_coef=0.1")], r"^--hp: expected ALGO\.FIELD=VALUE, got 'clip_coef=0\.1'"),
    ([("--ppo", "num_stepz=3")], r"^--ppo num_stepz: unknown ppo hyperparameter; valid: "
                                 r"\[.*\]; did you mean 'num_steps'\?$"),
    ([("--hp", "pop.clip_coef=1")], r"^--hp pop\.clip_coef: unknown algorithm 'pop'; "
                                    r"registered: \[.*\]; did you mean 'ppo'\?$"),
    ([("--sac", "tau")], r"^--sac: expected FIELD=VALUE, got 'tau'"),
    # the last one given played, silently
    ([("--hp", "ppo.clip_coef=0.1,ppo.clip_coef=0.3")],
     r"^--hp ppo\.clip_coef: ppo\.clip_coef is also set by --hp ppo\.clip_coef; give it "
     r"once$"),
    ([("--hp", "ppo.clip_coef=0.1"), ("--ppo", "clip_coef=0.2")],
     r"^--ppo clip_coef: ppo\.clip_coef is also set by --hp ppo\.clip_coef;"),
])
def test_bad_hp_overrides_give_one_line_errors(items, error):
    with pytest.raises(ValueError, match=error):
        parse_hp(items)


def test_hp_for_an_algorithm_the_run_does_not_use_is_refused():
    with pytest.raises(ValueError, match=r"--hp sac\.\*: this run has no sac learner .*ppo"):
        with_hp(get_preset("ppo_vs_smart"), {"sac": {"tau": 0.1}}, 1)


# ---- per-opponent metrics of agent-vs-agent runs (issue 15) ------------------------------------

def test_agent_opponents_are_named_by_the_opposing_learners():
    a, b = LearnerSpec("a", seats=(0,)), LearnerSpec("b", seats=(1,))
    assert opposing_learners([a, b], ["A", "B"]) == {"a": ("b",), "b": ("a",)}
    team = [LearnerSpec(n, seats=(i,)) for i, n in enumerate(("a1", "a2", "b1", "b2"))]
    assert opposing_learners(team, ["A", "A", "B", "B"])["a1"] == ("b1", "b2")  # no teammates
    assert opposing_learners([LearnerSpec("s", seats=(0, 1))], ["A", "B"]) == {
        "s": ("selfplay",)}


def test_agent_vs_agent_win_rates_are_logged_per_opponent(tmp_path):
    cfg = TrainConfig("pvp", "pair", total_steps=16 * 2, num_envs=2, wandb="disabled",
                      checkpoint_every=0, game={"max_steps": 12},
                      learners=(LearnerSpec("ppo_a", "ppo", (0,), TINY),
                                LearnerSpec("sac_b", "sac", (1,), TINY_SAC)))
    tr = Trainer(cfg, tmp_path / "pvp", progress=False)
    tr.train()
    keys = {k for k in tr.history[-1] if k.startswith("charts/win_rate_vs/")}
    assert keys == {"charts/win_rate_vs/sac_b/ppo_a", "charts/win_rate_vs/ppo_a/sac_b"}
    # a checkpoint written before the algorithm table (no input_dims, no map) still loads
    ck = load_checkpoint(tmp_path / "pvp")
    meta = json.loads((ck.path / "meta.json").read_text())
    del meta["input_dims"], meta["train_config"]["map"]
    (ck.path / "meta.json").write_text(json.dumps(meta))
    old = load_checkpoint(tmp_path / "pvp")
    assert [s.config for s in old.learner_specs] == [TINY, TINY_SAC]
    assert old.load_learner("sac_b").algo == "sac"
    resumed = resume_trainer(tmp_path / "pvp", progress=False, total_steps=16 * 4)
    assert len(resumed.learners["sac_b"].replay) == 16 * 2
    resumed.train()
    assert resumed.global_step == 16 * 4


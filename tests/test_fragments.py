"""Rollout fragments (``--fragments``): a shard acts a whole rollout with a frozen copy
of the learners. The fragment is the step loop's trajectory, worker processes give the
same fragment as their blocks stepped alone, runs are reproducible, and what fragments
cannot carry is refused by name."""

from __future__ import annotations

import dataclasses
import hashlib
import json
import signal

import numpy as np
import pytest

from alphatank.cli import main
from alphatank.envs.fragments import merge_fragments
from alphatank.envs.vector import SubprocVectorMatchEnv, VectorMatchEnv, _shm_room
from alphatank.training.fragments import FrozenLearners
from alphatank.training.hparams import MAPPOConfig, PPOConfig
from alphatank.training.ppo import PPO
from alphatank.training.presets import LearnerSpec, TrainConfig
from alphatank.training.runner import Trainer, derive_seed, resume_trainer

KW = {"game_overrides": {"max_steps": 20}}


def frozen(env, seed: int = 5) -> FrozenLearners:
    """Two PPO learners of random weights, one per learner seat of ``env``."""
    learners = {f"p{k}": PPO(env.obs_dim, env.num_envs, PPOConfig(num_steps=8), seed=k)
                for k in range(env.num_learners)}
    return FrozenLearners.of(learners, {f"p{k}": [k] for k in range(env.num_learners)}, seed)


def test_a_fragment_is_the_trajectory_of_its_actions_and_its_policy():
    env = VectorMatchEnv("team_vs_bot", 3, seed=2, **KW)
    policy = frozen(env)
    frag = env.rollout(policy, env.reset(4), 30)
    assert frag.steps == 30 and frag.obs.shape == (30, 3, 2, env.obs_dim)
    assert len(frag.episodes) >= 3  # 20-tick games: every env restarted inside
    # replaying the actions step by step gives the same observations, rewards and ends
    again = VectorMatchEnv("team_vs_bot", 3, seed=2, **KW)
    obs = again.reset(4)
    replay = []
    for t in range(30):
        np.testing.assert_array_equal(obs, frag.obs[t])
        obs, rewards, term, trunc, info = again.step(frag.actions[t])
        np.testing.assert_array_equal(rewards, frag.rewards[t])
        np.testing.assert_array_equal(term, frag.terminated[t])
        np.testing.assert_array_equal(trunc, frag.truncated[t])
        cut = trunc & ~term
        np.testing.assert_array_equal(frag.bootstrap[t][~cut], 0.0)
        if cut.any():
            np.testing.assert_array_equal(frag.bootstrap[t][cut],
                                          policy.values(info["final_obs"][cut], {}))
        replay += [(t, ep["env"], ep["length"]) for ep in info["episodes"]]
    np.testing.assert_array_equal(obs, frag.next_obs)
    assert replay == [(ep["step"], ep["env"], ep["length"]) for ep in frag.episodes]
    # and the policy, restarted for the shard, chose those actions from those observations
    policy.start(env.env_ids)
    for t in range(30):
        actions, logprobs, values = policy.act(frag.obs[t], {})
        np.testing.assert_array_equal(actions, frag.actions[t])
        np.testing.assert_array_equal(logprobs, frag.logprobs[t])
        np.testing.assert_array_equal(values, frag.values[t])


def test_worker_processes_give_each_block_its_own_fragment():
    """Rollouts of 12, then 5 (the workers' shared arrays have room to spare), then 20
    steps (they grow) with the env's extra inputs: each is its blocks' fragments stepped
    alone in this process, episodes in step order, and an earlier fragment is not
    overwritten by the later rollouts."""
    kw = {"game_overrides": {"max_steps": 8}, "inputs": ("state", "alive")}
    sv = SubprocVectorMatchEnv("team_vs_bot", 5, seed=2, num_workers=2, **kw)
    try:
        policy = frozen(sv)
        frags, obs = [], sv.reset(9)
        for steps in (12, 5, 20):
            frags.append(sv.rollout(policy, obs, steps))
            obs = frags[-1].next_obs
        kept = [{k: a.copy() for k, a in vars(f).items() if isinstance(a, np.ndarray)}
                for f in frags]
    finally:
        sv.close()
    parts = []
    for lo, hi in ((0, 2), (2, 5)):  # the workers' blocks
        block = VectorMatchEnv("team_vs_bot", hi - lo, seed=2, env_ids=range(lo, hi), **kw)
        o = block.reset(9)
        parts.append([])
        for steps in (12, 5, 20):
            parts[-1].append(block.rollout(policy, o, steps))
            o = parts[-1][-1].next_obs
    for k, frag in enumerate(frags):
        ref = merge_fragments([p[k] for p in parts])
        for name in ("obs", "actions", "logprobs", "values", "rewards", "terminated",
                     "truncated", "bootstrap", "next_obs"):
            np.testing.assert_array_equal(getattr(frag, name), getattr(ref, name))
            np.testing.assert_array_equal(kept[k][name], getattr(ref, name))
        for name in ("state", "alive"):
            np.testing.assert_array_equal(frag.inputs[name], ref.inputs[name])
            np.testing.assert_array_equal(frag.next_inputs[name], ref.next_inputs[name])
        assert [(ep["step"], ep["env"], ep["length"]) for ep in frag.episodes] == sorted(
            (ep["step"], ep["env"], ep["length"]) for ep in ref.episodes)
        for ep, want in zip(frag.episodes, ref.episodes, strict=True):
            np.testing.assert_array_equal(ep["return"], want["return"])
    assert sum(len(f.episodes) for f in frags) >= 5  # 37 steps of 8-tick games


def test_shared_memory_room_is_read_from_dev_shm():
    assert _shm_room(1) and not _shm_room(1 << 62)


def tiny_cfg(name: str, **kw) -> TrainConfig:
    return TrainConfig(name, "vs_aggressive", total_steps=3 * 16 * 4, num_envs=4,
                       wandb="disabled", checkpoint_every=0, game={"max_steps": 24},
                       learners=(LearnerSpec("ppo", "ppo", (0,),
                                             config=PPOConfig(num_steps=16, update_epochs=1)),),
                       **kw)


def weights(trainer: Trainer) -> str:
    h = hashlib.sha256()
    for key, t in sorted(trainer.learners["ppo"].state_dict()["net"].items()):
        h.update(key.encode() + t.numpy().tobytes())
    return h.hexdigest()


@pytest.mark.slow
def test_a_run_in_fragments_is_reproducible_and_counts_what_it_played(tmp_path):
    runs = []
    for k, workers in enumerate((2, 2, 1)):
        tr = Trainer(tiny_cfg(f"f{k}", num_workers=workers), tmp_path / f"f{k}",
                     progress=False, fragments=True)
        summary = tr.train()
        runs.append((tr, summary))
    (a, sa), (b, sb), (one, _) = runs
    assert a.learners["ppo"].updates == 3 and sa["global_step"] == 3 * 64
    assert weights(a) == weights(b) and sa["episodes"] == sb["episodes"] >= 8
    assert weights(one) != weights(a)  # other shards, other samples
    plain = Trainer(tiny_cfg("plain"), tmp_path / "plain", progress=False)
    plain.train()
    assert weights(plain) != weights(one)  # not step-equal to acting on the learner
    # the observation statistics took in every row of the three rollouts
    assert a.learners["ppo"].obs_norm.rms.count == pytest.approx(3 * 64, abs=1e-3)


@pytest.mark.slow
def test_a_resumed_run_in_fragments_goes_on_as_the_uninterrupted_one(tmp_path):
    cfg = dataclasses.replace(tiny_cfg("full", num_workers=2), checkpoint_every=2)
    full = Trainer(dataclasses.replace(cfg, total_steps=4 * 64), tmp_path / "full",
                   progress=False, fragments=True)
    full.train()
    Trainer(dataclasses.replace(cfg, total_steps=2 * 64), tmp_path / "half", progress=False,
            fragments=True).train()
    resumed = resume_trainer(tmp_path / "half", progress=False, fragments=True,
                             total_steps=4 * 64)
    resumed.train()
    assert [h["step"] for h in resumed.history] == [3 * 64, 4 * 64]
    for key in ("losses/policy_loss", "losses/value_loss", "charts/episodes"):
        assert [h[key] for h in resumed.history] == [h[key] for h in full.history[2:]], key
    assert weights(resumed) == weights(full)


@pytest.mark.parametrize(("preset", "message"), [
    ("sac_vs_aggressive", "acted by PPO and MAPPO learners only"),
    ("sac_vs_ppo", "this run has ['sac (sac)'] (SAC acts step by step)"),
    ("team_ppo_vs_ppo", "self-play swaps opponents"),
])
def test_what_fragments_cannot_carry_is_one_line(tmp_path, capsys, preset, message):
    code = main(["train", "--preset", preset, "--runs", str(tmp_path), "--fragments",
                 "--total-steps", "64", "--num-envs", "2", "--wandb", "disabled",
                 "--no-progress"])
    assert code == 2
    last = capsys.readouterr().err.strip().splitlines()[-1]
    assert "fragments: " in last and message in last
    # SAC has no rollout: it is not also reported as one of the wrong length
    assert "rollout must be" not in last


@pytest.mark.parametrize("flag", ["--fragments", "--overlap"])
@pytest.mark.slow
def test_two_learners_act_in_one_fragment_from_the_command_line(tmp_path, capsys, flag):
    code = main(["train", "--preset", "ppo_vs_ppo", "--runs", str(tmp_path), "--name", "pair",
                 flag, "--workers", "2", "--num-envs", "4", "--total-steps", "128",
                 "--ppo", "num_steps=16,update_epochs=1", "--wandb", "disabled",
                 "--no-progress"])
    assert code == 0, capsys.readouterr().err
    rows = (tmp_path / "pair" / "metrics.jsonl").read_text().splitlines()
    last = [r for r in rows if '"charts/sps"' in r][-1]
    assert '"losses/approx_kl/' in last and last.count("losses/approx_kl/") == 2
    assert main(["train", "--resume", str(tmp_path / "pair"), flag, "--total-steps", "256",
                 "--no-progress"]) == 0
    assert "resuming" in capsys.readouterr().out
    steps = [json.loads(r)["step"] for r in
             (tmp_path / "pair" / "metrics.jsonl").read_text().splitlines()]
    assert steps[-1] == 256


class SignalInFragment(VectorMatchEnv):
    """The vector env, raising SIGINT in this process during its ``at``-th step."""

    def __init__(self, *args, at: int, **kw):
        super().__init__(*args, **kw)
        self.at, self.calls = at, 0

    def step_into(self, *args):
        self.calls += 1
        if self.calls == self.at:
            signal.raise_signal(signal.SIGINT)
        return super().step_into(*args)


@pytest.mark.parametrize("overlap", [False, True])
def test_a_stop_during_a_fragment_drops_it_and_resumes_as_the_reference(tmp_path, overlap):
    """With ``overlap`` the stopped 4th fragment was started ahead, by the learners of
    one update earlier; the save is the state at that iteration's start all the same."""
    from test_stopping import states_equal

    def run(name: str, iterations: int, at: int = 0) -> Trainer:
        cfg = dataclasses.replace(tiny_cfg(name), total_steps=iterations * 64,
                                  checkpoint_every=2)
        env = SignalInFragment(cfg.scenario, 4, cfg.seed, game_overrides=cfg.game, at=at)
        return Trainer(cfg, tmp_path / name, env=env, progress=False, fragments=True,
                       overlap=overlap)

    assert run("ref", 3).train()["stopped"] is None
    stopped = run("stop", 5, at=3 * 16 + 6)  # inside the 4th fragment
    summary = stopped.train()
    assert summary["exit_code"] == 130
    assert summary["stopped"] == {"reason": "SIGINT", "checkpoint_step": 3 * 64,
                                  "dropped_steps": 64}
    runs = [resume_trainer(tmp_path / name, progress=False, fragments=True, overlap=overlap,
                           total_steps=5 * 64) for name in ("ref", "stop")]
    for tr in runs:
        assert tr.train()["stopped"] is None
    assert [h["charts/episodes"] for h in runs[0].history] == \
        [h["charts/episodes"] for h in runs[1].history]
    assert states_equal(runs[0].learners["ppo"].state_dict(),
                        runs[1].learners["ppo"].state_dict())


class StartsSeen(VectorMatchEnv):
    """The vector env, noting how many updates its trainer's learner had made each time a
    rollout started."""

    trainer: Trainer | None = None

    def rollout_start(self, *args):
        self.starts = [*getattr(self, "starts", []), self.trainer.learners["ppo"].updates]
        super().rollout_start(*args)


@pytest.mark.parametrize(("overlap", "checkpoint_every", "starts"), [
    (False, 0, [0, 1, 2, 3]),
    (True, 0, [0, 0, 1, 2]),  # each rollout acted by the learner of one update earlier
    (True, 2, [0, 0, 2, 2]),  # none across a checkpoint: the matches restart there
])
def test_an_overlapped_run_acts_each_rollout_with_the_learner_one_update_behind(
        tmp_path, overlap, checkpoint_every, starts):
    cfg = dataclasses.replace(tiny_cfg("seen"), total_steps=4 * 64,
                              checkpoint_every=checkpoint_every)
    env = StartsSeen(cfg.scenario, 4, cfg.seed, game_overrides=cfg.game)
    tr = Trainer(cfg, tmp_path / "seen", env=env, progress=False, fragments=True,
                 overlap=overlap)
    env.trainer = tr
    assert tr.train()["global_step"] == 4 * 64
    assert env.starts == starts and tr.learners["ppo"].updates == 4


def test_an_overlapped_run_is_the_same_in_one_process_and_in_a_worker(tmp_path):
    """One process plays a rollout started ahead when it is collected, by the copy given
    at the start; a worker plays it during the update: the same run. Reproducible, and
    not the run that acts every rollout with the current learner."""
    cfg = dataclasses.replace(tiny_cfg("one"), total_steps=4 * 64)
    runs = {}
    for name in ("one", "again", "worker", "sync"):
        env = (SubprocVectorMatchEnv(cfg.scenario, 4, cfg.seed, num_workers=1,
                                     game_overrides=cfg.game) if name == "worker" else None)
        tr = Trainer(dataclasses.replace(cfg, name=name), tmp_path / name, env=env,
                     progress=False, fragments=True, overlap=name != "sync")
        summary = tr.train()
        runs[name] = (summary["global_step"], summary["episodes"], weights(tr),
                      [h["losses/policy_loss"] for h in tr.history])
    assert runs["one"] == runs["again"] == runs["worker"]
    assert runs["one"][0] == runs["sync"][0] == 4 * 64 and runs["one"][2] != runs["sync"][2]


@pytest.mark.slow
def test_a_worker_rollout_in_flight_is_one_at_a_time_and_closes_cleanly():
    sv = SubprocVectorMatchEnv("team_vs_bot", 4, seed=2, num_workers=2, **KW)
    policy = frozen(sv)
    try:
        with pytest.raises(RuntimeError, match="without rollout_start"):
            sv.rollout_finish()
        obs = sv.reset(9)
        sv.rollout_start(policy, obs, 40)
        with pytest.raises(RuntimeError, match="while a rollout is in flight"):
            sv.rollout_start(policy, obs, 40)
        assert sv.rollout_finish().steps == 40
        sv.rollout_start(policy, obs, 40)
    finally:
        sv.close()  # collects the answer in flight before closing the workers
    assert not any(p.is_alive() for p in sv._procs)


@pytest.mark.parametrize("workers", [0, 2])
@pytest.mark.slow
def test_steps_resets_and_settings_wait_for_the_rollout_in_flight(workers):
    """While a rollout is in flight, a step, a reset or an opponent setting is refused
    with an error naming it, and nothing is lost: the rollout is then collected whole,
    the call goes through, and the run goes on as one that made the call between
    rollouts."""
    def make():
        return (SubprocVectorMatchEnv("team_vs_bot", 4, seed=2, num_workers=workers, **KW)
                if workers else VectorMatchEnv("team_vs_bot", 4, seed=2, **KW))

    def run(env, interrupt):
        policy = frozen(env)
        obs = env.reset(9)
        env.rollout_start(policy, obs, 30)
        if interrupt:
            calls = {"step": lambda: env.step(np.ones((4, 2, 3), dtype=np.int64)),
                     "reset": lambda: env.reset(), "set_bot_weakness":
                     lambda: env.set_bot_weakness(0.5),
                     "set_env_opponents": lambda: env.set_env_opponents([None] * 4),
                     "add_opponent": lambda: env.add_opponent("w", "smart@0.5")}
            for name, call in calls.items():
                with pytest.raises(RuntimeError, match=rf"^{name}\(\) while a rollout is "
                                                       "in flight: call rollout_finish"):
                    call()
        first = env.rollout_finish()
        env.set_bot_weakness(0.5)
        second = env.rollout(policy, first.next_obs, 30)
        return [hashlib.sha256(b"".join(np.ascontiguousarray(a).tobytes() for a in (
            f.obs, f.actions, f.rewards, f.terminated, f.next_obs))).hexdigest()
            for f in (first, second)]

    envs = [make(), make()]
    try:
        assert run(envs[0], True) == run(envs[1], False)
    finally:
        for env in envs:
            env.close()


@pytest.mark.parametrize("algo", ["ppo", "mappo"])
def test_an_update_from_a_fragment_is_the_update_from_acting_step_by_step(tmp_path, algo):
    """With the normalisers off and the learner sampling from the stream the fragment's
    shard draws from, acting step by step and in a fragment give the same trajectory,
    the same buffer and the same update (MAPPO: states, death masks, bootstraps)."""
    config = {"ppo": PPOConfig(num_steps=24, update_epochs=2, norm_obs=False, hidden=32),
              "mappo": MAPPOConfig(num_steps=24, update_epochs=2, norm_obs=False,
                                   norm_state=False, bootstrap_timeouts=True, hidden=32)}[algo]
    cfg = TrainConfig("eq", "team_vs_bot", total_steps=24 * 3, num_envs=3, seed=4,
                      wandb="disabled", checkpoint_every=0, game={"max_steps": 20},
                      learners=(LearnerSpec("team", algo, (0, 1), config=config),))
    step = Trainer(cfg, tmp_path / "step", progress=False)
    frag = Trainer(cfg, tmp_path / "frag", progress=False, fragments=True)
    shard = np.random.SeedSequence(derive_seed(cfg.seed, 0, 17), spawn_key=(0,))
    step.learners["team"].np_rng = np.random.default_rng(shard)
    results = []
    for tr in (step, frag):
        obs = tr._segment_reset()
        buf = tr.learners["team"].buffer
        seen = {}
        update = tr.learners["team"].update

        def keep(*args, _buf=buf, _seen=seen, _update=update, **kw):
            _seen.update({k: v.clone() for k, v in vars(_buf).items()
                          if hasattr(v, "clone")})
            return _update(*args, **kw)

        tr.learners["team"].update = keep
        results.append((tr._collect_fragment(obs) if tr.fragments else tr._collect(obs),
                        seen, tr.episodes))
    (o1, m1), b1, e1 = results[0]
    (o2, m2), b2, e2 = results[1]
    assert e1 == e2 >= 3  # 20-tick games ended inside the rollout
    for key in b1:
        assert (b1[key] == b2[key]).all(), key
    np.testing.assert_array_equal(o1, o2)
    assert m1 == m2 and weights_of(step) == weights_of(frag)


def weights_of(trainer: Trainer) -> str:
    h = hashlib.sha256()
    for key, t in sorted(trainer.learners["team"].state_dict()["net"].items()):
        h.update(key.encode() + t.numpy().tobytes())
    return h.hexdigest()

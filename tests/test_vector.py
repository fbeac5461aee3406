"""Batched vector env and its shared-memory subprocess variant."""

from __future__ import annotations

import copy
import gc
import os
import pickle
import signal

import numpy as np
import pytest

from alphatank.commands.benchenv import RandomRollout
from alphatank.envs.vector import (
    SubprocVectorMatchEnv,
    VectorMatchEnv,
    WorkerDied,
    episode_seed,
    make_vector_env,
)
from alphatank.game.scenarios import NoopPolicy, ScenarioError


class ExplodingPolicy(NoopPolicy):
    """A seat controller that fails at the start of an episode."""

    def reset(self, match, seat, seed=None):
        raise ValueError("boom at reset")


KEYS = {"env", "return", "length", "winner", "outcome", "opponent", "map", "terms"}


def rollout(env, steps: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    shape = (env.num_envs, env.num_learners, 3)
    out = [env.reset(seed)]
    eps = []
    for _ in range(steps):
        obs, rew, term, trunc, info = env.step(rng.integers(0, [3, 3, 2], size=shape))
        out += [obs, rew, term, trunc, info["final_obs"]]
        eps += info["episodes"]
    return out, eps


def test_contract_shapes_dtypes_and_spaces():
    env = VectorMatchEnv("team_vs_bot", 3, seed=1)
    assert env.num_envs == 3 and env.num_learners == 2 and env.learner_teams == ["A", "A"]
    assert env.observation_space.shape == (env.obs_dim,)
    assert env.action_space.nvec.tolist() == [3, 3, 2]
    obs = env.reset()
    assert obs.shape == (3, 2, env.obs_dim) and obs.dtype == np.float32
    obs, rew, term, trunc, info = env.step(np.ones((3, 2, 3), dtype=np.int64))
    assert rew.shape == (3, 2) and rew.dtype == np.float32
    assert term.shape == trunc.shape == (3,) and term.dtype == bool
    assert info["final_obs"].shape == obs.shape and info["episodes"] == []


def test_same_step_autoreset_and_episode_records():
    env = VectorMatchEnv("vs_random", 4, seed=2, game_overrides={"max_steps": 40})
    env.reset()
    rng = np.random.default_rng(0)
    seen = 0
    for _ in range(90):
        obs, rew, term, trunc, info = env.step(rng.integers(0, [3, 3, 2], size=(4, 1, 3)))
        done = term | trunc
        for e in np.flatnonzero(~done):
            assert not info["final_obs"][e].any()
        for ep in info["episodes"]:
            assert set(ep) == KEYS and done[ep["env"]]
            assert ep["map"] == "battlefield" and ep["opponent"] == "B:random(w=1)"
            assert ep["outcome"] == (["draw"] if ep["winner"] is None else
                                     ["win"] if ep["winner"] == "A" else ["loss"])
            assert ep["length"] <= 40 and ep["return"].shape == (1,)
            # The returned obs is the next episode's first: time restarts.
            assert info["final_obs"][ep["env"]].any()
            assert env.core.matches[ep["env"]].tick == 0
            seen += 1
        assert len(info["episodes"]) == done.sum()
    assert seen >= 8


def test_dead_learner_keeps_its_slot_until_the_match_ends():
    env = VectorMatchEnv("team_vs_bot", 1, seed=0)
    env.reset()
    m = env.core.matches[0]
    m.alive[1] = False
    m.world.remove_tank(1)
    obs, rew, term, trunc, info = env.step(np.ones((1, 2, 3), dtype=np.int64))
    alive = env.layout["self.alive"]
    assert obs[0, 1, alive][0] == 0.0 and obs[0, 0, alive][0] == 1.0
    assert not (term | trunc).any() and obs.shape[1] == 2


def test_match_is_played_out_in_the_step_its_last_learner_dies():
    """Learners on two teams (seats 2 and 5 of mixed_teams, bots beside them): with one
    learner dead the match goes on tick by tick; once the other is dead too, the same
    step plays the match out to its end."""
    env = VectorMatchEnv("mixed_teams", 1, seed=0)
    env.reset(3)
    m, noop = env.core.matches[0], np.ones((1, 2, 3), dtype=np.int64)
    for seat in (2, 5):
        m.alive[seat] = False
        m.world.remove_tank(seat)
        tick = m.tick
        _, _, term, trunc, info = env.step(noop)
        if seat == 2:
            assert m.tick == tick + 1 and not (term | trunc).any()
    assert (term | trunc)[0] and info["episodes"][0]["length"] == tick + 1


def test_wrong_actions_name_env_and_learner():
    env = VectorMatchEnv("team_vs_bot", 2)
    env.reset()
    bad = np.ones((2, 2, 3), dtype=np.int64)
    bad[1, 1, 2] = 5
    with pytest.raises(ValueError, match=r"env 1, learner 1 \(seat 1, team A\).*fire 0\.\.1"):
        env.step(bad)
    with pytest.raises(ValueError, match="shape"):
        env.step(np.ones((2, 3), dtype=np.int64))
    with pytest.raises(TypeError, match="integers"):
        env.step(np.ones((2, 2, 3)))


def test_seeds_reproduce_and_differ():
    a, _ = rollout(VectorMatchEnv("vs_smart", 2, seed=5), 60)
    b, _ = rollout(VectorMatchEnv("vs_smart", 2, seed=5), 60)
    c, _ = rollout(VectorMatchEnv("vs_smart", 2, seed=5), 60, seed=1)
    assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
    assert not np.array_equal(a[0], c[0])
    assert episode_seed(0, 1, 0) != episode_seed(0, 0, 1)


@pytest.mark.parametrize("observation", ["paper", "egocentric"])
def test_subprocess_variant_is_bit_identical(observation):
    kwargs = {"game_overrides": {"max_steps": 60}, "observation": observation}
    local, eps_local = rollout(VectorMatchEnv("team_vs_bot", 4, seed=3, **kwargs), 130)
    sub = SubprocVectorMatchEnv("team_vs_bot", 4, seed=3, num_workers=2, **kwargs)
    try:
        remote, eps_remote = rollout(sub, 130)
        assert sub.num_learners == 2 and sub.obs_dim == sub.observation_space.shape[0]
        with pytest.raises(ValueError, match="env 3, learner 0"):
            bad = np.ones((4, 2, 3), dtype=np.int64)
            bad[3, 0, 0] = 9
            sub.step(bad)
    finally:
        sub.close()
    assert len(local) == len(remote)
    for x, y in zip(local, remote, strict=True):
        assert x.dtype == y.dtype and np.array_equal(x, y)
    assert len(eps_local) == len(eps_remote) >= 4
    for p, q in zip(eps_local, eps_remote, strict=True):
        assert p["env"] == q["env"] and np.array_equal(p["return"], q["return"])


def test_benched_seats_reach_the_worker_processes():
    sub = SubprocVectorMatchEnv("team_vs_def_smart", 2, seed=0, num_workers=2,
                                observation="egocentric_nearest")
    try:
        with pytest.raises(ValueError, match="cannot bench seats"):
            sub.set_benched([1])
        sub.set_benched([2, 4])
        obs = sub.reset()
        alive = [sub.layout[f"tank[{k}].alive"].start for k in range(4)]
        # each learner: its mate, then the one enemy in play, then the two absent ones
        assert obs[..., alive].tolist() == [[[1.0, 1.0, 0.0, 0.0]] * 2] * 2
        sub.set_benched([])
        assert sub.reset()[..., alive].tolist() == [[[1.0] * 4] * 2] * 2
    finally:
        sub.close()


def test_worker_errors_reach_the_parent():
    sub = SubprocVectorMatchEnv("vs_random", 2, seed=0, num_workers=2,
                                seat_policies={1: ExplodingPolicy()})
    with pytest.raises(RuntimeError, match="boom at reset"):
        sub.reset()
    gone = r"the env is closed: a worker failed earlier \(ValueError: boom at reset\); make a new"
    with pytest.raises(RuntimeError, match=r"^step\(\): " + gone):
        sub.step(np.ones((2, 1, 3), dtype=np.int64))
    with pytest.raises(RuntimeError, match=r"^reset\(\): " + gone):
        sub.reset()
    sub.close()


def test_bad_settings_are_refused_before_the_workers_and_a_closed_env_says_so():
    sub = SubprocVectorMatchEnv("vs_random", 2, seed=0, num_workers=2)
    act = np.ones((2, 1, 3), dtype=np.int64)
    try:
        sub.reset()
        with pytest.raises(ValueError, match=r"^weakness must be in \[0, 1\], got 1.5"):
            sub.set_opponents(["smart"], weakness=1.5)
        with pytest.raises(ValueError, match=r"^unknown bot name\(s\) \['smartt'\]; valid"):
            sub.set_opponents(["smartt"])
        with pytest.raises(TypeError, match="policy must be a Policy"):
            sub.set_opponent_policy("smart")
        with pytest.raises(ScenarioError, match="opponent 'x'"):
            sub.add_opponent("x", "genius")
        with pytest.raises(ValueError, match=r"^unknown opponent\(s\) \['x'\]"):
            sub.set_env_opponents(["x", None])
        sub.set_opponents(["smart"], weakness=0.5)  # the workers are still there
        assert sub.step(act)[1].shape == (2, 1)
    finally:
        sub.close()
    for call in (lambda: sub.step(act), sub.reset, lambda: sub.set_bot_weakness(0.5)):
        with pytest.raises(RuntimeError, match=r"the env is closed: close\(\) was called"):
            call()


def test_an_env_with_workers_refuses_to_be_copied_and_carries_on():
    """deepcopy once copied the pipes, then closed them with the dropped half-copy: the
    env lost its workers (OSError: Bad file descriptor on its next step or close)."""
    sub = SubprocVectorMatchEnv("vs_random", 2, seed=0, num_workers=2)
    act = np.ones((2, 1, 3), dtype=np.int64)
    try:
        sub.reset()
        for copy_ in (copy.deepcopy, copy.copy, pickle.dumps):
            with pytest.raises(TypeError, match=r"^a vector env with worker processes "
                                                r"\(num_workers > 1\) cannot be pickled"):
                copy_(sub)
        gc.collect()
        assert sub.step(act)[1].shape == (2, 1)
    finally:
        sub.close()


@pytest.mark.parametrize("call", ["step", "rollout", "set_bot_weakness"])
def test_a_killed_worker_is_worker_died_whether_sent_to_or_heard_from(call):
    """A worker killed (as by the out-of-memory killer): the next call raises WorkerDied
    and the env is closed, whether the pipe broke on the send or the answer never came
    (a send raised a bare BrokenPipeError, which the train command took for its own
    stdout's reader going away: exit 141 without a word)."""
    sub = SubprocVectorMatchEnv("vs_random", 2, seed=0, num_workers=2)
    try:
        obs = sub.reset()
        proc = sub._procs[1]
        os.kill(proc.pid, signal.SIGKILL)
        proc.join(30)
        act = np.ones((2, 1, 3), dtype=np.int64)
        do = {"step": lambda: sub.step(act), "set_bot_weakness": lambda: sub.set_bot_weakness(1),
              "rollout": lambda: sub.rollout(RandomRollout(), obs, 4)}[call]
        with pytest.raises(WorkerDied, match="^vector env worker failed: the worker process "
                                             "exited without answering"):
            do()
        with pytest.raises(RuntimeError, match="the env is closed: a worker failed earlier"):
            sub.step(act)
    finally:
        sub.close()


def _blocked_signals(pid: int) -> int:
    """Process ``pid``'s mask of blocked signals (Linux /proc: bit s - 1 is signal s)."""
    with open(f"/proc/{pid}/status") as f:
        return int(next(line for line in f if line.startswith("SigBlk:")).split()[1], 16)


@pytest.mark.skipif(not os.path.exists(f"/proc/{os.getpid()}/status"), reason="Linux /proc")
def test_the_fork_server_starts_with_sigint_blocked_and_this_process_does_not_keep_it():
    """The fork server imports torch for seconds before it ignores SIGINT: a Ctrl-C to the
    process group in that window ended it with a KeyboardInterrupt traceback."""
    sub = SubprocVectorMatchEnv("vs_random", 2, seed=0, num_workers=2)
    try:
        with open(f"/proc/{os.getpid()}/task/{os.getpid()}/children") as f:
            kids = [int(k) for k in f.read().split()]
        servers = []
        for kid in kids:
            with open(f"/proc/{kid}/cmdline", "rb") as f:
                if b"forkserver" in f.read():
                    servers.append(kid)
        assert servers
        assert all(_blocked_signals(k) >> (signal.SIGINT - 1) & 1 for k in servers)
        assert not _blocked_signals(os.getpid()) >> (signal.SIGINT - 1) & 1
        assert sub.reset().shape[0] == 2
    finally:
        sub.close()


def test_make_vector_env_picks_the_variant():
    env = make_vector_env("vs_random", 2, seed=0)
    assert isinstance(env, VectorMatchEnv)
    for bad in (0, -1, 3):
        with pytest.raises(ValueError, match=rf"^num_workers must be a whole number in "
                                             rf"1\.\.num_envs=2, got {bad}"):
            make_vector_env("vs_random", 2, seed=0, num_workers=bad)
    sub = make_vector_env("vs_random", 2, seed=0, num_workers=2)
    try:
        assert isinstance(sub, SubprocVectorMatchEnv)
        sub.set_bot_weakness(0.5)
        sub.set_opponents(["smart"])
        sub.reset()
        _, eps = rollout(sub, 5)
    finally:
        sub.close()


def test_opponent_controls_apply_from_next_episode():
    env = VectorMatchEnv("vs_random", 4, seed=0, game_overrides={"max_steps": 5})
    env.reset()
    env.set_opponents(["smart", "dodge"], weakness=0.25)
    assert env.core.describe_opponents(0) == "B:smart(w=0.25)"
    assert env.core.describe_opponents(1) == "B:dodge(w=0.25)"
    _, eps = rollout(env, 6)
    assert {ep["opponent"] for ep in eps} == {"B:smart(w=0.25)", "B:dodge(w=0.25)"}
    assert type(env.core.controllers[0][1]).__name__ == "Weakened"
    env.set_opponent_policy(NoopPolicy())
    env.reset()
    assert env.core.describe_opponents(2) == "B:policy:NoopPolicy"
    assert isinstance(env.core.controllers[2][1], NoopPolicy)
    env.set_opponent_policy(None)
    env.set_opponents(None)
    env.set_bot_weakness(1.0)
    env.reset()
    assert env.core.describe_opponents(3) == "B:random(w=1)"
    with pytest.raises(ValueError, match="valid"):
        env.set_opponents(["genius"])
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        env.set_bot_weakness(2.0)
    with pytest.raises(ValueError, match=r"\[0, 1\]"):  # refused whole: no bot changes
        env.set_opponents(["dodge"], weakness=2.0)
    assert env.core.bot_override is None


def test_selfplay_two_learners_and_no_learner_scenarios():
    env = VectorMatchEnv("selfplay_1v1", 2, seed=0)
    assert env.num_learners == 2 and env.learner_teams == ["A", "B"]
    watch = VectorMatchEnv("bot_teams", 2, seed=0)
    obs = watch.reset()
    assert obs.shape == (2, 0, watch.obs_dim)
    obs, rew, *_ = watch.step(np.zeros((2, 0, 3), dtype=np.int64))
    assert rew.shape == (2, 0)


@pytest.mark.parametrize("workers", [1, 2])
def test_named_opponents_per_env(workers):
    env = make_vector_env("team_vs_bot", 4, seed=0, num_workers=workers,
                          game_overrides={"max_steps": 5})
    try:
        env.add_opponent("weak_smart", "smart@0.5")
        env.add_opponent("idle", NoopPolicy())
        env.set_env_opponents(["weak_smart", None, "idle", "weak_smart"])
        _, eps = rollout(env, 6)
        by_env = {ep["env"]: ep["opponent"] for ep in eps}
        assert by_env[0] == by_env[3] == "B:weak_smart"
        assert by_env[1] == "B:smart(w=1), B:smart(w=1)"
        assert by_env[2] == "B:idle"
        with pytest.raises(ValueError, match="unknown opponent"):
            env.set_env_opponents(["nobody", None, None, None])
        with pytest.raises(ValueError, match="one opponent name per env"):
            env.set_env_opponents([None])
    finally:
        env.close()


def test_named_opponent_fills_every_non_learner_seat():
    env = VectorMatchEnv("team_vs_bot", 1, seed=0)
    env.add_opponent("dodgy", "dodge")
    env.set_env_opponents(["dodgy"])
    env.reset()
    bots = [c for seat, c in enumerate(env.core.controllers[0]) if seat not in env.core.driven]
    assert len(bots) == 2 and all("DodgeBot" in repr(b) for b in bots)
    assert bots[0] is not bots[1]  # one controller per seat (their own seeds)


class CountingBatchPolicy(NoopPolicy):
    """A batch policy that counts how it is asked to act."""

    def __init__(self):
        self.single = self.batched = self.calls = 0

    def act(self, match, seat):
        self.single += 1
        return super().act(match, seat)

    def act_batch(self, pairs, observe=None):
        self.batched += len(pairs)
        self.calls += 1
        return np.ones((len(pairs), 3), dtype=np.int64)


def test_batch_policies_act_in_batches_and_the_others_one_by_one():
    from alphatank.sim.policy import BatchPolicy, is_batch_policy

    batch, plain = CountingBatchPolicy(), NoopPolicy()
    assert is_batch_policy(batch) and isinstance(batch, BatchPolicy)
    assert not is_batch_policy(plain) and not isinstance(plain, BatchPolicy)
    assert is_batch_policy(CountingBatchPolicy())  # the class's answer, asked again
    env = VectorMatchEnv("vs_smart", 3, seed=0, seat_policies={1: batch})
    rollout(env, 5)
    assert (batch.single, batch.batched, batch.calls) == (0, 15, 5)  # 3 matches a call


@pytest.mark.parametrize("bad", [2.0, "2", None, True])
def test_num_envs_and_num_workers_that_are_not_whole_numbers_are_named(bad):
    with pytest.raises(ValueError, match=rf"^num_envs must be a whole number in 1\.\.4096 .*"
                                         rf"got {bad!r}"):
        VectorMatchEnv("vs_random", bad)
    with pytest.raises(ValueError, match=rf"^num_envs must be a whole number .*got {bad!r}"):
        SubprocVectorMatchEnv("vs_random", bad, num_workers=1)
    with pytest.raises(ValueError, match=rf"^num_workers must be a whole number in "
                                         rf"1\.\.num_envs=2, got {bad!r}"):
        SubprocVectorMatchEnv("vs_random", 2, num_workers=bad)
    from alphatank.envs.ray_vector import RayVectorMatchEnv  # refused before Ray starts

    with pytest.raises(ValueError, match=rf"^num_envs must be a whole number .*got {bad!r}"):
        RayVectorMatchEnv("vs_random", bad, num_runners=1)
    with pytest.raises(ValueError, match=rf"^num_runners \(env runners\) must be a whole "
                                         rf"number in 1\.\.num_envs=2, got {bad!r}"):
        RayVectorMatchEnv("vs_random", 2, num_runners=bad)


@pytest.mark.parametrize("seats, match", [
    ([0, 0], r"learner_seats names seat\(s\) \[0\] more than once"),
    ([0.0], r"learner_seats \[0\.0\] are not learner seats"),
    (0, r"learner_seats must be a list of seat indices, got 0"),
])
def test_learner_seats_that_are_not_distinct_seat_indices_are_named(seats, match):
    with pytest.raises(ScenarioError, match=rf"{match}; its learner seats: \[0, 1, 2, 3\]"):
        VectorMatchEnv("team", 1, learner_seats=seats)


def test_inputs_given_as_one_string_are_named():
    with pytest.raises(ValueError, match=r"^inputs must be a list of input names, got the "
                                         r"string 'alive' \(e\.g\. \['alive'\]\)"):
        VectorMatchEnv("vs_random", 1, inputs="alive")


def test_a_set_of_more_matches_than_memory_allows_is_refused():
    with pytest.raises(ValueError, match=r"num_envs must be a whole number in 1\.\.4096 .*0\.5 MB"
                                         r".*got 4097"):
        VectorMatchEnv("vs_random", 4097)

"""MAPPO: mirrors, a seat-dependent toy task, death masking, posthumous credit through
the learner, timeouts, persistence, and a small 2v1 in the tank env."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from alphatank.envs.vector import VectorMatchEnv
from alphatank.game.scenarios import parse_scenario
from alphatank.game.state import AgentState
from alphatank.training.hparams import MAPPOConfig
from alphatank.training.mappo import MAPPO, ValueNorm
from alphatank.training.ppo import NumpyMLP

torch.set_num_threads(1)


class SeatToy:
    """``envs`` x ``seats`` streams. Each env shows a target in {0, 1, 2} (one-hot, the
    same for its seats; obs column 0 is an alive flag, always 1). Seat j earns 1 for
    rotate == (target + j) % 3, so the seat id matters. Episodes: 8 steps, truncated."""

    def __init__(self, envs: int, seats: int, seed: int):
        self.E, self.k, self.n = envs, seats, envs * seats
        self.rng = np.random.default_rng(seed)
        self.t = np.zeros(envs, dtype=np.int64)
        self.target = self.rng.integers(0, 3, envs)
        self.seat = np.tile(np.arange(seats), envs)

    def obs(self) -> np.ndarray:
        o = np.zeros((self.n, 6), dtype=np.float32)
        o[:, 0] = 1.0
        o[np.arange(self.n), 1 + np.repeat(self.target, self.k)] = 1.0
        o[:, 4:] = self.rng.normal(size=(self.n, 2))
        return o

    def state(self) -> np.ndarray:
        s = np.zeros((self.n, 3 + self.k), dtype=np.float32)
        s[np.arange(self.n), np.repeat(self.target, self.k)] = 1.0
        s[np.arange(self.n), 3 + self.seat] = 1.0
        return s

    def step(self, actions: np.ndarray):
        want = (np.repeat(self.target, self.k) + self.seat) % 3
        reward = (actions[:, 0] == want).astype(np.float32)
        self.t += 1
        trunc = self.t >= 8
        self.t[trunc] = 0
        self.target = self.rng.integers(0, 3, self.E)
        return reward, np.zeros(self.n, dtype=bool), np.repeat(trunc, self.k)


def run_toy(cfg: MAPPOConfig, updates: int, seed: int = 0) -> tuple[MAPPO, list[float]]:
    env = SeatToy(8, 2, seed)
    m = MAPPO(6, 16, cfg, seed=seed, num_seats=2, state_dim=5, alive_index=0)
    obs, state = env.obs(), env.state()
    means = []
    for _ in range(updates):
        total = 0.0
        for _ in range(cfg.num_steps):
            act = m.act(obs, state=state)
            rew, term, trunc = env.step(act)
            obs, state = env.obs(), env.state()
            m.observe(obs, rew, term, trunc)
            total += float(rew.mean())
        means.append(total / cfg.num_steps)
        m.update(obs, state=state)
    return m, means


TOY = MAPPOConfig(num_steps=32, update_epochs=4, learning_rate=3e-3, critic_learning_rate=3e-3)


def test_learns_a_seat_dependent_toy_task():
    _, means = run_toy(TOY, updates=20)
    assert means[0] < 0.45  # random play: 1/3
    assert max(means[-3:]) > 0.85, means


def test_same_seed_same_run_and_state_dict_round_trip():
    a, _ = run_toy(MAPPOConfig(num_steps=8, update_epochs=2), 2, seed=3)
    b, _ = run_toy(MAPPOConfig(num_steps=8, update_epochs=2), 2, seed=3)
    for pa, pb in zip(a.net.parameters(), b.net.parameters(), strict=True):
        assert torch.equal(pa, pb)
    c = MAPPO(6, 16, MAPPOConfig(num_steps=8, update_epochs=2), seed=9, num_seats=2,
              state_dim=5, alive_index=0)
    c.load_state_dict(a.state_dict())
    obs = SeatToy(8, 2, 1).obs()
    assert np.array_equal(a.policy_actions(obs, True), c.policy_actions(obs, True))
    assert a.value_norm.stats() == c.value_norm.stats() and c.updates == 2
    d = MAPPO(6, 16, seed=0, num_seats=2, state_dim=5)
    d.load_state_dict(a.state_dict(), weights_only=True)
    assert np.array_equal(a.policy_actions(obs, True), d.policy_actions(obs, True))
    with pytest.raises(ValueError, match="num_seats"):
        MAPPO(6, 24, num_seats=3, state_dim=5).load_state_dict(a.state_dict())


def test_numpy_mirrors_match_the_torch_networks():
    m = MAPPO(6, 4, num_seats=2, state_dim=5)
    x, s = torch.randn(16, 8), torch.randn(16, 5)
    with torch.no_grad():
        assert np.allclose(NumpyMLP(m.net.actor).forward(x.numpy()), m.net.logits(x).numpy(),
                           atol=1e-5)
        assert np.allclose(NumpyMLP(m.net.critic).forward(s.numpy())[:, 0],
                           m.net.value(s).numpy(), atol=1e-5)


def test_seat_ids_in_policy_actions():
    m = MAPPO(6, 4, num_seats=2)
    obs = np.zeros((1, 6), dtype=np.float32)
    with pytest.raises(ValueError, match="pass seat="):
        m.policy_actions(obs)
    with pytest.raises(ValueError, match="seat ids must be in 0..1"):
        m.policy_actions(obs, seat=2)
    x0, x1 = m._actor_input(obs, np.array([0])), m._actor_input(obs, np.array([1]))
    assert x0[0, -2:].tolist() == [1.0, 0.0] and x1[0, -2:].tolist() == [0.0, 1.0]
    assert m.policy_actions(np.zeros((4, 6), np.float32), True).shape == (4, 3)
    with pytest.raises(ValueError, match="pass state="):
        MAPPO(6, 4, num_seats=2, state_dim=3).act(np.zeros((4, 6), np.float32))
    with pytest.raises(ValueError, match="multiple of num_seats"):
        MAPPO(6, 5, num_seats=2)


def _rollout(m: MAPPO, env: SeatToy, dead_from: int, scramble: np.random.Generator | None):
    """A rollout in which stream 1 (seat 1 of env 0) is dead from row ``dead_from`` on;
    ``scramble`` randomises everything a dead seat observes (not its alive flag)."""
    for t in range(m.cfg.num_steps):
        obs, state = env.obs(), env.state()
        if t >= dead_from:
            obs[1, 0] = 0.0
            state[1] = 0.0
            if scramble is not None:
                obs[1, 1:] = scramble.normal(size=5)
                state[1] = scramble.normal(size=5)
        act = m.act(obs, state=state)
        rew, term, trunc = env.step(act)
        rew[1] = 0.5 if t >= dead_from else rew[1]  # what a dead seat still receives
        m.observe(None, rew, term, trunc)
    nxt, nstate = env.obs(), env.state()
    nxt[1, 0] = 0.0
    return nxt, nstate


def test_dead_rows_do_not_change_the_update():
    cfg = MAPPOConfig(num_steps=12, update_epochs=3, norm_obs=False, norm_state=False)
    params = []
    for scramble in (None, np.random.default_rng(5)):
        m = MAPPO(6, 4, cfg, seed=2, num_seats=2, state_dim=5, alive_index=0)
        nxt, nstate = _rollout(m, SeatToy(2, 2, 0), dead_from=4, scramble=scramble)
        assert m.buffer.active[:, 1].tolist() == [True] * 4 + [False] * 8
        assert m.buffer.active[:, [0, 2, 3]].all()
        m.update(nxt, state=nstate)
        params.append([p.detach().clone() for p in m.net.parameters()])
    for pa, pb in zip(*params, strict=True):
        assert torch.equal(pa, pb)


def test_posthumous_credit_bootstraps_from_the_living_teammate():
    gamma = 0.9
    cfg = MAPPOConfig(num_steps=5, gamma=gamma, gae_lambda=1.0, norm_obs=False)
    m = MAPPO(6, 4, cfg, seed=1, num_seats=2, state_dim=5, alive_index=0)
    env = SeatToy(2, 2, 0)
    rng = np.random.default_rng(0)
    m.value_norm.update(torch.tensor([5.0, 9.0]))  # non-trivial denormalisation
    nxt, nstate = _rollout(m, env, dead_from=2, scramble=rng)
    adv, ret, values = m.advantages(nxt, state=nstate)
    v_next = m._values(nstate, nxt)
    assert m._team_values(v_next, nxt[:, 0] > 0.5)[1] == pytest.approx(v_next[0])
    # Seat 1 acted on rows 0-1, then received 0.5 per row while dead; the tail after
    # the rollout is its living teammate's value.
    tail = v_next[0]
    post = 0.0
    for _ in range(3):
        post = 0.5 + gamma * post
    post += gamma ** 3 * tail
    r = m.buffer.rewards[:, 1]
    want = float(r[0]) + gamma * (float(r[1]) + gamma * post)
    assert float(ret[0, 1]) == pytest.approx(want, rel=1e-5)
    assert float(adv[1, 1]) == pytest.approx(float(r[1]) + gamma * post - float(values[1, 1]),
                                             rel=1e-4, abs=1e-4)
    assert not adv[2:, 1].any()


def test_team_values_uses_living_teammates():
    m = MAPPO(6, 6, num_seats=3)
    v = np.array([1.0, 2.0, 4.0, 7.0, 8.0, 9.0])
    alive = np.array([True, False, True, False, False, False])
    assert m._team_values(v, alive).tolist() == [1.0, 2.5, 4.0, 7.0, 8.0, 9.0]


def test_timeouts_end_the_game_unless_bootstrapped():
    for boot in (False, True):
        cfg = MAPPOConfig(num_steps=2, bootstrap_timeouts=boot, norm_obs=False)
        m = MAPPO(6, 2, cfg, seed=0, num_seats=2, alive_index=0)
        obs = SeatToy(1, 2, 0).obs()
        for t in range(2):
            m.act(obs)
            trunc = np.array([t == 0] * 2)
            m.observe(obs, np.zeros(2, np.float32), np.zeros(2, bool), trunc,
                      final_obs=obs * 3)
        adv, ret, values = m.advantages(obs)
        final = m._values(None, obs * 3)
        want = cfg.gamma * final[0] if boot else 0.0
        assert float(ret[0, 0]) == pytest.approx(want, abs=1e-5)


def test_value_norm_is_debiased():
    vn = ValueNorm(beta=0.9)
    assert vn.stats() == (0.0, 1.0)
    vn.update(torch.tensor([10.0, 30.0]))
    assert vn.stats() == pytest.approx((20.0, 10.0))
    x = torch.tensor([3.0, -1.0])
    assert torch.allclose(vn.denormalize(vn.normalize(x)), x)


RANGE = """name: range3
description: 5x5 range: two learners and a helpless bot

#######
#.....#
#.1...#
#.....#
#...3.#
#.2...#
#######
"""


@pytest.mark.slow
def test_mappo_team_learns_to_shoot_a_helpless_bot(tmp_path):
    (tmp_path / "range3.txt").write_text(RANGE)
    sc = parse_scenario({"name": "range3", "map": str(tmp_path / "range3.txt"),
                         "game": {"max_steps": 100}, "observation": "egocentric",
                         "seats": [{"team": "A", "controller": "learner"},
                                   {"team": "A", "controller": "learner"},
                                   {"team": "B", "controller": "bot", "bot": "aggressive",
                                    "weakness": 0.0}]})
    E = 8
    env = VectorMatchEnv(sc, E, seed=0)
    st = AgentState(env.core.batch, env.core.teams, env.core.driven)
    cfg = MAPPOConfig(num_steps=64)  # MAPPO's defaults otherwise
    m = MAPPO(env.obs_dim, 2 * E, cfg, seed=0, num_seats=2, state_dim=st.size,
              alive_index=env.layout["self.alive"].start)
    obs = env.reset()
    wins: list[list[bool]] = []
    for _ in range(24):
        won = []
        for _ in range(cfg.num_steps):
            a = m.act(obs.reshape(-1, env.obs_dim), state=st.build().reshape(-1, st.size))
            obs, rew, term, trunc, info = env.step(a.reshape(E, 2, 3))
            m.observe(None, rew.reshape(-1), np.repeat(term, 2), np.repeat(trunc, 2))
            won += [ep["outcome"][0] == "win" for ep in info["episodes"]]
        m.update(obs.reshape(-1, env.obs_dim), state=st.build().reshape(-1, st.size))
        wins.append(won)
    first = np.mean(sum(wins[:6], []))  # ~0.35: random shots often hit on this range
    last = np.mean(sum(wins[-6:], []))
    assert last > first + 0.15, (first, last)

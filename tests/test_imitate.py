"""Behaviour cloning warm start: a bot's games, the learner fitted to them, in a run."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from alphatank.commands.train import report
from alphatank.game.scenarios import load_scenario
from alphatank.training.fields import FieldError
from alphatank.training.hparams import ImitateConfig, MAPPOConfig, imitate_config
from alphatank.training.imitate import (
    agreement,
    collect,
    discounted_returns,
    fit,
    gather,
    samples,
)
from alphatank.training.mappo import MAPPO
from alphatank.training.ppo import PPO, PPOConfig
from alphatank.training.presets import LearnerSpec, TrainConfig
from alphatank.training.runner import Trainer, resume_trainer

torch.set_num_threads(1)


def test_discounted_returns_are_cut_at_episode_ends():
    r = np.array([[1.0, 0.0], [2.0, 1.0], [4.0, 0.0]])
    done = np.array([[False, False], [True, False], [False, False]])
    ret = discounted_returns(r, done, 0.5)
    assert ret[:, 0].tolist() == [1.0 + 0.5 * 2.0, 2.0, 4.0]
    assert ret[:, 1].tolist() == [0.5 * 1.0, 1.0, 0.0]


def greedy_agreement(ppo: PPO, obs: np.ndarray, actions: np.ndarray, alive: np.ndarray
                     ) -> float:
    """Share of live samples whose most likely action (every head) is the bot's."""
    x = ppo.obs_norm(obs[alive], update=False)
    logits, _ = ppo.mirror.forward(x)
    heads = [h.argmax(-1) for h in np.split(logits, np.cumsum(ppo.nvec)[:-1], axis=-1)]
    return float((np.stack(heads, -1) == actions[alive]).all(-1).mean())


def test_cloning_makes_the_learner_act_like_the_bot():
    sc = load_scenario("vs_aggressive")
    cfg = ImitateConfig(bot="aggressive", steps=300, epochs=12, minibatch=256)
    demo = collect(sc, cfg, 4, seed=1, observation="egocentric", game={}, rewards={},
                   driven=[0])
    T, E, L, D = demo.obs.shape
    assert (T, E, L) == (300, 4, 1) and demo.alive.any() and demo.games > 0
    assert demo.done.sum() == demo.games
    obs, acts = demo.obs.reshape(T, E, D), demo.actions.reshape(T, E, 3)
    alive, rew = demo.alive.reshape(T, E), demo.rewards.reshape(T, E)
    held = slice(240, None)  # the last 60 steps are not trained on
    ppo = PPO(D, E, PPOConfig(), seed=0)
    before = greedy_agreement(ppo, obs[held], acts[held], alive[held])
    stats = fit(ppo, samples(ppo, obs[:240], acts[:240], alive[:240], rew[:240],
                             demo.done[:240]), cfg, 0)
    after = greedy_agreement(ppo, obs[held], acts[held], alive[held])
    assert after > 0.5 and after > before + 0.3, (before, after)
    assert stats["action_accuracy"] > 0.5
    np.testing.assert_allclose(ppo.obs_norm.rms.mean, obs[:240].reshape(-1, D).mean(0), atol=1e-4)


@pytest.mark.parametrize("eps", [0.0, 0.3])
def test_label_smoothing_leaves_the_clone_that_share_of_its_choices(eps):
    """Actions written into the observations (as the advice block shows the smart bot's):
    a plain clone copies them with near certainty; with label smoothing e each head keeps
    about e spread over its choices, 1 - e + e / k on the bot's."""
    rng = np.random.default_rng(3)
    T = 600
    acts = rng.integers((3, 3, 2), size=(T, 3))
    obs = np.zeros((T, 8), dtype=np.float32)
    obs[np.arange(T), acts[:, 0]] = 1.0
    obs[np.arange(T), 3 + acts[:, 1]] = 1.0
    obs[:, 6] = acts[:, 2]
    obs[:, 7] = rng.normal(size=T)
    ppo = PPO(8, 1, PPOConfig(), seed=0)
    cfg = ImitateConfig(epochs=120, minibatch=300, learning_rate=3e-3, label_smoothing=eps)
    fit(ppo, samples(ppo, obs[:, None], acts[:, None], np.ones((T, 1), bool),
                     np.zeros((T, 1)), np.zeros(T, bool)), cfg, 0)
    logits, _ = ppo.mirror.forward(ppo.obs_norm(obs, update=False))
    for h, (lo, k) in enumerate([(0, 3), (3, 3), (6, 2)]):
        p = torch.softmax(torch.from_numpy(logits[:, lo:lo + k]), -1).numpy()
        on_bot = p[np.arange(T), acts[:, h]].mean()
        want = 1 - eps + eps / k if eps else 0.97
        assert (on_bot == pytest.approx(want, abs=0.03) if eps else on_bot > want), (h, on_bot)


def test_a_mappo_team_actor_is_cloned_per_seat_and_its_critic_left_to_warm_up():
    sc = load_scenario("team_vs_def_bot")
    cfg = ImitateConfig(bot="aggressive", steps=300, epochs=12, minibatch=256)
    demo = collect(sc, cfg, 4, seed=2, observation="egocentric", game={}, rewards={},
                   driven=[0, 1])
    T, E, L, D = demo.obs.shape
    assert (E, L) == (4, 2) and demo.alive[:, :, 1].any()
    B = E * L  # streams: (env, seat) pairs, env-major
    obs, acts = demo.obs.reshape(T, B, D), demo.actions.reshape(T, B, 3)
    alive, rew = demo.alive.reshape(T, B), demo.rewards.reshape(T, B)
    done = np.repeat(demo.done, L, axis=1)
    team = MAPPO(D, B, MAPPOConfig(), seed=0, num_seats=L)
    critic = [p.detach().clone() for p in team.net.critic.parameters()]
    held = samples(team, obs[240:], acts[240:], alive[240:], rew[240:], done[240:])
    before = agreement(team, held)
    stats = fit(team, samples(team, obs[:240], acts[:240], alive[:240], rew[:240],
                              done[:240]), cfg, 0)
    assert stats["action_accuracy"] > 0.5 and "value_loss" not in stats
    assert agreement(team, held) > before + 0.3, (before, agreement(team, held))
    assert all(torch.equal(a, b) for a, b in zip(critic, team.net.critic.parameters(),
                                                 strict=True))
    # the numpy rollout mirror acts as the fitted network: greedy actions agree
    x = held.obs[held.alive]
    seats = (np.arange(len(held.obs)) % L)[held.alive]
    greedy = team.policy_actions(x, deterministic=True, seat=seats)
    assert (greedy == held.actions[held.alive]).all(-1).mean() > before + 0.3


def test_dagger_games_are_played_by_the_learner_and_labelled_by_the_bot():
    sc = load_scenario("vs_aggressive")
    cfg = ImitateConfig(bot="aggressive")
    seen = []

    def idle(obs: np.ndarray) -> np.ndarray:  # a learner that never moves or fires
        seen.append(obs.copy())
        return np.zeros((*obs.shape[:2], 3), dtype=np.int64)

    demo = collect(sc, cfg, 4, seed=1, observation="egocentric", game={}, rewards={},
                   driven=[0], steps=400, drive=idle)
    assert demo.games > 0 and demo.wins == 0  # the idle tank never wins a game
    assert (demo.actions[demo.alive][:, 2] == 1).any()  # though the bot would have fired
    np.testing.assert_array_equal(np.stack(seen), demo.obs)  # it saw what was recorded


def run_config(name: str, **kw) -> TrainConfig:
    kw.setdefault("total_steps", 128)
    kw.setdefault("learners", (LearnerSpec("ppo", "ppo", (0,),
                                           config=PPOConfig(num_steps=32, update_epochs=1)),))
    return TrainConfig(name, "vs_aggressive", num_envs=2, wandb="disabled",
                       observation="egocentric", checkpoint_every=0, **kw)


def weights(tr: Trainer) -> list[np.ndarray]:
    return [p.detach().numpy().copy() for p in tr.learners["ppo"].net.parameters()]


def test_a_run_starts_from_the_clone_the_same_way_every_time(tmp_path):
    table = {"bot": "aggressive", "steps": 64, "epochs": 2}
    runs = [Trainer(run_config("bc", imitate=table), tmp_path / f"bc{k}", progress=False)
            for k in range(2)]
    plain = Trainer(run_config("plain"), tmp_path / "plain", progress=False)
    for tr in (*runs, plain):
        tr.train()
    first = (tmp_path / "bc0" / "metrics.jsonl").read_text().splitlines()[0]
    assert '"step": 0, "imitate/bot_win_rate"' in first and "imitate/ppo/action_accuracy" in first
    for a, b in zip(weights(runs[0]), weights(runs[1]), strict=True):
        np.testing.assert_array_equal(a, b)
    assert any(not np.array_equal(a, b)
               for a, b in zip(weights(runs[0]), weights(plain), strict=True))


def test_dagger_rounds_refit_the_clone_on_its_own_states_the_same_way_every_time(tmp_path):
    table = {"bot": "aggressive", "steps": 64, "epochs": 2, "dagger": 2, "dagger_steps": 48}
    runs = [Trainer(run_config("dagger", imitate=table), tmp_path / f"d{k}", progress=False)
            for k in range(2)]
    plain = Trainer(run_config("bc", imitate={**table, "dagger": 0}), tmp_path / "bc",
                    progress=False)
    for tr in (*runs, plain):
        tr.train()
    first = json.loads((tmp_path / "d0" / "metrics.jsonl").read_text().splitlines()[0])
    for r in (1, 2):
        assert 0 <= first[f"imitate/dagger{r}/win_rate"] <= 1
        assert 0 <= first[f"imitate/dagger{r}/ppo/agreement"] <= 1
    for a, b in zip(weights(runs[0]), weights(runs[1]), strict=True):
        np.testing.assert_array_equal(a, b)
    assert any(not np.array_equal(a, b)
               for a, b in zip(weights(runs[0]), weights(plain), strict=True))
    # the rounds' states are in the observation statistics: 64 + 2 x 48 steps of 2 envs
    assert runs[0].learners["ppo"].obs_norm.rms.count > plain.learners["ppo"].obs_norm.rms.count


def test_the_time_limit_cuts_the_demonstrations(tmp_path, capsys):
    cfg = run_config("cut", imitate={"steps": 10**6}, time_limit_s=1.0, total_steps=10**6)
    tr = Trainer(cfg, tmp_path / "cut", progress=False)
    out = tr.train()
    assert out["stopped"]["reason"] == "time limit" and out["elapsed_s"] < 10
    assert (tmp_path / "cut" / "latest").exists()
    # a resume under the same limit would be cut again: the summary says to lengthen it
    assert report(out) == 0
    said = capsys.readouterr().out
    assert "the cloning takes longer than the time limit" in said
    assert "longer --time-limit" in said and f"--resume {tmp_path / 'cut'}" in said


def test_a_run_stopped_while_cloning_clones_again_on_resume_as_if_never_stopped(tmp_path):
    table = {"bot": "aggressive", "steps": 16, "epochs": 2}
    whole = Trainer(run_config("whole", imitate=table), tmp_path / "whole", progress=False)
    whole.train()
    # 10,000 epochs outlast the 1 s budget: the stop comes while the clone is being fitted
    cut = Trainer(run_config("cut", imitate={**table, "epochs": 10_000}, time_limit_s=1.0),
                  tmp_path / "cut", progress=False)
    out = cut.train()
    assert out["stopped"]["clone_pending"] and out["global_step"] == 0
    assert not (tmp_path / "cut" / "metrics.jsonl").read_text().strip()  # nothing logged
    resumed = resume_trainer(tmp_path / "cut", progress=False, imitate=table, time_limit_s=0.0)
    assert resumed.imitation is not None
    resumed.train()
    assert resumed.global_step == whole.global_step == 128
    for a, b in zip(weights(resumed), weights(whole), strict=True):
        np.testing.assert_array_equal(a, b)
    rows = (tmp_path / "cut" / "metrics.jsonl").read_text().splitlines()
    assert sum('"imitate/bot_win_rate"' in row for row in rows) == 1
    # once cloned, a later resume goes on with PPO and does not clone again
    assert resume_trainer(tmp_path / "cut", progress=False, total_steps=256).imitation is None


@pytest.mark.parametrize("table, fragment", [
    ({"bot": "smrt"}, "unknown bot 'smrt'"),
    ({"teachers": {"vs_smart": "smrt"}}, "imitate.teachers.vs_smart 'smrt'"),
    ({"teachers": {"vs_smart": 3}}, "imitate.teachers.vs_smart must be a seat spec"),
    ({"teachers": {"vs_smart": "checkpoint:/no/such/run"}}, "/no/such/run"),
    ({"stepz": 5}, "imitate.stepz"),
    ({"steps": 0}, "imitate.steps"),
    ({"label_smoothing": 1.0}, "imitate.label_smoothing"),
])
def test_bad_imitate_tables_name_the_field(tmp_path, table, fragment):
    with pytest.raises((FieldError, ValueError), match=fragment):
        imitate_config(table)
    with pytest.raises((FieldError, ValueError), match=fragment):
        Trainer(run_config("bad", imitate=table), tmp_path / "bad", progress=False)
    assert not (tmp_path / "bad" / "latest").exists()


def test_a_mixed_run_clones_each_scenario_in_its_own_envs(tmp_path):
    cfg = run_config("mix", imitate={"bot": "smart", "steps": 48, "epochs": 1})
    from alphatank.training.mixed import MixedVectorEnv

    env = MixedVectorEnv(["vs_aggressive", "vs_random"], 4, observation="egocentric")
    tr = Trainer(cfg.with_overrides(num_envs=4), tmp_path / "mix", env=env, progress=False)
    tr.train()
    first = (tmp_path / "mix" / "metrics.jsonl").read_text().splitlines()[0]
    assert '"imitate/samples": ' in first
    assert float(first.split('"imitate/samples": ')[1].split(",")[0]) > 48 * 2


def anchor_divergence(tr: Trainer, anchor: PPO) -> float:
    """Mean KL(anchor || policy) over the heads, on the observations of one rollout of
    ``tr``'s env (each policy with its own statistics)."""
    from alphatank.training.ppo import head_log_probs

    obs = tr.env.reset(seed=5)[:, 0]
    lr = tr.learners["ppo"]
    with torch.no_grad():
        ref = head_log_probs(torch.from_numpy(
            anchor.anchor_np.forward(anchor.anchor_norm(obs))), lr.nvec)
        now = head_log_probs(torch.from_numpy(lr.mirror.forward(lr.obs_norm(obs))[0]), lr.nvec)
    return float((ref.exp() * (ref - now)).sum((-2, -1)).mean())


def test_anchor_kl_keeps_the_policy_near_the_clone_and_resumes_with_it(tmp_path):
    table = {"bot": "aggressive", "steps": 64, "epochs": 4}
    ppo = {"num_steps": 32, "update_epochs": 8, "learning_rate": 3e-3}

    def cfg(name: str, kl: float) -> TrainConfig:
        spec = LearnerSpec("ppo", "ppo", (0,), config=PPOConfig(**ppo, anchor_kl=kl))
        return run_config(name, imitate=table, total_steps=256, learners=(spec,))

    free = Trainer(cfg("free", 0.0), tmp_path / "free", progress=False)
    held = Trainer(cfg("held", 5.0), tmp_path / "held", progress=False)
    for tr in (free, held):
        tr.train()
    learner = held.learners["ppo"]
    assert free.learners["ppo"].anchor_np is None and learner.anchor_np is not None
    assert anchor_divergence(held, learner) < 0.5 * anchor_divergence(free, learner)
    logged = [json.loads(line) for line in (tmp_path / "held" / "metrics.jsonl").open()]
    assert any("losses/anchor_kl" in row for row in logged)
    # the anchor is saved with the learner and comes back on resume
    state = learner.state_dict()
    again = PPO(learner.obs_dim, learner.num_streams, learner.cfg)
    again.load_state_dict(state)
    for a, b in zip(again.anchor_actor.parameters(), learner.anchor_actor.parameters(),
                    strict=True):
        assert torch.equal(a, b) and not a.requires_grad
    np.testing.assert_array_equal(again.anchor_norm.rms.mean, learner.anchor_norm.rms.mean)


def test_anchor_kl_without_a_warm_start_is_refused():
    spec = LearnerSpec("ppo", "ppo", (0,), config=PPOConfig(num_steps=32, anchor_kl=1.0))
    with pytest.raises(FieldError, match="'ppo': anchor_kl = 1.0 needs a warm start"):
        run_config("cold", learners=(spec,))
    run_config("warm", learners=(spec,), init_from="runs/x")  # a warm start: allowed


def test_each_scenario_of_a_mixed_run_is_taught_by_its_own_teacher(tmp_path):
    """``teachers`` overrides ``bot`` per scenario: the random bot fires on about half
    its ticks, the smart bot only with a shot lined up."""
    from alphatank.training.mixed import MixedVectorEnv

    cfg = run_config("mix", imitate={"bot": "smart", "teachers": {"vs_random": "random"}})
    env = MixedVectorEnv(["vs_aggressive", "vs_random"], 4, observation="egocentric")
    tr = Trainer(cfg.with_overrides(num_envs=4), tmp_path / "mix", env=env, progress=False)
    demo = gather(tr, tr.imitation, 150, seed=3)
    fire = demo.actions[..., 2]
    smart, rand = fire[:, :2][demo.alive[:, :2]], fire[:, 2:][demo.alive[:, 2:]]
    assert smart.mean() < 0.2 and rand.mean() > 0.35, (smart.mean(), rand.mean())
    bad = {"bot": "smart", "teachers": {"vs_dodge": "random"}}
    with pytest.raises(FieldError, match="imitate.teachers names no scenario of this run: "
                                         "'vs_dodge'; its scenarios: vs_aggressive, vs_random"):
        Trainer(cfg.with_overrides(num_envs=4, imitate=bad), tmp_path / "bad", env=env,
                progress=False)


def test_a_checkpoint_teaches_as_the_policy_it_holds(tmp_path):
    """A run cloned from the aggressive bot, as teacher, labels the same states much as
    that bot does and far more so than the random bot (the learner plays: the same games
    whoever labels them)."""
    clone = {"bot": "aggressive", "steps": 300, "epochs": 12, "minibatch": 256}
    Trainer(run_config("clone", imitate=clone), tmp_path / "clone", progress=False).train()
    sc = load_scenario("vs_aggressive")

    def idle(obs: np.ndarray) -> np.ndarray:
        return np.zeros((*obs.shape[:2], 3), dtype=np.int64)

    demos = {bot: collect(sc, ImitateConfig(), 4, seed=5, observation="egocentric", game={},
                          rewards={}, driven=[0], steps=200, drive=idle, bot=bot)
             for bot in (f"checkpoint:{tmp_path / 'clone'}", "aggressive", "random")}
    taught, bot, rand = demos.values()
    np.testing.assert_array_equal(taught.obs, bot.obs)
    np.testing.assert_array_equal(taught.alive, bot.alive)
    live = bot.alive

    def agree(a, b):  # noqa: ANN001, ANN202
        return (a.actions == b.actions).all(-1)[live].mean()

    # the teacher samples its actions, so it agrees with the bot less often than greedily
    assert agree(taught, bot) > agree(rand, bot) + 0.2, (agree(taught, bot), agree(rand, bot))


def test_cloning_into_a_run_with_a_sac_learner_is_refused_before_it_starts(tmp_path):
    sac = (LearnerSpec("sac", "sac", (0,)),)
    with pytest.raises(ValueError, match=r"imitate: the cloning fills PPO and MAPPO learners "
                                         r"only; this run also has \[\('sac', 'sac'\)\]"):
        Trainer(run_config("bc", imitate={"bot": "smart", "steps": 32}, learners=sac),
                tmp_path / "bc", progress=False)
    assert not (tmp_path / "bc").exists()


@pytest.mark.parametrize("table, field", [
    ({"bot": "learner"}, "bot"), ({"bot": "human:wasd"}, "bot"),
    ({"bot": "smart", "teachers": {"vs_smart": "human"}}, "teachers.vs_smart")])
def test_a_teacher_must_play_by_itself(table, field):
    """A learner seat has nothing to copy and a keyboard seat idles: both are refused."""
    with pytest.raises(FieldError, match=rf"imitate\.{field} must be a seat that plays by "
                                         r"itself"):
        imitate_config(table)


def test_a_teacher_for_a_scenario_the_run_does_not_play_is_refused_before_it_starts(tmp_path):
    table = {"bot": "smart", "steps": 32, "teachers": {"vs_smart": "smart"}}
    with pytest.raises(ValueError, match=r"imitate\.teachers names no scenario of this run: "
                                         r"'vs_smart'; its scenarios: vs_aggressive"):
        Trainer(run_config("bc", imitate=table), tmp_path / "bc", progress=False)
    assert not (tmp_path / "bc").exists()


def test_a_teacher_that_cannot_play_the_learner_seats_is_refused_before_it_starts(tmp_path):
    """An agent of a 2-against-1 team in a 1v1 run: refused when the run is made, naming
    the field, not once the cloning starts (which left the run's folder behind)."""
    table = {"bot": "agent:team_vs_def", "steps": 32}
    with pytest.raises(FieldError, match=r"imitate\.bot 'agent:team_vs_def' cannot play the "
                                         r"learner seats \[0\] of scenario 'vs_aggressive': "
                                         r".*team_vs_def: expects 336 observation features"):
        Trainer(run_config("bc", imitate=table), tmp_path / "bc", progress=False)
    assert not (tmp_path / "bc").exists()


def test_demonstrations_too_big_for_the_memory_are_refused_before_the_run_starts(tmp_path):
    """They were allocated at the cloning's start: a numpy traceback after the run's folder
    was made (or, a little smaller, filled lazily until the machine ran out)."""
    table = {"bot": "smart", "steps": 10**10, "dagger": 2}
    with pytest.raises(ValueError, match=r"^imitate: the demonstrations of 10,000,000,000 "
                                         r"vector steps and 2 DAgger rounds of 2,048 x 2 "
                                         r"matches x 1 learner seats x \d+ inputs needs "
                                         r"[\d,.]+ GiB; this machine has .* lower "
                                         r"imitate\.steps or imitate\.dagger_steps"):
        Trainer(run_config("bc", imitate=table), tmp_path / "bc", progress=False)
    assert not (tmp_path / "bc").exists()

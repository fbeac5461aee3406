"""Opponent schedules: curriculum by bot weakness, cycle learning over a bot pool."""

import numpy as np
import pytest
import torch

from alphatank.envs.vector import VectorMatchEnv
from alphatank.training.ppo import PPOConfig
from alphatank.training.presets import LearnerSpec, TrainConfig
from alphatank.training.runner import Trainer, opponent_key, resume_trainer
from alphatank.training.schedules import (
    CurriculumSchedule,
    CycleSchedule,
    LineupCurriculum,
    WinRateCurriculum,
    make_schedule,
)

torch.set_num_threads(1)


class Recorder:
    """Stands in for a vector env's opponent setters, remembering every call."""

    def __init__(self):
        self.calls = []

    def set_bot_weakness(self, w):
        self.calls.append(("weakness", w))

    def set_opponents(self, names, weakness=None):
        self.calls.append(("opponents", tuple(names), weakness))


def test_linear_curriculum_goes_from_start_to_end():
    c = CurriculumSchedule(steps=1000)  # paper defaults 0.1 -> 0.8
    assert [c.weakness(s) for s in (0, 500, 1000, 5000)] == pytest.approx([0.1, 0.45, 0.8, 0.8])


def test_sigmoid_curriculum_is_slow_fast_slow_and_hits_the_ends():
    c = CurriculumSchedule(steps=1000, shape="sigmoid")
    lin = CurriculumSchedule(steps=1000)
    w = [c.weakness(s) for s in range(0, 1001, 50)]
    assert w[0] == pytest.approx(0.1) and w[-1] == pytest.approx(0.8)
    assert c.weakness(500) == pytest.approx(0.45)
    assert all(b > a for a, b in zip(w, w[1:], strict=False))
    assert c.weakness(100) < lin.weakness(100) and c.weakness(900) > lin.weakness(900)
    assert (c.weakness(550) - c.weakness(450)) > (lin.weakness(550) - lin.weakness(450))


def test_curriculum_reaches_the_bots_of_the_next_episode():
    env = VectorMatchEnv("vs_aggressive", 2, seed=0, game_overrides={"max_steps": 5})
    env.reset()
    c = CurriculumSchedule(steps=100)
    assert c.apply(env, 50) == {"schedule/weakness": 0.45}
    for _ in range(5):  # episodes end after 5 ticks; the reset picks up the new weakness
        env.step(np.ones((2, 1, 3), dtype=np.int64))
    bot = env.core.controllers[0][1]
    assert bot.weakness == pytest.approx(0.45)
    rec = Recorder()
    c2 = CurriculumSchedule(steps=100)
    for step in (0, 0, 10):
        c2.apply(rec, step)
    assert rec.calls == [("weakness", 0.1), ("weakness", 0.17)]  # only changes are pushed


def test_fixed_and_random_cycles():
    pool = ["random", "aggressive", "defensive", "dodge"]
    fixed = CycleSchedule(pool, "fixed", interval=10, scale_victory=False)
    rec = Recorder()
    seen = []
    for step in range(0, 80, 5):
        fixed.apply(rec, step)
        seen.append(fixed.current)
    assert seen[::2] == pool + pool
    assert [c[1] for c in rec.calls] == [(b,) for b in pool + pool]
    a = CycleSchedule(pool, "random", interval=1, seed=4)
    b = CycleSchedule(pool, "random", interval=1, seed=4)
    picks = []
    for step in range(200):
        a.apply(Recorder(), step)
        b.apply(Recorder(), step)
        picks.append(a.current)
        assert a.current == b.current
    assert set(picks) == set(pool)


def test_adaptive_cycle_favours_the_bots_it_loses_to_and_scales_victory():
    pool = ["random", "dodge"]
    c = CycleSchedule(pool, "adaptive", interval=1, window=20, target=0.6, mastery_phase=1000,
                      seed=0)
    for _ in range(20):
        c.record("B:random(w=1)", "win")
        c.record("B:dodge(w=1)", "loss")
    assert c.win_rate("random") == 1.0 and c.win_rate("dodge") == 0.0
    picks = []
    for step in range(400):
        c.apply(Recorder(), step)
        picks.append(c.current)
    assert picks.count("dodge") > 5 * picks.count("random")
    # victory reward scale: mastered fraction during the phase, all-or-nothing after it
    assert c.victory_scale(10) == 0.5
    assert c.victory_scale(5000) == 0.0
    for _ in range(20):
        c.record("B:dodge(w=1)", "win")
    assert c.victory_scale(10) == 1.0 and c.victory_scale(5000) == 1.0
    state = c.state_dict()
    d = CycleSchedule(pool, "adaptive", interval=1, window=20, seed=99)
    d.load_state_dict(state)
    assert d.win_rate("dodge") == c.win_rate("dodge") and d.current == c.current
    d.apply(Recorder(), 400), c.apply(Recorder(), 400)
    assert d.current == c.current  # same generator state


def test_winrate_curriculum_steps_up_when_the_team_wins():
    c = make_schedule({"kind": "winrate", "levels": [0.1, 0.5, 1.0], "threshold": 0.6,
                       "window": 10, "min_episodes": 5}, 1000)
    assert isinstance(c, WinRateCurriculum)
    rec = Recorder()
    assert c.apply(rec, 0)["schedule/weakness"] == 0.1
    for out in ["win", "loss", "win", "win"]:  # 3/4, but fewer than min_episodes
        c.record("B:defensive(w=0.1)", out)
    assert c.level == 0
    c.record("B:defensive(w=0.1)", "draw")  # 3/5 = 0.6: up
    assert c.level == 1 and c.weakness == 0.5 and not c.results
    c.record("B:defensive(w=0.1)", "win")  # finished at the old strength: not counted
    assert not c.results
    for _ in range(20):
        c.record("B:defensive(w=0.5)", "loss")
    assert c.level == 1 and len(c.results) == 10 and c.win_rate() == 0.0
    c.apply(rec, 10)
    c.apply(rec, 20)
    assert rec.calls == [("weakness", 0.1), ("weakness", 0.5)]  # changes only
    for _ in range(10):
        c.record("B:defensive(w=0.5)", "win")
    assert c.weakness == 1.0
    for _ in range(10):
        c.record("B:defensive(w=1)", "win")
    assert c.level == 2  # the top level stays
    d = WinRateCurriculum(levels=(0.1, 0.5, 1.0), window=10, min_episodes=5)
    d.load_state_dict(c.state_dict())
    assert d.level == 2 and list(d.results) == list(c.results)
    assert d.apply(rec, 30)["schedule/weakness"] == 1.0 and rec.calls[-1] == ("weakness", 1.0)


def test_winrate_curriculum_can_step_down_when_the_team_stops_winning():
    c = WinRateCurriculum(levels=(0.1, 0.5, 1.0), threshold=0.6, window=10, min_episodes=5,
                          demote=0.2)
    for _ in range(5):
        c.record("B:defensive(w=0.1)", "win")
    assert c.level == 1
    for out in ["loss", "draw", "loss", "win"]:  # fewer than min_episodes: stays
        c.record("B:defensive(w=0.5)", out)
    assert c.level == 1
    c.record("B:defensive(w=0.5)", "loss")  # 1/5 = 0.2: not below 0.2
    assert c.level == 1
    c.record("B:defensive(w=0.5)", "loss")  # 1/6 < 0.2: one level down
    assert c.level == 0 and c.weakness == 0.1 and not c.results
    for _ in range(10):
        c.record("B:defensive(w=0.1)", "loss")
    assert c.level == 0  # the bottom level stays
    with pytest.raises(ValueError, match="demote"):
        WinRateCurriculum(threshold=0.5, demote=0.5)


def test_winrate_curriculum_reaches_the_bots_of_the_next_episode():
    env = VectorMatchEnv("team_vs_def_bot", 2, seed=0, game_overrides={"max_steps": 5})
    env.reset()
    c = WinRateCurriculum(levels=(0.2, 1.0), window=4, min_episodes=2, threshold=0.5)
    c.apply(env, 0)
    for _ in range(5):
        _, _, _, _, info = env.step(np.ones((2, 2, 3), dtype=np.int64))
    assert env.core.controllers[0][2].weakness == pytest.approx(0.2)
    # the finished episodes began before the curriculum: labelled with what they met
    assert [ep["opponent"] for ep in info["episodes"]] == ["B:defensive(w=1)"] * 2
    assert env.core.episode_label == ["B:defensive(w=0.2)"] * 2  # the episodes begun now


def test_lineup_curriculum_adds_the_bots_as_the_team_wins():
    # team_vs_def_smart: learners 0, 1; defensive 2, smart 3 and 4
    env = VectorMatchEnv("team_vs_def_smart", 2, seed=0, game_overrides={"max_steps": 4})
    env.reset()
    c = make_schedule({"kind": "lineup", "levels": [[2, 3], [2], []], "threshold": 0.5,
                       "window": 4, "min_episodes": 2}, 1000)
    assert isinstance(c, LineupCurriculum) and c.benched == (2, 3)
    assert c.apply(env, 0)["schedule/absent"] == 2.0
    for _ in range(4):
        _, _, _, _, info = env.step(np.ones((2, 2, 3), dtype=np.int64))
    m = env.core.matches[0]
    assert m.alive.tolist() == [True, True, False, False, True]  # one smart bot left
    labels = env.core.episode_label
    assert labels == ["B:absent, B:absent, B:smart(w=1)"] * 2
    # the finished episodes had the full line-up: not counted at this level
    for ep in info["episodes"]:
        c.record(ep["opponent"], "win")
    assert not c.results
    c.record(labels[0], "win")
    c.record(labels[0], "loss")  # 1/2 = 0.5: one bot more
    assert c.level == 1 and c.benched == (2,)
    c.apply(env, 10)
    for _ in range(4):
        env.step(np.ones((2, 2, 3), dtype=np.int64))
    assert env.core.matches[1].alive.tolist() == [True, True, False, True, True]
    d = LineupCurriculum(levels=[[2, 3], [2], []])
    d.load_state_dict(c.state_dict())
    assert d.benched == (2,)


def test_benching_checks_the_seats():
    env = VectorMatchEnv("team_vs_def_smart", 1, seed=0)
    with pytest.raises(ValueError, match=r"cannot bench seats \[0\]; bot seats: \[2, 3, 4\]"):
        env.set_benched([0])
    with pytest.raises(ValueError, match="leaves a team with no tank"):
        env.set_benched([2, 3, 4])
    # neither truncated (2.5 benched seat 2) nor read digit by digit ("23": seats 2, 3)
    for seats, why in (([2.5], r"indices \(integers\), got \[2\.5\]"),
                       ("23", "a list of seat indices, got '23'"),
                       (2, "a list of seat indices, got 2"), ([True], r"got \[True\]")):
        with pytest.raises(ValueError, match=f"{why}; bot seats: \\[2, 3, 4\\]"):
            env.set_benched(seats)
    assert env.core.benched == ()
    with pytest.raises(ValueError, match="fewer seats at each level"):
        LineupCurriculum(levels=[[2], [2, 3], []])
    with pytest.raises(ValueError, match="end with the full line-up"):
        LineupCurriculum(levels=[[2, 3], [2]])
    with pytest.raises(ValueError, match="lists of seat numbers"):
        LineupCurriculum(levels=[2, 3])


def test_bad_schedule_settings_are_rejected():
    with pytest.raises(ValueError, match="must rise"):
        WinRateCurriculum(levels=(0.5, 0.1))
    with pytest.raises(ValueError, match="min_episodes"):
        make_schedule({"kind": "winrate", "window": 10, "min_episodes": 20}, 100)
    with pytest.raises(ValueError, match="shape"):
        CurriculumSchedule(steps=10, shape="cubic")
    with pytest.raises(ValueError, match="weakness"):
        CurriculumSchedule(steps=10, end=1.5)
    with pytest.raises(ValueError, match="cycle mode"):
        CycleSchedule(["random"], mode="round-robin")
    with pytest.raises(ValueError, match="unknown schedule kind"):
        make_schedule({"kind": "tournament"}, 100)
    with pytest.raises(ValueError, match=r"speed: unknown key for kind 'curriculum'; valid "
                                         r"keys: \['kind', 'end', 'shape'"):
        make_schedule({"kind": "curriculum", "speed": 2}, 100)
    with pytest.raises(ValueError, match="cycle pool: unknown bot 'genius'"):
        make_schedule({"kind": "cycle", "pool": ["smart", "genius"]}, 100)
    # a string pool was read letter by letter ("unknown bot 'r'"), levels that are not a
    # list of numbers gave Python's words ("'float' object is not iterable")
    with pytest.raises(ValueError, match=r"cycle pool must be a list of bot names, got 'random'"):
        make_schedule({"kind": "cycle", "pool": "random"}, 100)
    for levels in (0.5, ["a"], [[0.1]], [True]):
        with pytest.raises(ValueError, match=r"winrate curriculum levels must be a list of "
                                             r"weaknesses in \[0, 1\], got "):
            make_schedule({"kind": "winrate", "levels": levels}, 100)


@pytest.mark.parametrize("steepness", [1e-17, 0.001, 2000.0, 1e308])
def test_a_sigmoid_steepness_it_cannot_compute_is_refused(steepness):
    """Beyond [0.01, 1000] the sigmoid overflowed (OverflowError) or its ends met (division
    by zero) at the first apply, once the run had started."""
    with pytest.raises(ValueError, match=r"steepness must be in \[0.01, 1000\], got "):
        make_schedule({"kind": "curriculum", "shape": "sigmoid", "steepness": steepness}, 100)


@pytest.mark.parametrize("steepness", [0.01, 1000.0])
def test_the_steepest_and_flattest_sigmoids_allowed_run_from_start_to_end(steepness):
    c = make_schedule({"kind": "curriculum", "shape": "sigmoid", "steepness": steepness}, 100)
    w = [c.weakness(s) for s in range(101)]
    assert w[0] == pytest.approx(0.1) and w[-1] == pytest.approx(0.8)
    assert all(b >= a for a, b in zip(w, w[1:], strict=False))


def test_cycle_training_rotates_the_opponents_and_scales_the_victory_reward(tmp_path):
    cfg = TrainConfig("cyc", "vs_aggressive", total_steps=6 * 64, num_envs=4, wandb="disabled",
                      checkpoint_every=0, game={"max_steps": 16},
                      schedule={"kind": "cycle", "pool": ["random", "aggressive"],
                                "mode": "fixed", "interval": 64, "mastery_phase": 10**6},
                      learners=(LearnerSpec("ppo", "ppo", (0,),
                                            config=PPOConfig(num_steps=16, update_epochs=1)),))
    tr = Trainer(cfg, tmp_path / "cyc", progress=False)
    tr.train()
    opps = {k for h in tr.history for k in h if k.startswith("charts/win_rate_vs/")}
    assert opps == {"charts/win_rate_vs/random", "charts/win_rate_vs/aggressive"}
    assert all(h["schedule/victory_scale"] == 0.0 for h in tr.history)  # nothing mastered yet
    # a win's victory reward is scaled away before the learner sees it
    rewards = np.full((4, 1), 250.0, dtype=np.float32)
    ep = {"env": 2, "length": 9, "outcome": ["win"], "return": np.array([250.0]),
          "opponent": "B:random(w=1)"}
    tr._record_episode(ep, rewards, scale=0.25)
    assert rewards[2, 0] == pytest.approx(250.0 - 0.75 * 200.0) and rewards[0, 0] == 250.0
    assert opponent_key("B:aggressive(w=1), B:smart(w=0.5,ricochet=False)") == "aggressive+smart"


def _cycle_config(total_steps: int, **kw) -> TrainConfig:
    base = dict(name="cyc", scenario="vs_aggressive", total_steps=total_steps, num_envs=4,
                wandb="disabled", checkpoint_every=2, game={"max_steps": 12}, seed=5,
                schedule={"kind": "cycle", "pool": ["random", "dodge"], "mode": "random",
                          "interval": 96, "mastery_phase": 10**6},
                learners=(LearnerSpec("ppo", "ppo", (0,),
                                      config=PPOConfig(num_steps=16, update_epochs=1)),))
    base.update(kw)
    return TrainConfig(**base)


def test_a_schedule_sets_the_opponents_of_every_first_episode(tmp_path):
    """The scenario's own bot (aggressive) never plays: the cycle's first opponent is in
    place before the first episodes start, and a curriculum's first episodes are at its
    starting weakness."""
    tr = Trainer(_cycle_config(4 * 64), tmp_path / "cyc", progress=False)
    tr.train()
    opps = {k for h in tr.history for k in h if k.startswith("charts/win_rate_vs/")}
    assert opps and opps <= {"charts/win_rate_vs/random", "charts/win_rate_vs/dodge"}
    cur = Trainer(_cycle_config(64, schedule={"kind": "curriculum", "start": 0.2, "end": 0.3,
                                              "steps": 10**6}), tmp_path / "cur",
                  progress=False)
    cur.env.reset(seed=0)  # what the run's first reset finds
    cur._segment_reset()
    labels = {cur.env.core.describe_opponents(e) for e in range(4)}
    assert labels == {"B:aggressive(w=0.2)"}, labels


def test_a_resumed_scheduled_run_goes_on_as_the_uninterrupted_one(tmp_path):
    """With a cycle switching opponents at random, the updates after a resume are the
    uninterrupted run's, and so are the opponents' win-rate windows."""
    full = Trainer(_cycle_config(6 * 64), tmp_path / "full", progress=False)
    full.train()
    Trainer(_cycle_config(2 * 64), tmp_path / "half", progress=False).train()
    resumed = resume_trainer(tmp_path / "half", progress=False, total_steps=6 * 64)
    resumed.train()
    assert [h["step"] for h in resumed.history] == [h["step"] for h in full.history[2:]]
    for got, want in zip(resumed.history, full.history[2:], strict=True):
        same = {k: got[k] for k in want if k not in ("charts/sps", "charts/elapsed_s")}
        assert same == {k: want[k] for k in same}, got["step"]


def test_the_logged_return_is_the_one_paid_after_the_victory_scale(tmp_path):
    """A cycle that scales the victory reward away logs the return the learner got."""
    tr = Trainer(_cycle_config(64), tmp_path / "ret", progress=False)
    rewards = np.zeros((4, 1), dtype=np.float32)
    ep = {"env": 1, "length": 9, "outcome": ["win"], "return": np.array([250.0]),
          "opponent": "B:random(w=1)"}
    tr._record_episode(ep, rewards, scale=0.25)
    assert tr.returns["ppo"][-1] == pytest.approx(250.0 - 0.75 * tr.victory)
    tr._record_episode({**ep, "outcome": ["loss"], "return": np.array([-40.0])}, rewards,
                       scale=0.25)
    assert tr.returns["ppo"][-1] == pytest.approx(-40.0)


@pytest.mark.parametrize("schedule, message", [
    ({"kind": "lineup", "levels": [[5], []]},
     r"schedule levels: vs_aggressive: cannot bench seats \[5\]; bot seats: \[1\]"),
    ({"kind": "lineup", "levels": [[0], []]}, r"cannot bench seats \[0\]"),
    ({"kind": "league", "settings": {"smart": ["vs_nope"]}},
     r"league settings name scenario\(s\) \['vs_nope'\] that the env does not play"),
])
def test_a_schedule_the_scenario_cannot_play_is_refused_before_the_run_starts(
        tmp_path, schedule, message):
    with pytest.raises(ValueError, match=message):
        Trainer(_cycle_config(64, schedule=schedule), tmp_path / "run", progress=False)
    assert not (tmp_path / "run").exists()

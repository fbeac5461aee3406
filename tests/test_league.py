"""The league (PFSP over bots and snapshots), the mixed-scenario vector env and episode
labels that name the opponent each episode was really played against."""

import numpy as np
import pytest
import torch

from alphatank.envs.vector import VectorMatchEnv
from alphatank.training.hparams import PPOConfig
from alphatank.training.league import LeagueSchedule, opponent_name
from alphatank.training.mixed import MixedVectorEnv
from alphatank.training.presets import LearnerSpec, TrainConfig
from alphatank.training.runner import Trainer
from alphatank.training.schedules import make_schedule

torch.set_num_threads(1)


def test_pfsp_weights_follow_the_loss_rate_with_a_floor():
    lg = LeagueSchedule(bots=["random", "smart"], weaknesses=[1.0], power=2.0, floor=0.1,
                        window=4, snapshots=0)
    assert lg.opponents() == ["random@1", "smart@1"]
    assert np.allclose(lg.probabilities(), [0.5, 0.5])  # never played: both tried first
    for out in ("win", "win", "win", "win"):
        lg.record("B:random@1", out)
    for out in ("win", "loss", "draw", "loss"):
        lg.record("B:smart@1", out)
    # random: score 1 -> weight max(0.1, 0) = 0.1; smart: score 0.375 -> 0.625^2 = 0.390625
    assert np.allclose(lg.probabilities(), np.array([0.1, 0.390625]) / 0.490625)
    lg.record("B:smart(w=1)", "win")  # not a league opponent (an episode before the league)
    assert lg.games == 8
    mu = {name: m for name, m, *_ in lg.table()}
    assert mu["learner"] > mu["random@1"]  # four wins rated


def test_snapshot_share_splits_the_draws_between_snapshots_and_bots():
    lg = LeagueSchedule(bots=["random", "smart"], weaknesses=[1.0], power=1.0, floor=0.1,
                        window=4, snapshots=2, snapshot_share=0.25)
    for name in ("self@100", "self@200"):  # as _snapshot adds them, without a trainer
        lg._add(name)
        lg.pool.append(name)
    for out in ("win", "win", "win", "loss"):
        lg.record("B:random@1", out)  # score 0.75 -> weight 0.25
    for out in ("win", "loss", "loss", "loss"):
        lg.record("B:self@100", out)  # 0.75; self@200 never played: 1.0
    p = lg.probabilities()
    assert lg.opponents() == ["random@1", "smart@1", "self@100", "self@200"]
    assert np.allclose(p, [0.75 * 0.25 / 1.25, 0.75 * 1.0 / 1.25, 0.25 * 0.75 / 1.75,
                           0.25 * 1.0 / 1.75])
    # a block where smart does not play: the bots' three quarters all go to random
    assert np.allclose(lg.probabilities(np.array([True, False, True, True])),
                       [0.75, 0.0, 0.25 * 0.75 / 1.75, 0.25 / 1.75])
    plain = LeagueSchedule(bots=["random", "smart"], weaknesses=[1.0], snapshots=2)
    plain._add("self@100")
    plain.pool.append("self@100")
    assert np.allclose(plain.probabilities(), [1 / 3] * 3)  # no share: weighed together
    for bad in (1.0, -0.1):
        with pytest.raises(ValueError, match="snapshot_share must be in"):
            LeagueSchedule(snapshot_share=bad)


def test_opponent_names_and_bad_settings():
    assert opponent_name("B:smart@0.5") == "smart@0.5"
    assert opponent_name("B:self@4096") == "self@4096"
    assert opponent_name("B:x, C:x") == "x"
    with pytest.raises(ValueError, match="league bots"):
        LeagueSchedule(bots=["genius"])
    with pytest.raises(ValueError, match="weaknesses"):
        LeagueSchedule(weaknesses=[0.0])
    assert isinstance(make_schedule({"kind": "league", "bots": ["dodge"]}, 100), LeagueSchedule)
    with pytest.raises(ValueError, match="colour: unknown key for kind 'league'"):
        make_schedule({"kind": "league", "colour": "red"}, 100)


@pytest.mark.parametrize("spec, message", [
    # twice the same opponent: two table rows of one name, one of them never rated
    ({"bots": ["smart", "smart"]}, r"league bots must be a list of distinct names"),
    ({"weaknesses": [0.5, 0.5000001]}, r"league weaknesses must differ \(an opponent is "
                                        r"named with 6 digits: \['0.5', '0.5'\]\)"),
    ({"bots": "smart"}, r"league bots must be a list of distinct names .*, got 'smart'"),
    ({"weaknesses": 0.5}, r"league weaknesses must be a list of numbers in \(0, 1\], got 0.5"),
    ({"weaknesses": ["a"]}, r"league weaknesses must be a list of numbers"),
    ({"weaknesses": [True]}, r"league weaknesses must be a list of numbers"),
    ({"settings": ["vs_smart"]}, r"league settings must be a table of bot name = "
                                 r"\[scenario names\], got \['vs_smart'\]"),
    ({"settings": {"smart": 3}}, r"league settings: 'smart' = 3; keys must be"),
])
def test_a_mistyped_league_setting_is_one_line_naming_it(spec, message):
    with pytest.raises(ValueError, match=message):
        make_schedule({"kind": "league", **spec}, 100)


def test_settings_keep_each_bot_to_its_scenarios_blocks():
    mix = MixedVectorEnv(["vs_random", "vs_dodge"], 5, seed=0, observation="egocentric",
                         game_overrides={"max_steps": 8})
    lg = LeagueSchedule(bots=["random", "aggressive", "dodge"], weaknesses=[0.5, 1.0],
                        snapshots=0, settings={"random": ["vs_random"], "dodge": ["vs_dodge"]})
    picks = set()
    for step in range(0, 4000, 100):
        lg.apply(mix, step)
        names = mix.blocks[0].core.env_opponent + mix.blocks[1].core.env_opponent
        assert not any(n.startswith("dodge") for n in names[:3])
        assert not any(n.startswith("random") for n in names[3:])
        picks |= {(e < 3, n.partition("@")[0]) for e, n in enumerate(names)}
    # aggressive, named nowhere, plays in both blocks
    assert picks == {(True, "random"), (True, "aggressive"), (False, "dodge"),
                     (False, "aggressive")}
    only_dodge = LeagueSchedule(bots=["dodge"], snapshots=0, settings={"dodge": ["vs_dodge"]})
    with pytest.raises(ValueError, match="no opponent plays in scenario 'vs_random'"):
        only_dodge.apply(mix, 0)
    elsewhere = LeagueSchedule(bots=["dodge"], snapshots=0, settings={"dodge": ["vs_smart"]})
    with pytest.raises(ValueError, match=r"scenario\(s\) \['vs_smart'\] that the env"):
        elsewhere.apply(mix, 0)
    for bad in ({"smart": ["vs_smart"]}, {"dodge": "vs_dodge"}, {"dodge": []}):
        with pytest.raises(ValueError, match="league settings"):
            LeagueSchedule(bots=["dodge"], settings=bad)


def test_labels_name_the_opponent_the_episode_was_played_against():
    env = VectorMatchEnv("vs_random", 2, seed=0, game_overrides={"max_steps": 6})
    env.add_opponent("idle_smart", "smart@0.0")
    env.reset(seed=1)
    env.step(np.ones((2, 1, 3), dtype=np.int64))
    env.set_env_opponents(["idle_smart", None])  # mid-episode: applies from the next one
    eps = []
    for _ in range(12):
        eps += env.step(np.ones((2, 1, 3), dtype=np.int64))[4]["episodes"]
    first = [ep["opponent"] for ep in eps if ep["env"] == 0]
    assert first[0] == "B:random(w=1)" and set(first[1:]) == {"B:idle_smart"}
    assert {ep["opponent"] for ep in eps if ep["env"] == 1} == {"B:random(w=1)"}


def test_mixed_env_splits_matches_over_scenarios():
    mix = MixedVectorEnv(["vs_random", "vs_dodge"], 5, seed=3, observation="egocentric",
                         game_overrides={"max_steps": 8})
    assert [b.num_envs for b in mix.blocks] == [3, 2]
    assert [b.env_ids for b in mix.blocks] == [[0, 1, 2], [3, 4]]
    assert mix.blocks[1].core.game.bullet_speed > mix.blocks[0].core.game.bullet_speed
    obs = mix.reset(seed=3)
    single = VectorMatchEnv("vs_random", 5, seed=3, observation="egocentric",
                            game_overrides={"max_steps": 8})
    assert obs.shape == (5, 1, mix.obs_dim)
    assert np.array_equal(obs[:3], single.reset(seed=3)[:3])  # same env ids, same episodes
    mix.add_opponent("weak", "aggressive@0.5")
    mix.set_env_opponents([None, "weak", None, None, "weak"])
    eps = []
    for _ in range(20):
        obs, rew, term, trunc, info = mix.step(np.ones((5, 1, 3), dtype=np.int64))
        assert rew.shape == (5, 1) and term.shape == (5,) and info["final_obs"].shape == obs.shape
        eps += info["episodes"]
    by_env = {}
    for ep in eps:
        by_env.setdefault(ep["env"], set()).add(ep["opponent"])
    assert "B:weak" in by_env[1] and "B:weak" in by_env[4] and by_env[3] == {"B:dodge(w=1)"}
    with pytest.raises(ValueError, match="egocentric"):
        MixedVectorEnv(["vs_random", "vs_aggressive"], 2)  # paper observations differ


def test_league_trains_against_bots_and_its_own_snapshots(tmp_path):
    cfg = TrainConfig("lg", "vs_smart", total_steps=1536, num_envs=4, wandb="disabled",
                      observation="egocentric", game={"max_steps": 60}, checkpoint_every=0,
                      schedule={"kind": "league", "bots": ["random", "dodge"],
                                "weaknesses": [0.5, 1.0], "snapshot_every": 512,
                                "snapshots": 2},
                      learners=(LearnerSpec("ppo", "ppo", (0,),
                                            PPOConfig(num_steps=64, update_epochs=1)),))
    # the open map has 4 wall rectangles, the battlefield 11: snapshots play on both
    env = MixedVectorEnv(["vs_aggressive", "vs_dodge"], 4, observation="egocentric",
                         game_overrides={"max_steps": 60})
    tr = Trainer(cfg, tmp_path / "run", env=env, progress=False)
    tr.train()
    lg = tr.schedule
    assert lg.pool == deque_of(["self@512", "self@1024"])  # the newest 2 of 3 snapshots
    names = {name for name, *_ in lg.table()}
    assert {"learner", "random@0.5", "dodge@1", "self@0", "self@1024"} <= names
    assert lg.games > 0 and sum(len(r) for r in lg.results.values()) == lg.games
    assert sum(len(r) for n, r in lg.results.items() if n.startswith("self@")) > 0
    assert any(k.startswith("league/score/") for k in tr.history[-1])
    state = lg.state_dict()
    again = make_schedule(cfg.schedule, cfg.total_steps)
    again.load_state_dict(state)
    assert again.table() == lg.table() and again.games == lg.games


def deque_of(items):
    from collections import deque
    return deque(items)


def test_league_snapshots_of_a_mappo_team_play_the_bot_team(tmp_path):
    """A MAPPO learner driving both seats of a team: its snapshots (one learner for the two
    bot seats) play the other team (the first snapshot raised 'num_streams (1) must be a
    multiple of num_seats (2)')."""
    from alphatank.training.hparams import MAPPOConfig

    cfg = TrainConfig("lg", "team_vs_bot", total_steps=512, num_envs=2, wandb="disabled",
                      game={"max_steps": 40}, checkpoint_every=0,
                      schedule={"kind": "league", "bots": ["random"], "weaknesses": [1.0],
                                "snapshot_every": 256, "snapshots": 2},
                      learners=(LearnerSpec("team", "mappo", (0, 1),
                                            MAPPOConfig(num_steps=64, update_epochs=1)),))
    tr = Trainer(cfg, tmp_path / "run", progress=False)
    tr.train()
    lg = tr.schedule
    assert list(lg.pool) == ["self@0", "self@256"]
    assert sum(len(r) for n, r in lg.results.items() if n.startswith("self@")) > 0

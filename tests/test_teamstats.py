"""``alphatank eval --team-stats``: the cooperation figures come from the very games the
win rate counts, whatever ``--num-envs``."""

from __future__ import annotations

import json
import os

from alphatank.cli import main
from alphatank.game.seats import checkpoint_source
from alphatank.training.evaluate import evaluate_checkpoint
from alphatank.training.teamstats import TeamWatch, format_team_stats


def test_team_stats_follow_the_evaluated_games_for_any_num_envs():
    agent = checkpoint_source("agent:team_vs_def")
    runs = [evaluate_checkpoint(agent, [None], games=6, seed=11, num_envs=k,
                                team_stats=True)[0] for k in (2, 3)]
    for r in runs:
        s = r.team_stats
        assert (s["wins"], s["losses"], s["draws"]) == (r.wins, r.losses, r.draws)
        assert s["games"] == 6 and len(s["hits_per_game_by_seat"]) == 2
        assert s["crossfire_kills"] <= s["kills"] <= round(6 * sum(s["hits_per_game_by_seat"]))
    assert runs[0].team_stats == runs[1].team_stats
    assert runs[0].outcomes == runs[1].outcomes


def test_team_watch_counts_one_game_per_index():
    w = TeamWatch("A", 2, ["A", "A", "B"])
    w.start(0)
    w.hits[0] = [2, 1, 0]
    w.kills[0] = [1, 0, 0]
    w.end(5, 0, "win")
    w.start(0)  # a new game in env 0 starts from zero
    w.end(6, 0, "draw")
    s = w.summary()
    assert (s["games"], s["wins"], s["draws"], s["wins_both_scored"]) == (2, 1, 1, 1)
    assert s["hits_per_game_by_seat"] == [1.0, 0.5] and s["kills"] == 1
    assert s["wins_both_scored_share"] == 1.0 and "in 100% of the wins" in format_team_stats(s)


def test_no_wins_give_no_share_and_the_interval_of_nothing_known():
    w = TeamWatch("A", 1, ["A", "A", "B"])
    w.start(0)
    w.end(5, 0, "loss")
    s = w.summary()
    assert s["wins"] == 0 and s["wins_both_scored_share"] is None
    assert s["wins_both_scored_ci95"] == [0.0, 1.0]
    assert "no wins, so no share of wins" in format_team_stats(s)
    # no kills: no share of them in crossfire either (0 of 0 was printed as "0%")
    assert s["kills"] == 0 and s["crossfire_share"] is None
    assert "kills 0, so no share of them in crossfire;" in format_team_stats(s)


def test_a_team_of_one_tank_has_no_cooperation_shares(tmp_path, capsys):
    """On a 1v1 scenario the evaluated team is one tank: no teammate to score beside it
    or to fire across. Its shares were printed as measured ("every teammate hit an enemy
    in 100% of the wins", "in crossfire 0%"); they are None, and the terminal says why."""
    out = tmp_path / "e.json"
    assert main(["eval", "bot:smart", "--scenario", "vs_random", "--games", "2", "--seed",
                 "1", "--team-stats", "--json", str(out)]) == 0
    [s] = json.loads(out.with_suffix(".team.json").read_text(encoding="utf-8"))
    assert s["seats"] == 1 and s["wins"] == 2 and s["kills"] >= 2
    assert s["wins_both_scored_share"] is None and s["crossfire_share"] is None
    assert s["wins_both_scored_ci95"] == [0.0, 1.0]
    text = capsys.readouterr().out
    assert "one tank, so no teammate to hit enemies beside it or to fire across" in text
    assert "every teammate" not in text and "crossfire" not in text


def test_eval_cli_writes_team_stats_beside_json(tmp_path, capsys):
    out = tmp_path / "e.json"
    assert main(["eval", "agent:team_vs_def", "--games", "2", "--seed", "3",
                 "--num-envs", "2", "--team-stats", "--json", str(out)]) == 0
    stats = json.loads(out.with_suffix(".team.json").read_text(encoding="utf-8"))
    rows = json.loads(out.read_text(encoding="utf-8"))
    assert stats[0]["checkpoint"] == "agent:team_vs_def" and stats[0]["games"] == 2
    assert stats[0]["wins"] == rows[0]["wins"]
    assert "every teammate hit an enemy" in capsys.readouterr().out


def test_eval_cli_team_stats_of_a_stand_in_bot(tmp_path, capsys):
    """The smart bot in the learner seats gets the same cooperation figures as an agent
    (a yardstick), counted from the same games as its win rate."""
    out = tmp_path / "bot.json"
    assert main(["eval", "bot:smart", "--scenario", "team_vs_def_bot", "--games", "4",
                 "--seed", "5", "--num-envs", "2", "--team-stats", "--json", str(out)]) == 0
    stats = json.loads(out.with_suffix(".team.json").read_text(encoding="utf-8"))
    rows = json.loads(out.read_text(encoding="utf-8"))
    assert stats[0]["checkpoint"] == "bot:smart" and stats[0]["games"] == 4
    assert stats[0]["opponent"] == "B:defensive(w=1)"  # the other side only
    assert (stats[0]["wins"], stats[0]["losses"]) == (rows[0]["wins"], rows[0]["losses"])
    assert stats[0]["kills"] >= stats[0]["wins"]  # a win against one bot takes a kill
    assert "every teammate hit an enemy" in capsys.readouterr().out


def test_eval_cli_team_stats_through_a_symlink_and_not_beside_a_device(tmp_path, capsys):
    """``--json`` a link: the rows go to its target, which gets FILE.team.json beside it
    (as ``/dev/stdout`` sent to a file); a device or pipe has no folder for it: refused
    before any game, in one line."""
    (tmp_path / "real").mkdir()
    link = tmp_path / "link.json"
    link.symlink_to(tmp_path / "real" / "e.json")
    assert main(["eval", "agent:team_vs_def", "--games", "2", "--seed", "3",
                 "--num-envs", "2", "--team-stats", "--json", str(link)]) == 0
    assert link.is_symlink() and json.loads(link.read_text(encoding="utf-8"))[0]["games"] == 2
    stats = json.loads((tmp_path / "real" / "e.team.json").read_text(encoding="utf-8"))
    assert stats[0]["games"] == 2 and sorted(p.name for p in tmp_path.iterdir()) == [
        "link.json", "real"]
    capsys.readouterr()
    os.mkfifo(tmp_path / "pipe")
    assert main(["eval", "agent:team_vs_def", "--games", "2", "--team-stats",
                 "--json", str(tmp_path / "pipe")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "--team-stats: --json " in err and "is not a file" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["link.json", "pipe", "real"]

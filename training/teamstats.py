"""Cooperation of a team, measured: who of the team scores, and whether kills come from
two directions at once (``alphatank eval --team-stats``).

Per game (an :class:`~alphatank.sim.episode.EpisodeHook` on the line-up's episodes):

* ``hits`` / ``kills`` of each seat of the team (enemies only);
* **both scored**: every seat of the team hit an enemy in the game;
* **crossfire kill**: when an enemy dies, a bullet of the killer's teammate is in flight
  within ``radius`` px of it (the enemy was shot at from two sides).

Summary: win / loss / draw counts of these games, the share of won games in which every
teammate scored, the share of the team's kills made in crossfire, and hits per seat.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from alphatank.sim.episode import Episode, EpisodeHook
from alphatank.sim.match import TickEvents
from alphatank.stats import wilson_interval

CROSSFIRE_PX = 100.0


@dataclass
class TeamGame:
    """One game of the team: its outcome (+1, 0, -1), hits and kills per team seat, and
    how many of its kills were made in crossfire."""

    outcome: int
    hits: list[int]
    kills: list[int]
    crossfire: int


class TeamStatsHook(EpisodeHook):
    """Counts a team's hits, kills and crossfire kills in each episode it joins."""

    def __init__(self, team: str, radius: float = CROSSFIRE_PX):
        self.team, self.radius = team, float(radius)
        self.games: list[TeamGame] = []

    def on_start(self, episode: Episode) -> None:
        m = episode.match
        self.seats = [s for s in range(m.n) if m.teams[s] == self.team]
        self.hits = np.zeros(m.n, dtype=np.int64)
        self.kills = np.zeros(m.n, dtype=np.int64)
        self.crossfire = 0

    def on_tick(self, episode: Episode, events: TickEvents) -> None:
        m = episode.match
        for h in events.hits:
            if not h.friendly and m.teams[h.shooter] == self.team:
                self.hits[h.shooter] += 1
        for k in events.kills:
            if m.teams[k.shooter] != self.team or m.teams[k.victim] == self.team:
                continue
            self.kills[k.shooter] += 1
            mates = [s for s in self.seats if s != k.shooter]
            owner = m.bullet_owner
            live = m.bullet_active & np.isin(owner, mates)
            if live.any():
                d = np.hypot(*(m.bullet_xy[live] - m.tank_xy[k.victim]).T)
                self.crossfire += int((d <= self.radius).any())

    def on_end(self, episode: Episode) -> None:
        seat = self.seats[0]
        self.games.append(TeamGame(episode.outcome(seat), self.hits[self.seats].tolist(),
                                   self.kills[self.seats].tolist(), self.crossfire))


@dataclass
class TeamStats:
    """Summary of :class:`TeamGame` records."""

    games: list[TeamGame] = field(default_factory=list)

    def summary(self) -> dict[str, Any]:
        g = self.games
        n = len(g)
        wins = [x for x in g if x.outcome > 0]
        both = sum(all(h > 0 for h in x.hits) for x in wins)
        kills = sum(sum(x.kills) for x in g)
        cross = sum(x.crossfire for x in g)
        lo, hi = wilson_interval(both, len(wins)) if wins else (0.0, 0.0)
        seats = len(g[0].hits) if g else 0
        return {"games": n, "wins": len(wins), "losses": sum(x.outcome < 0 for x in g),
                "draws": sum(x.outcome == 0 for x in g),
                "wins_both_scored": both,
                "wins_both_scored_share": round(both / len(wins), 4) if wins else 0.0,
                "wins_both_scored_ci95": [round(lo, 4), round(hi, 4)],
                "kills": kills, "crossfire_kills": cross,
                "crossfire_share": round(cross / kills, 4) if kills else 0.0,
                "hits_per_game_by_seat": [round(sum(x.hits[k] for x in g) / n, 3)
                                          for k in range(seats)] if n else []}


def team_stats(checkpoint: str, games: int = 100, seed: int = 0,
               scenario: str | None = None, team: str | None = None,
               radius: float = CROSSFIRE_PX) -> dict[str, Any]:
    """Play ``games`` games of the checkpoint's scenario (or ``scenario``) with the
    checkpoint in its learner seats (one Policy per seat; game ``i`` from the seed
    ``alphatank eval --seed`` gives it) and summarise the team's cooperation (see the
    module docstring)."""
    from alphatank.game.lineup import build_lineup
    from alphatank.game.scenarios import load_scenario, parse_scenario
    from alphatank.training.checkpoint import load_checkpoint
    from alphatank.training.evaluate import game_seed

    ckpt = load_checkpoint(checkpoint)
    sc = load_scenario(scenario) if scenario is not None else ckpt.scenario
    game = ckpt.train_config.game
    if game:
        sc = parse_scenario({**sc.to_dict(), "game": {**sc.game, **game}}, sc.source)
    lineup = build_lineup(sc, learner=f"checkpoint:{ckpt.path}")
    team = team or sc.seats[sc.learner_seats[0]].team
    hook = TeamStatsHook(team, radius)
    for i in range(games):
        lineup.play(game_seed(seed, i), hooks=[hook])
    return {"checkpoint": str(ckpt.path), "scenario": sc.name, "team": team,
            "crossfire_px": radius, **TeamStats(hook.games).summary()}


def format_team_stats(s: dict[str, Any]) -> str:
    """Two lines for the terminal."""
    lo, hi = s["wins_both_scored_ci95"]
    return (f"team {s['team']} in {s['scenario']}: {s['wins']}/{s['losses']}/{s['draws']} "
            f"(W/L/D) of {s['games']} games; every teammate hit an enemy in "
            f"{100 * s['wins_both_scored_share']:.0f}% of the wins [{100 * lo:.0f}, "
            f"{100 * hi:.0f}]\n"
            f"  kills {s['kills']}, in crossfire (a teammate's bullet within "
            f"{s['crossfire_px']:.0f} px of the victim) {100 * s['crossfire_share']:.0f}%; "
            f"hits per game by seat {s['hits_per_game_by_seat']}")

"""Cooperation of a team, measured: who of the team scores, and whether kills come from
two directions at once (``alphatank eval --team-stats``).

:class:`TeamWatch` follows the games of an evaluation (``play_games(..., watch=...)``),
so the statistics come from the very games, and sampled actions, the win rates count.
Per game:

* ``hits`` / ``kills`` of each seat of the team (enemies only);
* **both scored**: every seat of the team hit an enemy in the game;
* **crossfire kill**: when an enemy dies, a bullet of the killer's teammate is in flight
  within ``radius`` px of it (the enemy was shot at from two sides).

Summary: win / loss / draw counts of these games, the share of won games in which every
teammate scored, the share of the team's kills made in crossfire, and hits per seat. A
share with nothing to count is None: no wins, no kills, or a team of one tank (no
teammate to score beside it or to fire across; a 1v1 scenario).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from alphatank.sim.match import Match, TickEvents
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


class TeamWatch:
    """Counts ``team``'s hits, kills and crossfire kills in the current game of each of
    ``num_envs`` envs (seat teams ``teams``); a finished game is kept by its index in the
    evaluation."""

    def __init__(self, team: str, num_envs: int, teams: list[str],
                 radius: float = CROSSFIRE_PX):
        self.team, self.radius = team, float(radius)
        self.seats = [s for s, t in enumerate(teams) if t == team]
        self.games: dict[int, TeamGame] = {}
        self.hits = np.zeros((num_envs, len(teams)), dtype=np.int64)
        self.kills = np.zeros((num_envs, len(teams)), dtype=np.int64)
        self.crossfire = np.zeros(num_envs, dtype=np.int64)

    def start(self, e: int) -> None:
        """Env ``e`` starts a new game."""
        self.hits[e] = self.kills[e] = self.crossfire[e] = 0

    def tick(self, e: int, m: Match, events: TickEvents) -> None:
        """Env ``e`` played a tick with these events."""
        for h in events.hits:
            if not h.friendly and m.teams[h.shooter] == self.team:
                self.hits[e, h.shooter] += 1
        for k in events.kills:
            if m.teams[k.shooter] != self.team or m.teams[k.victim] == self.team:
                continue
            self.kills[e, k.shooter] += 1
            mates = [s for s in self.seats if s != k.shooter]
            live = m.bullet_active & np.isin(m.bullet_owner, mates)
            if live.any():
                d = np.hypot(*(m.bullet_xy[live] - m.tank_xy[k.victim]).T)
                self.crossfire[e] += int((d <= self.radius).any())

    def end(self, index: int, e: int, outcome: str) -> None:
        """Env ``e``'s game, game ``index`` of the evaluation, ended with ``outcome``
        (win, loss or draw for the team)."""
        self.games[index] = TeamGame({"win": 1, "loss": -1}.get(outcome, 0),
                                     self.hits[e, self.seats].tolist(),
                                     self.kills[e, self.seats].tolist(),
                                     int(self.crossfire[e]))

    def summary(self) -> dict[str, Any]:
        """The statistics of the finished games (in game-index order)."""
        g = [self.games[i] for i in sorted(self.games)]
        n = len(g)
        wins = [x for x in g if x.outcome > 0]
        both = sum(all(h > 0 for h in x.hits) for x in wins)
        kills = sum(sum(x.kills) for x in g)
        cross = sum(x.crossfire for x in g)
        mates = len(self.seats) > 1  # a lone tank (1v1) has no teammate
        lo, hi = wilson_interval(both, len(wins)) if mates else (0.0, 1.0)  # (0, 1): unknown
        return {"team": self.team, "crossfire_px": self.radius, "seats": len(self.seats),
                "games": n, "wins": len(wins), "losses": sum(x.outcome < 0 for x in g),
                "draws": sum(x.outcome == 0 for x in g),
                "wins_both_scored": both,
                "wins_both_scored_share": round(both / len(wins), 4) if wins and mates
                else None,
                "wins_both_scored_ci95": [round(lo, 4), round(hi, 4)],
                "kills": kills, "crossfire_kills": cross,
                "crossfire_share": round(cross / kills, 4) if kills and mates else None,
                "hits_per_game_by_seat": [round(sum(x.hits[k] for x in g) / n, 3)
                                          for k in range(len(self.seats))] if n else []}


def format_team_stats(s: dict[str, Any]) -> str:
    """Two lines for the terminal."""
    lo, hi = s["wins_both_scored_ci95"]
    share, cross = s["wins_both_scored_share"], s["crossfire_share"]
    lone = s["seats"] == 1
    both = ("one tank, so no teammate to hit enemies beside it or to fire across" if lone
            else "no wins, so no share of wins in which every teammate hit an enemy"
            if share is None else f"every teammate hit an enemy in {100 * share:.0f}% of the "
                                  f"wins [{100 * lo:.0f}, {100 * hi:.0f}]")
    crossfire = ("" if lone else ", so no share of them in crossfire" if cross is None
                 else f", in crossfire (a teammate's bullet within {s['crossfire_px']:.0f} px "
                      f"of the victim) {100 * cross:.0f}%")
    return (f"team {s['team']}: {s['wins']}/{s['losses']}/{s['draws']} "
            f"(W/L/D) of {s['games']} games; {both}\n"
            f"  kills {s['kills']}{crossfire}; hits per game by seat "
            f"{s['hits_per_game_by_seat']}")

"""Evaluation: exact win/loss/draw counts with Wilson 95% intervals, in the layout of the
paper's Table 3, also as CSV and JSON.

Games run in a :class:`~alphatank.envs.core.MatchSet` (the engine under every env): the
checkpoint's learners drive their seats with batched inference over all matches, bots or
any other Policy fill the rest. Each env plays a fixed quota of games (never "the first N
to finish", which would favour short games), and game ``i`` always uses the seed derived
from ``(seed, i)``, so counts are reproducible.
"""

from __future__ import annotations

import csv
import dataclasses
import json
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from alphatank.envs.core import MatchSet
from alphatank.game.scenarios import Scenario, Seat, load_scenario
from alphatank.sim.policy import Policy
from alphatank.stats import wilson_interval
from alphatank.training.checkpoint import Checkpoint, load_checkpoint


@dataclass
class EvalResult:
    """Outcome counts of ``games`` games from the evaluated team's point of view."""

    name: str
    opponent: str
    wins: int = 0
    losses: int = 0
    draws: int = 0
    lengths: list[int] = field(default_factory=list)

    @property
    def games(self) -> int:
        return self.wins + self.losses + self.draws

    @property
    def win_rate(self) -> float:
        return self.wins / self.games if self.games else 0.0

    @property
    def interval(self) -> tuple[float, float]:
        return wilson_interval(self.wins, self.games)

    def as_dict(self) -> dict[str, Any]:
        lo, hi = self.interval
        return {"experiment": self.name, "opponent": self.opponent, "games": self.games,
                "wins": self.wins, "losses": self.losses, "draws": self.draws,
                "win_rate": round(self.win_rate, 4), "ci95_low": round(lo, 4),
                "ci95_high": round(hi, 4),
                "mean_length": round(float(np.mean(self.lengths)), 1) if self.lengths else 0.0}


def game_seed(seed: int, index: int) -> int:
    return int(np.random.SeedSequence([seed, index]).generate_state(1, np.uint64)[0])


def play_games(core: MatchSet, team: str, games: int, seed: int,
               act: Callable[[np.ndarray], np.ndarray] | None = None,
               result: EvalResult | None = None) -> EvalResult:
    """Play ``games`` games in ``core`` (its driven seats moved by ``act(obs)`` ->
    (E, L, 3) actions) and count them for ``team``."""
    if games <= 0:
        raise ValueError(f"games must be > 0, got {games}")
    res = result or EvalResult(name="", opponent="")
    E = core.num_envs
    quota = [games // E + (1 if e < games % E else 0) for e in range(E)]
    start = np.concatenate([[0], np.cumsum(quota)[:-1]]).astype(int)
    played = [0] * E
    extra = games  # seeds for envs that are done but must keep ticking
    seeds = []
    for e in range(E):
        if quota[e]:
            seeds.append(game_seed(seed, int(start[e])))
        else:
            seeds.append(game_seed(seed, extra))
            extra += 1
    obs = core.reset_all(seeds)
    L = len(core.driven)
    idle = np.ones((E, L, 3), dtype=np.int64)
    while min(p - q for p, q in zip(played, quota, strict=True)) < 0:
        actions = act(obs) if act is not None and L else idle
        _, obs = core.step(actions)
        for e, m in enumerate(core.matches):
            if not m.done:
                continue
            if played[e] < quota[e]:
                if m.winner is None:
                    res.draws += 1
                elif m.winner == team:
                    res.wins += 1
                else:
                    res.losses += 1
                res.lengths.append(int(m.tick))
                played[e] += 1
            if played[e] < quota[e]:
                core.reset_env(e, game_seed(seed, int(start[e]) + played[e]))
            else:
                core.reset_env(e, game_seed(seed, extra))
                extra += 1
        obs = core.obs.build()
    return res


def batched_actor(learners: dict[str, Any], groups: dict[str, list[int]], num_envs: int,
                  deterministic: bool, seed: int) -> Callable[[np.ndarray], np.ndarray]:
    """``act(obs (E, L, D)) -> (E, L, 3)``: each learner acts for its columns ``groups``."""
    rng = np.random.default_rng(seed)
    width = sum(len(cols) for cols in groups.values())
    out = np.ones((num_envs, width, 3), dtype=np.int64)

    def act(obs: np.ndarray) -> np.ndarray:
        for name, cols in groups.items():
            x = obs[:, cols].reshape(-1, obs.shape[-1])
            a = learners[name].policy_actions(x, deterministic, rng)
            out[:, cols] = a.reshape(num_envs, len(cols), 3)
        return out

    return act


def _label(seats: Sequence[Seat], algo_of: dict[int, str], idx: Sequence[int],
           agent: bool) -> str:
    """'PPO Agent', '2 PPO Agents', 'Smart Bot', '1 Defensive + 2 Smart Bots'."""
    kinds = Counter()
    for i in idx:
        s = seats[i]
        kinds[algo_of[i].upper() + " Agent" if i in algo_of else
              (s.bot or s.controller).capitalize() + (" Bot" if s.bot else "")] += 1
    if not kinds:
        return "nobody"
    if len(kinds) == 1:
        (name, k), = kinds.items()
        return name if k == 1 else f"{k} {name}s"
    noun = "Bots" if not agent else "Agents"
    parts = [f"{k} {name.rsplit(' ', 1)[0]}" for name, k in sorted(kinds.items())]
    return " + ".join(parts) + f" {noun}"


def evaluate_checkpoint(checkpoint: str | Path | Checkpoint, opponents: Sequence[str | None],
                        games: int = 100, seed: int = 0, scenario: str | Scenario | None = None,
                        team: str | None = None, deterministic: bool = False,
                        num_envs: int = 16, weakness: float | None = None
                        ) -> list[EvalResult]:
    """One :class:`EvalResult` per opponent for a saved checkpoint (see
    :func:`evaluate_learners`)."""
    ckpt = checkpoint if isinstance(checkpoint, Checkpoint) else load_checkpoint(checkpoint)
    tc = ckpt.train_config
    learners = {name: ckpt.load_learner(name, weights_only=True)
                for name in ckpt.learner_names()}
    return evaluate_learners(
        learners, ckpt.meta["observation"], {s.name: s.algo for s in ckpt.learner_specs},
        load_scenario(scenario) if scenario is not None else ckpt.scenario, opponents,
        games=games, seed=seed, team=team, deterministic=deterministic, num_envs=num_envs,
        weakness=weakness, game_overrides=tc.game, reward_overrides=tc.rewards,
        source=str(ckpt.path))


def evaluate_learners(learners: dict[str, Any], observation: dict[str, Any],
                      algos: dict[str, str], base: Scenario, opponents: Sequence[str | None],
                      games: int = 100, seed: int = 0, team: str | None = None,
                      deterministic: bool = False, num_envs: int = 16,
                      weakness: float | None = None, game_overrides: dict | None = None,
                      reward_overrides: dict | None = None, source: str = "learners"
                      ) -> list[EvalResult]:
    """One :class:`EvalResult` per opponent. The evaluated ``team`` (default: the team of
    the first learner seat) is played by ``learners`` (per seat as in training). Opponent
    ``None`` keeps the scenario's own opponents (other learner seats are played by their
    learners too); a bot name puts that bot, at ``weakness`` (default 1), in every seat
    outside the team."""
    seat_learner = {int(k): v for k, v in observation["seat_learner"].items()}
    first = next(iter(learners))
    if not base.learner_seats:
        raise ValueError(f"{base.source}: no learner seat for the learners to play")
    team = team or base.seats[base.learner_seats[0]].team
    if team not in base.teams:
        raise ValueError(f"team {team!r} not in scenario {base.name!r}; teams: "
                         f"{sorted(set(base.teams))}")
    results = []
    for opp in opponents:
        seats = []
        for s in base.seats:
            if s.team != team and opp is not None:
                seats.append(Seat(s.team, "bot", bot=opp,
                                  weakness=1.0 if weakness is None else weakness))
            elif s.team != team and s.controller == "bot" and weakness is not None:
                seats.append(Seat(s.team, "bot", bot=s.bot, weakness=weakness,
                                  options=s.options))
            else:
                seats.append(s)
        sc = dataclasses.replace(base, seats=tuple(seats))
        driven = [i for i, s in enumerate(seats) if s.controller == "learner"]
        n_env = max(1, min(num_envs, games))
        core = MatchSet(sc, n_env, observation=observation["kind"],
                        game_overrides=game_overrides, reward_overrides=reward_overrides,
                        driven=driven)
        if core.obs_dim != int(observation["obs_dim"]):
            raise ValueError(f"{source}: expects {observation['obs_dim']} observation "
                             f"features; scenario {sc.name!r} gives {core.obs_dim} "
                             f"(different map walls, tank count or observation kind)")
        groups: dict[str, list[int]] = {}
        for col, seat in enumerate(driven):
            groups.setdefault(seat_learner.get(seat, first), []).append(col)
        act = batched_actor(learners, groups, n_env, deterministic, seed)
        algo_of = {i: algos[seat_learner.get(i, first)] for i in driven}
        ours = [i for i, s in enumerate(seats) if s.team == team]
        theirs = [i for i, s in enumerate(seats) if s.team != team]
        res = EvalResult(name=f"{_label(seats, algo_of, ours, True)} vs "
                              f"{_label(seats, algo_of, theirs, False)}",
                         opponent=opp or core.describe_opponents(0))
        results.append(play_games(core, team, games, seed, act, res))
    return results


def evaluate_policies(scenario: str | Scenario, policies: dict[int, Policy], team: str,
                      games: int = 100, seed: int = 0, num_envs: int = 8,
                      name: str = "") -> EvalResult:
    """Count games of a scenario whose learner seats are filled by ``policies`` (any
    Policy: bots, checkpoints, ...); bot seats play as the scenario says."""
    sc = load_scenario(scenario)
    core = MatchSet(sc, max(1, min(num_envs, games)), driven=[], seat_policies=policies)
    res = EvalResult(name=name or sc.name, opponent=core.describe_opponents(0))
    return play_games(core, team, games, seed, None, res)


HEADER = ("Experiment Name", "Agent Wins", "Bot Wins", "Draws", "Agent Win Ratio",
          "Wilson 95% CI")


def format_table(results: Sequence[EvalResult]) -> str:
    """Markdown table in the paper's Table 3 layout (plus draws and Wilson interval)."""
    rows = []
    for r in results:
        lo, hi = r.interval
        rows.append((r.name, str(r.wins), str(r.losses), str(r.draws),
                     f"{100 * r.win_rate:.0f}%", f"[{100 * lo:.1f}%, {100 * hi:.1f}%]"))
    widths = [max(len(h), *(len(row[k]) for row in rows)) if rows else len(h)
              for k, h in enumerate(HEADER)]
    line = "| " + " | ".join(h.ljust(w) for h, w in zip(HEADER, widths, strict=True)) + " |"
    sep = "|" + "|".join("-" * (w + 2) for w in widths) + "|"
    body = ["| " + " | ".join(c.ljust(w) for c, w in zip(row, widths, strict=True)) + " |"
            for row in rows]
    return "\n".join([line, sep, *body])


def write_csv(results: Sequence[EvalResult], path: str | Path) -> None:
    rows = [r.as_dict() for r in results]
    with open(path, "w", newline="", encoding="utf-8") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]) if rows else list(HEADER))
        writer.writeheader()
        writer.writerows(rows)


def write_json(results: Sequence[EvalResult], path: str | Path) -> None:
    Path(path).write_text(json.dumps([r.as_dict() for r in results], indent=1) + "\n",
                          encoding="utf-8")

"""Evaluation: exact win/loss/draw counts with Wilson 95% intervals, in the layout of the
paper's Table 3, also as CSV and JSON, and an openskill table of the games.

Games run in a :class:`~alphatank.envs.core.MatchSet` (the engine under every env): the
checkpoint's learners drive their seats with batched inference over all matches, bots or
any other Policy fill the rest. Each env plays a fixed quota of games (never "the first N
to finish", which would favour short games). Game ``i`` depends only on ``(seed, i)``:
its match seed is :func:`game_seed` ``(seed, i)`` and a sampled policy draws its actions
from :func:`sampling_rng` ``(seed, i)`` (each env row of a batched forward pass takes its
noise from the generator of the game that env is playing), so counts and per-game
outcomes are the same whatever ``num_envs``.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import json
from collections import Counter
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from alphatank.envs.core import MatchSet
from alphatank.files import write_text_atomic
from alphatank.game.scenarios import Scenario, Seat, load_scenario, team_misfit
from alphatank.sim.config import MATCHES_MAX
from alphatank.stats import League, wilson_interval
from alphatank.training.checkpoint import Checkpoint, load_checkpoint
from alphatank.training.streams import GameStreams
from alphatank.training.teamstats import TeamWatch

SAMPLING_STREAM = 1  # third SeedSequence word of the policy's sampling generator
OUTCOME_SCORE = {"win": 1, "draw": 0, "loss": -1}
SELF_PLAY = "itself"  # the opponent of a row whose checkpoint drives every seat


@dataclass
class EvalResult:
    """Outcome counts of ``games`` games from the evaluated team's point of view.

    ``agent`` labels what was evaluated (the checkpoint as given); ``sides`` names what
    plays on each side ("Agent", "Bot" or "Opponent" for a mix), for column headers;
    ``outcomes`` and ``lengths`` are per game, in game-index order."""

    name: str
    opponent: str
    wins: int = 0
    losses: int = 0
    draws: int = 0
    lengths: list[int] = field(default_factory=list)
    agent: str = ""
    sides: tuple[str, str] = ("Agent", "Bot")
    outcomes: list[str] = field(default_factory=list)
    team_stats: dict[str, Any] | None = None  # evaluate_learners(team_stats=True)

    @property
    def games(self) -> int:
        return self.wins + self.losses + self.draws

    @property
    def win_rate(self) -> float:
        return self.wins / self.games if self.games else 0.0

    @property
    def interval(self) -> tuple[float, float]:
        return wilson_interval(self.wins, self.games)

    def as_dict(self, per_game: bool = False) -> dict[str, Any]:
        """One row of the CSV / JSON (``per_game``: with the outcome of every game)."""
        lo, hi = self.interval
        row = {"checkpoint": self.agent, "experiment": self.name, "opponent": self.opponent,
               "opponent_kind": self.sides[1].lower(), "games": self.games,
               "wins": self.wins, "losses": self.losses, "draws": self.draws,
               "win_rate": round(self.win_rate, 4), "ci95_low": round(lo, 4),
               "ci95_high": round(hi, 4),
               "mean_length": round(float(np.mean(self.lengths)), 1) if self.lengths else 0.0}
        if per_game:
            row["outcomes"] = list(self.outcomes)
        return row


def game_seed(seed: int, index: int) -> int:
    """Match seed of game ``index`` of an evaluation seeded ``seed`` (an integer >= 0)."""
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise ValueError(f"seed must be an integer >= 0, got {seed!r}")
    return int(np.random.SeedSequence([seed, index]).generate_state(1, np.uint64)[0])


def sampling_rng(seed: int, index: int) -> np.random.Generator:
    """The generator a sampled policy draws game ``index``'s actions from."""
    return np.random.default_rng([seed, index, SAMPLING_STREAM])


def play_games(core: MatchSet, team: str, games: int, seed: int,
               act: Callable[[np.ndarray, list[np.random.Generator]], np.ndarray] | None = None,
               result: EvalResult | None = None, watch: TeamWatch | None = None
               ) -> EvalResult:
    """Play ``games`` games in ``core`` (its driven seats moved by ``act(obs, gens)`` ->
    (E, L, 3) actions, ``gens[e]`` the sampling generator of env ``e``'s current game)
    and count them for ``team``; ``watch`` follows every tick and keeps each counted
    game's team statistics."""
    if games <= 0:
        raise ValueError(f"games must be > 0, got {games}")
    res = result or EvalResult(name="", opponent="")
    E = core.num_envs
    quota = [games // E + (1 if e < games % E else 0) for e in range(E)]
    start = np.concatenate([[0], np.cumsum(quota)[:-1]]).astype(int)
    played = [0] * E
    extra = games  # seeds for envs that are done but must keep ticking
    index = []  # game index each env plays now
    for e in range(E):
        if quota[e]:
            index.append(int(start[e]))
        else:
            index.append(extra)
            extra += 1
    gens = [sampling_rng(seed, i) for i in index]
    obs = core.reset_all([game_seed(seed, i) for i in index])
    if watch is not None:
        core.tick_watch = watch.tick
        for e in range(E):
            watch.start(e)
    L = len(core.driven)
    idle = np.ones((E, L, 3), dtype=np.int64)
    done: dict[int, tuple[str, int]] = {}
    while min(p - q for p, q in zip(played, quota, strict=True)) < 0:
        actions = act(obs, gens) if act is not None and L else idle
        _, obs = core.step(actions)
        for e, m in enumerate(core.matches):
            if not m.done:
                continue
            if played[e] < quota[e]:
                out = "draw" if m.winner is None else "win" if m.winner == team else "loss"
                done[index[e]] = (out, int(m.tick))
                played[e] += 1
                if watch is not None:
                    watch.end(index[e], e, out)
            if played[e] < quota[e]:
                index[e] = int(start[e]) + played[e]
            else:
                index[e] = extra
                extra += 1
            gens[e] = sampling_rng(seed, index[e])
            core.reset_env(e, game_seed(seed, index[e]))
            if watch is not None:
                watch.start(e)
        obs = core.obs.build()
    core.tick_watch = None
    for i in sorted(done):
        out, length = done[i]
        res.outcomes.append(out)
        res.lengths.append(length)
    counts = Counter(out for out, _ in done.values())
    res.wins += counts["win"]
    res.losses += counts["loss"]
    res.draws += counts["draw"]
    return res


def batched_actor(learners: dict[str, Any], groups: dict[str, list[int]], num_envs: int,
                  deterministic: bool
                  ) -> Callable[[np.ndarray, list[np.random.Generator]], np.ndarray]:
    """``act(obs (E, L, D), gens) -> (E, L, 3)``: each learner acts for its columns
    ``groups``, env ``e``'s rows sampled from ``gens[e]``."""
    width = sum(len(cols) for cols in groups.values())
    out = np.ones((num_envs, width, 3), dtype=np.int64)

    def act(obs: np.ndarray, gens: list[np.random.Generator]) -> np.ndarray:
        for name, cols in groups.items():
            x = obs[:, cols].reshape(-1, obs.shape[-1])
            a = learners[name].policy_actions(x, deterministic, GameStreams(gens, len(cols)))
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


def side_kind(seats: Sequence[Seat], idx: Sequence[int]) -> str:
    """What plays seats ``idx``: "Bot" (bots only), "Agent" (learners, checkpoints,
    shipped agents only) or "Opponent" (a mix, or anything else)."""
    kinds = {"Bot" if seats[i].controller == "bot" else
             "Agent" if seats[i].controller in ("learner", "checkpoint", "agent") else
             "Opponent" for i in idx}
    return kinds.pop() if len(kinds) == 1 else "Opponent"


def with_map(sc: Scenario, map_name: str | None) -> Scenario:
    """``sc`` played on ``map_name`` (a shipped map or folder such as ``test``, a .txt
    path or a folder of maps); None keeps its own. Map errors name ``--map``."""
    if map_name is None:
        return sc
    from alphatank.game.scenarios import parse_scenario

    return parse_scenario({**sc.to_dict(), "map": map_name}, f"{sc.source} (map {map_name!r})",
                          map_label="--map")


def evaluate_checkpoint(checkpoint: str | Path | Checkpoint, opponents: Sequence[str | None],
                        games: int = 100, seed: int = 0, scenario: str | Scenario | None = None,
                        team: str | None = None, deterministic: bool = False,
                        num_envs: int = 16, weakness: float | None = None,
                        map_name: str | None = None, label: str | None = None,
                        team_stats: bool = False, game: dict[str, Any] | None = None
                        ) -> list[EvalResult]:
    """One :class:`EvalResult` per opponent for a saved checkpoint (see
    :func:`evaluate_learners`), each labelled ``label`` (default: the checkpoint's path);
    ``map_name`` plays the scenario on other maps; ``game`` changes settings of the game
    the checkpoint trained in (e.g. ``{"random_spawns": False}``)."""
    ckpt = checkpoint if isinstance(checkpoint, Checkpoint) else load_checkpoint(checkpoint)
    tc = ckpt.train_config
    learners = {name: ckpt.load_learner(name, weights_only=True)
                for name in ckpt.learner_names()}
    base = load_scenario(scenario) if scenario is not None else ckpt.scenario
    results = evaluate_learners(
        learners, ckpt.meta["observation"], {s.name: s.algo for s in ckpt.learner_specs},
        with_map(base, map_name), opponents, games=games, seed=seed, team=team,
        deterministic=deterministic, num_envs=num_envs, weakness=weakness,
        game_overrides={**tc.game, **(game or {})}, reward_overrides=tc.rewards,
        source=str(ckpt.path),
        team_stats=team_stats, trained_as=ckpt.trained_as, trained_teams=ckpt.trained_teams)
    for r in results:
        r.agent = label if label is not None else str(checkpoint if not isinstance(
            checkpoint, Checkpoint) else checkpoint.path)
    return results


def evaluate_learners(learners: dict[str, Any], observation: dict[str, Any],
                      algos: dict[str, str], base: Scenario, opponents: Sequence[str | None],
                      games: int = 100, seed: int = 0, team: str | None = None,
                      deterministic: bool = False, num_envs: int = 16,
                      weakness: float | None = None, game_overrides: dict | None = None,
                      reward_overrides: dict | None = None, source: str = "learners",
                      team_stats: bool = False, trained_as: str = "",
                      trained_teams: Sequence[str] = ()) -> list[EvalResult]:
    """One :class:`EvalResult` per opponent. The evaluated ``team`` (default: the team of
    the first learner seat) is played by ``learners`` (per seat as in training). Opponent
    ``None`` keeps the scenario's own opponents (other learner seats are played by their
    learners too); a bot name puts that bot, at ``weakness`` (default 1), in every seat
    outside the team. Results do not depend on ``num_envs`` (module docstring).
    ``team_stats``: each result's ``team_stats`` holds the team's cooperation figures of
    the same games (:mod:`~alphatank.training.teamstats`). ``trained_as`` names what the
    learners were trained on, for the error when the scenario does not fit them;
    ``trained_teams`` (the team of each training seat) refuses seats in teams of other
    sizes."""
    seat_learner = {int(k): v for k, v in observation["seat_learner"].items()}
    first = next(iter(learners))
    team = learner_team(base, team)
    results = []
    for opp, opp_name in zip(opponents, row_opponents(base, opponents, team, weakness),
                             strict=True):
        seats = opponent_seats(base, team, opp, weakness)
        sc = dataclasses.replace(base, seats=tuple(seats))
        driven = [i for i, s in enumerate(seats) if s.controller == "learner"]
        n_env = max(1, min(num_envs, games, MATCHES_MAX))  # the games are the same
        room = tuple(int(observation[k]) for k in ("max_walls", "max_buffs", "max_debuffs"))
        core = MatchSet(sc, n_env, observation=observation["kind"],
                        game_overrides=game_overrides, reward_overrides=reward_overrides,
                        driven=driven, action_repeat=observation["action_repeat"],
                        slots=room)  # maps with fewer walls or zones: padded as trained
        if core.obs_dim != int(observation["obs_dim"]):
            raise ValueError(f"{source}: expects {observation['obs_dim']} observation "
                             f"features; scenario {sc.name!r} on map {sc.map!r} gives "
                             f"{core.obs_dim} ({observation_misfit(observation, core)})"
                             + (f"; it fits {trained_as}" if trained_as else ""))
        for seat in driven:
            misfit = team_misfit(trained_teams, seat_learner, sc.teams, seat)
            if misfit is not None:
                raise ValueError(f"{source}: scenario {sc.name!r}: {misfit}"
                                 + (f", in {trained_as}" if trained_as else ""))
        groups: dict[str, list[int]] = {}
        for col, seat in enumerate(driven):
            groups.setdefault(seat_learner.get(seat, first), []).append(col)
        act = batched_actor(learners, groups, n_env, deterministic)
        algo_of = {i: algos[seat_learner.get(i, first)] for i in driven}
        ours = [i for i, s in enumerate(seats) if s.team == team]
        theirs = [i for i, s in enumerate(seats) if s.team != team]
        res = EvalResult(name=f"{_label(seats, algo_of, ours, True)} vs "
                              f"{_label(seats, algo_of, theirs, False)}",
                         opponent=opp_name,
                         sides=("Agent", side_kind(seats, theirs)))
        watch = TeamWatch(team, n_env, list(sc.teams)) if team_stats else None
        results.append(play_games(core, team, games, seed, act, res, watch))
        if watch is not None:
            res.team_stats = watch.summary()
    return results


def observation_misfit(observation: dict[str, Any], core: MatchSet) -> str:
    """Why ``core``'s observations are not those of a policy trained with ``observation``
    (its meta): the tank count, or the walls or zones of the maps beyond its room."""
    from alphatank.game.observe import room_misfit, slot_counts

    tanks = int(observation["tanks"])
    why = [f"the match has {core.n} tanks; it trained with {tanks}"] if core.n != tanks else []
    room = [observation[k] for k in ("max_walls", "max_buffs", "max_debuffs")]
    why += room_misfit(observation["kind"], room, slot_counts(core.game, core.specs),
                       "its maps have up to")
    return "; ".join(why) or "its observation has another layout"


def learner_team(base: Scenario, team: str | None) -> str:
    """The evaluated team: ``team``, or that of the scenario's first learner seat; a team
    without a learner seat is refused (the learners would not play its games)."""
    if not base.learner_seats:
        raise ValueError(f"{base.source}: no learner seat for the learners to play")
    ours = list(dict.fromkeys(base.seats[i].team for i in base.learner_seats))
    team = team or ours[0]
    if team not in base.teams:
        raise ValueError(f"team {team!r} not in scenario {base.name!r}; teams: "
                         f"{sorted(set(base.teams))}")
    if team not in ours:
        raise ValueError(f"team {team!r}: scenario {base.name!r} has no learner seat on team "
                         f"{team} (learner teams: {', '.join(ours)})")
    return team


def row_opponents(base: Scenario, opponents: Sequence[str | None], team: str | None = None,
                  weakness: float | None = None, stand_in: bool = False) -> list[str]:
    """The ``opponent`` of each row :func:`evaluate_learners` (``stand_in``:
    :func:`evaluate_stand_in`) plays in ``base``, known before any game: a bot name, or
    for None the seats it does not drive (``stand_in``: the other teams' seats) such as
    ``B:smart(w=1)``; ``itself`` where it drives every seat (self-play)."""
    team = learner_team(base, team)
    seats = opponent_seats(base, team, None, weakness)
    own = ", ".join(f"{s.team}:{s.describe()}" for s in seats
                    if (s.team != team if stand_in else s.controller != "learner"))
    return [opp or own or SELF_PLAY for opp in opponents]


def opponent_seats(base: Scenario, team: str, opp: str | None,
                   weakness: float | None) -> list[Seat]:
    """``base``'s seats with bot ``opp`` (at ``weakness``, default 1) in every seat
    outside ``team``; ``opp`` None keeps the scenario's opponents (their bots at
    ``weakness`` when given)."""
    seats = []
    for s in base.seats:
        if s.team != team and opp is not None:
            seats.append(Seat(s.team, "bot", bot=opp,
                              weakness=1.0 if weakness is None else weakness))
        elif s.team != team and s.controller == "bot" and weakness is not None:
            seats.append(Seat(s.team, "bot", bot=s.bot, weakness=weakness, options=s.options))
        else:
            seats.append(s)
    return seats


def evaluate_stand_in(bot: str, scenario: str | Scenario, opponents: Sequence[str | None],
                      games: int = 100, seed: int = 0, team: str | None = None,
                      num_envs: int = 16, weakness: float | None = None,
                      map_name: str | None = None, label: str | None = None,
                      team_stats: bool = False, game: dict[str, Any] | None = None
                      ) -> list[EvalResult]:
    """Bot parity: :func:`evaluate_learners`'s games (same seeds, same opponents) with a
    bot (a seat spec such as ``smart`` or ``smart@0.5``) in every learner seat of
    ``team``, so an agent's win rate (and, with ``team_stats``, its cooperation figures)
    can be set beside a rule-based player's; ``game`` overrides the scenario's game."""
    from alphatank.game.lineup import spec_seat

    base = with_map(load_scenario(scenario), map_name)
    team = learner_team(base, team)
    stand = spec_seat(bot, team, where=f"bot:{bot}")
    results = []
    for opp, opp_name in zip(opponents, row_opponents(base, opponents, team, weakness, True),
                             strict=True):
        seats = opponent_seats(base, team, opp, weakness)
        played = [stand if s.team == team and s.controller == "learner" else s for s in seats]
        sc = dataclasses.replace(base, seats=tuple(played))
        n_env = max(1, min(num_envs, games, MATCHES_MAX))  # the games are the same
        core = MatchSet(sc, n_env, driven=[], game_overrides=game)
        ours = [i for i, s in enumerate(played) if s.team == team]
        theirs = [i for i, s in enumerate(played) if s.team != team]
        res = EvalResult(name=f"{_label(played, {}, ours, True)} vs "
                              f"{_label(played, {}, theirs, False)}",
                         opponent=opp_name,
                         sides=(side_kind(played, ours), side_kind(played, theirs)),
                         agent=label or f"bot:{bot}")
        watch = TeamWatch(team, n_env, list(sc.teams)) if team_stats else None
        results.append(play_games(core, team, games, seed, None, res, watch))
        if watch is not None:
            res.team_stats = watch.summary()
    return results


def header(results: Sequence[EvalResult]) -> tuple[str, ...]:
    """Column names by what plays: "Agent Wins" / "Bot Wins" as in the paper when every
    row is agents against bots, "Opponent Wins" when some opponent is not a bot; a
    "Checkpoint" column first when rows are labelled."""
    ours = {r.sides[0] for r in results}
    theirs = {r.sides[1] for r in results}
    us = ours.pop() if len(ours) == 1 else "Evaluated"
    them = theirs.pop() if len(theirs) == 1 and theirs != {us} else "Opponent"
    cols = ("Experiment Name", f"{us} Wins", f"{them} Wins", "Draws", f"{us} Win Ratio",
            "Wilson 95% CI")
    return (("Checkpoint",) + cols) if any(r.agent for r in results) else cols


def format_table(results: Sequence[EvalResult]) -> str:
    """Markdown table in the paper's Table 3 layout (plus draws and Wilson interval), each
    row labelled with its checkpoint."""
    head = header(results)
    rows = []
    for r in results:
        lo, hi = r.interval
        row = (r.name, str(r.wins), str(r.losses), str(r.draws),
               win_ratio_text(r.wins, r.games), f"[{100 * lo:.1f}%, {100 * hi:.1f}%]")
        rows.append(((r.agent,) + row) if head[0] == "Checkpoint" else row)
    return markdown_table(head, rows)


def win_ratio_text(wins: int, games: int) -> str:
    """``wins / games`` in whole percent as in the paper's Table 3, with as many decimals
    as it takes never to read 0% with a win or 100% short of all wins (1 of 200:
    ``0.5%``, 199 of 200: ``99.5%``, not ``0%`` and ``100%``)."""
    if not games:
        return "0%"
    digits = 0
    while True:
        text = f"{100 * wins / games:.{digits}f}"
        if not (float(text) == 0 < wins or float(text) == 100 and wins < games):
            return f"{text}%"
        digits += 1


def markdown_table(head: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    """A Markdown table with aligned columns."""
    widths = [max(len(h), *(len(row[k]) for row in rows)) if rows else len(h)
              for k, h in enumerate(head)]
    line = "| " + " | ".join(h.ljust(w) for h, w in zip(head, widths, strict=True)) + " |"
    sep = "|" + "|".join("-" * (w + 2) for w in widths) + "|"
    body = ["| " + " | ".join(c.ljust(w) for c, w in zip(row, widths, strict=True)) + " |"
            for row in rows]
    return "\n".join([line, sep, *body])


def rate_games(games: Iterable[tuple[str, str, Sequence[str]]]) -> League:
    """An openskill (Plackett-Luce) league from ``(player, opponent, outcomes)`` triples
    (``outcomes``: 'win' / 'loss' / 'draw' of ``player``; draws are ties). Agents and bots
    share one table. Game k of every triple makes rating period k
    (:meth:`~alphatank.stats.League.record_period`), so the table does not depend on the
    order of the triples: identical results, identical ratings."""
    league = League([])
    index: dict[str, int] = {}
    rows = []
    for player, opponent, outcomes in games:
        for name in (player, opponent):
            if name not in index:
                index[name] = league.add(name)
        rows.append((index[player], index[opponent], list(outcomes)))
    for k in range(max((len(outs) for *_, outs in rows), default=0)):
        league.record_period([(i, j, OUTCOME_SCORE[outs[k]]) for i, j, outs in rows
                              if k < len(outs)])
    return league


def rating_table(league: League) -> str:
    """The league as a Markdown table, best ordinal (mu - 3 sigma) first."""
    return markdown_table(("Player", "mu", "sigma", "ordinal"),
                          [(n, f"{mu:.2f}", f"{sg:.2f}", f"{o:.2f}")
                           for n, mu, sg, o in league.table()])


def results_league(results: Sequence[EvalResult]) -> League:
    """The openskill league of an evaluation: each row's checkpoint (or experiment name)
    against its opponent, game by game. Self-play rows (opponent ``itself``) are left
    out: a player against itself says nothing of its skill."""
    return rate_games((r.agent or r.name, r.opponent, r.outcomes) for r in results
                      if r.opponent != SELF_PLAY)


def write_csv(results: Sequence[EvalResult], path: str | Path) -> None:
    rows = [r.as_dict() for r in results]
    fields = list(rows[0]) if rows else list(EvalResult("", "").as_dict())
    text = io.StringIO(newline="")
    writer = csv.DictWriter(text, fieldnames=fields)
    writer.writeheader()
    writer.writerows(rows)
    write_text_atomic(path, text.getvalue(), newline="")


def write_json(results: Sequence[EvalResult], path: str | Path, per_game: bool = False
               ) -> None:
    write_text_atomic(path, json.dumps([r.as_dict(per_game) for r in results], indent=1) + "\n")

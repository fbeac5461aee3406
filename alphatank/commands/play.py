"""``alphatank play``: interactive matches in a window at a steady frame rate.

Seats come from a scenario (``--scenario``) or a seat list (``--map`` + ``--seats``):
humans on one keyboard (player 1 WASD + F, player 2 arrows + Space, player 3 IJKL + P),
any bot, or a trained checkpoint. Keys: R new match, P or Esc pause (Esc only when a
player uses IJKL + P), V/T/B toggle aim line / bullet trajectory / BFS path, Q quits
from the pause or end screen. This module also holds the seat-list parser and the
line-up builder that ``alphatank record`` uses.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from alphatank.commands.argtypes import positive_float, positive_int, seed
from alphatank.game.scenarios import Scenario, ScenarioError, load_scenario, parse_scenario
from alphatank.sim.match import Match
from alphatank.sim.policy import Policy
from alphatank.ui.human import HUMAN_ORDER, LAYOUTS, KeyboardPolicy
from alphatank.ui.render import (
    DEFAULT_OVERLAYS,
    DIM_TEXT,
    TEXT,
    DisplayUnavailable,
    Renderer,
    open_window,
    parse_overlays,
    plural,
    team_color,
)
from alphatank.ui.replay import ReplayRecorder, save_replay

NO_DISPLAY_HELP = ("no display available for an interactive window{why}. Run `alphatank play` "
                   "on a desktop session (set DISPLAY or WAYLAND_DISPLAY and unset "
                   "SDL_VIDEODRIVER=dummy), or play headless and get a video with "
                   "`alphatank record` instead.")
SEAT_HELP = ("comma-separated seats, each [TEAM=]KIND[:ARG][@WEAKNESS]: human[:wasd|arrows|"
             "ijkl], bot:NAME (or just NAME), learner, checkpoint:PATH; without TEAM= seat k "
             "gets its own team A, B, C, ... e.g. 'A=human:wasd,B=bot:smart' or "
             "'A=human,A=smart,B=human:arrows,B=aggressive'")


# ---- seats and line-ups ----------------------------------------------------------------

def parse_seats(text: str, map_name: str, game: dict[str, Any] | None = None) -> Scenario:
    """A Scenario from ``--map`` and a ``--seats`` list (errors name the seat and the
    allowed values)."""
    from alphatank.bots import BOT_NAMES

    items = [s.strip() for s in text.split(",") if s.strip()]
    if len(items) < 2:
        raise ScenarioError(f"--seats needs at least 2 seats, got {text!r}; {SEAT_HELP}")
    seats, humans = [], 0
    for k, item in enumerate(items):
        team, _, body = item.rpartition("=")
        team = team.strip() or chr(ord("A") + k)
        body, _, weak = body.partition("@")
        kind, _, arg = body.partition(":")
        kind, arg = kind.strip(), arg.strip()
        seat: dict[str, Any] = {"team": team}
        if kind in BOT_NAMES:
            kind, arg = "bot", kind
        where = f"--seats[{k}] {item!r}"  # seats count from 0, as in scenarios and envs
        if kind == "human":
            seat.update(controller="human", keys=arg or HUMAN_ORDER[min(humans, 2)])
            humans += 1
        elif kind == "bot":
            if not arg:
                raise ScenarioError(f"{where}: bot needs a name, e.g. bot:smart; "
                                    f"valid bots: {list(BOT_NAMES)}")
            seat.update(controller="bot", bot=arg)
            if weak:
                try:
                    seat["weakness"] = float(weak)
                except ValueError:
                    raise ScenarioError(f"{where}: weakness must be a number in [0, 1], "
                                        f"got {weak!r}") from None
        elif kind == "learner":
            seat["controller"] = "learner"
        elif kind == "checkpoint":
            seat.update(controller="checkpoint", path=arg)
        else:
            raise ScenarioError(f"{where}: unknown seat kind {kind!r}; valid: human, bot, "
                                f"learner, checkpoint or a bot name {list(BOT_NAMES)}")
        if weak and kind != "bot":
            raise ScenarioError(f"{where}: @weakness only applies to bots")
        seats.append(seat)
    data = {"name": "custom", "map": map_name, "seats": seats, "game": dict(game or {})}
    return parse_scenario(data, source="--seats")


@dataclass
class Lineup:
    """The controllers of a scenario's seats for one session (``scenario`` is None for a
    replay's playback line-up)."""

    scenario: Scenario | None
    policies: list[Policy]
    labels: list[str]  # drawn over the tanks
    seats: list[str]  # descriptions for summaries and replays
    keyboards: list[KeyboardPolicy] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


def build_lineup(sc: Scenario, checkpoint: str | None = None, stand_in: str = "smart",
                 humans: bool = True) -> Lineup:
    """Controllers for every seat: keyboards for humans (or ``stand_in`` bots when
    ``humans`` is False), bots, checkpoints; learner seats get ``checkpoint`` if given,
    else a ``stand_in`` bot."""
    from alphatank.bots import make_bot

    policies: list[Policy] = []
    labels, descs, keyboards, notes = [], [], [], []
    loaded: dict[str, Policy] = {}

    def load(path: str) -> Policy:
        if path not in loaded:
            from alphatank.training.checkpoint import load_policy
            loaded[path] = load_policy(path)
        return loaded[path]

    for i, seat in enumerate(sc.seats):
        desc = seat.describe()
        if seat.controller == "human" and humans:
            kb = KeyboardPolicy(seat.keys or "wasd")
            if any(k.keys == kb.keys for k in keyboards):
                raise ScenarioError(f"{sc.source}: seats[{i}]: two human seats use the "
                                    f"{kb.keys!r} keys; give each player its own set "
                                    f"{list(LAYOUTS)}")
            keyboards.append(kb)
            policies.append(kb)
            labels.append(f"P{HUMAN_ORDER.index(kb.keys) + 1}")
        elif seat.controller == "bot":
            policies.append(make_bot(seat.bot, weakness=seat.weakness, **seat.options))
            labels.append(seat.bot or "bot")
        elif seat.controller == "checkpoint":
            policies.append(load(str(seat.path)))
            labels.append("agent")
        elif seat.controller == "learner" and checkpoint:
            policies.append(load(checkpoint))
            labels.append("agent")
            desc = f"checkpoint:{checkpoint}"
        else:
            policies.append(make_bot(stand_in))
            labels.append(stand_in)
            notes.append(f"seat {i} ({desc}) is played by the {stand_in!r} bot")
            desc = f"{stand_in}(for {desc})"
        descs.append(desc)
    return Lineup(sc, policies, labels, descs, keyboards, notes)


def lineup_from_args(args: argparse.Namespace, humans: bool = True) -> Lineup:
    """The line-up a ``play``/``record`` command line asks for."""
    game = {"max_steps": args.max_steps} if getattr(args, "max_steps", None) is not None else {}
    if args.scenario and args.seats:
        raise ScenarioError("give either --scenario or --seats, not both")
    if args.scenario:
        sc = load_scenario(args.scenario)
        if game:
            sc = parse_scenario({**sc.to_dict(), "game": {**sc.game, **game}},
                                source=sc.source)
    else:
        seats = args.seats or "human:wasd,bot:smart"
        n = len([s for s in seats.split(",") if s.strip()])
        default_map = "battlefield" if n <= 2 else "arena4" if n <= 4 else "arena8"
        sc = parse_seats(seats, args.map or default_map, game)
    return build_lineup(sc, args.checkpoint, args.stand_in, humans)


def start_episode(lineup: Lineup, seed: int) -> tuple[Match, int]:
    """A new match of the line-up's scenario, seeded like the envs do
    (``SeedSequence(seed)`` -> map choice, match seed, one seed per seat); resets every
    controller. Returns the match and its match seed."""
    sc = lineup.scenario
    if sc is None:
        raise ValueError("this line-up has no scenario to start episodes from")
    specs = sc.map_specs()
    s_map, s_match, s_seats = np.random.SeedSequence(seed).spawn(3)
    k = int(np.random.default_rng(s_map).integers(len(specs))) if len(specs) > 1 else 0
    match_seed = int(s_match.generate_state(1, np.uint64)[0])
    seat_seeds = [int(x) for x in s_seats.generate_state(len(sc.seats), np.uint64)]
    match = Match(sc.game_config(), specs[k], sc.teams, seed=match_seed)
    for seat, pol in enumerate(lineup.policies):
        pol.reset(match, seat, seat_seeds[seat])
    return match, match_seed


def summary_lines(match: Match, lineup_labels: Sequence[str], shots: np.ndarray
                  ) -> list[tuple[str, tuple[int, int, int]]]:
    """One line per seat: label, team, hits, shots, alive."""
    out = []
    for i in range(match.n):
        state = "alive" if match.alive[i] else "destroyed"
        out.append((f"seat {i}: {lineup_labels[i]} (team {match.teams[i]}): "
                    f"{plural(int(match.score[i]), 'hit')}, {plural(int(shots[i]), 'shot')}, "
                    f"{state}", team_color(int(match.team_index[i]))))
    return out


def result_title(match: Match) -> str:
    if match.winner is not None:
        return f"Team {match.winner} wins"
    return "Draw" if match.terminated or match.truncated else "Unfinished"


# ---- the interactive loop --------------------------------------------------------------

@dataclass
class EpisodeResult:
    seed: int
    ticks: int
    winner: str | None
    done: bool
    hits: list[int]
    replay: Path | None = None


@dataclass
class PlayReport:
    frames: int
    seconds: float  # from the first frame shown to the last
    episodes: list[EpisodeResult]

    @property
    def fps(self) -> float:
        """Steady frame rate: frames shown per second after the first."""
        return (self.frames - 1) / self.seconds if self.seconds > 0 else 0.0


class PlaySession:
    """One window, one line-up, episodes one after the other."""

    def __init__(self, lineup: Lineup, *, seed: int = 0, fps: float = 60.0,
                 overlays: Iterable[str] | str = DEFAULT_OVERLAYS, scale: float | None = None,
                 save_replay: str | Path | None = None, realtime: bool = True,
                 verbose: bool = True,
                 new_match: Callable[[int], tuple[Match, int]] | None = None,
                 tick_limit: int | None = None):
        """``new_match(seed) -> (match, match_seed)`` replaces :func:`start_episode`
        (replay playback); ``tick_limit`` ends an episode after that many ticks."""
        if not fps > 0:
            raise ValueError(f"--fps must be > 0, got {fps}")
        self.lineup, self.fps, self.realtime, self.verbose = lineup, fps, realtime, verbose
        self.new_match = new_match or (lambda s: start_episode(lineup, s))
        self.tick_limit = tick_limit
        self.save_path = Path(save_replay) if save_replay else None
        self.renderer = Renderer(None, overlays=overlays, labels=lineup.labels, fps=fps)
        self.renderer.banner = False  # the end screen shows the full summary instead
        self._scale = scale
        # P pauses unless a player fires with it (IJKL + P); Esc always pauses.
        self.pause_keys = {"escape"} | ({"p"} if not any(k.keys == "ijkl"
                                                         for k in lineup.keyboards) else set())
        self.episodes: list[EpisodeResult] = []
        self.paused = False
        self.running = True
        self._acc = 0.0
        self.start_new(seed)

    # -- episodes --

    def start_new(self, seed: int) -> None:
        self.seed = seed
        self.match, match_seed = self.new_match(seed)
        sc = self.lineup.scenario
        self.recorder = ReplayRecorder(
            self.match, match_seed=match_seed, seed=seed, scenario=sc.name if sc else None,
            seats=self.lineup.seats, labels=self.lineup.labels,
            policies=self.lineup.policies)
        self.actions = np.ones((self.match.n, 3), dtype=np.int64)
        self.shots = np.zeros(self.match.n, dtype=np.int64)
        self.finished = False
        self.paused = False
        self._acc = 0.0

    def end_episode(self) -> None:
        """Record the current episode's result (and replay) once."""
        m = self.match
        if self.finished or m.tick == 0:
            return
        self.finished = True
        path = None
        if self.save_path is not None:
            k = len(self.episodes) + 1
            path = self.save_path if k == 1 else self.save_path.with_name(
                f"{self.save_path.stem}-{k}{self.save_path.suffix}")
            save_replay(self.recorder.finish(), path)
        res = EpisodeResult(self.seed, m.tick, m.winner, m.done, m.score.tolist(), path)
        self.episodes.append(res)
        if self.verbose:
            print(f"match {len(self.episodes)} (seed {self.seed}): {result_title(m)} after "
                  f"{m.tick} ticks ({m.tick / m.cfg.tick_hz:.1f}s)")
            for line, _ in summary_lines(m, self.lineup.labels, self.shots):
                print(f"   {line}")
            if path is not None:
                print(f"   replay saved: {path}  (alphatank replay {path})")

    def tick(self) -> None:
        m, acts = self.match, self.actions
        for seat in np.flatnonzero(m.alive):
            acts[seat] = self.lineup.policies[seat].act(m, int(seat))
        self.recorder.record(acts)
        ev = m.step(acts)
        for f in ev.fired:
            self.shots[f.tank] += 1
        if self.over:
            self.end_episode()

    @property
    def over(self) -> bool:
        """The episode has ended (or reached ``tick_limit``)."""
        m = self.match
        return m.done or (self.tick_limit is not None and m.tick >= self.tick_limit)

    # -- input --

    def handle(self, event: Any) -> None:
        import pygame

        if event.type == pygame.QUIT:
            self.running = False
            return
        used = False
        for kb in self.lineup.keyboards:
            used |= kb.handle_event(event)
        if event.type != pygame.KEYDOWN or used:
            return
        name = pygame.key.name(event.key)
        if name in self.pause_keys:
            if self.over and name == "escape":
                self.running = False
            elif not self.over:
                self.paused = not self.paused
        elif event.key == pygame.K_r:
            self.end_episode()
            self.start_new(self.seed + 1)
        elif event.key == pygame.K_q and (self.paused or self.over):
            self.running = False
        else:
            self.renderer.handle_key(event.key)

    # -- frames --

    def update(self) -> None:
        """Advance the game by this frame's share of ticks (tick_hz / fps per frame)."""
        if self.paused or self.over:
            return
        self._acc += self.match.cfg.tick_hz / self.fps
        while self._acc >= 1.0 and not self.over:
            self._acc -= 1.0
            self.tick()

    def draw(self) -> Any:
        r, m = self.renderer, self.match
        surf = r.draw(m, self.lineup.policies)
        if self.paused:
            keys = [f"P{HUMAN_ORDER.index(kb.keys) + 1}: {kb.layout.describe()}"
                    for kb in self.lineup.keyboards]
            pause = "P/Esc" if "p" in self.pause_keys else "Esc"
            r.panel(surf, [*((k, TEXT) for k in keys),
                           ("V aim line   T trajectory   B BFS path", DIM_TEXT)],
                    title=("PAUSED", TEXT),
                    footer=(f"{pause} resume   R new match   Q quit", DIM_TEXT))
        elif self.over:
            title_col = (team_color(m.team_names.index(m.winner)) if m.winner is not None
                         else TEXT)
            r.panel(surf, summary_lines(m, self.lineup.labels, self.shots),
                    title=(result_title(m), title_col),
                    footer=("R play again   Esc/Q quit", DIM_TEXT), align="left")
        return surf

    def run(self, max_frames: int | None = None,
            event_source: Callable[[int], Iterable[Any]] | None = None,
            caption: str = "AlphaTank") -> PlayReport:
        """The frame loop: events, ticks due, draw, flip, hold ``fps``. ``event_source(k)``
        returns events to post into pygame's queue before frame k (scripted input)."""
        import pygame

        spec = self.match.spec
        try:
            pygame.display.init()
        except pygame.error as exc:
            raise DisplayUnavailable(str(exc)) from exc
        scale = self._scale
        if scale is None:
            info = pygame.display.Info()
            fit = 0.92 * min(info.current_w / spec.width, info.current_h / spec.height)
            scale = min(1.0, fit) if info.current_w > 0 and info.current_h > 0 else 1.0
        size = (round(spec.width * scale), round(spec.height * scale))
        screen = open_window(size, caption)
        frames, first, last = 0, 0.0, 0.0
        base, base_frame = 0.0, 0  # frame k is due at base + (k - base_frame) / fps
        try:
            while self.running and (max_frames is None or frames < max_frames):
                if event_source is not None:
                    for ev in event_source(frames):
                        pygame.event.post(ev)
                for ev in pygame.event.get():
                    self.handle(ev)
                if not self.running:
                    break
                self.update()
                surf = self.draw()
                if surf.get_size() != size:
                    pygame.transform.smoothscale(surf, size, screen)
                else:
                    screen.blit(surf, (0, 0))
                pygame.display.flip()
                last = time.perf_counter()
                if not first:
                    first = base = last
                frames += 1
                if self.realtime:  # catch up after a slow frame; resync after a stall
                    delay = base + (frames - base_frame) / self.fps - last
                    if delay > 0:
                        time.sleep(delay)
                    elif delay < -0.25:
                        base, base_frame = last, frames - 1
        finally:
            self.end_episode()
            pygame.display.quit()
        return PlayReport(frames, last - first, self.episodes)


# ---- command line ----------------------------------------------------------------------

def add_lineup_arguments(p: argparse.ArgumentParser) -> None:
    """Options shared by ``play`` and ``record``."""
    p.add_argument("--scenario", help="scenario name or .toml path (e.g. mixed_teams)")
    p.add_argument("--map", help="map for --seats (default: battlefield for 2 seats, "
                                 "arena4 up to 4, arena8 up to 8)")
    p.add_argument("--seats", help=SEAT_HELP)
    p.add_argument("--checkpoint", help="checkpoint that plays the scenario's learner seats")
    p.add_argument("--stand-in", default="smart",
                   help="bot for learner seats when no --checkpoint is given (default: smart)")
    p.add_argument("--seed", type=seed, default=0, help="episode seed (default: 0)")
    p.add_argument("--max-steps", type=int, help="episode length limit in ticks")
    p.add_argument("--overlays", default=",".join(DEFAULT_OVERLAYS),
                   help="aim,trajectory,bfs | all | none (default: aim,bfs)")


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_lineup_arguments(p)
    p.add_argument("--fps", type=positive_float, default=60.0,
                   help="frames per second (default: 60)")
    p.add_argument("--scale", type=positive_float, help="window scale (default: fit the screen)")
    p.add_argument("--save-replay", metavar="FILE",
                   help="save each match as a replay (FILE, FILE-2, ...)")
    p.add_argument("--headless-test", action="store_true",
                   help="allow SDL_VIDEODRIVER=dummy (automated tests only)")
    p.add_argument("--max-frames", type=positive_int, help="stop after this many frames")


def run(args: argparse.Namespace) -> int:
    if os.environ.get("SDL_VIDEODRIVER") == "dummy" and not args.headless_test:
        print("alphatank play: " + NO_DISPLAY_HELP.format(why=" (SDL_VIDEODRIVER=dummy)"),
              file=sys.stderr)
        return 2
    try:
        lineup = lineup_from_args(args)
        session = PlaySession(lineup, seed=args.seed, fps=args.fps,
                              overlays=parse_overlays(args.overlays), scale=args.scale,
                              save_replay=args.save_replay)
    except (ScenarioError, ValueError, FileNotFoundError) as exc:
        print(f"alphatank play: {exc}", file=sys.stderr)
        return 2
    for note in lineup.notes:
        print(f"note: {note}")
    for kb in lineup.keyboards:
        print(f"player {HUMAN_ORDER.index(kb.keys) + 1} ({kb.keys}): {kb.layout.describe()}")
    try:
        report = session.run(max_frames=args.max_frames)
    except DisplayUnavailable as exc:
        print("alphatank play: " + NO_DISPLAY_HELP.format(why=f" ({exc})"),
              file=sys.stderr)
        return 2
    wins: dict[str, int] = {}
    for ep in report.episodes:
        key = ep.winner or "draw"
        wins[key] = wins.get(key, 0) + 1
    print(f"{len(report.episodes)} match(es), results {wins}; "
          f"{report.frames} frames at {report.fps:.1f} fps")
    return 0


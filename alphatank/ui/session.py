"""The interactive play session: one window, one line-up, episodes one after the other.

``alphatank play`` and ``alphatank replay --render`` run a :class:`PlaySession`: each
frame it handles keys (players' keyboards, pause, new match, overlays), advances the game
by the frame's share of ticks through the episode loop (:mod:`alphatank.sim.episode`),
and draws the match (with a pause panel or the end-of-match summary).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from alphatank.game.lineup import Lineup
from alphatank.sim.episode import Episode, EpisodeHook
from alphatank.sim.match import Match
from alphatank.ui.human import HUMAN_ORDER, KeyboardPolicy
from alphatank.ui.render import (
    DEFAULT_OVERLAYS,
    DIM_TEXT,
    TEXT,
    Renderer,
    init_display,
    open_window,
    plural,
    team_color,
)
from alphatank.ui.replay import ReplayRecorder

# The verb's one line when no window can show: format with the verb, why, and what to do
# instead (headless).
NO_DISPLAY_HELP = ("no display available for an interactive window{why}. Run `alphatank {verb}` "
                   "on a desktop session (set DISPLAY or WAYLAND_DISPLAY and unset "
                   "SDL_VIDEODRIVER=dummy), or {instead} instead.")


def summary_lines(match: Match, lineup_labels: Sequence[str], shots: np.ndarray
                  ) -> list[tuple[str, tuple[int, int, int]]]:
    """One line per seat (numbered from 0, as in scenarios and envs): label, team, hits,
    shots, alive."""
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


class PlaySession(EpisodeHook):
    """One window, one line-up, episodes one after the other (the session is a hook of
    each episode: it notes the result when the episode ends)."""

    def __init__(self, lineup: Lineup | None = None, *, seed: int = 0, fps: float = 60.0,
                 overlays: Iterable[str] | str = DEFAULT_OVERLAYS, scale: float | None = None,
                 save_replay: str | Path | None = None, realtime: bool = True,
                 verbose: bool = True,
                 new_episode: Callable[[int, Sequence[EpisodeHook]], Episode] | None = None,
                 labels: Sequence[str] | None = None):
        """Episodes come from ``lineup.start(seed, hooks)``, or from ``new_episode(seed,
        hooks)`` (replay playback; ``labels`` name the tanks)."""
        if not fps > 0:
            raise ValueError(f"--fps must be > 0, got {fps}")
        if new_episode is None:
            if lineup is None:
                raise ValueError("a PlaySession needs a lineup or new_episode")
            new_episode = lineup.start
        self.lineup, self.fps, self.realtime, self.verbose = lineup, fps, realtime, verbose
        self.new_episode = new_episode
        self.labels = list(labels if labels is not None else lineup.labels if lineup else [])
        self.save_path = Path(save_replay) if save_replay else None
        self.renderer = Renderer(None, overlays=overlays, labels=self.labels or None, fps=fps)
        self.renderer.banner = False  # the end screen shows the full summary instead
        self._scale = scale
        self.keyboards = [c for c in (lineup.controllers if lineup else [])
                          if isinstance(c, KeyboardPolicy)]
        # P pauses unless a player fires with it (IJKL + P); Esc always pauses.
        self.pause_keys = {"escape"} | ({"p"} if not any(k.keys == "ijkl"
                                                         for k in self.keyboards) else set())
        self.episodes: list[EpisodeResult] = []
        self.paused = False
        self.running = True
        self._acc = 0.0
        self.start_new(seed)

    # -- episodes --

    def _replay_path(self) -> Path | None:
        """Match 1's replay goes to ``save_path`` (FILE), match k's to the first of FILE-k,
        FILE-(k+1), ... that does not exist: files the user did not name are never
        overwritten."""
        if self.save_path is None or not self.episodes:
            return self.save_path
        p, k = self.save_path, len(self.episodes) + 1
        while (path := p.with_name(f"{p.stem}-{k}{p.suffix}")).exists():
            k += 1
        return path

    def start_new(self, seed: int) -> None:
        self.seed = seed
        hooks: list[EpisodeHook] = []
        path = self._replay_path()
        if path is not None:
            lu = self.lineup
            hooks.append(ReplayRecorder(  # without a lineup: the episode's controllers
                scenario=lu.scenario.name if lu else None, seats=lu.seats if lu else (),
                labels=self.labels, path=path, policies=lu.controllers if lu else None))
        self.replay_path = path
        self.episode = self.new_episode(seed, [*hooks, self])
        self.match = self.episode.match
        self.paused = False
        self._acc = 0.0

    @property
    def shots(self) -> np.ndarray:
        return self.episode.shots

    def end_episode(self) -> None:
        """End the current episode (result noted, replay saved) unless it never ticked."""
        if self.match.tick > 0:
            self.episode.end()

    def on_end(self, episode: Episode) -> None:
        m = episode.match
        res = EpisodeResult(self.seed, m.tick, m.winner, m.done, m.score.tolist(),
                            self.replay_path)
        self.episodes.append(res)
        if self.verbose:
            print(f"match {len(self.episodes)} (seed {self.seed}): {result_title(m)} after "
                  f"{m.tick} ticks ({m.tick / m.cfg.tick_hz:.1f}s)")
            for line, _ in summary_lines(m, self.labels, episode.shots):
                print(f"   {line}")
            if self.replay_path is not None:
                print(f"   replay saved: {self.replay_path}  "
                      f"(alphatank replay {self.replay_path})")

    def tick(self) -> None:
        self.episode.tick()

    @property
    def over(self) -> bool:
        """The episode has ended (or reached its tick limit)."""
        return self.episode.over

    # -- input --

    def handle(self, event: Any) -> None:
        import pygame

        if event.type == pygame.QUIT:
            self.running = False
            return
        used = False
        for kb in self.keyboards:
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
        surf = r.draw(m, self.episode.controllers)
        if self.paused:
            keys = [f"P{HUMAN_ORDER.index(kb.keys) + 1}: {kb.layout.describe()}"
                    for kb in self.keyboards]
            pause = "P/Esc" if "p" in self.pause_keys else "Esc"
            r.panel(surf, [*((k, TEXT) for k in keys),
                           ("V aim line   T trajectory   B BFS path", DIM_TEXT)],
                    title=("PAUSED", TEXT),
                    footer=(f"{pause} resume   R new match   Q quit", DIM_TEXT))
        elif self.over:
            title_col = (team_color(m.team_names.index(m.winner)) if m.winner is not None
                         else TEXT)
            r.panel(surf, summary_lines(m, self.labels, self.shots),
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
        init_display()
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



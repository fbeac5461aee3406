"""Record a match to MP4 (H.264 via imageio-ffmpeg) and GIF (imageio + Pillow).

:class:`VideoRecorder` is an episode hook (:mod:`alphatank.sim.episode`): it draws a frame
of the initial state and one after every ``every``-th tick (plus the final state) and
streams them to an MP4; an optional GIF gets a downscaled, thinned copy.
:func:`record_match` plays an already reset match with one Policy per seat through it.
``alphatank record``, ``alphatank replay --record`` and training's wandb videos
(:func:`wandb_video`) all use it.
"""

from __future__ import annotations

import signal
from collections.abc import Iterable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from alphatank.errors import InputError
from alphatank.extras import require
from alphatank.files import check_writable, replace_into
from alphatank.sim.episode import Episode, EpisodeHook
from alphatank.ui.render import DEFAULT_OVERLAYS, Renderer, surface_to_array

if TYPE_CHECKING:
    from alphatank.sim.match import Match, TickEvents
    from alphatank.sim.policy import Policy
    from alphatank.ui.replay import ReplayRecorder


@dataclass
class Recording:
    """What :func:`record_match` produced."""

    ticks: int
    frames: int  # frames in the MP4 (initial state + recorded ticks + hold)
    winner: str | None
    final_hash: str
    mp4: Path | None = None
    gif: Path | None = None
    fps: float = 30.0
    kept: np.ndarray | None = None  # (frames, H, W, 3) uint8 when keep_frames=True


VIDEO_SUFFIXES = (".mp4", ".mkv", ".mov", ".avi")  # containers that hold H.264
_STOP_SIGNALS = {signal.SIGINT, signal.SIGTERM}


def check_outputs(mp4: str | Path | None, gif: str | Path | None,
                  names: tuple[str, str] = ("mp4", "gif")) -> None:
    """InputError naming the setting (``names``: what the caller calls the MP4 and the GIF)
    unless the MP4 path ends in a video suffix, the GIF path in ``.gif``, and both can be
    written."""
    for path, name, suffixes in ((mp4, names[0], VIDEO_SUFFIXES), (gif, names[1], (".gif",))):
        if path is None:
            continue
        if Path(path).suffix.lower() not in suffixes:
            ends = " or ".join(filter(None, (", ".join(suffixes[:-1]), suffixes[-1])))
            raise InputError(f"{name}: {str(path)!r} must end in {ends}")
        check_writable(path, name)


class _Mp4:
    """Stream RGB frames to an H.264 MP4 (even sizes for yuv420p), written atomically."""

    def __init__(self, path: Path, fps: float, quality: float = 7.0):
        require("video", "MP4 recording")
        import imageio.v2 as imageio

        self.path = path
        path.parent.mkdir(parents=True, exist_ok=True)
        self.tmp = path.with_name(f".{path.stem}.partial{path.suffix}")
        self.writer = imageio.get_writer(self.tmp, format="FFMPEG", mode="I", fps=fps,
                                         codec="libx264", quality=quality,
                                         macro_block_size=1, pixelformat="yuv420p",
                                         ffmpeg_log_level="error")

    def append(self, frame: np.ndarray) -> None:
        h, w = frame.shape[:2]
        if h % 2 or w % 2:
            frame = np.pad(frame, ((0, h % 2), (0, w % 2), (0, 0)), mode="edge")
        # Ctrl-C or SIGTERM wait for the whole frame to be written: one arriving mid-write
        # left ffmpeg a torn frame, which it reported on stderr besides our one line
        held = signal.pthread_sigmask(signal.SIG_BLOCK, _STOP_SIGNALS)
        try:
            self.writer.append_data(frame)
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, held)

    def close(self, ok: bool) -> None:
        self.writer.close()
        if ok:
            replace_into(self.tmp, self.path)
        else:
            self.tmp.unlink(missing_ok=True)


class VideoRecorder(EpisodeHook):
    """An episode hook that draws frames into an MP4 (and/or a GIF, or memory).

    Frames: the initial state (``on_start``), the state after every ``every``-th tick and
    after the last tick, then ``hold_s`` seconds of the final frame (``on_end``, which also
    closes the files; :attr:`recording` then holds the result). With ``every=1`` and no
    hold an episode of T ticks gives T + 1 frames. ``fps`` defaults to the game's tick
    rate divided by ``every`` (real time). ``keep_frames`` also keeps the frames as an
    array (mind the memory: 2.1 MB per 770 x 770 frame; use ``scale`` < 1 and ``every`` >
    1 for long matches).
    """

    def __init__(self, *, mp4: str | Path | None = None, gif: str | Path | None = None,
                 fps: float | None = None, every: int = 1, hold_s: float = 0.0,
                 overlays: Iterable[str] | str = DEFAULT_OVERLAYS,
                 labels: Sequence[str] | None = None, scale: float = 1.0,
                 gif_scale: float = 0.5, gif_every: int = 2, keep_frames: bool = False,
                 renderer: Renderer | None = None):
        if every < 1 or gif_every < 1:
            raise ValueError(f"every and gif_every must be >= 1, got {every}, {gif_every}")
        check_outputs(mp4, gif)
        self.mp4, self.gif, self.fps, self.every, self.hold_s = mp4, gif, fps, every, hold_s
        self.gif_scale, self.gif_every, self.keep_frames = gif_scale, gif_every, keep_frames
        self.renderer = renderer or Renderer(None, overlays=overlays, labels=labels,
                                             fps=fps or 30.0, scale=scale)
        self.writer: _Mp4 | None = None
        self.recording: Recording | None = None
        self._gif_frames: list[np.ndarray] = []
        self._kept: list[np.ndarray] = []
        self._count = 0

    def _emit(self, episode: Episode) -> None:
        surf = self.renderer.draw(episode.match, episode.controllers)
        frame = surface_to_array(surf)
        if self.writer is not None:
            self.writer.append(frame)
        if self.keep_frames:
            self._kept.append(frame)
        if self.gif is not None and self._count % self.gif_every == 0:
            self._gif_frames.append(_downscale(surf, self.gif_scale))
        self._count += 1

    def on_start(self, episode: Episode) -> None:
        self.fps = float(self.fps or episode.match.cfg.tick_hz / self.every)
        self.renderer.fps = self.fps
        self.writer = _Mp4(Path(self.mp4), self.fps) if self.mp4 is not None else None
        try:
            self._emit(episode)
        except BaseException:
            self.close(ok=False)
            raise

    def on_tick(self, episode: Episode, events: TickEvents) -> None:
        if episode.match.tick % self.every == 0 or episode.over:
            self._emit(episode)

    def on_end(self, episode: Episode) -> None:
        ok = False
        try:
            for _ in range(round(self.hold_s * self.fps)):
                self._emit(episode)
            ok = True
        finally:
            self.close(ok)
        if self.gif is not None:
            _write_gif(Path(self.gif), self._gif_frames, self.fps / self.gif_every)
        m = episode.match
        self.recording = Recording(
            ticks=m.tick, frames=self._count, winner=m.winner, final_hash=m.state_hash(),
            mp4=Path(self.mp4) if self.mp4 is not None else None,
            gif=Path(self.gif) if self.gif is not None else None, fps=self.fps,
            kept=np.stack(self._kept) if self.keep_frames else None)

    def close(self, ok: bool) -> None:
        """Close the MP4 (kept only if ``ok``; else the partial file is removed)."""
        if self.writer is not None:
            self.writer.close(ok)
            self.writer = None


def record_episode(episode: Episode, video: VideoRecorder) -> Recording:
    """Play ``episode`` (which has ``video`` among its hooks) to its end; the partial MP4
    is removed if anything fails on the way."""
    try:
        episode.run()
    except BaseException:
        video.close(ok=False)
        raise
    assert video.recording is not None
    return video.recording


@contextmanager
def sigterm_interrupts() -> Iterator[None]:
    """Within the block SIGTERM (``kill``, ``timeout``) raises KeyboardInterrupt as Ctrl-C
    does, so :func:`record_episode` removes its partial files instead of the process dying
    with them (for a command's main thread; the previous handler is restored after)."""
    def on_term(signum: int, frame: Any) -> None:
        raise KeyboardInterrupt("by SIGTERM")
    previous = signal.signal(signal.SIGTERM, on_term)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def record_match(match: Match, policies: Sequence[Policy], *,
                 max_ticks: int | None = None, recorder: ReplayRecorder | None = None,
                 **video: Any) -> Recording:
    """Play ``match`` (already reset; policies already reset) to its end or ``max_ticks``
    ticks with ``policies[seat]`` in each seat, drawing it as :class:`VideoRecorder`
    (keyword arguments: ``mp4``, ``gif``, ``fps``, ``every``, ``hold_s``, ``overlays``,
    ``labels``, ``scale``, ``gif_scale``, ``gif_every``, ``keep_frames``, ``renderer``)
    does. ``recorder`` (a ReplayRecorder) gets every tick's actions."""
    if len(policies) != match.n:
        raise ValueError(f"need one policy per seat: {match.n} seats, {len(policies)} policies")
    hook = VideoRecorder(**video)
    hooks: list[EpisodeHook] = [hook] if recorder is None else [hook, recorder]
    return record_episode(Episode(match, policies, hooks=hooks, tick_limit=max_ticks), hook)


def _downscale(surf: Any, factor: float) -> np.ndarray:
    import pygame

    if factor == 1.0:
        return surface_to_array(surf)
    w, h = surf.get_size()
    size = (max(2, round(w * factor)), max(2, round(h * factor)))
    return surface_to_array(pygame.transform.smoothscale(surf, size))


def _write_gif(path: Path, frames: list[np.ndarray], fps: float) -> None:
    require("video", "GIF recording")
    import imageio.v3 as iio

    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.stem}.partial{path.suffix}")
    iio.imwrite(tmp, np.stack(frames), extension=".gif", duration=1000.0 / fps, loop=0)
    replace_into(tmp, path)


def wandb_video(recording: Recording, caption: str | None = None) -> Any:
    """A ``wandb.Video`` of a recording's MP4 (for ``wandb.log({"eval/video": ...})``)."""
    require("train", "wandb video logging")
    import wandb

    if recording.mp4 is None:
        raise ValueError("record_match(..., mp4=PATH) first: wandb logs the MP4 file")
    return wandb.Video(str(recording.mp4), caption=caption, format="mp4")

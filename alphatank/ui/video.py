"""Record a match to MP4 (H.264 via imageio-ffmpeg) and GIF (imageio + Pillow).

:func:`record_match` plays a match with one Policy per seat, draws a frame of the initial
state and one after every ``every``-th tick (plus the final state), and streams them to an
MP4; an optional GIF gets a downscaled, thinned copy. ``alphatank record``, ``alphatank
replay --record`` and training's wandb videos (:func:`wandb_video`) all use it.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from alphatank.extras import require
from alphatank.ui.render import DEFAULT_OVERLAYS, Renderer, surface_to_array

if TYPE_CHECKING:
    from alphatank.sim.match import Match
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
        self.writer.append_data(frame)

    def close(self, ok: bool) -> None:
        self.writer.close()
        if ok:
            os.replace(self.tmp, self.path)
        else:
            self.tmp.unlink(missing_ok=True)


def record_match(match: Match, policies: Sequence[Policy], *,
                 mp4: str | Path | None = None, gif: str | Path | None = None,
                 fps: float | None = None, every: int = 1, max_ticks: int | None = None,
                 hold_s: float = 0.0, overlays: Iterable[str] | str = DEFAULT_OVERLAYS,
                 labels: Sequence[str] | None = None, scale: float = 1.0,
                 gif_scale: float = 0.5, gif_every: int = 2, keep_frames: bool = False,
                 recorder: ReplayRecorder | None = None,
                 renderer: Renderer | None = None) -> Recording:
    """Play ``match`` (already reset; policies already reset) to its end or ``max_ticks``
    ticks, with ``policies[seat]`` choosing each live seat's action every tick.

    Frames: the initial state, then the state after every ``every``-th tick and after the
    last tick, then ``hold_s`` seconds of the final frame. With ``every=1`` and no hold an
    episode of T ticks gives T + 1 frames. ``fps`` defaults to the game's tick rate divided
    by ``every`` (real time). ``recorder`` (a ReplayRecorder) gets every tick's actions.
    ``keep_frames`` also returns the frames as an array (mind the memory: 2.1 MB per
    770 x 770 frame; use ``scale`` < 1 and ``every`` > 1 for long matches).
    """
    if every < 1 or gif_every < 1:
        raise ValueError(f"every and gif_every must be >= 1, got {every}, {gif_every}")
    if len(policies) != match.n:
        raise ValueError(f"need one policy per seat: {match.n} seats, {len(policies)} policies")
    fps = float(fps or match.cfg.tick_hz / every)
    renderer = renderer or Renderer(None, overlays=overlays, labels=labels, fps=fps,
                                    scale=scale)
    writer = _Mp4(Path(mp4), fps) if mp4 is not None else None
    gif_frames: list[np.ndarray] = []
    kept: list[np.ndarray] = []
    count = 0

    def emit() -> None:
        nonlocal count
        surf = renderer.draw(match, policies)
        frame = surface_to_array(surf)
        if writer is not None:
            writer.append(frame)
        if keep_frames:
            kept.append(frame)
        if gif is not None and count % gif_every == 0:
            gif_frames.append(_downscale(surf, gif_scale))
        count += 1

    ok = False
    try:
        emit()
        actions = np.ones((match.n, 3), dtype=np.int64)
        limit = match.cfg.max_steps if max_ticks is None else max_ticks
        while not match.done and match.tick < limit:
            for seat in np.flatnonzero(match.alive):
                actions[seat] = policies[seat].act(match, int(seat))
            if recorder is not None:
                recorder.record(actions)
            match.step(actions)
            if match.tick % every == 0 or match.done or match.tick >= limit:
                emit()
        for _ in range(round(hold_s * fps)):
            emit()
        ok = True
    finally:
        if writer is not None:
            writer.close(ok)
    if gif is not None:
        _write_gif(Path(gif), gif_frames, fps / gif_every)
    return Recording(ticks=match.tick, frames=count, winner=match.winner,
                     final_hash=match.state_hash(), mp4=writer.path if writer else None,
                     gif=Path(gif) if gif is not None else None, fps=fps,
                     kept=np.stack(kept) if keep_frames else None)


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
    os.replace(tmp, path)


def wandb_video(recording: Recording, caption: str | None = None) -> Any:
    """A ``wandb.Video`` of a recording's MP4 (for ``wandb.log({"eval/video": ...})``)."""
    require("train", "wandb video logging")
    import wandb

    if recording.mp4 is None:
        raise ValueError("record_match(..., mp4=PATH) first: wandb logs the MP4 file")
    return wandb.Video(str(recording.mp4), caption=caption, format="mp4")

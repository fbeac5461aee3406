"""Render modes of the renderer and the envs, in one place (no pygame import here, so
envs made with ``render_mode=None`` never load pygame)."""

from __future__ import annotations

RENDER_MODES = ["rgb_array", "human"]  # a list: Gymnasium's metadata["render_modes"]


def check_render_mode(mode: str | None) -> None:
    """ValueError unless ``mode`` is None or one of :data:`RENDER_MODES`."""
    if mode is not None and mode not in RENDER_MODES:
        raise ValueError(f"render_mode must be one of {RENDER_MODES} or None, got {mode!r}")

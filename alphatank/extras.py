"""Optional dependency groups (pyproject's extras) and the one check that names them.

The core install is the simulator and the envs (pymunk, numpy, gymnasium, pettingzoo,
pygame-ce). Everything else comes in an extra; code that needs one calls
:func:`require` before importing it, so a missing package fails with the ``pip install``
line that fixes it instead of a bare ``ModuleNotFoundError``.
"""

from __future__ import annotations

import importlib.util

# extra -> import names of the packages it installs (pyproject.toml lists the same)
EXTRAS: dict[str, tuple[str, ...]] = {
    "train": ("torch", "wandb", "tqdm", "matplotlib", "openskill"),
    "video": ("imageio", "imageio_ffmpeg"),
    "sb3": ("stable_baselines3",),
    "ray": ("ray",),  # --ray: experiments and env runners on a Ray cluster
}


class MissingExtraError(ImportError):
    """An optional dependency group is not installed; ``extra`` names it."""

    def __init__(self, extra: str, feature: str, missing: list[str]):
        self.extra, self.feature, self.missing = extra, feature, missing
        super().__init__(f"{feature} needs the '{extra}' extra ({', '.join(missing)} not "
                         f"installed): {install_hint(extra)}")


def install_hint(extra: str) -> str:
    return f"pip install 'alphatank[{extra}]'"


def missing(extra: str) -> list[str]:
    """Import names of ``extra``'s packages that are not importable here."""
    if extra not in EXTRAS:
        raise ValueError(f"unknown extra {extra!r}; extras: {sorted(EXTRAS)}")
    return [m for m in EXTRAS[extra] if importlib.util.find_spec(m) is None]


def require(extra: str, feature: str) -> None:
    """Raise :class:`MissingExtraError` naming ``feature`` (what needs it, e.g.
    ``"alphatank.training"``) unless every package of ``extra`` is importable."""
    gone = missing(extra)
    if gone:
        raise MissingExtraError(extra, feature, gone)

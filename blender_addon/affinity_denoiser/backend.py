"""The one seam between the add-on and the affinity core (the native ``affinity`` module).

Everything the add-on needs from the core goes through ``create_denoiser`` and
``write_sample_frame``. The module is imported lazily so that the add-on registers (and its
panel shows a clear message) even when the core is missing.
"""

from __future__ import annotations

import os
from typing import Any, Callable, Protocol

import numpy as np


class CoreMissing(RuntimeError):
    """The affinity core cannot be imported."""


class SequenceDenoiser(Protocol):
    def denoise(self, frame: dict[str, Any]) -> np.ndarray: ...  # (H, W, 3) linear RGB

    def reset(self) -> None: ...


#: Tests and development builds may replace the factory (``set_denoiser_factory``).
_factory: Callable[[str], SequenceDenoiser] | None = None


def load_core(need_denoiser: bool = True) -> Any:
    """The ``affinity`` module, or CoreMissing with the reason and what to do.

    ``need_denoiser=False`` accepts a core that can only read and write frame files.
    """
    try:
        import affinity
    except ImportError as exc:
        raise CoreMissing(
            "the affinity core (Python module 'affinity') is not installed for this Blender: "
            f"{exc}. Build it (cmake --build build --target _core) and put build/python on "
            "PYTHONPATH, or install the extension package that bundles its wheel."
        ) from exc
    if need_denoiser and not hasattr(affinity, "Denoiser"):
        raise CoreMissing(
            f"the affinity core at {getattr(affinity, '__file__', '?')} has no Denoiser "
            "(too old a build)"
        )
    return affinity


def core_status() -> str:
    """'' when the core is usable, else the reason (for the panel)."""
    if _factory is not None:
        return ""
    try:
        load_core()
    except CoreMissing as exc:
        return str(exc)
    return ""


def set_denoiser_factory(factory: Callable[[str], SequenceDenoiser] | None) -> None:
    """Replaces the core's Denoiser (model path -> denoiser); None goes back to the core."""
    global _factory
    _factory = factory


def create_denoiser(model_path: str) -> SequenceDenoiser:
    """A sequence denoiser for ``model_path`` ('' = the model built into the core)."""
    if _factory is not None:
        return _factory(model_path)
    affinity = load_core()
    # The core reports a missing or corrupt model file with its own message.
    return affinity.Denoiser(os.path.abspath(model_path) if model_path else None)


def write_sample_frame(path: str, frame: dict[str, Any]) -> None:
    """Writes the per-sample frame file (docs/FRAME_FILES.md) through the core, atomically."""
    load_core(need_denoiser=False).write_frame(path, frame)


class MeanDenoiser:
    """Stand-in for development without the core: the mean of each pixel's samples.

    Used only where explicitly installed with ``set_denoiser_factory``.
    """

    def __init__(self, model_path: str = "") -> None:
        self.model_path = model_path

    def denoise(self, frame: dict[str, Any]) -> np.ndarray:
        samples = frame["samples"]
        return (samples[..., 0:3] + samples[..., 3:6]).mean(axis=2).astype(np.float32)

    def reset(self) -> None:
        pass

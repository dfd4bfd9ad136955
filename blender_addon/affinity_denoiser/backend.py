"""The one seam between the add-on and the affinity core (the native ``affinity_core`` module).

Everything the add-on needs from the core goes through ``create_denoiser`` and
``write_sample_frame``. The module is imported lazily so that the add-on registers (and its
panel shows a clear message) even when the core is missing.

The core comes from the wheel bundled with the extension (``wheels`` in blender_manifest.toml),
which Blender installs into the extensions' site-packages; it is preferred over any other
``affinity_core`` on the path (e.g. a development build in ``build/python``), which is used only
when there is no bundled one.
"""

from __future__ import annotations

import functools
import os
import sys
from collections.abc import Callable
from typing import Any, Protocol

import numpy as np


class CoreMissing(RuntimeError):
    """The affinity core cannot be imported."""


class SequenceDenoiser(Protocol):
    def denoise(self, frame: dict[str, Any]) -> np.ndarray: ...  # (H, W, 3) linear RGB

    def reset(self) -> None: ...

    # Whether a frame of this size and camera would carry the history on (a jump of the camera
    # as at a cut would not); asked before the frame is rendered.
    def continues_sequence(self, width: int, height: int, world_to_camera: np.ndarray) -> bool: ...


#: The model the extension denoises with when the panel names none: the core's small model with a
#: fourth, wider kernel, fine-tuned on Cycles frames captured through this extension
#: (docs/CYCLES_DATA.md, ``cycles_d8``), its temporal gain set to 200 %. The model built into
#: the core was trained on our own renderer's frames, whose features and light differ from Cycles'.
CYCLES_MODEL = os.path.join(os.path.dirname(os.path.abspath(__file__)), "models", "cycles.affw")

#: Tests and development builds may replace the factory (``set_denoiser_factory``).
_factory: Callable[[str], SequenceDenoiser] | None = None


#: What -march=x86-64-v3 (the core's build, CMakeLists.txt) lets the compiler use, as Linux
#: names it in /proc/cpuinfo: without them the core would die of an illegal instruction.
X86_64_V3_FLAGS = ("avx", "avx2", "fma", "bmi1", "bmi2", "f16c", "movbe", "abm")


def missing_cpu_features(cpuinfo: str) -> list[str]:
    """The x86-64-v3 features absent from a /proc/cpuinfo text ([] when it has no flags line)."""
    for line in cpuinfo.splitlines():
        key, _, value = line.partition(":")
        if key.strip() == "flags":
            present = set(value.split())
            return [flag for flag in X86_64_V3_FLAGS if flag not in present]
    return []


def bundled_site_packages() -> str | None:
    """Where Blender installed the bundled wheel (the extensions' site-packages), if it did."""
    try:
        import bpy
    except ImportError:
        return None
    # Blender puts the folder it installs extensions' wheels into on sys.path (at start-up, and
    # when it installs an extension); its layout below the extensions folder is Blender's own.
    roots = []
    for resource in (bpy.utils.user_resource, bpy.utils.system_resource):
        folder = resource("EXTENSIONS")
        if folder:
            roots.append(os.path.realpath(folder) + os.sep)
    for entry in sys.path:
        real = os.path.realpath(entry) if entry else ""
        if real.startswith(tuple(roots)) and os.path.isfile(os.path.join(entry, "affinity_core", "__init__.py")):
            return entry
    return None


@functools.cache
def _cpu_problem() -> str:
    """'' when this CPU can run the core (or /proc/cpuinfo does not say), else why not."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as handle:
            missing = missing_cpu_features(handle.read())
    except OSError:
        return ""
    if not missing:
        return ""
    return ("the affinity core needs an x86-64-v3 CPU (AVX2 + FMA: Intel Haswell, AMD Zen or "
            f"newer); this one lacks {', '.join(missing)}")


def _import_core() -> Any:
    """``affinity_core``: the bundled wheel's when there is one, else whatever the path has."""
    if "affinity_core" in sys.modules:
        return sys.modules["affinity_core"]
    if problem := _cpu_problem():
        raise CoreMissing(problem)
    bundled = bundled_site_packages()
    bundled_error = ""
    if bundled is not None:
        sys.path.insert(0, bundled)
        try:
            import affinity_core
            return affinity_core
        except ImportError as exc:
            bundled_error = f" (the bundled one in {bundled} failed: {exc})"
        finally:
            sys.path.remove(bundled)  # the first occurrence: the one inserted above
    try:
        import affinity_core
    except ImportError as exc:
        raise CoreMissing(
            "the affinity core (Python module 'affinity_core') is not installed for this Blender: "
            f"{exc}{bundled_error}. Install the extension package that bundles its wheel "
            "(scripts/build_extension.sh builds it), or build it (cmake --build build --target "
            "_core) and put build/python on PYTHONPATH."
        ) from exc
    return affinity_core


def load_core(need_denoiser: bool = True) -> Any:
    """The ``affinity_core`` module, or CoreMissing with the reason and what to do.

    ``need_denoiser=False`` accepts a core that can only read and write frame files.
    """
    affinity = _import_core()
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


def create_denoiser(model_path: str, precision: str = "auto") -> SequenceDenoiser:
    """A sequence denoiser for ``model_path`` ('' = the extension's Cycles model, CYCLES_MODEL).

    ``precision`` as the panel names it: "auto" takes the network's products in bfloat16 where
    this CPU has AVX512-BF16 (docs/MODEL.md, "bfloat16 products") and in FP32 elsewhere, so that a
    .blend file saved with it still renders on any machine; "fp32" everywhere.
    """
    if _factory is not None:
        return _factory(model_path)
    affinity = load_core()
    # The core reports a missing or corrupt model file with its own message.
    return affinity.Denoiser(os.path.abspath(model_path) if model_path else CYCLES_MODEL, precision=precision)


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

    def continues_sequence(self, width: int, height: int, world_to_camera: np.ndarray) -> bool:
        return True  # it keeps no history, so no jump of the camera cuts one

"""affinity_core: frame files of per-sample render features, as numpy arrays.

A frame is a dict::

    {
        "samples":   float32 (H, W, S, 18)  every sample's features, channel order FEATURE_NAMES
        "motion":    float32 (H, W, 2)      pixels into the previous frame, x right, y down
        "valid":     float32 (H, W)         1 where the previous frame saw the same surface
        "reference": float32 (H, W, 3) or None   converged linear RGB radiance
        "info": {
            "scene_name": str,
            "frame_index": int,
            "reference_spp": int,            0 without a reference
            "seed": int,                     unsigned 64-bit
            "world_to_camera": float32 (4, 4),
            "camera_to_clip": float32 (4, 4),
        },
    }

Matrices are row-major and act on column vectors (``p_camera = world_to_camera @ p_world``).
The file format and every convention are described in docs/FRAME_FILES.md.
"""

from __future__ import annotations

import os
from typing import Any

from . import _core

__all__ = [
    "Denoiser",
    "Error",
    "Model",
    "Svgf",
    "FEATURE_COUNT",
    "FEATURE_NAMES",
    "MAX_SPP",
    "frame_file_name",
    "list_frame_files",
    "read_frame",
    "write_frame",
]

Error = _core.Error
Error.__module__ = __name__
Error.__doc__ = (
    "Raised for every failure inside the affinity library: unreadable, corrupt or incomplete "
    "files, failed writes. The message names the file and the problem. A subclass of "
    "RuntimeError."
)

#: The 18 per-sample feature channel names in channel order, e.g. "diffuse.R", "normal.X".
FEATURE_NAMES: list[str] = list(_core.FEATURE_NAMES)
#: Number of features per sample (the last axis of "samples").
FEATURE_COUNT: int = _core.FEATURE_COUNT
#: Largest number of samples per pixel a frame may hold.
MAX_SPP: int = _core.MAX_SPP


def _version() -> str:
    """The version of this build: one source, the ``project(affinity VERSION ...)`` line of the
    top-level CMakeLists.txt, which pyproject.toml reads for the wheel's metadata.

    An installed wheel: the metadata of the distribution ``affinity-core`` beside this package
    (a shared site-packages, such as Blender's, holds other projects' metadata too). A build tree
    (``<build>/python/affinity_core``): CMakeLists.txt of
    the source folder that ``<build>/CMakeCache.txt`` names. Otherwise "0+unknown"."""
    import re
    from importlib import metadata

    package = os.path.dirname(os.path.abspath(__file__))
    for distribution in metadata.distributions(path=[os.path.dirname(package)]):
        if re.sub(r"[-_.]+", "-", distribution.metadata["Name"] or "").lower() == "affinity-core":
            return distribution.version
    try:
        with open(os.path.join(package, "..", "..", "CMakeCache.txt"), encoding="utf-8") as handle:
            source = re.search(r"^affinity_SOURCE_DIR:\w+=(.*)$", handle.read(), re.MULTILINE)
        if source:
            with open(os.path.join(source.group(1), "CMakeLists.txt"), encoding="utf-8") as handle:
                version = re.search(r"project\(affinity VERSION ([0-9.]+)", handle.read())
            if version:
                return version.group(1)
    except OSError:
        pass
    return "0+unknown"


#: The version of this build, e.g. "0.1.0" (the wheel's version; in a build tree, the
#: CMake project's).
__version__: str = _version()


def read_frame(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Reads a frame file into a frame dict (see the module docstring).

    The arrays are freshly allocated and writable. Raises ``affinity_core.Error`` naming the file for
    a missing, incomplete, corrupt or non-conforming file.
    """
    return _core.read_frame(os.fspath(path))


def write_frame(
    path: str | os.PathLike[str], frame: dict[str, Any], compression: str = "piz"
) -> None:
    """Writes a frame dict (see the module docstring) to ``path`` atomically.

    Every key except "reference" is required, "reference" may be None or absent; every array
    must be float32 with the documented shape (any memory layout). ``compression`` is "none",
    "zip" or "piz" (all lossless). Raises ``ValueError``/``TypeError``/``KeyError`` naming the
    offending key for malformed input, ``affinity_core.Error`` when writing fails.
    """
    _core.write_frame(os.fspath(path), frame, compression)


def frame_file_name(frame_index: int) -> str:
    """The file name of a frame in a sequence folder: ``frame_0007.exr`` for index 7."""
    return _core.frame_file_name(frame_index)


def list_frame_files(directory: str | os.PathLike[str]) -> list[str]:
    """Paths of the frame files in a sequence folder, in frame order.

    Raises ``affinity_core.Error`` if the folder does not exist.
    """
    return _core.list_frame_files(os.fspath(directory))


Model = _core.Model
Model.__module__ = __name__
bfloat16_supported = _core.bfloat16_supported

#: SVGF (Schied et al. 2017), the hand-designed spatio-temporal baseline. Stateful like Denoiser:
#: ``Svgf(**settings).denoise(frame)`` -> float32 (H, W, 3) in sequence order, ``reset()`` at
#: cuts; keyword settings (atrous_iterations=5, sigma_depth=1, sigma_normal=128,
#: sigma_luminance=4, alpha_color=0.2, alpha_moments=0.2, history_cap=32, ...) default to the
#: paper's values, see core/include/affinity/svgf.h.
Svgf = _core.Svgf
Svgf.__module__ = __name__


class Denoiser:
    """Denoises a frame sequence, keeping temporal state between calls.

    Feed frames (dicts as returned by ``read_frame``) in sequence order; each call returns the
    denoised linear RGB radiance as float32 (H, W, 3). Call ``reset()`` at a camera cut; the
    history is also dropped automatically when the frame size changes or the camera jumps.
    The GIL is released while denoising; Ctrl-C (KeyboardInterrupt) stops a frame between its
    steps, and the next frame then starts a new sequence as after ``reset()``. A Denoiser takes
    one call at a time: a call from another thread while one runs raises ``affinity_core.Error``
    (give each thread its own Denoiser). It cannot be copied or pickled.

    ``precision`` is the arithmetic of the network's products: "auto" (the default) takes them
    in bfloat16 where the CPU has AVX512-BF16 (``affinity_core.bfloat16_supported()``; faster, SMAPE and
    temporal error equal to the fourth digit: docs/MODEL.md, "bfloat16 products") and in FP32
    elsewhere; "fp32" and "bf16" ask for one ("bf16" raises ``affinity_core.Error`` on other CPUs).
    ``model.precision`` says which ran. A model given as a ``Model`` keeps its own precision.

    ``ablation`` switches off one part of the trained pipeline, for measuring what it buys:
    "single_frame" (no history: every frame denoised on its own), "no_temporal_kernel" (the
    last kernel has no taps into the previous output), "one_kernel" (only the last, widest
    kernel filters), "no_light_restoration" (the kernels' output without the coarse light
    restoration after them), "no_input_fallback" (without the move back toward the noisy input
    where the output departs from it by more than its noise explains), "no_peak_guard" (without
    the cap on lone output pixels far above their neighbours and the input around them) or
    "no_history_guard" (the temporal taps also take previous output far brighter than anything
    the frame shows at the pixel). None runs the whole pipeline.
    """

    ABLATIONS = ("single_frame", "no_temporal_kernel", "one_kernel", "no_light_restoration", "no_input_fallback",
                 "no_peak_guard", "no_history_guard")

    def __init__(
        self,
        model: str | os.PathLike[str] | Model | None = None,
        *,
        ablation: str | None = None,
        precision: str = "auto",
    ) -> None:
        if model is None:
            model = Model.built_in(precision)
        elif not isinstance(model, Model):
            model = Model.from_file(os.fspath(model), precision)
        if ablation is not None and ablation not in self.ABLATIONS:
            raise ValueError(f"unknown ablation {ablation!r} (known: {', '.join(self.ABLATIONS)})")
        self.ablation = ablation
        self._native = _core.Denoiser(
            model,
            use_history=ablation != "single_frame",
            temporal_kernel=ablation != "no_temporal_kernel",
            all_kernels=ablation != "one_kernel",
            light_restoration=ablation != "no_light_restoration",
            input_fallback=ablation != "no_input_fallback",
            peak_guard=ablation != "no_peak_guard",
            history_guard=ablation != "no_history_guard",
        )
        #: What the last call did: invalid_radiance (NaN/Inf/negative values read as 0),
        #: used_history, reset_reason, exposure (the factor on the radiance the network saw, set by
        #: the sequence's first frame: 1 for scenes as bright as the training scenes), stage_ms
        #: (milliseconds per pipeline stage), buffer_bytes (memory of the buffers the denoiser
        #: keeps between frames).
        self.last_report: dict[str, Any] = {}

    @property
    def model(self) -> Model:
        return self._native.model

    def denoise(self, frame: dict[str, Any]) -> Any:
        output, self.last_report = self._native.denoise(frame)
        return output

    def denoise_file(self, path: str | os.PathLike[str]) -> tuple[Any, dict[str, Any]]:
        """Reads a frame file and denoises it as the next frame of the sequence, the samples
        read straight into memory the denoiser lends, so that they are never held beside all of
        its buffers (what ``affinity denoise`` does). Returns the float32 (H, W, 3) output, bit
        for bit ``denoise(read_frame(path))``, and the frame as ``read_frame`` gives it but with
        "samples" None and "noisy", the per-pixel mean of the samples' radiance (H, W, 3)."""
        output, self.last_report, frame = self._native.denoise_file(os.fspath(path))
        return output, frame

    # Streaming: a frame's samples in batches, so that they are never held together (Blender
    # renders one sample per sub-render). The result is bit for bit ``denoise`` on the whole
    # frame, except that the depth normalisation comes from the first batch alone.

    def add_samples(self, samples: Any) -> None:
        """Adds float32 (H, W, S, 18) samples, or (H, W, 18) for one, to the frame being built.

        Batches must come in sample order and share H and W. The array is read during the
        call only (the GIL is released).
        """
        self._native.add_samples(samples)

    def finish_frame(self, frame: dict[str, Any]) -> Any:
        """Denoises the frame built by ``add_samples``; ``frame`` is a frame dict without
        "samples" (motion, valid, info). Returns float32 (H, W, 3) like ``denoise``."""
        output, self.last_report = self._native.finish_frame(frame)
        return output

    def discard_samples(self) -> None:
        """Drops the samples added since the last ``finish_frame`` (after a cancelled render)."""
        self._native.discard_samples()

    @property
    def pending_samples(self) -> int:
        """Samples per pixel added since the last ``finish_frame``."""
        return self._native.pending_samples

    def reset(self) -> None:
        self._native.reset()

    def continues_sequence(self, width: int, height: int, world_to_camera: Any) -> bool:
        """Whether a width x height frame seen through ``world_to_camera`` (4, 4) would carry the
        history on, asked before its samples exist: False without a history, after a size
        change, or where the camera jumped as at a cut (turned by more than 45 degrees, or moved
        by more than half the last frame's mean depth), where ``denoise`` would drop it."""
        return self._native.continues_sequence(width, height, world_to_camera)

    # A Denoiser is one sequence's history in native memory: a copy would share it, and two
    # copies fed different frames would corrupt each other's sequence.
    def _refuse_copy(self, *_: Any) -> Any:
        raise TypeError(
            "an affinity_core.Denoiser holds one sequence's history and cannot be copied or pickled; "
            "make a new affinity_core.Denoiser(model) instead (its history starts empty)"
        )

    __copy__ = __deepcopy__ = __reduce_ex__ = _refuse_copy

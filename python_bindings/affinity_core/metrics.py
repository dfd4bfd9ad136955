"""Error metrics of the evaluation (docs/METHOD.md section 10), one definition each.

Images are linear RGB float arrays of shape (H, W, 3) (any float dtype; converted to float32).
SMAPE, relMSE, PSNR, the temporal error and the warping error are the C++ functions of core (affinity/metrics.h),
so the CLI's summaries, the training evaluation and the benchmark share one implementation;
FLIP is NVIDIA's ꟻLIP through the ``flip-evaluator`` package.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from . import _core

__all__ = ["smape", "relmse", "psnr", "temporal_error", "tonemapped_temporal_error", "warping_error", "flip",
           "ms_per_megapixel"]


def smape(image: Any, reference: Any) -> float:
    """Symmetric mean absolute percentage error: mean |a - b| / (|a| + |b| + 0.01) over every
    pixel and channel. 0 is perfect; lower is better."""
    return _core.smape(image, reference)


def relmse(image: Any, reference: Any) -> float:
    """Relative mean squared error: 0.5 * mean (a - b)^2 / (b^2 + 0.01). Lower is better."""
    return _core.relmse(image, reference)


def psnr(image: Any, reference: Any) -> float:
    """PSNR in dB of the tone-mapped images, x / (1 + x) after clamping negatives to 0 (so
    values lie in [0, 1)); inf for identical images. Higher is better."""
    return _core.psnr(image, reference)


def temporal_error(
    output: Any, previous_output: Any, reference: Any, previous_reference: Any, motion: Any, valid: Any
) -> float:
    """Flicker relative to the reference's own change between frame t-1 and frame t.

    Mean over counted pixels and the 3 channels of |(O_t - W O_{t-1}) - (R_t - W R_{t-1})|,
    where W warps the previous frame bilinearly by the motion vectors of frame t (``motion``
    (H, W, 2): pixels into the previous frame, as in a frame dict). A pixel counts when
    ``valid`` (H, W) is >= 0.5 and its warp target (x + motion.x, y + motion.y) lies within
    [0, W-1] x [0, H-1]. NaN when no pixel counts. Lower is better; 0 means the output changes
    exactly as the reference does.
    """
    return _core.temporal_error(output, previous_output, reference, previous_reference, motion, valid)


def tonemap(image: Any) -> np.ndarray:
    """x / (1 + x) after clamping negatives to 0: the tone map of ``psnr``, values in [0, 1)."""
    linear = np.maximum(np.asarray(image, np.float32), 0.0)
    return np.ascontiguousarray(linear / (1.0 + linear))


def tonemapped_temporal_error(
    output: Any, previous_output: Any, reference: Any, previous_reference: Any, motion: Any, valid: Any
) -> float:
    """``temporal_error`` of the tone-mapped images (``tonemap``, as ``psnr`` sees them).

    The linear temporal error counts flicker by its size in radiance, so a few flickering lamp
    pixels outweigh everything else in a frame; on a display a lamp is white either way. This one
    counts flicker as a viewer sees it: at most 1 per pixel and channel.
    """
    return _core.temporal_error(tonemap(output), tonemap(previous_output), tonemap(reference),
                                tonemap(previous_reference), motion, valid)


def warping_error(image: Any, previous_image: Any, motion: Any, valid: Any) -> float:
    """Warping error of Lai et al. 2018: the flicker of a sequence on its own, no reference.

    Mean over the pixels that ``temporal_error`` counts of the squared difference, summed over the
    3 channels, between frame t and frame t-1 warped bilinearly by ``motion`` (H, W, 2), both
    tone-mapped as for ``psnr`` (``tonemap``) first, so a pixel counts at most 3. Real changes of
    the scene (moving shadows, highlights sliding over a surface) count too: a reference sequence
    has a warping error of its own, the value a perfect denoiser would have. NaN when no pixel
    counts. Lower is steadier.
    """
    return _core.warping_error(image, previous_image, motion, valid)


def flip(image: Any, reference: Any) -> float:
    """Mean HDR-ꟻLIP error (``flip_evaluator.evaluate(reference, image, "HDR")``) in [0, 1].

    Negative values are clamped to 0 first (HDR-ꟻLIP takes non-negative linear sRGB). The
    exposure range is chosen by ꟻLIP from the reference. Lower is better.
    """
    import flip_evaluator  # imported here: only the benchmark needs it

    test = np.ascontiguousarray(np.maximum(np.asarray(image, np.float32), 0.0))
    ref = np.ascontiguousarray(np.maximum(np.asarray(reference, np.float32), 0.0))
    if test.shape != ref.shape or test.ndim != 3 or test.shape[2] != 3:
        raise ValueError(f"image has shape {test.shape} and reference {ref.shape}, expected equal (H, W, 3)")
    _, mean, _ = flip_evaluator.evaluate(ref, test, "HDR", applyMagma=False)
    return float(mean)


def ms_per_megapixel(seconds: float, width: int, height: int) -> float:
    """Milliseconds per megapixel (10^6 pixels) of a call that took ``seconds`` on one frame."""
    return seconds * 1e3 / (width * height / 1e6)

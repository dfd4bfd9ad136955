"""Where a sequence's temporal error comes from: the pixels that carry most of it.

    PYTHONPATH=build/python .venv/bin/python scripts/temporal_error_map.py SEQUENCE_DIR SPP [MODEL.affw]

Denoises the sequence's frames at their first SPP samples (the built-in model unless a weights
file is given), computes each pixel's mean over frames 2..N of the temporal error of
docs/BENCHMARK.md, checks that the per-pixel mean reproduces core's `temporal_error`, and prints
the share of the few worst pixels and what they are.
"""

from __future__ import annotations

import sys

import numpy as np

import affinity_core
from affinity_core import metrics


def warp(image: np.ndarray, motion: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Bilinear lookup of `image` at (x + mx, y + my), border-clamped, and where that lies inside."""
    height, width, _ = image.shape
    ys, xs = np.mgrid[0:height, 0:width].astype(np.float32)
    sx, sy = xs + motion[..., 0], ys + motion[..., 1]
    inside = (sx >= 0) & (sx <= width - 1) & (sy >= 0) & (sy <= height - 1)
    px, py = np.clip(sx, 0, width - 1), np.clip(sy, 0, height - 1)
    x0, y0 = np.floor(px).astype(int), np.floor(py).astype(int)
    x1, y1 = np.minimum(x0 + 1, width - 1), np.minimum(y0 + 1, height - 1)
    fx, fy = (px - x0)[..., None], (py - y0)[..., None]
    top = image[y0, x0] * (1 - fx) + image[y0, x1] * fx
    bottom = image[y1, x0] * (1 - fx) + image[y1, x1] * fx
    return top * (1 - fy) + bottom * fy, inside


def main(sequence_dir: str, spp: int, model: str | None) -> None:
    frames = [affinity_core.read_frame(path) for path in affinity_core.list_frame_files(sequence_dir)]
    denoiser = affinity_core.Denoiser(model)
    outputs = []
    for frame in frames:
        view = dict(frame, samples=np.ascontiguousarray(frame["samples"][:, :, :spp, :]))
        outputs.append(denoiser.denoise(view))
    # Each pixel's error scaled so that the mean over the image is the temporal error.
    per_pixel = np.zeros(frames[0]["reference"].shape[:2])
    core_means = []
    for t in range(1, len(frames)):
        motion, reference = frames[t]["motion"], frames[t]["reference"]
        warped_output, inside = warp(outputs[t - 1], motion)
        warped_reference, _ = warp(frames[t - 1]["reference"], motion)
        counted = (frames[t]["valid"] > 0.5) & inside
        error = np.abs((outputs[t] - warped_output) - (reference - warped_reference)).mean(-1)
        per_pixel += np.where(counted, error, 0.0) / counted.sum() * counted.size
        core_means.append(metrics.temporal_error(outputs[t], outputs[t - 1], reference, frames[t - 1]["reference"],
                                                 motion, frames[t]["valid"]))
    per_pixel /= len(frames) - 1
    mean = per_pixel.mean()
    print(f"temporal error {mean:.4f} (core: {np.mean(core_means):.4f})")
    order = np.argsort(per_pixel.ravel())[::-1]
    total = per_pixel.sum()
    for count in (10, 50, 200):
        share = per_pixel.ravel()[order[:count]].sum() / total
        print(f"  the worst {count} of {per_pixel.size} pixels carry {share:.0%}")
    last = frames[-1]
    for index in order[:8]:
        y, x = divmod(int(index), per_pixel.shape[1])
        samples = last["samples"][y, x, :spp]
        print(f"  pixel ({x}, {y}): weighted error {per_pixel[y, x]:.1f}, "
              f"reference {last['reference'][y, x].mean():.1f}, emissive samples {samples[:, 14].mean():.2f}")


if __name__ == "__main__":
    if len(sys.argv) not in (3, 4):
        sys.exit(__doc__)
    main(sys.argv[1], int(sys.argv[2]), sys.argv[3] if len(sys.argv) == 4 else None)

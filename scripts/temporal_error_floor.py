"""How much temporal error a flicker-free output scores for its blur alone.

    PYTHONPATH=build/python .venv/bin/python scripts/temporal_error_floor.py [BENCH_CACHE_DIR]

Scores each reference of the benchmark's cached sequences (default ~/.cache/affinity/bench-v1,
made by `python -m affinity_bench`), blurred by a Gaussian of a few widths, against the
reference itself: SMAPE and the temporal error of docs/BENCHMARK.md, means over the sequences.
Such an output has no noise and does not flicker, yet its temporal error is not 0: the metric
compares O_t - W O_{t-1} with R_t - W R_{t-1}, and a blurred output does not reproduce what the
bilinear warp W and the scene's own change leave in the reference's difference. A denoiser's
temporal error is read against this floor at its own SMAPE.
"""

from __future__ import annotations

import pathlib
import sys

import numpy as np

import affinity_core
from affinity_core import metrics

SIGMAS = (0.0, 0.3, 0.4, 0.5, 0.6, 0.7, 0.85, 1.0)


def gaussian_blur(image: np.ndarray, sigma: float) -> np.ndarray:
    """Separable Gaussian blur of an (H, W, C) image, borders extended."""
    if sigma == 0.0:
        return image
    radius = int(np.ceil(3.0 * sigma))
    offsets = np.arange(-radius, radius + 1)
    kernel = np.exp(-offsets**2 / (2.0 * sigma**2))
    kernel /= kernel.sum()
    out = image.astype(np.float64)
    for axis in (0, 1):
        pad = [(0, 0)] * image.ndim
        pad[axis] = (radius, radius)
        padded = np.pad(out, pad, mode="edge")
        size = image.shape[axis]
        out = sum(weight * np.take(padded, np.arange(i, i + size), axis=axis) for i, weight in enumerate(kernel))
    return np.ascontiguousarray(out, dtype=np.float32)


def score(frames: list[dict], sigma: float) -> tuple[float, float]:
    """Mean SMAPE over frames and mean temporal error over frames 1..N-1 of the blurred references."""
    references = [frame["reference"] for frame in frames]
    outputs = [gaussian_blur(reference, sigma) for reference in references]
    smape = float(np.mean([metrics.smape(o, r) for o, r in zip(outputs, references)]))
    temporal = float(np.mean([
        metrics.temporal_error(outputs[t], outputs[t - 1], references[t], references[t - 1], frames[t]["motion"],
                               frames[t]["valid"]) for t in range(1, len(frames))]))
    return smape, temporal


def main() -> None:
    root = pathlib.Path(sys.argv[1]) if len(sys.argv) > 1 else pathlib.Path.home() / ".cache/affinity/bench-v1"
    folders = sorted(p for p in root.iterdir() if p.is_dir() and p.name.endswith("_ref1024"))
    if not folders:
        sys.exit(f"temporal_error_floor: no benchmark sequences (*_ref1024) in {root}")
    rows = {sigma: [] for sigma in SIGMAS}  # (sequence, smape, temporal) per sigma
    for folder in folders:
        frames = [affinity_core.read_frame(path) for path in affinity_core.list_frame_files(folder)]
        name = folder.name.split("_seed")[0]
        for sigma in SIGMAS:
            rows[sigma].append((name, *score(frames, sigma)))
        print(name, " ".join(f"{sigma}:{rows[sigma][-1][2]:.4f}" for sigma in SIGMAS), flush=True)
    print("\n| Gaussian sigma (px) | SMAPE | temporal error | temporal error without fireflies |")
    print("|---|---|---|---|")
    for sigma in SIGMAS:
        smape = np.mean([row[1] for row in rows[sigma]])
        temporal = np.mean([row[2] for row in rows[sigma]])
        calm = np.mean([row[2] for row in rows[sigma] if row[0] != "fireflies"])
        print(f"| {sigma} | {smape:.4f} | {temporal:.4f} | {calm:.4f} |")


if __name__ == "__main__":
    main()

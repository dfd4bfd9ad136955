"""How many warm-up frames a chunk of an animation needs to match one continuous render.

    PYTHONPATH=build/python:. .venv/bin/python scripts/warmup_frames.py --out results/blender/warmup_frames.md

A render farm renders an animation in chunks, each on its own machine with no history. The
engine warms a chunk up by denoising the W frames before its first (blender_addon/.../worker.py);
the warm-up frames are the continuous run's own frames (the same Cycles noise), so a chunk
starting at frame k with W warm-up frames gives the output of a run started at frame k - W.
This script denoises the Cycles suite's validation sequences (training/cycles/make_data.py)
from every start and reports, per W, the relative mean absolute difference of frame k's output
to the continuous run's: mean |chunk - continuous| / mean |continuous| over the image, the worst
over sequences and over the last frames k.
"""

from __future__ import annotations

import argparse
import os
import pathlib
import sys

import numpy as np

import affinity_core
from affinity_bench import cycles

TOLERANCE = 1e-3


def _frames(folder: pathlib.Path, spp: int) -> list[dict]:
    frames = []
    for path in affinity_core.list_frame_files(folder):
        frame = affinity_core.read_frame(path)
        frame["samples"] = np.ascontiguousarray(frame["samples"][:, :, :spp])
        frames.append(frame)
    return frames


def _run(model: affinity_core.Model, frames: list[dict]) -> np.ndarray:
    """The last frame's output of a run over ``frames`` from a fresh history."""
    denoiser = affinity_core.Denoiser(model)
    output = None
    for frame in frames:
        output = denoiser.denoise(frame)
    return np.asarray(output)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", type=pathlib.Path,
                        default=pathlib.Path(os.environ.get("AFFINITY_DATA", cycles.DEFAULT_DATA_DIR)))
    parser.add_argument("--spp", type=int, default=4, help="samples per frame (the add-on's default)")
    parser.add_argument("--last-frames", type=int, default=2, help="how many of the last frames to check")
    parser.add_argument("--out", type=pathlib.Path, required=True, help="markdown file to write")
    args = parser.parse_args(argv)
    folders = sorted((args.data / "val").glob("cycles_*"))
    if not folders:
        parser.error(f"no Cycles validation sequences in {args.data / 'val'}")
    model = affinity_core.Model.built_in("auto")  # what the add-on uses by default

    worst: dict[int, float] = {}
    rows = []
    for folder in folders:
        frames = _frames(folder, args.spp)
        for last in range(len(frames) - args.last_frames, len(frames)):
            continuous = _run(model, frames[:last + 1])
            scale = float(np.abs(continuous).mean())
            for warmup in range(last + 1):
                chunk = _run(model, frames[last - warmup:last + 1])
                difference = float(np.abs(chunk - continuous).mean()) / scale
                worst[warmup] = max(worst.get(warmup, 0.0), difference)
                rows.append((folder.name, last, warmup, difference))
            print(f"{folder.name} frame {last}: " + " ".join(
                f"W{w}={d:.2e}" for name, k, w, d in rows if name == folder.name and k == last), flush=True)

    command = " ".join([os.path.basename(sys.argv[0])] + (argv if argv is not None else sys.argv[1:]))
    enough = [w for w in sorted(worst) if all(worst[v] <= TOLERANCE for v in worst if v >= w)]
    lines = ["# Warm-up frames: a chunk against the continuous run", "",
             f"Command: `{command}` (scripts/warmup_frames.py), built-in model, {args.spp} spp, "
             f"{len(folders)} Cycles validation sequences of {len(frames)} frames.", "",
             "Relative mean absolute difference of a chunk's frame to the continuous run's, the worst over "
             f"the sequences and their last {args.last_frames} frames; W = warm-up frames "
             f"(W = k for frame k: the whole run, 0 by construction).", "",
             "| W | worst relative difference |", "|---:|---:|"]
    lines += [f"| {w} | {worst[w]:.2e} |" for w in sorted(worst)]
    lines += ["", (f"Smallest W within {TOLERANCE:g} on every checked frame: {enough[0]}." if enough and
                   enough[0] < max(worst) else
                   f"No W below the whole run reaches {TOLERANCE:g} on these {len(frames)}-frame sequences.")]
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text("\n".join(lines) + "\n")
    print(f"warmup_frames: wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Where the light goes on the Cycles suite: how bright the noisy input, a model's output and
Blender's own denoiser come out against the reference, how sure the reference itself is of its
brightness, and how much of the input's light arrives in its brightest pixels.

    PYTHONPATH=build/python:. .venv/bin/python scripts/cycles_energy.py \
        --model cycles=training/results/cycles_ft1/cycles_ft1.affw --out results/bench_cycles/energy.md

Brightness is the sequence's mean radiance over the reference's (docs/BENCHMARK.md). The
reference is the mean of two independent renders (reference_halves.npz); the ratio of one
half's mean to the other's bounds how well any brightness can be judged on that scene. "Top 1 %"
is the share of the noisy input's light in its brightest 1 % of pixels per frame (fireflies),
and "kept" what the model's output keeps of the input's light there and overall.
"""

from __future__ import annotations

import argparse
import os
import pathlib
import sys

import numpy as np

import affinity_core
from affinity_bench import cycles

LUMINANCE = np.array([0.2126, 0.7152, 0.0722], np.float32)


def sequence_energy(folder: pathlib.Path, model: str, spp: int) -> dict[str, float]:
    """Light sums over the sequence's frames (luminance) for one model at `spp` samples."""
    halves = np.load(folder / "reference_halves.npz")
    blender = np.load(folder / "blender_oidn.npz")
    denoiser = affinity_core.Denoiser(model)
    sums = dict.fromkeys(("reference", "noisy", "output", "blender", "half_a", "half_b",
                          "noisy_top", "output_top"), 0.0)
    half_ratios = []
    for index, path in enumerate(affinity_core.list_frame_files(folder)):
        frame = affinity_core.read_frame(path)
        frame["samples"] = np.ascontiguousarray(frame["samples"][:, :, :spp])
        output = denoiser.denoise(frame)
        samples = frame["samples"]
        noisy = (samples[..., 0:3] + samples[..., 3:6]).mean(axis=2) @ LUMINANCE
        lit = output @ LUMINANCE
        top = noisy >= np.quantile(noisy, 0.99)
        a, b = (halves[f"{half}_frame{index}"][..., :3] @ LUMINANCE for half in "ab")
        half_ratios.append(float(a.mean() / b.mean()))
        for key, value in (("reference", frame["reference"] @ LUMINANCE), ("noisy", noisy), ("output", lit),
                           ("blender", blender[f"spp{spp}_frame{index}"][..., :3] @ LUMINANCE),
                           ("half_a", a), ("half_b", b), ("noisy_top", noisy[top]), ("output_top", lit[top])):
            sums[key] += float(value.sum(dtype=np.float64))
    return {
        "noisy": sums["noisy"] / sums["reference"],
        "output": sums["output"] / sums["reference"],
        "blender": sums["blender"] / sums["reference"],
        "halves": sums["half_a"] / sums["half_b"],
        "halves_min": min(half_ratios),
        "halves_max": max(half_ratios),
        "top_share": sums["noisy_top"] / sums["noisy"],
        "kept": sums["output"] / sums["noisy"],
        "kept_top": sums["output_top"] / sums["noisy_top"],
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", type=pathlib.Path,
                        default=pathlib.Path(os.environ.get("AFFINITY_DATA", cycles.DEFAULT_DATA_DIR)))
    parser.add_argument("--model", required=True, help="LABEL=FILE.affw (or LABEL=builtin)")
    parser.add_argument("--spp", type=lambda text: [int(s) for s in text.split(",")], default=[2, 4, 8])
    parser.add_argument("--out", type=pathlib.Path, required=True, help="markdown file to write")
    args = parser.parse_args(argv)
    label, _, path = args.model.partition("=")
    if not path:
        parser.error("--model expects LABEL=FILE.affw")
    model = None if path == "builtin" else path
    folders = sorted(p for p in (args.data / "val").glob("cycles_*") if (p / "reference_halves.npz").is_file())
    if not folders:
        parser.error(f"no Cycles validation sequences with reference halves in {args.data / 'val'}")

    lines = [f"# Where the light goes on the Cycles suite (model `{label}`)", "",
             f"Command: `{' '.join([os.path.basename(sys.argv[0])] + (argv if argv is not None else sys.argv[1:]))}`",
             "(scripts/cycles_energy.py; brightness = sequence mean / reference mean, luminance).", "",
             "| sequence | spp | noisy | ours | Blender's OIDN | reference half A / B (frames) | top 1 % share "
             "| ours kept (top 1 %) |",
             "|---|---:|---:|---:|---:|---|---:|---|"]
    for folder in folders:
        for spp in args.spp:
            e = sequence_energy(folder, model, spp)
            lines.append(f"| {folder.name} | {spp} | {e['noisy']:.3f} | {e['output']:.3f} | {e['blender']:.3f} | "
                         f"{e['halves']:.3f} ({e['halves_min']:.3f}-{e['halves_max']:.3f}) | {e['top_share']:.2f} | "
                         f"{e['kept']:.3f} ({e['kept_top']:.3f}) |")
            print(lines[-1], flush=True)
    args.out.write_text("\n".join(lines) + "\n")
    print(f"cycles_energy: wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

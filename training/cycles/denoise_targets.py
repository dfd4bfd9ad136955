"""A copy of the Cycles cache whose training targets are denoised by OpenImageDenoise.

A 64-spp target of a dim interior is mostly single bright samples; the losses the trainer uses
(SMAPE, the displayed image's L1) are minimised by something close to a median, so against such
targets the model learns to drop that light (docs/CYCLES_DATA.md, "Brightness"). OpenImageDenoise
on the target (HDR, with the mean albedo and normal of the frame's own input samples) turns that
light into the smooth glow a converged render has, for a small bias. Validation sequences are
linked unchanged: they keep their two-half references.

Runs in the repository's .venv (affinity_core and pyoidn), not in Blender:

    PYTHONPATH=build/python:. .venv/bin/python training/cycles/denoise_targets.py \\
        ~/.cache/affinity/cycles-v1 ~/.cache/affinity/cycles-v1-oidn

A finished sequence (its render_summary.json copied last) is skipped, so it resumes.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import shutil
import sys
import time

import affinity_core
from affinity_bench.methods import oidn_denoise

SUMMARY = "render_summary.json"


def denoise_sequence(source: pathlib.Path, destination: pathlib.Path) -> None:
    """Writes every frame of `source` into `destination` with its reference denoised."""
    work = destination.with_name(destination.name + ".tmp")
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True)
    for path in map(pathlib.Path, affinity_core.list_frame_files(source)):
        frame = affinity_core.read_frame(path)
        if frame["reference"] is None:
            raise ValueError(f"{path}: no reference to denoise")
        frame["reference"] = oidn_denoise(frame["reference"], frame)
        affinity_core.write_frame(work / path.name, frame, compression="none")
    summary = json.loads((source / SUMMARY).read_text())
    summary["reference_denoised"] = "OpenImageDenoise (pyoidn, HDR, the input's mean albedo and normal)"
    (work / SUMMARY).write_text(json.dumps(summary, indent=1))
    shutil.rmtree(destination, ignore_errors=True)
    work.rename(destination)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("source", type=pathlib.Path, help="the cache made by make_data.py")
    parser.add_argument("destination", type=pathlib.Path, help="the copy to write (train/ denoised, val/ linked)")
    args = parser.parse_args(argv)
    sequences = sorted(p for p in (args.source / "train").glob("cycles_*") if (p / SUMMARY).is_file())
    if not sequences:
        parser.error(f"{args.source}/train holds no finished sequence (make it with training/cycles/make_data.py)")
    (args.destination / "val").mkdir(parents=True, exist_ok=True)
    for folder in sorted((args.source / "val").glob("cycles_*")):
        link = args.destination / "val" / folder.name
        if not link.exists():
            link.symlink_to(folder.resolve())
    start = time.monotonic()
    for i, folder in enumerate(sequences):
        destination = args.destination / "train" / folder.name
        if (destination / SUMMARY).is_file():
            continue
        denoise_sequence(folder, destination)
        print(f"denoise_targets: {i + 1}/{len(sequences)} {folder.name} "
              f"({time.monotonic() - start:.0f} s)", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())

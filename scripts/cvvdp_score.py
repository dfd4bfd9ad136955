"""ColorVideoVDP (Mantiuk et al. 2024) of every output sequence a benchmark run saved.

    PYTHONPATH=build/python:. .venv/bin/python -m affinity_bench --config cycles --out OUT --save-outputs FRAMES
    .venv-cvvdp/bin/python scripts/cvvdp_score.py FRAMES --out OUT/cvvdp.csv

ColorVideoVDP is a perceptual full-reference video metric in JOD units (10: indistinguishable
from the reference); flicker counts as people see it. The frames are shown as on an ordinary
display: linear radiance tone-mapped by x / (1 + x), encoded with gamma 1/2.2, on the
`standard_fhd` display model at 24 frames per second. It needs PyTorch from PyPI
(`scripts/setup_cvvdp.sh` makes `.venv-cvvdp`); Debian's python3-torch fails inside it.
Writes a CSV row per (sequence, method, spp) and prints the means per method and spp as a
markdown table (also written beside the CSV as .md). With ``--reference-halves DATA`` the table
is followed by each sequence's reference noise in the same units: one half of its reference
(``DATA/val/<sequence>/reference_halves.npz``, made by training/cycles/make_data.py) scored
against the other.
"""

from __future__ import annotations

import argparse
import collections
import csv
import os
import pathlib
import re
import sys

import numpy as np

DISPLAY = "standard_fhd"
FPS = 24.0
NAME = re.compile(r"^(?P<method>.+)_(?P<spp>\d+)spp\.npy$")


def display_encoded(linear: np.ndarray) -> np.ndarray:
    """[frames, H, W, 3] linear radiance -> display-encoded values in [0, 1)."""
    linear = np.maximum(linear.astype(np.float32), 0.0)
    return (linear / (1.0 + linear)) ** (1.0 / 2.2)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("frames", type=pathlib.Path, help="the --save-outputs folder of a benchmark run")
    parser.add_argument("--out", type=pathlib.Path, required=True, help="CSV to write")
    parser.add_argument("--reference-halves", type=pathlib.Path, metavar="DATA",
                        help="also score each sequence's reference halves against each other")
    args = parser.parse_args(argv)
    import pycvvdp
    import torch

    torch.set_num_threads(max(1, len(os.sched_getaffinity(0))))
    metric = pycvvdp.cvvdp(display_name=DISPLAY, device=torch.device("cpu"))
    rows = []
    sequences = sorted(p for p in args.frames.iterdir() if (p / "reference.npy").is_file())
    if not sequences:
        raise SystemExit(f"cvvdp_score: no sequence folders with reference.npy in {args.frames}")
    for folder in sequences:
        reference = display_encoded(np.load(folder / "reference.npy"))
        for path in sorted(folder.glob("*spp.npy")):
            match = NAME.match(path.name)
            if not match:
                continue
            test = display_encoded(np.load(path))
            if test.shape != reference.shape:
                raise SystemExit(f"cvvdp_score: {path} has shape {test.shape}, the reference {reference.shape}")
            jod, _ = metric.predict(torch.from_numpy(test), torch.from_numpy(reference), dim_order="FHWC",
                                    frames_per_second=FPS)
            rows.append((folder.name, match["method"], int(match["spp"]), float(jod)))
            print(f"{folder.name} {match['method']} {match['spp']} spp: {float(jod):.3f} JOD", flush=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    temporary = args.out.with_suffix(".tmp")
    with open(temporary, "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["sequence", "method", "spp", "cvvdp_jod"])
        writer.writerows(rows)
    os.replace(temporary, args.out)

    means: dict[tuple[str, int], list[float]] = collections.defaultdict(list)
    for _, method, spp, jod in rows:
        means[(method, spp)].append(jod)
    counts = sorted({spp for _, spp in means})
    methods = list(dict.fromkeys(method for _, method, _, _ in rows))
    lines = [f"ColorVideoVDP ({DISPLAY}, {FPS:g} fps, x/(1+x), gamma 1/2.2), JOD, mean over "
             f"{len(sequences)} sequences (`{' '.join(sys.argv)}`)", "",
             "| method | " + " | ".join(f"{c} spp" for c in counts) + " |",
             "|---|" + "---:|" * len(counts)]
    for method in methods:
        cells = [f"{np.mean(means[(method, c)]):.2f}" if (method, c) in means else "" for c in counts]
        lines.append(f"| `{method}` | " + " | ".join(cells) + " |")
    if args.reference_halves is not None:
        lines += reference_noise(metric, [folder.name for folder in sequences], args.reference_halves)
    text = "\n".join(lines) + "\n"
    args.out.with_suffix(".md").write_text(text)
    print(text)
    return 0


def reference_noise(metric: object, names: list[str], data: pathlib.Path) -> list[str]:
    """Markdown lines: per sequence, ColorVideoVDP of its reference's half b against half a."""
    import torch

    lines = ["", "Reference noise: half b of each reference scored against half a (each half has "
             "half the reference's samples, so twice its variance)", "",
             "| sequence | JOD |", "|---|---:|"]
    for name in names:
        halves_file = data / "val" / name / "reference_halves.npz"
        if not halves_file.is_file():
            raise SystemExit(f"cvvdp_score: {halves_file} is missing")
        halves = np.load(halves_file)
        count = sum(1 for key in halves.files if key.startswith("a_frame"))
        a, b = (display_encoded(np.stack([halves[f"{half}_frame{i}"] for i in range(count)]))
                for half in "ab")
        jod, _ = metric.predict(torch.from_numpy(b), torch.from_numpy(a), dim_order="FHWC",
                                frames_per_second=FPS)
        lines.append(f"| {name} | {float(jod):.2f} |")
        print(f"{name} reference half b against half a: {float(jod):.3f} JOD", flush=True)
    return lines


if __name__ == "__main__":
    sys.exit(main())

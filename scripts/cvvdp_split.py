"""Where a ColorVideoVDP gap comes from: space, time, or the sequence's first frames.

    .venv-cvvdp/bin/python scripts/cvvdp_split.py FRAMES --methods ours-cycles,blender-oidn --spp 4 \
        --out results/bench_cycles/cvvdp_split.md

FRAMES is the --save-outputs folder of a Cycles benchmark run (as for scripts/cvvdp_score.py,
whose display model and tone mapping this uses). Per sequence and method:
- video: the JOD of the whole sequence (what cvvdp_score.py reports);
- images: the mean JOD of each frame judged as a still image (no temporal channel): the
  spatial quality alone; video below images is what the eye sees change over time;
- first image: the first frame's image JOD (no history: a temporal denoiser starts cold);
- video from frame N: the JOD of the sequence without its first N frames, once the history has
  built up.
"""

from __future__ import annotations

import argparse
import os
import pathlib
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from cvvdp_score import DISPLAY, FPS, display_encoded  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("frames", type=pathlib.Path, help="the --save-outputs folder of a benchmark run")
    parser.add_argument("--methods", default="ours-cycles,blender-oidn")
    parser.add_argument("--spp", type=int, default=4)
    parser.add_argument("--skip", type=int, default=3, help="N of 'video from frame N'")
    parser.add_argument("--out", type=pathlib.Path, required=True, help="markdown file to write")
    args = parser.parse_args(argv)
    import pycvvdp
    import torch

    torch.set_num_threads(max(1, len(os.sched_getaffinity(0))))
    metric = pycvvdp.cvvdp(display_name=DISPLAY, device=torch.device("cpu"))

    def jod(test: np.ndarray, reference: np.ndarray, video: bool) -> float:
        value, _ = metric.predict(torch.from_numpy(test), torch.from_numpy(reference),
                                  dim_order="FHWC" if video else "HWC",
                                  **({"frames_per_second": FPS} if video else {}))
        return float(value)

    methods = args.methods.split(",")
    sequences = sorted(p for p in args.frames.iterdir() if (p / "reference.npy").is_file())
    if not sequences:
        raise SystemExit(f"cvvdp_split: no sequence folders with reference.npy in {args.frames}")
    command = " ".join([os.path.basename(sys.argv[0])] + (argv if argv is not None else sys.argv[1:]))
    lines = [f"# ColorVideoVDP split by space, time and the first frames ({args.spp} spp)", "",
             f"Command: `{command}` (scripts/cvvdp_split.py; {DISPLAY}, {FPS:g} fps, x/(1+x), gamma 1/2.2). "
             "JOD: 10 = indistinguishable from the reference. *video*: the sequence; *images*: mean of the "
             "frames judged as stills (space alone); *first*: the first frame as a still; "
             f"*from {args.skip}*: the sequence without its first {args.skip} frames.", "",
             "| sequence | " + " | ".join(f"{m} video / images / first / from {args.skip}" for m in methods) + " |",
             "|---|" + "---|" * len(methods)]
    for folder in sequences:
        reference = display_encoded(np.load(folder / "reference.npy"))
        cells = []
        for method in methods:
            path = folder / f"{method}_{args.spp}spp.npy"
            if not path.is_file():
                cells.append("")
                continue
            test = display_encoded(np.load(path))
            images = [jod(test[i], reference[i], video=False) for i in range(len(reference))]
            cells.append(f"{jod(test, reference, True):.2f} / {np.mean(images):.2f} / {images[0]:.2f} / "
                         f"{jod(test[args.skip:], reference[args.skip:], True):.2f}")
        lines.append(f"| {folder.name} | " + " | ".join(cells) + " |")
        print(lines[-1], flush=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text("\n".join(lines) + "\n")
    print(f"cvvdp_split: wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

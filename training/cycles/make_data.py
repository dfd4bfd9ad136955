"""Renders Cycles training and validation sequences into a cache outside the repository.

    .venv-blender/bin/python training/cycles/make_data.py [--out DIR] [--train-seeds 0-99]
        [--val-seeds 9000-9005] [--frames 8] [--train-frames 6] [--size 160x96] [--spp 8] [--train-target-spp 64]
        [--val-target-spp 256] [--blender-oidn-spp 2,4,8] [--threads 2]

Each sequence is a scene of the generator (scene_generator.py) by seed, captured by capture.py:
``OUT/train/cycles_NNNNN`` with one independent noisy target per frame (Noise2Noise),
``OUT/val/cycles_NNNNN`` with two (their mean the reference, their difference its noise) and
Blender's own denoiser at the benchmark's sample counts. A sequence is rendered into a
temporary folder and renamed when complete, so the command can be stopped at any time and run
again to continue; finished sequences are skipped. The default cache is
``$AFFINITY_DATA`` or ``~/.cache/affinity/cycles-v1``.
"""

from __future__ import annotations

import argparse
import glob
import os
import shutil
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
for path in (HERE, os.path.join(ROOT, "blender_addon"), os.path.join(ROOT, "build", "python")):
    if path not in sys.path:
        sys.path.append(path)


import capture  # noqa: E402
import scene_generator  # noqa: E402

import affinity_denoiser  # noqa: E402


def seed_list(text: str) -> list[int]:
    """"a-b,c" -> [a..b, c]."""
    seeds: list[int] = []
    for part in filter(None, text.split(",")):
        if "-" in part:
            first, last = part.split("-")
            seeds.extend(range(int(first), int(last) + 1))
        else:
            seeds.append(int(part))
    return seeds


def size(text: str) -> tuple[int, int]:
    width, _, height = text.partition("x")
    if not (width.isdigit() and height.isdigit()) or int(width) < 8 or int(height) < 8:
        raise argparse.ArgumentTypeError(f"size must be WxH with both at least 8, not '{text}'")
    return int(width), int(height)


def spp_list(text: str) -> tuple[int, ...]:
    return tuple(int(s) for s in text.split(",") if s)


def render_sequence(split: str, seed: int, folder: str, args: argparse.Namespace) -> None:
    width, height = args.size
    validation = split == "val"
    frames = args.frames if validation else args.train_frames
    scene = scene_generator.build_scene(seed, width=width, height=height, frames=frames,
                                        threads=args.threads)
    scene.cycles.seed = seed
    # Artists render with and without an animated seed: both noise behaviours over time.
    scene.cycles.use_animated_seed = seed % 2 == 0
    settings = capture.CaptureSettings(
        spp=args.spp,
        target_spp=args.val_target_spp if validation else args.train_target_spp,
        targets=2 if validation else 1,
        blender_oidn_spp=args.blender_oidn_spp if validation else (),
    )
    for stale in glob.glob(glob.escape(folder) + ".tmp-*"):  # left by a stopped run
        shutil.rmtree(stale, ignore_errors=True)
    temporary = folder + f".tmp-{os.getpid()}"
    summary = capture.capture_sequence(scene, temporary, settings)
    os.replace(temporary, folder)
    kind = scene_generator.describe(scene)["kind"]
    seconds = summary["seconds"]
    print(f"{split} cycles_{seed:05d} ({kind}) done: input {seconds['input']:.1f} s, "
          f"targets {seconds['targets']:.1f} s", flush=True)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default=os.environ.get(
        "AFFINITY_DATA", os.path.expanduser("~/.cache/affinity/cycles-v1")))
    parser.add_argument("--train-seeds", type=seed_list, default=seed_list("0-99"))
    parser.add_argument("--val-seeds", type=seed_list, default=seed_list("9000-9005"))
    parser.add_argument("--frames", type=int, default=8, help="frames of a validation sequence")
    parser.add_argument("--train-frames", type=int, default=6, help="frames of a training sequence")
    parser.add_argument("--size", type=size, default=(160, 96))
    parser.add_argument("--spp", type=int, default=8)
    parser.add_argument("--train-target-spp", type=int, default=64)
    parser.add_argument("--val-target-spp", type=int, default=256)
    parser.add_argument("--blender-oidn-spp", type=spp_list, default=(2, 4, 8))
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args(argv)
    if min(args.frames, args.train_frames) < 2:
        parser.error("--frames and --train-frames must be at least 2 (motion needs a previous frame)")

    affinity_denoiser.register()
    jobs = [("val", s) for s in args.val_seeds] + [("train", s) for s in args.train_seeds]
    todo = [(split, seed, os.path.join(args.out, split, f"cycles_{seed:05d}"))
            for split, seed in jobs]
    todo = [job for job in todo if not os.path.isfile(os.path.join(job[2], "render_summary.json"))]
    print(f"make_data: {len(jobs) - len(todo)} of {len(jobs)} sequences already in {args.out}",
          flush=True)
    start = time.perf_counter()
    for done, (split, seed, folder) in enumerate(todo):
        os.makedirs(os.path.dirname(folder), exist_ok=True)
        render_sequence(split, seed, folder, args)
        elapsed = time.perf_counter() - start
        left = elapsed / (done + 1) * (len(todo) - done - 1)
        print(f"make_data: {done + 1}/{len(todo)}, {elapsed / 60:.1f} min, "
              f"about {left / 60:.0f} min left", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Renders Cycles training and validation sequences into a cache outside the repository.

    .venv-blender/bin/python training/cycles/make_data.py [--out DIR] [--train-seeds 0-99]
        [--val-seeds 9000-9005] [--frames 8] [--train-frames 6] [--size 160x96] [--spp 8] [--train-target-spp 64]
        [--val-target-spp 256] [--blender-oidn-spp 2,4,8] [--preroll-frames 8] [--threads 2]
        [--refresh-inputs] [--deepen-references] [--input-draw N --references-from DIR]

Each sequence is a scene of the generator (scene_generator.py) by seed, captured by capture.py:
``OUT/train/cycles_NNNNN`` with one independent noisy target per frame (Noise2Noise),
``OUT/val/cycles_NNNNN`` with two (their mean the reference, their difference its noise),
Blender's own denoiser at the benchmark's sample counts and the extension's pre-roll of the
first frame (added to complete sequences that lack it). A sequence is rendered into a
temporary folder and renamed when complete, so the command can be stopped at any time and run
again to continue; finished sequences are skipped. The default cache is
``$AFFINITY_DATA`` or ``~/.cache/affinity/cycles-v1``.

``--input-draw N --references-from DIR`` (N >= 1) captures the validation sequences of DIR again
with other noise: the inputs, the pre-roll and Blender's own denoiser from the seed moved N
strides (``capture.INPUT_DRAW_SEED_STRIDE``), the references taken from DIR's, into ``--out``:
a cache the benchmark reads as it reads DIR, for scoring methods over several draws of the same
scenes (docs/CYCLES_DATA.md, "Draws"). Training sequences are not drawn again.
"""

from __future__ import annotations

import argparse
import glob
import json
import math
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
from affinity_denoiser.pipeline import DEFAULT_PREROLL_FRAMES, automatic_preroll_samples  # noqa: E402


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
    """Renders the sequence of ``seed`` into ``folder``; where ``folder`` is complete, captures
    its inputs again (an older capture version), deepens its references
    (``args.deepen_references``, validation only) or adds the pre-roll it lacks."""
    width, height = args.size
    validation = split == "val"
    frames = args.frames if validation else args.train_frames
    scene = scene_generator.build_scene(seed, width=width, height=height, frames=frames,
                                        threads=args.threads)
    scene.cycles.seed = seed + args.input_draw * capture.INPUT_DRAW_SEED_STRIDE
    # Artists render with and without an animated seed: both noise behaviours over time.
    scene.cycles.use_animated_seed = seed % 2 == 0
    settings = capture.CaptureSettings(
        spp=args.spp,
        target_spp=args.val_target_spp if validation else args.train_target_spp,
        targets=2 if validation else 1,
        blender_oidn_spp=args.blender_oidn_spp if validation else (),
        preroll_frames=args.preroll_frames if validation else 0,
    )
    for stale in glob.glob(glob.escape(folder) + ".tmp-*") + glob.glob(glob.escape(folder) + ".old-*"):
        shutil.rmtree(stale, ignore_errors=True)  # left by a stopped run
    temporary = folder + f".tmp-{os.getpid()}"
    summary = sequence_summary(folder)
    deepen = needs_deeper_references(split, summary, args)
    if summary is None and args.input_draw:
        reference_folder = os.path.join(args.references_from, split, os.path.basename(folder))
        summary = capture.capture_input_draw(scene, temporary, reference_folder, args.input_draw, settings)
        os.replace(temporary, folder)
    elif summary is None:
        summary = capture.capture_sequence(scene, temporary, settings)
        os.replace(temporary, folder)
    elif deepen or capture_version(folder) != capture.CAPTURE_VERSION:
        if deepen:
            summary = capture.deepen_references(scene, temporary, folder, args.val_target_spp)
        else:
            summary = capture.refresh_inputs(scene, temporary, folder, settings)
        # Two renames: a stop between them leaves the complete old sequence in .old-*, which
        # the next run puts back (restore_interrupted_refresh, in main) and processes again.
        old = folder + f".old-{os.getpid()}"
        os.replace(folder, old)
        os.replace(temporary, folder)
        shutil.rmtree(old)
    if missing_preroll(split, folder, args):
        summary = capture.add_preroll(scene, folder, settings)  # one file added, atomically
    kind = scene_generator.describe(scene)["kind"]
    seconds = summary["seconds"]
    preroll = f", pre-roll {seconds['preroll']:.1f} s" if "preroll" in seconds else ""
    print(f"{split} cycles_{seed:05d} ({kind}) done: input {seconds['input']:.1f} s, "
          f"targets {seconds['targets']:.1f} s{preroll}", flush=True)


def restore_interrupted_refresh(folder: str) -> bool:
    """Puts back a complete sequence that a refresh stopped between its two renames left in
    ``folder``.old-*: its targets took far longer to render than its inputs. True if it did."""
    if os.path.isdir(folder):
        return False
    for old in sorted(glob.glob(glob.escape(folder) + ".old-*")):
        if capture_version(old) is not None:
            os.replace(old, folder)
            return True
    return False


def sequence_summary(folder: str) -> dict | None:
    """A complete sequence's render_summary.json; None where the sequence is not complete."""
    try:
        with open(os.path.join(folder, "render_summary.json")) as handle:
            return json.load(handle)
    except FileNotFoundError:
        return None


def needs_deeper_references(split: str, summary: dict | None, args: argparse.Namespace) -> bool:
    """With --deepen-references: a complete validation sequence whose reference halves have
    fewer than --val-target-spp samples."""
    return (args.deepen_references and split == "val" and summary is not None
            and summary["reference_spp"] < 2 * args.val_target_spp)


def missing_preroll(split: str, folder: str, args: argparse.Namespace) -> bool:
    """A complete validation sequence without the pre-roll that --preroll-frames asks for."""
    summary = sequence_summary(folder)
    return (split == "val" and summary is not None
            and int(summary.get("preroll_frames", 0)) < args.preroll_frames)


def capture_version(folder: str) -> int | None:
    """The capture path that made a complete sequence's inputs (1: before the field existed);
    None where the sequence is not complete."""
    summary = sequence_summary(folder)
    return None if summary is None else int(summary.get("capture_version", 1))


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
    parser.add_argument("--preroll-frames", type=int, default=None,
                        help="keep this many pre-roll frames of --spp samples of each validation "
                             "sequence's first frame, as the extension renders them (preroll.npz), added "
                             "to complete sequences that lack them; the benchmark pools them into the "
                             "extension's pre-roll (default: enough for its default pre-roll)")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--refresh-inputs", action="store_true",
                        help="capture again the inputs of sequences made by an older capture path "
                             "(capture.CAPTURE_VERSION), keeping their targets and Blender's frames")
    parser.add_argument("--deepen-references", action="store_true",
                        help="add samples to the reference halves of complete validation sequences "
                             "until each half has --val-target-spp, keeping their inputs")
    parser.add_argument("--input-draw", type=int, default=0, metavar="N",
                        help="capture the validation sequences of --references-from again with the "
                             "input's seed moved N strides, keeping their references (N >= 1)")
    parser.add_argument("--references-from", metavar="DIR",
                        help="the cache whose validation sequences --input-draw draws again")
    args = parser.parse_args(argv)
    if args.input_draw < 0:
        parser.error(f"--input-draw must be at least 1, not {args.input_draw}")
    if bool(args.input_draw) != bool(args.references_from):
        parser.error("--input-draw and --references-from go together")
    if args.input_draw:
        if os.path.realpath(args.out) == os.path.realpath(args.references_from):
            parser.error("--out must be another cache than --references-from")
        if args.deepen_references or args.refresh_inputs:
            parser.error("--input-draw takes the references as they are: no --deepen-references or "
                         "--refresh-inputs")
        args.train_seeds = []  # only the benchmark's sequences are drawn again
        missing = [s for s in args.val_seeds if sequence_summary(
            os.path.join(args.references_from, "val", f"cycles_{s:05d}")) is None]
        if missing:
            parser.error(f"{args.references_from} lacks the complete validation sequences of seeds "
                         f"{', '.join(map(str, missing))} (make_data.py --out {args.references_from} makes them)")
    if args.preroll_frames is None:
        args.preroll_frames = math.ceil(DEFAULT_PREROLL_FRAMES * automatic_preroll_samples(args.spp) / args.spp)
    if args.deepen_references and args.refresh_inputs:
        parser.error("--deepen-references and --refresh-inputs are separate runs")
    if min(args.frames, args.train_frames) < 2:
        parser.error("--frames and --train-frames must be at least 2 (motion needs a previous frame)")

    affinity_denoiser.register()
    jobs = [("val", s) for s in args.val_seeds] + [("train", s) for s in args.train_seeds]
    todo = [(split, seed, os.path.join(args.out, split, f"cycles_{seed:05d}"))
            for split, seed in jobs]
    for job in todo:
        if restore_interrupted_refresh(job[2]):
            print(f"make_data: {job[2]} put back from a stopped refresh", flush=True)
    versions = {job[2]: capture_version(job[2]) for job in todo}
    stale = [job for job in todo if versions[job[2]] not in (None, capture.CAPTURE_VERSION)]
    todo = [job for job in todo if versions[job[2]] is None or (args.refresh_inputs and job in stale)
            or needs_deeper_references(job[0], sequence_summary(job[2]), args)
            or (versions[job[2]] == capture.CAPTURE_VERSION and missing_preroll(job[0], job[2], args))]
    print(f"make_data: {len(jobs) - len(todo)} of {len(jobs)} sequences already in {args.out}",
          flush=True)
    if stale and not args.refresh_inputs:
        print(f"make_data: {len(stale)} of them come from an older capture path "
              f"(capture version < {capture.CAPTURE_VERSION}); --refresh-inputs captures their inputs again",
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

"""python -m affinity_bench: see the package docstring and docs/BENCHMARK.md."""

from __future__ import annotations

import argparse
import datetime
import importlib.metadata
import os
import pathlib
import platform
import shlex
import sys
import time
from collections.abc import Callable

import numpy as np

from . import REPOSITORY, cycles, report
from .config import CONFIGS, Config
from .data import (
    DEFAULT_DATA_DIR,
    ensure_second_reference,
    ensure_sequence,
    find_affinity_binary,
    load_references,
    load_sequence,
)
from .evaluate import EQUAL_TIME_METHODS, SequenceResult, evaluate_sequence, reference_noise
from .methods import BUILT_IN, Method, make_methods


def parse_spp_list(text: str) -> tuple[int, ...]:
    counts = []
    for part in text.split(","):
        part = part.strip()
        if not part.isdigit() or not 1 <= int(part) <= 64:
            raise argparse.ArgumentTypeError(f"'{part}' is not a sample count in 1..64")
        counts.append(int(part))
    return tuple(sorted(set(counts)))


def parse_model(text: str) -> tuple[str, str]:
    label, separator, path = text.partition("=")
    if not separator or not label or not path or not label.replace("_", "").replace("-", "").isalnum():
        raise argparse.ArgumentTypeError(f"'{text}' is not LABEL=PATH (LABEL: letters, digits, _ and -)")
    return label, path


def parse_arguments(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        prog="python -m affinity_bench",
        description="Error against time of our denoiser and its competitors on the same frames; "
                    "stability on the failure-case scenes. Speed at 1080p: scripts/bench_denoiser.sh.")
    parser.add_argument("--out", required=True, type=pathlib.Path, help="output folder (created)")
    parser.add_argument("--config", choices=sorted(CONFIGS), default="full",
                        help="full (the documented benchmark), tiny (CI) or cycles (Blender renders, "
                             "docs/CYCLES_DATA.md); default full")
    parser.add_argument("--data", type=pathlib.Path,
                        help=f"render cache (default $AFFINITY_BENCH_DATA or {DEFAULT_DATA_DIR}; for the "
                             f"cycles config $AFFINITY_DATA or {cycles.DEFAULT_DATA_DIR})")
    parser.add_argument("--affinity-bin", help="the affinity program (default $AFFINITY_BIN or <build>/core/affinity)")
    parser.add_argument("--model", type=parse_model, action="append", default=[], metavar="LABEL=PATH",
                        help=f"a model of the ladder, repeatable; PATH '{BUILT_IN}' is the built-in model, "
                             "PATH:bf16 the model with bfloat16 products (CPUs with AVX512-BF16). The first "
                             "one's ablations run too. Default: small=builtin and the ladder's other models in "
                             "core/models of this repository (tiny, medium)")
    parser.add_argument("--methods", help="comma-separated method labels to run (default: all)")
    parser.add_argument("--sequences", help="comma-separated sequence names to run (default: the config's)")
    parser.add_argument("--spp", type=parse_spp_list, metavar="S,...",
                        help="input samples per pixel of the main comparison, e.g. 1,16,32 (default: the config's; "
                             "full: 2,4,8); the crops use the config's count if listed, else the first")
    parser.add_argument("--reference-spp", type=int, help="override the config's reference samples per pixel")
    parser.add_argument("--reference-noise", action=argparse.BooleanOptionalAction,
                        help="render a second reference per sequence and score it against the first "
                             "(default: on)")
    parser.add_argument("--save-outputs", type=pathlib.Path, metavar="DIR",
                        help="write every method's output frames (and the references) as .npy files into "
                             "DIR/<sequence>/<method>_<spp>spp.npy, e.g. for scripts/cvvdp_score.py")
    return parser.parse_args(argv)


def default_models(notice: Callable[[str], None]) -> list[tuple[str, str]]:
    models = [("small", BUILT_IN)]
    # The other trained rungs of the model ladder (docs/TRAINING.md), smallest first.
    for label in ("tiny", "medium"):
        file = f"core/models/{label}.affw"
        if (REPOSITORY / file).is_file():
            models.append((label, str(REPOSITORY / file)))
        else:
            notice(f"ours-{label} skipped: {file} not found (pass --model)")
    return models


def configure(args: argparse.Namespace) -> Config:
    config = CONFIGS[args.config]
    if args.sequences:
        wanted = [name.strip() for name in args.sequences.split(",") if name.strip()]
        known = {s.name: s for s in config.sequences}
        unknown = [name for name in wanted if name not in known]
        if unknown:
            raise SystemExit(f"bench: unknown sequence(s) {', '.join(unknown)} (config {config.name} has "
                             f"{', '.join(known)})")
        config = config.with_overrides(sequences=tuple(known[name] for name in wanted))
    if args.spp:
        chart_spp = config.chart_spp if config.chart_spp in args.spp else args.spp[0]
        config = config.with_overrides(spp=args.spp, chart_spp=chart_spp)
    if args.reference_spp is not None:
        config = config.with_overrides(reference_spp=args.reference_spp)
    if args.reference_noise is not None:
        config = config.with_overrides(reference_noise=args.reference_noise)
    return config


def select_methods(methods: list[Method], wanted: str | None) -> list[Method]:
    if not wanted:
        return methods
    labels = [label.strip() for label in wanted.split(",") if label.strip()]
    known = {m.label: m for m in methods}
    unknown = [label for label in labels if label not in known]
    if unknown:
        raise SystemExit(f"bench: unknown method(s) {', '.join(unknown)} (available: {', '.join(known)})")
    return [known[label] for label in labels]


def version(package: str) -> str:
    try:
        return importlib.metadata.version(package)
    except importlib.metadata.PackageNotFoundError:
        return "not installed"


def machine_text() -> str:
    cpu = platform.processor() or "unknown CPU"
    try:
        for line in pathlib.Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    threads = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return f"{cpu}, {threads} hardware threads usable, Python {platform.python_version()}"


def evaluate_cycles_sequence(data: pathlib.Path, seed: int, methods: list[Method],
                             config: Config, keep_outputs: bool
                             ) -> tuple[list[SequenceResult], SequenceResult | None, list[np.ndarray]]:
    """A Cycles validation sequence (cycles.py): every method, plus Blender's own denoiser,
    whose time is its whole render. Also the reference noise and the references."""
    sequence = cycles.CyclesSequence(cycles.sequence_folder(data, seed))
    name = sequence.folder.name
    blender = sequence.blender_oidn_method()
    everything = methods + ([blender] if blender else [])
    if max(config.spp) > sequence.render_spp:
        raise SystemExit(f"bench: {sequence.folder} has {sequence.render_spp} samples per pixel, "
                         f"{max(config.spp)} asked")
    equal_time = tuple(s for s in config.equal_time_spp if s <= sequence.render_spp)
    results = evaluate_sequence(name, False, sequence.frames, sequence.noisy_seconds_per_frame,
                                sequence.render_spp, everything, config.spp, equal_time,
                                config.chart_spp, config.timing_runs, keep_outputs, sequence.preroll)
    for result in results:
        if result.method == cycles.BLENDER_OIDN:
            result.render_seconds_per_frame = sequence.blender_oidn_seconds(result.spp)
            for frame in result.frames:
                frame.seconds = 0.0
    second = sequence.second_reference()
    noise = None
    if second is not None and config.reference_noise:
        images, frames = second
        noise = reference_noise(name, False, frames, images)
    return results, noise, [frame["reference"] for frame in sequence.frames]


def save_outputs(folder: pathlib.Path, sequence: str, results: list[SequenceResult],
                 references: list[np.ndarray]) -> None:
    """Each result's output frames, and the references, as float32 arrays [frames, H, W, 3]."""
    target = folder / sequence
    target.mkdir(parents=True, exist_ok=True)
    np.save(target / "reference.npy", np.stack(references))
    for result in results:
        if result.outputs is not None:
            np.save(target / f"{result.method}_{result.spp}spp.npy", np.stack(result.outputs))


def crop_chart(results: list[SequenceResult], reference, sequence: str, spp: int, out: pathlib.Path) -> None:
    outputs = {r.method: r.last_output for r in results if r.spp == spp and r.last_output is not None}
    ours = next((r.method for r in results if r.family == "ours" and r.method in outputs), None)
    panels = [(label, outputs[label]) for label in ("noisy", ours, cycles.BLENDER_OIDN, "oidn", "svgf")
              if label in outputs]
    if panels:
        report.chart_crops(panels, reference, ours or panels[0][0], sequence, spp, out / f"crops_{sequence}.png")


def main(argv: list[str] | None = None) -> None:
    argv = sys.argv[1:] if argv is None else argv
    args = parse_arguments(argv)
    config = configure(args)
    if args.data is None:
        args.data = (pathlib.Path(os.environ.get("AFFINITY_DATA", cycles.DEFAULT_DATA_DIR)) if config.name == "cycles"
                     else pathlib.Path(os.environ.get("AFFINITY_BENCH_DATA", DEFAULT_DATA_DIR)))
    started = time.perf_counter()
    load_at_start = os.getloadavg()[0]
    out: pathlib.Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    notices: list[str] = []

    def notice(text: str) -> None:
        print(f"bench: notice: {text}", flush=True)
        notices.append(text)

    models = args.model or default_models(notice)
    methods = select_methods(make_methods(models), args.methods)
    binary = find_affinity_binary(args.affinity_bin)
    print(f"bench: config {config.name}: {len(config.sequences)} sequences, {config.frames} frames "
          f"{config.width}x{config.height}, spp {config.spp}, reference {config.reference_spp} spp; methods "
          f"{', '.join(m.label for m in methods)}", flush=True)

    results: list[SequenceResult] = []
    noise: list[SequenceResult] = []  # the second reference against the first, per sequence
    for sequence in config.sequences:
        start = time.perf_counter()
        if config.name == "cycles":
            mine, second_reference, references = evaluate_cycles_sequence(
                args.data, sequence.seed, methods, config, args.save_outputs is not None)
            if second_reference is not None:
                noise.append(second_reference)
        else:
            folder = ensure_sequence(args.data, sequence, config, binary)
            frames, noisy_seconds = load_sequence(folder)
            references = [frame["reference"] for frame in frames]
            if config.reference_noise:
                second = load_references(ensure_second_reference(args.data, sequence, config, binary))
                noise.append(reference_noise(sequence.name, sequence.failure_case, frames, second))
            mine = evaluate_sequence(sequence.name, sequence.failure_case, frames, noisy_seconds, config.render_spp,
                                     methods, config.spp, config.equal_time_spp, config.chart_spp,
                                     config.timing_runs, args.save_outputs is not None)
        if sequence.failure_case or config.name == "cycles":
            report.chart_temporal_error(mine, sequence.name, config.spp, out / f"temporal_error_{sequence.name}.png")
            crop_chart(mine, references[-1], sequence.name, config.chart_spp, out)
        if args.save_outputs is not None:
            save_outputs(args.save_outputs, sequence.name, mine, references)
        for result in mine:
            result.last_output = None
            result.outputs = None
        results += mine
        at = [r for r in mine if r.spp == config.chart_spp]
        print(f"bench: {sequence.name} in {time.perf_counter() - start:.1f} s; SMAPE at {config.chart_spp} spp: "
              + ", ".join(f"{r.method} {r.mean('smape'):.4f}" for r in at), flush=True)

    header, rows = report.result_rows(results)
    report.write_csv(out / "results.csv", header, rows)
    header, rows = report.per_frame_rows(results)
    report.write_csv(out / "per_frame.csv", header, rows)
    if noise:
        header, rows = report.reference_noise_rows(noise)
        report.write_csv(out / "reference_noise.csv", header, rows)
    for count in config.spp:
        report.chart_error_vs_time(results, count, out / f"error_vs_time_{count}spp.png", config.name)
    equal_time = [m.label for m in methods if m.family == "ours" or m.label in EQUAL_TIME_METHODS]
    if config.name == "cycles":
        equal_time.append(cycles.BLENDER_OIDN)
    points = report.equal_time_points(results, equal_time)
    if points:
        report.chart_equal_time(points, out / "equal_time.png", config.name)

    elapsed = time.perf_counter() - started
    load = (load_at_start, os.getloadavg()[0])
    if config.name == "cycles":
        methods = methods + [cycles.blender_oidn_description()]
    report.write_text(out / "results.md", results_markdown(argv, config, methods, results, noise, points,
                                                          notices, elapsed, load))
    print(f"bench: done in {elapsed:.0f} s -> {out}", flush=True)


def results_markdown(argv: list[str], config: Config, methods: list[Method], results: list[SequenceResult],
                     noise: list[SequenceResult], points: dict, notices: list[str], elapsed: float,
                     load: tuple[float, float]) -> str:
    sequences = ", ".join(s.name for s in config.sequences)
    # Sequences with per-frame charts and crops: the failure cases, or every Cycles scene.
    failure_cases = [s.name for s in config.sequences if s.failure_case or config.name == "cycles"]
    text = f"# Benchmark results ({config.name} configuration)\n\n"
    text += f"Command: `python -m affinity_bench {shlex.join(argv)}`, {elapsed:.0f} s, "
    text += f"{datetime.date.today().isoformat()}.  \n"
    text += (f"Machine: {machine_text()}; 1-minute load average {load[0]:.1f} at the start, {load[1]:.1f} at the "
             f"end (timings are wall-clock: other work on the machine inflates them); pyoidn {version('pyoidn')}, "
             f"flip-evaluator {version('flip-evaluator')}.\n\n")
    if config.name == "cycles":
        text += cycles.SUITE_TEXT
    else:
        text += (f"Sequences ({len(config.sequences)}): {sequences}; {config.frames} frames of "
             f"{config.width}x{config.height}, references of {config.reference_spp} spp. Each sequence is rendered "
                 f"once at {config.render_spp} spp and an S-spp input is the first S samples of every pixel. Render "
                 f"time at S spp: a render of the same frames without reference (`affinity render --reference-spp "
                 f"0`, path tracing only) scaled by S/{config.render_spp}. ")
    text += (f"Metrics: means over frames, the temporal "
             f"error over frames 2..N (docs/BENCHMARK.md). Time: each sequence is denoised {config.timing_runs} "
             f"times by a fresh instance of each method; per frame the fastest call counts; ms/Mpx is the median "
             f"over frames 2..N of that, then the mean over sequences.\n")
    if notices:
        text += "\nNotices:\n" + "".join(f"- {n}\n" for n in notices)
    text += "\n## Quality and speed\n"
    text += report.summary_markdown(results, config.spp, {m.label: m.description for m in methods})
    text += "\n" + "".join(f"![error against time, {c} spp](error_vs_time_{c}spp.png)\n" for c in config.spp)
    if points:
        text += "\n## Equal time\n\nSMAPE against render + denoise time per frame, means over sequences.\n\n"
        text += report.equal_time_markdown(points) + "\n![equal time](equal_time.png)\n"
    if failure_cases:
        text += "\n## Temporal error per frame\n\n"
        text += "".join(f"![temporal error, {n}](temporal_error_{n}.png)\n" for n in failure_cases)
        text += f"\n## Crops of the last frame, {config.chart_spp} spp\n\n"
        text += "".join(f"![crops, {n}](crops_{n}.png)\n" for n in failure_cases)
    if noise:
        second = (cycles.SECOND_REFERENCE_TEXT if config.name == "cycles" else
                  f"A second {config.reference_spp}-spp reference of every sequence, rendered with other "
                  "random numbers")
        text += "\n## Reference noise\n\n" + report.reference_noise_markdown(noise, second)
    text += "\n## Per sequence\n" + report.per_scene_markdown(results, config.spp)
    return text


if __name__ == "__main__":
    main()

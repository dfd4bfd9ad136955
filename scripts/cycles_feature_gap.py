"""What the Cycles feature differences cost in denoising quality (docs/BLENDER.md, "Feature mapping").

Renders the benchmark's sequences (python -m affinity_bench's `full` config: the seven
failure-case scenes and four held-out procedural seeds, same seeds, size and frames) twice at
the largest sample count, with `affinity render --feature-convention renderer` and `cycles`:
the same paths and radiance, only the features differ (path_tracer.h). Both are denoised at each
sample count with the built-in model (temporal, a fresh Denoiser per sequence) and with
OpenImageDenoise (colour + albedo + normal), and measured against the benchmark's 1024-spp
references (its render cache; rendered first if missing). Writes a markdown report.

    PYTHONPATH=build-gap/python:. .venv/bin/python scripts/cycles_feature_gap.py \
        --affinity-bin build-gap/core/affinity --out results/cycles_feature_gap.md
"""

from __future__ import annotations

import argparse
import os
import pathlib
import shlex
import subprocess
import sys
import time
from typing import Any

import numpy as np

import affinity_core
from affinity_bench.config import FULL, Sequence
from affinity_bench.data import DEFAULT_DATA_DIR, ensure_sequence, find_affinity_binary, with_spp
from affinity_bench.methods import BUILT_IN, make_methods
from affinity_core import metrics

CONVENTIONS = ("renderer", "cycles")
#: What FeatureConvention::Cycles (core/render/path_tracer.cpp, CyclesFeatures) reproduces.
EMULATION_NOTES = [
    "Emulated (docs/BLENDER.md, \"Feature mapping\", as the extension's features.py maps Cycles' passes):",
    "",
    "- normal, depth, albedo at the first vertex that Cycles does not count as specular: conductors and",
    "  glass of GGX alpha <= 0.075 (roughness <= 0.274) are passed through, ours only below roughness",
    "  0.02; albedo multiplied by the passed vertices' reflectance (the chain's tint), clamped to [0, 1];",
    "- a pure emitter (black reflectance, all bundled lamps) has no BSDF: normal and albedo 0 there, depth",
    "  its path length; one seen only through mirrors / clear glass, and any path that reached no BSDF,",
    "  is a miss (depth, roughness 0, emissive 1);",
    "- roughness, metallic, transmissive are the first hit's (shader AOVs): a mirror reports roughness",
    "  0.02 and metallic 1, clear glass transmissive 1 also where the path reflected; metallic 0 on a",
    "  miss, transmissive not;",
    "- emissive = miss or an emitting first hit; specular_bounce = a first hit exists and the features",
    "  were written past it or the sample is a miss (features.py's rule);",
    "- diffuse / specular split at the first hit's closures (Cycles' light passes): everything seen",
    "  through a mirror or glass is specular.",
    "",
    "Not emulated: Cycles' closure mix (a vertex is specular when >= 75 % of its closures' sample weight",
    "is; our materials have one lobe, plastic counts as diffuse), Cycles' Fresnel-dependent albedo of",
    "microfacet closures (we use the F0 / tint colour), the plastic coat's albedo added to Cycles'",
    "denoising albedo when its roughness is above the threshold, two-sided emission, the Denoising",
    "Depth's near-plane term and float rounding of the pass arithmetic, Principled metallic values",
    "between 0 and 1, and Cycles' own sampling (the paths are ours; only the features follow Cycles).",
]
METHODS = ("noisy", "ours-small", "oidn")
#: Attribution: the renderer's features with one group taken from the cycles render (the paths
#: are the same, so each is that one difference alone). Channels as in docs/FEATURES.md.
SWAPS = {
    "radiance split (diffuse, specular)": [0, 1, 2, 3, 4, 5],
    "features vertex (normal, depth, albedo)": [6, 7, 8, 9, 10, 11, 12],
    "first-hit roughness, metallic, transmissive": [13, 15, 16],
    "emissive, specular_bounce": [14, 17],
}


def render(binary: pathlib.Path, sequence: Sequence, convention: str, frames: int, spp: int,
           out: pathlib.Path) -> None:
    if (out / "render_summary.json").is_file():
        return
    command = [str(binary), "render", "--scene", sequence.scene, "--frames", str(frames), "--spp", str(spp),
               "--size", f"{FULL.width}x{FULL.height}", "--reference-spp", "0", "--seed", str(sequence.seed),
               "--feature-convention", convention, "--out", str(out), "--force"]
    result = subprocess.run(command, capture_output=True, text=True)
    if result.returncode != 0:
        raise SystemExit(f"{' '.join(command)} failed:\n{result.stderr.strip()}")


def feature_differences(ours: list[dict[str, Any]], cycles: list[dict[str, Any]]) -> dict[str, float]:
    """Fraction of samples whose feature group differs between the conventions (all frames)."""
    groups = {"diffuse/specular split": slice(0, 6), "normal": slice(6, 9), "depth": slice(9, 10),
              "albedo": slice(10, 13), "roughness": slice(13, 14), "flags": slice(14, 18)}
    a = np.stack([f["samples"] for f in ours])
    b = np.stack([f["samples"] for f in cycles])
    return {name: float(np.any(np.abs(a[..., s] - b[..., s]) > 1e-5 * (1 + np.abs(a[..., s])), axis=-1).mean())
            for name, s in groups.items()}


def swapped(ours: dict[str, Any], cycles: dict[str, Any], channels: list[int]) -> dict[str, Any]:
    samples = ours["samples"].copy()
    samples[..., channels] = cycles["samples"][..., channels]
    return {**ours, "samples": samples}


def evaluate(frames: list[dict[str, Any]], references: list[np.ndarray], runner) -> tuple[float, float]:
    """Mean SMAPE over the frames and mean temporal error over frames 2..N (as the benchmark)."""
    outputs = [np.asarray(runner(frame), np.float32) for frame in frames]
    smape = [metrics.smape(o, r) for o, r in zip(outputs, references)]
    temporal = [metrics.temporal_error(outputs[t], outputs[t - 1], references[t], references[t - 1],
                                       frames[t]["motion"], frames[t]["valid"]) for t in range(1, len(outputs))]
    temporal = [v for v in temporal if not np.isnan(v)]
    return float(np.mean(smape)), float(np.mean(temporal)) if temporal else float("nan")


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=pathlib.Path, required=True, help="markdown report")
    parser.add_argument("--affinity-bin", help="the affinity program (default as python -m affinity_bench)")
    parser.add_argument("--data", type=pathlib.Path,
                        default=pathlib.Path(os.environ.get("AFFINITY_BENCH_DATA", DEFAULT_DATA_DIR)),
                        help="the benchmark's render cache, for the references")
    parser.add_argument("--work", type=pathlib.Path,
                        default=pathlib.Path.home() / ".cache" / "affinity" / "cycles-gap-v1",
                        help="where the two conventions' renders are kept")
    parser.add_argument("--frames", type=int, default=FULL.frames, help=f"frames per sequence (default {FULL.frames})")
    parser.add_argument("--spp", default=",".join(str(s) for s in FULL.spp), help="sample counts (default 2,4,8)")
    parser.add_argument("--sequences", help="comma-separated sequence names (default: all of the full config)")
    parser.add_argument("--attribution-spp", type=int, default=FULL.chart_spp,
                        help=f"sample count of the one-difference-at-a-time table (default {FULL.chart_spp}; 0: none)")
    args = parser.parse_args(argv)

    start = time.perf_counter()
    load_start = os.getloadavg()
    binary = find_affinity_binary(args.affinity_bin)
    spp_list = tuple(int(s) for s in args.spp.split(","))
    render_spp = max(spp_list)
    sequences = FULL.sequences
    if args.sequences:
        wanted = args.sequences.split(",")
        sequences = tuple(s for s in sequences if s.name in wanted)
    methods = {m.label: m for m in make_methods([("small", BUILT_IN)]) if m.label in METHODS}

    # results[(method, convention, spp)][sequence] = (smape, temporal)
    results: dict[tuple[str, str, int], dict[str, tuple[float, float]]] = {}
    differences: dict[str, dict[str, float]] = {}
    attribution: dict[str, dict[str, tuple[float, float]]] = {}
    for sequence in sequences:
        cached = ensure_sequence(args.data, sequence, FULL, binary)
        cached_files = affinity_core.list_frame_files(cached)
        references = [affinity_core.read_frame(p)["reference"] for p in cached_files][:args.frames]
        cached_first = affinity_core.read_frame(cached_files[0])["samples"][:, :, :render_spp]
        loaded = {}
        for convention in CONVENTIONS:
            folder = args.work / (f"{sequence.name}_seed{sequence.seed}_{FULL.width}x{FULL.height}_"
                                  f"{args.frames}f_{render_spp}spp_{convention}")
            render(binary, sequence, convention, args.frames, render_spp, folder)
            loaded[convention] = [affinity_core.read_frame(p) for p in affinity_core.list_frame_files(folder)]
        # The renderer-convention render must be the benchmark's input (its first samples).
        if not np.array_equal(loaded["renderer"][0]["samples"], cached_first):
            raise SystemExit(f"{sequence.name}: renderer-convention samples differ from the benchmark cache {cached}")
        differences[sequence.name] = feature_differences(loaded["renderer"], loaded["cycles"])
        for spp in spp_list:
            for convention in CONVENTIONS:
                inputs = [with_spp(frame, spp) for frame in loaded[convention]]
                for label, method in methods.items():
                    results.setdefault((label, convention, spp), {})[sequence.name] = evaluate(
                        inputs, references, method.start())
        if args.attribution_spp in spp_list:
            ours_in = [with_spp(frame, args.attribution_spp) for frame in loaded["renderer"]]
            cycles_in = [with_spp(frame, args.attribution_spp) for frame in loaded["cycles"]]
            for swap, channels in SWAPS.items():
                inputs = [swapped(a, b, channels) for a, b in zip(ours_in, cycles_in)]
                attribution.setdefault(swap, {})[sequence.name] = evaluate(
                    inputs, references, methods["ours-small"].start())
        print(f"{sequence.name}: done ({time.perf_counter() - start:.0f} s)", flush=True)

    wall = time.perf_counter() - start
    load_end = os.getloadavg()
    names = [s.name for s in sequences]
    command = "PYTHONPATH=" + os.environ.get("PYTHONPATH", "") + " " + " ".join(
        shlex.quote(a) for a in [pathlib.Path(sys.executable).as_posix(), "scripts/cycles_feature_gap.py", *argv])

    def mean(label: str, convention: str, spp: int, index: int) -> float:
        values = [results[(label, convention, spp)][n][index] for n in names]
        return float(np.nanmean(values))

    lines = [
        "# Cycles feature convention vs the renderer's: what it costs in denoising quality",
        "",
        "Generated by `scripts/cycles_feature_gap.py` (see docs/BLENDER.md, \"Feature mapping\" and",
        "\"What the feature differences cost\"). The same paths rendered with both feature",
        "conventions (`affinity render --feature-convention renderer|cycles`): identical radiance per",
        "sample (so identical noisy input), only the features differ. Denoised with the built-in model",
        "(`ours-small`, temporal) and OpenImageDenoise (`oidn`, colour + albedo + normal); SMAPE is the",
        "mean over frames, temporal error the mean over frames 2..N, then both are averaged over the",
        f"sequences. Sequences: {', '.join(names)}; {FULL.width}x{FULL.height}, {args.frames} frames, "
        f"{', '.join(str(s) for s in spp_list)} spp (the first samples of a {render_spp}-spp render), "
        f"references: the benchmark's {FULL.reference_spp}-spp ones.",
        "",
        "```",
        command,
        "```",
        f"Wall time {wall:.0f} s (rendering, denoising and metrics; renders reused when present), "
        f"load average {load_start[0]:.1f} at the start and {load_end[0]:.1f} at the end (2 cores, shared).",
        "",
        "## Means",
        "",
        "| method | convention | " + " | ".join(f"SMAPE {s} spp" for s in spp_list) + " | "
        + " | ".join(f"temporal {s} spp" for s in spp_list) + " |",
        "|---|---|" + "---:|" * (2 * len(spp_list)),
    ]
    for label in METHODS:
        for convention in CONVENTIONS:
            if label == "noisy" and convention == "cycles":
                continue  # the same radiance
            cells = [f"{mean(label, convention, s, 0):.4f}" for s in spp_list]
            cells += [f"{mean(label, convention, s, 1):.4f}" for s in spp_list]
            shown = "both" if label == "noisy" else convention
            lines.append(f"| {label} | {shown} | " + " | ".join(cells) + " |")
    lines += ["", "Change (cycles / renderer - 1):", "",
              "| method | " + " | ".join(f"SMAPE {s} spp" for s in spp_list) + " | "
              + " | ".join(f"temporal {s} spp" for s in spp_list) + " |",
              "|---|" + "---:|" * (2 * len(spp_list))]
    for label in METHODS[1:]:
        cells = []
        for index in (0, 1):
            for s in spp_list:
                cells.append(f"{mean(label, 'cycles', s, index) / mean(label, 'renderer', s, index) - 1:+.1%}")
        lines.append(f"| {label} | " + " | ".join(cells) + " |")

    if attribution:
        a = args.attribution_spp
        lines += ["", f"## One difference at a time (ours-small, {a} spp)", "",
                  "The renderer convention's samples with one feature group replaced by the cycles render's.",
                  "Means over the sequences; the last two columns name the sequence that changed most (against",
                  "the renderer convention) and by how much.", "",
                  "| features from the cycles render | SMAPE | temporal error | largest SMAPE change | "
                  "largest temporal change |", "|---|---:|---:|---|---|"]

        def largest(per_sequence: dict[str, tuple[float, float]], index: int) -> str:
            base = results[("ours-small", "renderer", a)]
            change = {n: per_sequence[n][index] / base[n][index] - 1 for n in names}
            worst = max(change, key=lambda n: abs(change[n]))
            return f"{worst} {change[worst]:+.1%}" if abs(change[worst]) >= 5e-4 else "-"

        rows = [("none (renderer convention)", results[("ours-small", "renderer", a)]),
                *attribution.items(), ("all (cycles convention)", results[("ours-small", "cycles", a)])]
        for label, per_sequence in rows:
            smape_mean = float(np.nanmean([per_sequence[n][0] for n in names]))
            temporal_mean = float(np.nanmean([per_sequence[n][1] for n in names]))
            lines.append(f"| {label} | {smape_mean:.4f} | {temporal_mean:.4f} | {largest(per_sequence, 0)} | "
                         f"{largest(per_sequence, 1)} |")

    for index, metric in ((0, "SMAPE"), (1, "temporal error")):
        lines += ["", f"## {metric} per sequence", "",
                  "| sequence | " + " | ".join(f"{label} {c[:3]} {s}" for label in METHODS[1:] for s in spp_list
                                                  for c in CONVENTIONS) + " |",
                  "|---|" + "---:|" * (len(METHODS[1:]) * len(spp_list) * 2)]
        for n in names:
            cells = [f"{results[(label, c, s)][n][index]:.4f}" for label in METHODS[1:] for s in spp_list
                     for c in CONVENTIONS]
            lines.append(f"| {n} | " + " | ".join(cells) + " |")

    groups = list(next(iter(differences.values())).keys())
    lines += ["", "## Where the features differ", "",
              "Fraction of samples (all frames, at the rendered sample count) whose feature group differs "
              "between the conventions.", "",
              "| sequence | " + " | ".join(groups) + " |", "|---|" + "---:|" * len(groups)]
    for n in names:
        lines.append(f"| {n} | " + " | ".join(f"{differences[n][g]:.3f}" for g in groups) + " |")
    lines += ["", "## What the cycles convention emulates, and what it does not", "", *EMULATION_NOTES]
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

"""The model ladder table (issue: training): for each model size its parameters, kFLOP per
pixel, core ms per 1080p frame, and SMAPE / PSNR / FLIP / temporal error at every benchmarked
spp, with the inference ablations of the default model and the baselines as reference rows.

    .venv/bin/python scripts/model_ladder.py results/bench/results.csv results/speed_1080p.jsonl [MORE.jsonl ...] \
        > results/ladder.md

Inputs: the benchmark's results.csv (python -m affinity_bench, mean over its sequences) and
the JSON lines of one or more runs of scripts/bench_denoiser.sh (BENCH_JSON=FILE), whose labels
match the benchmark's `ours-<label>` methods. With several runs a model's ms is the median
over them: on a shared VM one run can be 25 % off for one model and not for the next.
"""

from __future__ import annotations

import csv
import json
import math
import sys
from collections import defaultdict


def main() -> None:
    results_csv, speed_runs = sys.argv[1], sys.argv[2:]
    runs: dict[str, list[dict]] = defaultdict(list)
    for speed_jsonl in speed_runs:
        for line in open(speed_jsonl):
            row = json.loads(line)
            # The ladder compares whole-frame runs with the kernels the machine picks (the AVX2,
            # lent and streamed rows of bench_denoiser.sh are the same models, fed otherwise).
            whole_frame = not (row["result"].get("streamed") or row["result"].get("lent"))
            if whole_frame and "AVX2 kernel" not in row["label"]:
                runs[row["label"]].append(row["result"])
    # Per model the run with the median time (the lower middle one for an even count).
    speed = {label: sorted(results, key=lambda r: r["ms_per_frame"])[(len(results) - 1) // 2]
             for label, results in runs.items()}
    # (method, spp) -> metric -> values over sequences
    values: dict[tuple[str, int], dict[str, list[float]]] = defaultdict(lambda: defaultdict(list))
    methods: list[str] = []
    spps: set[int] = set()
    reader = csv.DictReader(open(results_csv))
    # Results of benchmarks older than the tone-mapped temporal error (or the warping error) lack its column.
    metrics = [m for m in ("smape", "psnr", "flip", "temporal_error", "temporal_error_tonemapped", "warping_error")
               if m in (reader.fieldnames or [])]
    for row in reader:
        key = (row["method"], int(row["spp"]))
        spps.add(key[1])
        if row["method"] not in methods:
            methods.append(row["method"])
        for metric in metrics:
            values[key][metric].append(float(row[metric]))
    spp_list = sorted(s for s in spps if all((m, s) in values for m in methods if m.startswith("ours-")))

    def mean(method: str, spp: int, metric: str) -> str:
        v = [x for x in values.get((method, spp), {}).get(metric, []) if not math.isnan(x)]
        if not v:
            return "-"
        digits = {"psnr": 2, "warping_error": 5}.get(metric, 4)
        return f"{sum(v) / len(v):.{digits}f}"

    sequences = len(next(iter(values.values()))["smape"])
    print(f"Model ladder: mean over the benchmark's {sequences} sequences (7 bundled failure-case scenes and "
          "4 held-out procedural seeds, 128x96, 8 frames, 1024-spp references); ms per frame is the core "
          "(bench_denoiser) at 1920x1080, 4 spp, 2 threads"
          + (f", median of {len(speed_runs)} runs of scripts/bench_denoiser.sh" if len(speed_runs) > 1 else "")
          + ". Ablations switch parts of the default model off "
          "at inference (not retrained).\n")
    header = ["method", "parameters", "kFLOP/px", "ms / 1080p frame"]
    for s in spp_list:
        headings = {"smape": "SMAPE", "psnr": "PSNR", "flip": "FLIP", "temporal_error": "temporal",
                    "temporal_error_tonemapped": "temporal tone-mapped", "warping_error": "warping"}
        header += [f"{headings[m]} {s}spp" for m in metrics]
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    order = [m for m in methods if m.startswith("ours-")] + [m for m in methods if not m.startswith("ours-")]
    for method in order:
        label = method.removeprefix("ours-")
        r = speed.get(label) if method.startswith("ours-") else None
        cells = [method, f"{r['parameters']:,}" if r else "", f"{r['kflop_per_pixel']:.1f}" if r else "",
                 f"{r['ms_per_frame']:.0f}" if r else ""]
        for s in spp_list:
            cells += [mean(method, s, m) for m in metrics]
        print("| " + " | ".join(cells) + " |")
    # Sizes timed but not benchmarked for quality (no trained weights yet).
    for label, r in speed.items():
        if f"ours-{label}" not in methods:
            cells = [f"{label} (not trained: speed only)", f"{r['parameters']:,}", f"{r['kflop_per_pixel']:.1f}",
                     f"{r['ms_per_frame']:.0f}"] + ["-"] * (len(metrics) * len(spp_list))
            print("| " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()

"""Speed and peak memory at large frame sizes, each method in its own process.

The parent runs ``python -m affinity.bench.speed --worker METHOD ...`` once per method and size;
the worker synthesises one frame (uniform random features, zero motion, all pixels valid; the
methods' cost does not depend on the content), calls the method once to warm up and then
`repeats` times on the same frame (so temporal methods run with history), and prints one JSON
line: the wall time of each timed call and its peak resident memory (getrusage ru_maxrss), also
measured right after synthesising the input, so the method's own memory is the difference.
"""

from __future__ import annotations

import argparse
import json
import resource
import statistics
import subprocess
import sys
import time
from typing import Any

import numpy as np

from affinity import metrics

from .report import markdown_table

WORKER_TIMEOUT_SECONDS = 3600


def peak_rss_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # KiB on Linux


def synthetic_frame(width: int, height: int, spp: int) -> dict[str, Any]:
    from affinity import FEATURE_COUNT

    rng = np.random.default_rng(0)
    eye = np.eye(4, dtype=np.float32)
    return {
        "samples": rng.random((height, width, spp, FEATURE_COUNT), dtype=np.float32),
        "motion": np.zeros((height, width, 2), np.float32),
        "valid": np.ones((height, width), np.float32),
        "reference": None,
        "info": {"scene_name": "synthetic", "frame_index": 0, "reference_spp": 0, "seed": 0,
                 "world_to_camera": eye, "camera_to_clip": eye},
    }


def worker(label: str, width: int, height: int, spp: int, repeats: int, models: list[tuple[str, str]]) -> dict[str, Any]:
    from .methods import make_methods

    methods = {m.label: m for m in make_methods(models)}
    if label not in methods:
        raise SystemExit(f"speed worker: no method {label!r} (have {', '.join(methods)})")
    frame = synthetic_frame(width, height, spp)
    input_rss = peak_rss_mib()
    runner = methods[label].start()
    runner(frame)  # warm-up: first-call allocations, no history yet
    seconds = []
    for _ in range(repeats):
        start = time.perf_counter()
        runner(frame)
        seconds.append(time.perf_counter() - start)
    return {"method": label, "width": width, "height": height, "spp": spp, "seconds": seconds,
            "input_rss_mib": input_rss, "peak_rss_mib": peak_rss_mib()}


def _model_arguments(models: list[tuple[str, str]]) -> list[str]:
    return [argument for label, path in models for argument in ("--model", f"{label}={path}")]


def measure_speed(methods: list[str], sizes: list[tuple[int, int]], spp: int, repeats: int,
                  models: list[tuple[str, str]], log: Any = print) -> list[dict[str, Any]]:
    """One worker process per method and size; a failed worker is recorded with its error."""
    records = []
    for width, height in sizes:
        for label in methods:
            command = [sys.executable, "-m", "affinity.bench.speed", "--worker", label, "--size", f"{width}x{height}",
                       "--spp", str(spp), "--repeats", str(repeats), *_model_arguments(models)]
            try:
                done = subprocess.run(command, capture_output=True, text=True,
                                      timeout=WORKER_TIMEOUT_SECONDS)
                if done.returncode != 0:
                    raise RuntimeError(done.stderr.strip().splitlines()[-1] if done.stderr.strip()
                                       else f"exit status {done.returncode}")
                record = json.loads(done.stdout.strip().splitlines()[-1])
                record["error"] = ""
            except (RuntimeError, subprocess.TimeoutExpired, json.JSONDecodeError, IndexError) as error:
                record = {"method": label, "width": width, "height": height, "spp": spp, "seconds": [],
                          "input_rss_mib": float("nan"), "peak_rss_mib": float("nan"), "error": str(error)}
            records.append(record)
            log(f"bench: speed {label} {width}x{height}: " + (
                f"{statistics.median(record['seconds']) * 1e3:.0f} ms, peak {record['peak_rss_mib']:.0f} MiB"
                if record["seconds"] else f"failed ({record['error']})"))
    return records


def speed_rows(records: list[dict[str, Any]]) -> tuple[list[str], list[list[Any]]]:
    header = ["method", "width", "height", "spp", "ms_per_frame", "ms_per_mpx", "runs_ms", "input_rss_mib",
              "peak_rss_mib", "error"]
    rows = []
    for r in records:
        median = statistics.median(r["seconds"]) if r["seconds"] else float("nan")
        rows.append([r["method"], r["width"], r["height"], r["spp"], f"{median * 1e3:.1f}",
                     f"{metrics.ms_per_megapixel(median, r['width'], r['height']):.1f}",
                     " ".join(f"{s * 1e3:.1f}" for s in r["seconds"]), f"{r['input_rss_mib']:.0f}",
                     f"{r['peak_rss_mib']:.0f}", r["error"]])
    return header, rows


def speed_markdown(records: list[dict[str, Any]], repeats: int) -> str:
    rows = []
    for r in records:
        size = f"{r['width']}x{r['height']}"
        if not r["seconds"]:
            rows.append([f"`{r['method']}`", size, "failed: " + r["error"].replace("|", "/"), "", "", ""])
            continue
        median = statistics.median(r["seconds"])
        rows.append([f"`{r['method']}`", size, f"{median * 1e3:.0f}",
                     f"{metrics.ms_per_megapixel(median, r['width'], r['height']):.0f}",
                     f"{r['peak_rss_mib']:.0f}", f"{r['peak_rss_mib'] - r['input_rss_mib']:.0f}"])
    spp = records[0]["spp"] if records else 0
    return (f"Synthetic {spp}-spp frames, each method in its own process: median of {repeats} calls after one "
            f"warm-up call; peak resident memory of the process, and that peak minus the peak right after the "
            f"input frame was made (the method's own memory).\n\n"
            + markdown_table(["method", "size", "ms/frame", "ms/Mpx", "peak MiB", "beyond input MiB"], rows))


def main() -> None:
    parser = argparse.ArgumentParser(description="One speed measurement (used by python -m affinity.bench).")
    parser.add_argument("--worker", required=True, metavar="METHOD")
    parser.add_argument("--size", required=True, metavar="WxH")
    parser.add_argument("--spp", type=int, default=4)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--model", action="append", default=[], metavar="LABEL=PATH")
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.lower().split("x"))
    models = [tuple(m.split("=", 1)) for m in args.model]
    print(json.dumps(worker(args.worker, width, height, args.spp, args.repeats, models)))  # type: ignore[arg-type]


if __name__ == "__main__":
    main()

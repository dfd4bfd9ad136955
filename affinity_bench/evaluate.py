"""Runs every method on every sequence at every sample count and measures it."""

from __future__ import annotations

import statistics
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from affinity_core import metrics

from .data import preroll_groups, with_spp
from .methods import Method, PrerollRunner

#: Metrics of a frame against the frame before: NaN on the first frame, left out of the means.
PAIR_METRICS = ("temporal_error", "temporal_error_tonemapped", "warping_error")

#: Methods that also run at the equal-time chart's extra sample counts.
EQUAL_TIME_METHODS = ("noisy", "oidn")


@dataclass
class FrameResult:
    frame: int
    smape: float
    relmse: float
    psnr: float
    flip: float
    temporal_error: float  # NaN on the first frame (no previous frame)
    temporal_error_tonemapped: float  # likewise
    warping_error: float   # likewise (Lai et al. 2018: the output against its own previous frame)
    brightness: float      # mean output / mean reference (1: no energy gained or lost)
    seconds: float         # wall time of the method's call on this frame (fastest of the timing runs)


@dataclass
class SequenceResult:
    method: str
    family: str
    sequence: str
    failure_case: bool
    spp: int
    width: int
    height: int
    render_seconds_per_frame: float  # noisy render at this spp (scaled from the rendered spp)
    frames: list[FrameResult]
    last_output: np.ndarray | None = field(default=None, repr=False)
    outputs: list[np.ndarray] | None = field(default=None, repr=False)  # every frame, when asked

    def mean(self, metric: str) -> float:
        values = [getattr(f, metric) for f in self.frames]
        if metric in PAIR_METRICS:
            values = [v for v in values[1:] if not np.isnan(v)]  # frames 2..N
        return float(np.mean(values)) if values else float("nan")

    @property
    def seconds_per_frame(self) -> float:
        """Median seconds per call, the first (warm-up) call excluded when there are more than 2."""
        times = [f.seconds for f in self.frames]
        return statistics.median(times[1:] if len(times) > 2 else times)

    @property
    def ms_per_mpx(self) -> float:
        return metrics.ms_per_megapixel(self.seconds_per_frame, self.width, self.height)


def run_once(method: Method, inputs: list[dict[str, Any]],
             preroll: list[np.ndarray] | None = None) -> tuple[list[np.ndarray], list[float]]:
    """The sequence in order through a fresh runner: the outputs and the wall time of each call.
    A runner with a pre-roll (methods.PrerollRunner) gets the pre-roll's sample groups
    (data.preroll_groups) first, timed with the first frame."""
    runner = method.start()
    outputs, seconds = [], []
    for t, frame in enumerate(inputs):
        start = time.perf_counter()
        if t == 0 and preroll is not None and isinstance(runner, PrerollRunner):
            runner.preroll(frame, preroll)
        output = runner(frame)
        seconds.append(time.perf_counter() - start)
        outputs.append(np.asarray(output, np.float32))
    return outputs, seconds


def run_methods(methods: list[Method], inputs: list[dict[str, Any]], runs: int,
                preroll: list[np.ndarray] | None = None) -> dict[str, tuple[list[np.ndarray], list[float]]]:
    """Each method's outputs (of its first run) and, per frame, its fastest call over `runs`
    runs. The runs go round-robin over the methods, so a burst of other work on a shared
    machine slows at most one run of a method rather than all of them; the methods are
    deterministic, so only the timings differ between runs."""
    results = {m.label: run_once(m, inputs, preroll) for m in methods}
    for _ in range(runs - 1):
        for method in methods:
            outputs, fastest = results[method.label]
            _, seconds = run_once(method, inputs, preroll)
            results[method.label] = (outputs, [min(a, b) for a, b in zip(fastest, seconds)])
    return results


def measure(outputs: list[np.ndarray], seconds: list[float], frames: list[dict[str, Any]]) -> list[FrameResult]:
    """Every metric of every frame against the frames' references (timing done before this)."""
    results = []
    for t, (output, frame) in enumerate(zip(outputs, frames)):
        reference = frame["reference"]
        temporal = tonemapped_temporal = warping = float("nan")
        if t > 0:
            pair = (output, outputs[t - 1], reference, frames[t - 1]["reference"], frame["motion"], frame["valid"])
            temporal = metrics.temporal_error(*pair)
            tonemapped_temporal = metrics.tonemapped_temporal_error(*pair)
            warping = metrics.warping_error(output, outputs[t - 1], frame["motion"], frame["valid"])
        brightness = float(np.mean(output, dtype=np.float64) / np.mean(reference, dtype=np.float64))
        results.append(FrameResult(t, metrics.smape(output, reference), metrics.relmse(output, reference),
                                   metrics.psnr(output, reference), metrics.flip(output, reference), temporal,
                                   tonemapped_temporal, warping, brightness, seconds[t]))
    return results


def reference_noise(name: str, failure_case: bool, frames: list[dict[str, Any]],
                    second: list[np.ndarray]) -> SequenceResult:
    """The second, independent reference scored like a method's output against the first: the
    error that the references' own noise gives any output. No time is measured (NaN)."""
    height, width = second[0].shape[:2]
    untimed = [float("nan")] * len(second)
    return SequenceResult("reference-2", "reference", name, failure_case, 0, width, height, float("nan"),
                          measure(second, untimed, frames))


def evaluate_sequence(name: str, failure_case: bool, frames: list[dict[str, Any]], noisy_seconds: float,
                      render_spp: int, methods: list[Method], spp: tuple[int, ...],
                      equal_time_spp: tuple[int, ...], keep_last_at: int, timing_runs: int,
                      keep_outputs: bool = False,
                      captured_preroll: list[np.ndarray] | None = None) -> list[SequenceResult]:
    """All methods at the main sample counts, plus noisy and OIDN at the equal-time ones.

    `noisy_seconds` is the noisy render's time per frame at `render_spp`; `keep_last_at` is the
    sample count whose last output is kept (for the crops); `timing_runs` as in run_methods;
    `keep_outputs` keeps every output frame in the results (to be saved for video metrics);
    `captured_preroll` the extension's pre-roll frames where the sequence holds them."""
    height, width = frames[0]["reference"].shape[:2]
    results = []
    for count in sorted(set(spp) | set(equal_time_spp)):
        inputs = [with_spp(frame, count) for frame in frames]
        active = [m for m in methods if count in spp or m.label in EQUAL_TIME_METHODS]
        runs = run_methods(active, inputs, timing_runs, preroll_groups(frames[0], count, captured_preroll))
        for method in active:
            outputs, seconds = runs[method.label]
            result = SequenceResult(method.label, method.family, name, failure_case, count, width, height,
                                    noisy_seconds * count / render_spp, measure(outputs, seconds, frames))
            if count == keep_last_at:
                result.last_output = outputs[-1]
            if keep_outputs:
                result.outputs = outputs
            results.append(result)
    return results

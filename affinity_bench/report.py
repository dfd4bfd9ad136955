"""The benchmark's outputs: CSV tables, the markdown report and the PNG charts.

Every file is written to a temporary name in the output folder and renamed over the final
name, so a reader never sees a half-written file and an interrupted run leaves the previous
file intact.
"""

from __future__ import annotations

import csv
import io
import math
import os
import pathlib
import tempfile
from collections.abc import Callable, Iterable
from typing import Any

import numpy as np

from .evaluate import SequenceResult

# (column, heading, format) of the per-method summary tables.
SUMMARY_COLUMNS = (
    ("smape", "SMAPE", "{:.4f}"),
    ("relmse", "relMSE", "{:.4f}"),
    ("psnr", "PSNR (dB)", "{:.2f}"),
    ("flip", "FLIP", "{:.4f}"),
    ("temporal_error", "temporal error", "{:.4f}"),
    ("temporal_error_tonemapped", "temporal error, tone-mapped", "{:.4f}"),
    ("warping_error", "warping error", "{:.5f}"),
    ("brightness", "brightness / reference", "{:.3f}"),
    ("ms_per_mpx", "ms/Mpx", "{:.0f}"),
)
METRICS = ("smape", "relmse", "psnr", "flip", "temporal_error", "temporal_error_tonemapped", "warping_error",
           "brightness")


# --- writing ---------------------------------------------------------------------------------

def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def write_atomically(path: pathlib.Path, write: Callable[[str], None]) -> None:
    """Calls write(temporary path) and renames the result over `path`."""
    descriptor, temporary = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(descriptor)
    try:
        write(temporary)
        os.chmod(temporary, 0o666 & ~_umask())  # mkstemp makes 0600; give the file the usual mode
        os.replace(temporary, path)
    except BaseException:
        os.unlink(temporary)
        raise


def write_text(path: pathlib.Path, text: str) -> None:
    write_atomically(path, lambda temporary: pathlib.Path(temporary).write_text(text))


def write_csv(path: pathlib.Path, header: list[str], rows: Iterable[list[Any]]) -> None:
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(header)
    writer.writerows(rows)
    write_text(path, buffer.getvalue())


def save_figure(figure: Any, path: pathlib.Path) -> None:
    import matplotlib.pyplot as plt

    write_atomically(path, lambda temporary: figure.savefig(temporary, format="png", dpi=110))
    plt.close(figure)


def _number(value: float) -> str:
    return "nan" if math.isnan(value) else f"{value:.6g}"


# --- tables ----------------------------------------------------------------------------------

def result_rows(results: list[SequenceResult]) -> tuple[list[str], list[list[Any]]]:
    header = ["method", "family", "sequence", "failure_case", "spp", "frames", *METRICS, "ms_per_frame",
              "ms_per_mpx", "render_s_per_frame", "total_s_per_frame"]
    rows = []
    for r in results:
        rows.append([r.method, r.family, r.sequence, int(r.failure_case), r.spp, len(r.frames),
                     *(_number(r.mean(m)) for m in METRICS), _number(r.seconds_per_frame * 1e3),
                     _number(r.ms_per_mpx), _number(r.render_seconds_per_frame),
                     _number(r.render_seconds_per_frame + r.seconds_per_frame)])
    return header, rows


def per_frame_rows(results: list[SequenceResult]) -> tuple[list[str], list[list[Any]]]:
    header = ["method", "sequence", "spp", "frame", *METRICS, "ms"]
    rows = [[r.method, r.sequence, r.spp, f.frame, *(_number(getattr(f, m)) for m in METRICS),
             _number(f.seconds * 1e3)] for r in results for f in r.frames]
    return header, rows


def _methods_in_order(results: list[SequenceResult]) -> list[str]:
    return list(dict.fromkeys(r.method for r in results))


def _at(results: list[SequenceResult], spp: int) -> list[SequenceResult]:
    return [r for r in results if r.spp == spp]


def mean_over_sequences(results: list[SequenceResult], method: str, spp: int,
                        value: Callable[[SequenceResult], float]) -> float:
    values = [value(r) for r in results if r.method == method and r.spp == spp]
    return float(np.mean(values)) if values else float("nan")


def _summary_value(column: str) -> Callable[[SequenceResult], float]:
    return (lambda r: r.ms_per_mpx) if column == "ms_per_mpx" else (lambda r, c=column: r.mean(c))


def markdown_table(header: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |",
             "|" + "|".join("---" if i == 0 else "---:" for i in range(len(header))) + "|"]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def summary_markdown(results: list[SequenceResult], spp: tuple[int, ...], descriptions: dict[str, str]) -> str:
    text = ""
    for count in spp:
        at = _at(results, count)
        sequences = len({r.sequence for r in at})
        text += f"\n### {count} spp (mean over {sequences} sequences)\n\n"
        rows = []
        for method in _methods_in_order(at):
            rows.append([f"`{method}`"] + [fmt.format(mean_over_sequences(at, method, count, _summary_value(c)))
                                           for c, _, fmt in SUMMARY_COLUMNS])
        text += markdown_table(["method"] + [h for _, h, _ in SUMMARY_COLUMNS], rows)
    text += "\nMethods: " + "; ".join(f"`{m}`: {d}" for m, d in descriptions.items()) + ".\n"
    return text


def reference_noise_rows(noise: list[SequenceResult]) -> tuple[list[str], list[list[Any]]]:
    header = ["sequence", "failure_case", "frames", *METRICS]
    return header, [[r.sequence, int(r.failure_case), len(r.frames), *(_number(r.mean(m)) for m in METRICS)]
                    for r in noise]


def reference_noise_markdown(noise: list[SequenceResult], second: str) -> str:
    """Per sequence and on average, the second reference's scores against the first. ``second``
    says what the second reference is (a sentence without its end)."""
    columns = [(c, h, f) for c, h, f in SUMMARY_COLUMNS if c != "ms_per_mpx"]
    rows = [[r.sequence] + [f.format(r.mean(c)) for c, _, f in columns] for r in noise]
    rows.append(["**mean**"] + [f.format(float(np.mean([r.mean(c) for r in noise]))) for c, _, f in columns])
    text = (f"{second}, scored against the first exactly as a method's output is. The references are noisy too, so "
            "every method's error includes theirs: for a perfect output, about these values divided by the "
            "square root of 2 (the errors of two independent references add in quadrature). The warping error "
            "is the second reference's own (it needs no reference): what a perfect output would score.\n\n")
    return text + markdown_table(["sequence"] + [h for _, h, _ in columns], rows)


def per_scene_markdown(results: list[SequenceResult], spp: tuple[int, ...]) -> str:
    text = ""
    for count in spp:
        at = _at(results, count)
        methods = _methods_in_order(at)
        text += f"\n### SMAPE per sequence, {count} spp\n\n"
        rows = []
        for sequence in dict.fromkeys(r.sequence for r in at):
            by_method = {r.method: r.mean("smape") for r in at if r.sequence == sequence}
            rows.append([sequence] + [f"{by_method[m]:.4f}" if m in by_method else "" for m in methods])
        text += markdown_table(["sequence"] + [f"`{m}`" for m in methods], rows)
    return text


def equal_time_points(results: list[SequenceResult],
                      methods: list[str]) -> dict[str, list[tuple[int, float, float, float]]]:
    """Per method: (spp, render s/frame, denoise s/frame, SMAPE), means over sequences."""
    points: dict[str, list[tuple[int, float, float, float]]] = {}
    for method in methods:
        for count in sorted({r.spp for r in results if r.method == method}):
            render = mean_over_sequences(results, method, count, lambda r: r.render_seconds_per_frame)
            denoise = mean_over_sequences(results, method, count, lambda r: r.seconds_per_frame)
            error = mean_over_sequences(results, method, count, lambda r: r.mean("smape"))
            points.setdefault(method, []).append((count, render, denoise, error))
    return points


def equal_time_markdown(points: dict[str, list[tuple[int, float, float, float]]]) -> str:
    rows = [[f"`{m}`", str(s), f"{render * 1e3:.1f}", f"{denoise * 1e3:.1f}", f"{(render + denoise) * 1e3:.1f}",
             f"{e:.4f}"]
            for m, values in points.items() for s, render, denoise, e in values]
    return markdown_table(["method", "spp", "render ms/frame", "denoise ms/frame", "total ms/frame", "SMAPE"], rows)


# --- charts ----------------------------------------------------------------------------------

def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _colours(methods: list[str]) -> dict[str, Any]:
    plt = _pyplot()
    cycle = plt.get_cmap("tab10")
    return {m: cycle(i % 10) for i, m in enumerate(methods)}


def chart_error_vs_time(results: list[SequenceResult], spp: int, path: pathlib.Path, title: str) -> None:
    plt = _pyplot()
    at = _at(results, spp)
    methods = _methods_in_order(at)
    colours = _colours(methods)
    figure, axes = plt.subplots(figsize=(7, 4.5))
    markers = "osD^vP*X"
    for i, method in enumerate(methods):
        x = mean_over_sequences(at, method, spp, lambda r: r.ms_per_mpx)
        y = mean_over_sequences(at, method, spp, lambda r: r.mean("smape"))
        axes.scatter([x], [y], color=colours[method], marker=markers[i % len(markers)], s=50, zorder=3,
                     label=method)
    axes.legend(fontsize=8, loc="best")
    axes.set_xscale("log")
    axes.set_xlabel("ms per megapixel (median per frame, log scale)")
    axes.set_ylabel("SMAPE (mean over sequences)")
    axes.set_title(f"{title}: error against time, {spp} spp")
    axes.grid(True, which="both", alpha=0.3)
    figure.tight_layout()
    save_figure(figure, path)


def chart_temporal_error(results: list[SequenceResult], sequence: str, spp: tuple[int, ...],
                         path: pathlib.Path) -> None:
    plt = _pyplot()
    from matplotlib import ticker
    mine = [r for r in results if r.sequence == sequence and r.spp in spp]
    methods = _methods_in_order(mine)
    colours = _colours(methods)
    figure, axes = plt.subplots(1, len(spp), figsize=(4.2 * len(spp), 3.8), sharey=True, squeeze=False)
    for axis, count in zip(axes[0], spp):
        for r in (r for r in mine if r.spp == count):
            frames = [f.frame for f in r.frames[1:]]
            axis.plot(frames, [f.temporal_error for f in r.frames[1:]], marker="o", markersize=3,
                      color=colours[r.method], label=r.method)
        axis.set_title(f"{count} spp")
        axis.set_xlabel("frame")
        axis.xaxis.set_major_locator(ticker.MaxNLocator(integer=True))
        axis.grid(True, alpha=0.3)
    axes[0][0].set_ylabel("temporal error")
    axes[0][-1].legend(fontsize=7, loc="best")
    figure.suptitle(f"{sequence}: temporal error per frame (vs frame before)")
    figure.tight_layout()
    save_figure(figure, path)


def _display(image: np.ndarray) -> np.ndarray:
    """Tone map x/(1+x), then the sRGB transfer curve, as 0..1 for imshow."""
    mapped = np.maximum(image, 0.0) / (1.0 + np.maximum(image, 0.0))
    return np.where(mapped <= 0.0031308, 12.92 * mapped, 1.055 * np.power(mapped, 1 / 2.4) - 0.055).clip(0, 1)


def worst_window(error: np.ndarray, size: int) -> tuple[int, int]:
    """Top-left corner of the size x size window with the largest summed error."""
    integral = np.pad(error, ((1, 0), (1, 0))).cumsum(0).cumsum(1)
    sums = integral[size:, size:] - integral[:-size, size:] - integral[size:, :-size] + integral[:-size, :-size]
    y, x = np.unravel_index(int(np.argmax(sums)), sums.shape)
    return int(y), int(x)


def chart_crops(panels: list[tuple[str, np.ndarray]], reference: np.ndarray, focus: str, sequence: str,
                spp: int, path: pathlib.Path) -> None:
    """Side-by-side crops of the last frame, placed where the panel named `focus` (our output)
    differs most from the reference after tone mapping."""
    plt = _pyplot()
    height, width = reference.shape[:2]
    size = max(8, min(height, width) // 2)
    error = np.abs(_display(dict(panels)[focus]) - _display(reference)).sum(axis=2)
    y, x = worst_window(error, size)
    columns = panels + [("reference", reference)]
    figure, axes = plt.subplots(1, len(columns), figsize=(2.3 * len(columns), 2.7), squeeze=False)
    for axis, (name, image) in zip(axes[0], columns):
        axis.imshow(_display(image[y:y + size, x:x + size]), interpolation="nearest")
        axis.set_title(name, fontsize=9)
        axis.set_xticks([])
        axis.set_yticks([])
    figure.suptitle(f"{sequence}, last frame, {spp} spp: {size}x{size} crop at ({x}, {y}), where {focus} errs most",
                    fontsize=9)
    figure.tight_layout()
    save_figure(figure, path)


def chart_equal_time(points: dict[str, list[tuple[int, float, float, float]]], path: pathlib.Path, title: str) -> None:
    plt = _pyplot()
    colours = _colours(list(points))
    figure, axes = plt.subplots(figsize=(7, 4.5))
    for method, values in points.items():
        totals = [render + denoise for _, render, denoise, _ in values]
        errors = [e for *_, e in values]
        axes.plot(totals, errors, marker="o", color=colours[method], label=method)
        for (count, *_), total, error in zip(values, totals, errors):
            axes.annotate(f"{count}", (total, error), textcoords="offset points", xytext=(4, 3), fontsize=7)
    axes.set_xscale("log")
    axes.set_xlabel("render + denoise seconds per frame (log scale); labels: spp")
    axes.set_ylabel("SMAPE (mean over sequences)")
    axes.set_title(f"{title}: equal-time comparison")
    axes.grid(True, which="both", alpha=0.3)
    axes.legend(fontsize=8)
    figure.tight_layout()
    save_figure(figure, path)

"""The benchmark's input sequences: rendered once with `affinity render`, cached, reused.

Each sequence is rendered once at the largest sample count any method needs (Config.render_spp)
with a clean reference; an S-spp input is the first S samples of every pixel (the renderer's
samples are independent, so that is an S-spp render). The time of the noisy render is measured
by a second render of the same frames without a reference (``--reference-spp 0``), whose
``render_summary.json`` seconds cover path tracing only (not file writing); it is stored beside
the frames as ``noisy_timing.json``. The time at S spp is that time scaled by S / render_spp.

A second reference of every sequence, rendered with other random numbers (the seed plus
SECOND_REFERENCE_SEED_OFFSET; 1 spp of input, which nothing reads), measures how noisy the
references themselves are: scored against the first, it is the error floor of every method.
"""

from __future__ import annotations

import json
import os
import pathlib
import subprocess
import tempfile
import time
from collections.abc import Callable
from typing import Any

import numpy as np

import affinity_core

from .config import SECOND_REFERENCE_SEED_OFFSET, Config, Sequence

DEFAULT_DATA_DIR = pathlib.Path.home() / ".cache" / "affinity" / "bench-v1"
TIMING_FILE = "noisy_timing.json"


def find_affinity_binary(explicit: str | None = None) -> pathlib.Path:
    """--affinity-bin, else $AFFINITY_BIN, else <build>/core/affinity beside <build>/python."""
    candidates = [explicit, os.environ.get("AFFINITY_BIN")]
    candidates.append(str(pathlib.Path(affinity_core.__file__).resolve().parents[2] / "core" / "affinity"))
    for candidate in candidates:
        if candidate and os.access(candidate, os.X_OK) and os.path.isfile(candidate):
            return pathlib.Path(candidate)
    tried = ", ".join(c for c in candidates if c)
    raise SystemExit(f"bench: the affinity program was not found (tried {tried}); build it or pass --affinity-bin")


def sequence_dir(data_dir: pathlib.Path, sequence: Sequence, config: Config) -> pathlib.Path:
    """Cache folder of one sequence; the name holds every render setting, so configs never collide."""
    return data_dir / (f"{sequence.name}_seed{sequence.seed}_{config.width}x{config.height}_{config.frames}f_"
                       f"{config.render_spp}spp_ref{config.reference_spp}")


def second_reference_dir(data_dir: pathlib.Path, sequence: Sequence, config: Config) -> pathlib.Path:
    """Cache folder of the sequence's second, independent reference."""
    return data_dir / (
        f"{sequence.name}_seed{sequence.seed + SECOND_REFERENCE_SEED_OFFSET}_{config.width}x{config.height}_"
        f"{config.frames}f_ref{config.reference_spp}")


def _render(binary: pathlib.Path, sequence: Sequence, config: Config, reference_spp: int,
            out: pathlib.Path, spp: int | None = None, seed: int | None = None) -> dict[str, Any]:
    command = [str(binary), "render", "--scene", sequence.scene, "--frames", str(config.frames),
               "--spp", str(spp or config.render_spp), "--size", f"{config.width}x{config.height}",
               "--reference-spp", str(reference_spp), "--seed", str(sequence.seed if seed is None else seed),
               "--out", str(out)]
    result = subprocess.run(command, capture_output=True, text=True)
    if result.returncode != 0:
        raise SystemExit(f"bench: {' '.join(command)} failed:\n{result.stderr.strip()}")
    return json.loads((out / "render_summary.json").read_text())


def _render_once(data_dir: pathlib.Path, final: pathlib.Path, marker: str,
                 render: Callable[[pathlib.Path, pathlib.Path], None]) -> float | None:
    """Makes the cache folder `final` unless it holds `marker` (the last file a render writes):
    render(frames_dir, work) fills frames_dir inside a temporary sibling folder, renamed into
    place only when complete, so an interrupted run never leaves a folder that looks finished.
    Returns the seconds it took, or None when the folder was already there."""
    if (final / marker).is_file():
        return None
    if final.exists():
        raise SystemExit(f"bench: {final} exists but is incomplete (no {marker}); remove it to re-render")
    data_dir.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix=final.name + ".partial-", dir=data_dir) as work:
        frames_dir = pathlib.Path(work) / "frames"
        render(frames_dir, pathlib.Path(work))
        os.replace(frames_dir, final)
    return time.perf_counter() - start


def ensure_sequence(data_dir: pathlib.Path, sequence: Sequence, config: Config,
                    binary: pathlib.Path) -> pathlib.Path:
    """The sequence's cache folder, rendered first if it is not there yet."""
    def render(frames_dir: pathlib.Path, work: pathlib.Path) -> None:
        summary = _render(binary, sequence, config, config.reference_spp, frames_dir)
        timing = _render(binary, sequence, config, 0, work / "timing")
        record = {
            "render_spp": config.render_spp,
            "frames": config.frames,
            "noisy_seconds_per_frame": timing["seconds"] / config.frames,
            "with_reference_seconds": summary["seconds"],
            "measured_by": "affinity render --reference-spp 0 (render_summary.json seconds: path tracing only)",
        }
        (frames_dir / TIMING_FILE).write_text(json.dumps(record, indent=2) + "\n")

    final = sequence_dir(data_dir, sequence, config)
    seconds = _render_once(data_dir, final, TIMING_FILE, render)
    if seconds is not None:
        print(f"bench: rendered {sequence.name} ({config.frames} frames {config.width}x{config.height}, "
              f"{config.render_spp} spp, reference {config.reference_spp} spp) in {seconds:.1f} s", flush=True)
    return final


def ensure_second_reference(data_dir: pathlib.Path, sequence: Sequence, config: Config,
                            binary: pathlib.Path) -> pathlib.Path:
    """The folder of the sequence's second reference, rendered first if it is not there yet."""
    def render(frames_dir: pathlib.Path, work: pathlib.Path) -> None:
        _render(binary, sequence, config, config.reference_spp, frames_dir, spp=1,
                seed=sequence.seed + SECOND_REFERENCE_SEED_OFFSET)

    final = second_reference_dir(data_dir, sequence, config)
    seconds = _render_once(data_dir, final, "render_summary.json", render)
    if seconds is not None:
        print(f"bench: rendered the second reference of {sequence.name} in {seconds:.1f} s", flush=True)
    return final


def load_references(folder: pathlib.Path) -> list[np.ndarray]:
    """The reference images of a sequence folder, in frame order."""
    return [affinity_core.read_frame(path)["reference"] for path in affinity_core.list_frame_files(folder)]


def load_sequence(folder: pathlib.Path) -> tuple[list[dict[str, Any]], float]:
    """The frames (in order) and the noisy render's seconds per frame at the rendered spp."""
    frames = [affinity_core.read_frame(path) for path in affinity_core.list_frame_files(folder)]
    timing = json.loads((folder / TIMING_FILE).read_text())
    return frames, float(timing["noisy_seconds_per_frame"])


def with_spp(frame: dict[str, Any], spp: int) -> dict[str, Any]:
    """The frame's first `spp` samples per pixel, without the reference (what a denoiser sees)."""
    if spp > frame["samples"].shape[2]:
        raise ValueError(f"frame has {frame['samples'].shape[2]} samples per pixel, {spp} asked")
    return {"samples": np.ascontiguousarray(frame["samples"][:, :, :spp]), "motion": frame["motion"],
            "valid": frame["valid"], "reference": None, "info": frame["info"]}


#: The extension's pre-roll frames (blender_addon/affinity_denoiser/pipeline.py,
#: DEFAULT_PREROLL_FRAMES; restated here: that module needs Blender).
PREROLL_FRAMES = 1


def preroll_samples(spp: int) -> int:
    """The samples of each of the extension's pre-roll frames at `spp` samples per frame, by
    default (pipeline.automatic_preroll_samples): 8 x spp, at least 16, at most 64."""
    return min(64, max(16, 8 * spp))


def preroll_groups(frame: dict[str, Any], spp: int, captured: list[np.ndarray] | None = None,
                   preroll_frames: int = PREROLL_FRAMES, preroll_spp: int | None = None) -> list[np.ndarray]:
    """The sample groups a pre-roll of the first frame denoises at `spp` (methods.py), each
    [H, W, samples, 18]: `preroll_frames` groups of `preroll_spp` samples (None: the extension's
    default at `spp`, preroll_samples), drawn in order from a
    pool of the first frame's samples that its own `spp` do not use. With `captured` (the
    extension's own pre-roll frames, as capture.py keeps them, in groups of its --spp) the pool
    is all of theirs, whatever `spp`, and must hold the whole pre-roll. Without, it is the
    frame's samples after its first `spp`, which make as many groups as they hold, the last
    one smaller where the pool runs out."""
    if preroll_spp is None:
        preroll_spp = preroll_samples(spp)
    if captured:
        pool = np.concatenate(captured, axis=2)
        if pool.shape[2] < preroll_frames * preroll_spp:
            raise ValueError(f"the captured pre-roll holds {pool.shape[2]} samples per pixel, fewer than the "
                             f"{preroll_frames} x {preroll_spp} asked")
    else:
        pool = frame["samples"][:, :, spp:]
    return [np.ascontiguousarray(pool[:, :, g * preroll_spp:(g + 1) * preroll_spp])
            for g in range(preroll_frames) if g * preroll_spp < pool.shape[2]]


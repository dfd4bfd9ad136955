"""The Cycles suite: validation sequences rendered by Blender through the extension's capture path.

The sequences are made by ``training/cycles/make_data.py`` (in Blender's Python, with bpy) into
``<data>/val/cycles_NNNNN``; the benchmark reads them and never renders. Besides the methods
every suite has, this one has Blender's own denoiser exactly as users get it: Cycles rendering
S samples with OpenImageDenoise on (albedo + normal, prefilter Accurate), stored by the capture
as ``blender_oidn.npz``. Its time is that whole render (sampling and denoising), counted as
render time; the other methods' render time is the capture path's one-sample sub-renders.
The reference is the mean of two independent target renders with other seeds than the input;
``reference_halves.npz`` holds both, and one scored against the other is the reference noise.
``preroll.npz`` holds the extension's pre-roll of the first frame, which the ``+preroll``
method denoises before it, as the extension does.
"""

from __future__ import annotations

import json
import pathlib
import statistics
from typing import Any

import numpy as np

import affinity_core

from .methods import Method, Runner

#: Where make_data.py writes by default.
DEFAULT_DATA_DIR = pathlib.Path.home() / ".cache" / "affinity" / "cycles-v1"
BLENDER_OIDN = "blender-oidn"
BLENDER_OIDN_TEXT = ("Blender's Cycles with its own OpenImageDenoise (albedo + normal, prefilter Accurate), "
                     "as users get it; its time is the whole render (sampling and denoising)")
MAKE_DATA = "training/cycles/make_data.py"
SUITE_TEXT = (
    "Sequences: Cycles validation scenes of `training/cycles/scene_generator.py` (seeds never trained on), captured by "
    f"`{MAKE_DATA}` through the Blender extension's own path (one-sample sub-renders, its features, motion and "
    "validity); an S-spp input is the first S sub-renders of each frame. Reference: the mean of two independent "
    "Cycles renders with other seeds (their spp in each sequence's render_summary.json; the reference noise below "
    "scores one against the other). Render time at S spp: the capture's sub-renders, feature mapping and motion "
    "of a frame scaled by S/8; "
    "`blender-oidn`'s time is Cycles rendering S samples and denoising, as one ordinary render. ")


#: What the reference noise scores on this suite (report.reference_noise_markdown).
SECOND_REFERENCE_TEXT = ("Half b of each sequence's reference (half its samples, the spp in its "
                         "render_summary.json), as the second reference, with half a as the first")


def blender_oidn_description() -> Method:
    """Blender's denoiser as an entry of the methods' descriptions (its runner is per sequence)."""
    def start() -> Runner:
        raise RuntimeError("blender-oidn runs per sequence (CyclesSequence.blender_oidn_method)")

    return Method(BLENDER_OIDN, "baseline", BLENDER_OIDN_TEXT, start)


def sequence_folder(data_dir: pathlib.Path, seed: int) -> pathlib.Path:
    folder = data_dir / "val" / f"cycles_{seed:05d}"
    if not (folder / "render_summary.json").is_file():
        raise SystemExit(f"bench: {folder} is missing or incomplete: make it with "
                         f".venv-blender/bin/python {MAKE_DATA} --out {data_dir} --val-seeds {seed} "
                         "--train-seeds ''")
    return folder


class CyclesSequence:
    """One validation sequence: frames, timings, Blender's denoised frames, reference halves."""

    def __init__(self, folder: pathlib.Path) -> None:
        self.folder = folder
        self.summary: dict[str, Any] = json.loads((folder / "render_summary.json").read_text())
        self.frames = [affinity_core.read_frame(path) for path in affinity_core.list_frame_files(folder)]
        oidn_file = folder / "blender_oidn.npz"
        self.blender_oidn = dict(np.load(oidn_file)) if oidn_file.is_file() else {}
        #: The extension's pre-roll of the first frame, as capture.py keeps it; None without.
        self.preroll: list[np.ndarray] | None = None
        preroll_file = folder / "preroll.npz"
        if preroll_file.is_file():
            with np.load(preroll_file) as groups:
                self.preroll = [groups[f"group{g}"] for g in range(1, len(groups.files) + 1)]

    @property
    def render_spp(self) -> int:
        return int(self.summary["spp"])

    @property
    def noisy_seconds_per_frame(self) -> float:
        """The capture path's work on a frame at render_spp, the denoiser's excepted: one-sample
        sub-renders with their passes read, the features mapped, the motion computed."""
        seconds = self.summary["seconds"]
        return (seconds["sub_renders"] + seconds["features"] + seconds["motion"]) / len(self.frames)

    def blender_oidn_seconds(self, spp: int) -> float:
        """Median wall time of Cycles rendering and denoising a frame at `spp` (first excluded)."""
        times = self.summary["blender_oidn_seconds"].get(str(spp), [])
        if not times:
            return float("nan")
        return statistics.median(times[1:] if len(times) > 2 else times)

    def blender_oidn_method(self) -> Method | None:
        if not self.blender_oidn:
            return None
        images = self.blender_oidn

        def start() -> Runner:
            def run(frame: dict[str, Any]) -> np.ndarray:
                key = f"spp{frame['samples'].shape[2]}_frame{frame['info']['frame_index']}"
                if key not in images:
                    raise SystemExit(f"bench: {self.folder}/blender_oidn.npz has no {key}")
                return images[key]

            return run

        return Method(BLENDER_OIDN, "baseline", BLENDER_OIDN_TEXT, start)

    def second_reference(self) -> tuple[list[np.ndarray], list[dict[str, Any]]] | None:
        """Half b scored against half a: frames whose reference is half a, and half b's images."""
        halves_file = self.folder / "reference_halves.npz"
        if not halves_file.is_file():
            return None
        halves = np.load(halves_file)
        frames = [dict(frame, reference=halves[f"a_frame{i}"]) for i, frame in enumerate(self.frames)]
        return [halves[f"b_frame{i}"] for i in range(len(self.frames))], frames

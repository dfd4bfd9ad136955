"""The compared methods, all fed the same frame dicts (first S samples of each pixel, no
reference).

A Method makes a fresh runner per sequence (``start()``); the runner is called on the frames in
order and returns linear RGB float32 (H, W, 3). Families: "input" (the noisy mean), "baseline"
(OpenImageDenoise, SVGF), "ours" (each model of the ladder), "ablation" (the default model with
one part switched off).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

import affinity_core

from .data import PREROLL_FRAMES

Runner = Callable[[dict[str, Any]], np.ndarray]

#: The ablations of affinity_core.Denoiser (docs/METHOD.md section 9).
ABLATIONS = affinity_core.Denoiser.ABLATIONS
#: The built-in model, where a model path is expected.
BUILT_IN = "builtin"
BF16_SUFFIX = ":bf16"  # after a model's path: its bfloat16 form


def _channels(group: str) -> slice:
    first = affinity_core.FEATURE_NAMES.index(f"{group}.{'X' if group == 'normal' else 'R'}")
    return slice(first, first + 3)


DIFFUSE, SPECULAR, NORMAL, ALBEDO = (_channels(g) for g in ("diffuse", "specular", "normal", "albedo"))


@dataclass(frozen=True)
class Method:
    label: str
    family: str
    description: str
    start: Callable[[], Runner]


def noisy_mean(frame: dict[str, Any]) -> np.ndarray:
    """Per-pixel mean radiance (diffuse + specular) of the samples: the undenoised input."""
    samples = frame["samples"]
    return (samples[:, :, :, DIFFUSE] + samples[:, :, :, SPECULAR]).mean(axis=2, dtype=np.float32)


def _noisy() -> Runner:
    return noisy_mean


def _oidn() -> Runner:
    import pyoidn

    def run(frame: dict[str, Any]) -> np.ndarray:
        samples = frame["samples"]
        colour = noisy_mean(frame)
        albedo = np.clip(samples[:, :, :, ALBEDO].mean(axis=2, dtype=np.float32), 0.0, 1.0)
        normal = samples[:, :, :, NORMAL].mean(axis=2, dtype=np.float32)
        length = np.linalg.norm(normal, axis=2, keepdims=True)
        normal = np.divide(normal, length, out=np.zeros_like(normal), where=length > 0)  # misses stay 0
        return pyoidn.denoise(colour, albedo, normal, hdr=True)

    return run


def _svgf() -> Runner:
    return affinity_core.Svgf().denoise


def _ours(model: affinity_core.Model, ablation: str | None = None) -> Callable[[], Runner]:
    def start() -> Runner:
        return affinity_core.Denoiser(model, ablation=ablation).denoise

    return start


class PrerollRunner:
    """The extension's pre-roll: before the first frame, `preroll` denoises groups of samples
    of it (data.preroll_groups) as frames of a still camera (output unused), so the first frame
    starts with a history."""

    def __init__(self, model: affinity_core.Model) -> None:
        self.denoiser = affinity_core.Denoiser(model)
        self.prerolled = False

    def preroll(self, first: dict[str, Any], groups: list[np.ndarray]) -> None:
        still = np.zeros_like(first["motion"])
        for index, samples in enumerate(groups):
            valid = np.full_like(first["valid"], 1.0 if index > 0 else 0.0)
            self.denoiser.denoise(dict(first, samples=samples, motion=still, valid=valid))
        self.prerolled = bool(groups)

    def __call__(self, frame: dict[str, Any]) -> np.ndarray:
        if self.prerolled:  # the frame before was this one, from the same camera
            self.prerolled = False
            frame = dict(frame, motion=np.zeros_like(frame["motion"]), valid=np.ones_like(frame["valid"]))
        return self.denoiser.denoise(frame)


def _prerolled(model: affinity_core.Model) -> Callable[[], Runner]:
    return lambda: PrerollRunner(model)


def load_model(path: str) -> affinity_core.Model:
    """PATH, or PATH:bf16 for the model with bfloat16 products (affinity/precision.h)."""
    precision = "fp32"
    if path.endswith(BF16_SUFFIX):
        path, precision = path[: -len(BF16_SUFFIX)], "bf16"
    if path == BUILT_IN:
        return affinity_core.Model.built_in(precision)
    return affinity_core.Model.from_file(os.fspath(path), precision)


def make_methods(models: list[tuple[str, str]]) -> list[Method]:
    """noisy, oidn, svgf, ours-<label> and ours-<label>+preroll for every (label, path) in
    `models` (the extension runs every model with its pre-roll), and the ablations of the first
    model."""
    methods = [
        Method("noisy", "input", "per-pixel mean of the samples", _noisy),
        Method("oidn", "baseline", "OpenImageDenoise (pyoidn), HDR colour + albedo + normal, single frame", _oidn),
    ]
    methods.append(Method("svgf", "baseline", "SVGF (Schied et al. 2017), affinity_core.Svgf", _svgf))
    loaded = [(label, path, load_model(path)) for label, path in models]
    for label, path, model in loaded:
        methods.append(Method(f"ours-{label}", "ours", f"affinity_core.Denoiser, model {label} ({path})", _ours(model)))
        methods.append(Method(f"ours-{label}+preroll", "ours",
                              f"model {label} with the Blender extension's pre-roll: before the first frame, "
                              f"{PREROLL_FRAMES} frame(s) of 8 times the samples per frame (16 to 64) denoised "
                              "as a still camera: "
                              "from the extension's own pre-roll where the sequence holds it (Cycles suite), else "
                              "from the first frame's spare samples (fewer where it holds fewer); costs those "
                              "samples once per sequence",
                              _prerolled(model)))
    if loaded:
        label, path, model = loaded[0]
        for ablation in ABLATIONS:
            if ablation == "no_light_restoration" and not model.light_restoration:
                continue  # the model's file does not ask for it: the row would be the model's own
            methods.append(Method(f"{label}-{ablation}", "ablation",
                                  f"model {label} with ablation={ablation!r}", _ours(model, ablation)))
    return methods

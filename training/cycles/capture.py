"""One Cycles sequence as training or benchmark data, through the extension's own capture path.

The per-sample features, motion and validity come from the extension's ``DenoiseRender`` (the
very code that feeds the core inside Blender), so the network is trained and judged on exactly
what it gets from artists' scenes. On top of that, per frame:

- a target: the Combined pass rendered at many samples with a *different* seed, so that its
  noise is independent of the input's (a Noise2Noise target when it is noisy: the trainer's
  loss sees its noise as zero-mean);
- for validation and benchmark sequences, two such targets with different seeds: their mean is
  the reference and their difference measures how noisy it still is;
- optionally Blender's own denoiser exactly as users get it: Cycles at S samples with
  OpenImageDenoise (albedo + normal, prefilter Accurate), and the wall time of that render.

Writes ``frame_NNNN.exr`` files (docs/FRAME_FILES.md, the reference included) and
``render_summary.json``; Blender's denoised frames go to ``blender_oidn.npz`` (``spp{S}_frame{i}``),
the two target halves of validation sequences to ``reference_halves.npz`` (``a_frame{i}``,
``b_frame{i}``), and the extension's pre-roll of the first frame to ``preroll.npz``
(``group{g}``: the per-sample features of pre-roll frame g, as the extension gives them to the
core before the first frame).
"""

from __future__ import annotations

import json
import os
import shutil
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from affinity_denoiser import engine, passes, pipeline
from affinity_denoiser.overrides import Overrides

#: Raised whenever the extension's capture path changes what it gives the core, so that
#: sequences captured before can be found and their inputs refreshed (``refresh_inputs``).
#: 2: the capture animates Cycles' seed whatever the scene's setting.
#: 3: pixels whose first sample scattered in a volume take their depth from a later sample,
#: and the validity test allows for the depth's change across a pixel (motion.py).
CAPTURE_VERSION = 3

#: Added to the scene's seed for the k-th target render (k = 1, 2): far from any seed a
#: sequence's own frames use, so the target's samples share nothing with the input's.
TARGET_SEED_STRIDE = 7_919_111

#: Added d times to a validation scene's seed for its d-th draw of inputs (capture_input_draw):
#: no multiple of it up to a hundred draws meets a target's seed.
INPUT_DRAW_SEED_STRIDE = 1_000_003


@dataclass
class CaptureSettings:
    spp: int = 8                    # input samples per pixel (one-sample sub-renders)
    target_spp: int = 64            # samples of each target render
    targets: int = 1                # independent target renders per frame (2: measure their noise)
    blender_oidn_spp: tuple[int, ...] = ()  # Blender's own denoiser at these sample counts
    preroll_frames: int = 0         # the extension's pre-roll of the first frame, kept (add_preroll)


def render_combined(scene: Any, samples: int, seed: int, denoise: bool) -> tuple[np.ndarray, float]:
    """One ordinary Cycles render of the current frame: its Combined RGB and wall seconds.

    ``denoise``: Cycles' OpenImageDenoise as Blender users get it (albedo + normal, prefilter
    Accurate, on the CPU)."""
    cycles = scene.cycles

    def read(result: Any) -> np.ndarray:
        combined = passes.read_result(result)[passes.PASS_NAMES["combined"][0]]
        return np.ascontiguousarray(combined[..., :3])

    with Overrides() as overrides:
        overrides.set(scene.render, "engine", engine.IDNAME)
        overrides.set(scene.render, "use_persistent_data", True)
        overrides.set(scene.render, "use_compositing", False)
        overrides.set(scene.render, "use_sequencer", False)
        overrides.set(cycles, "samples", samples)
        overrides.set(cycles, "seed", seed)
        overrides.set(cycles, "use_adaptive_sampling", False)
        overrides.set_if_present(cycles, "use_sample_subset", False)
        overrides.set(cycles, "sample_offset", 0)
        overrides.set(cycles, "use_denoising", denoise)
        if denoise:
            overrides.set(cycles, "denoiser", "OPENIMAGEDENOISE")
            overrides.set(cycles, "denoising_input_passes", "RGB_ALBEDO_NORMAL")
            overrides.set(cycles, "denoising_prefilter", "ACCURATE")
            overrides.set_if_present(cycles, "denoising_use_gpu", False)
        scene.update_tag()  # persistent data would otherwise repeat the previous render
        image, seconds = engine.render_and_capture(read)
    if image is None:
        raise pipeline.Cancelled("the render was cancelled")
    return image, seconds


def capture_sequence(scene: Any, folder: str, settings: CaptureSettings,
                     progress: Callable[[str], None] = lambda text: None) -> dict[str, Any]:
    """Renders every frame of ``scene`` (frame_start..frame_end) into ``folder`` (created; must
    not hold frames yet) and returns the summary also written to render_summary.json."""
    from affinity_core import metrics

    _start_folder(folder)
    run, input_seconds = _capture_inputs(scene, folder, settings, progress)
    results = run.results

    base_seed = int(scene.cycles.seed)
    target_seconds = 0.0
    target_noise: list[float] = []
    halves: dict[str, np.ndarray] = {}
    for index, result in enumerate(results):
        scene.frame_set(result.frame)
        progress(f"targets, frame {result.frame}")
        targets = []
        for k in range(1, settings.targets + 1):
            image, seconds = render_combined(scene, settings.target_spp,
                                             base_seed + k * TARGET_SEED_STRIDE, denoise=False)
            targets.append(image)
            target_seconds += seconds
        if len(targets) == 2:
            target_noise.append(metrics.smape(targets[0], targets[1]))
            halves[f"a_frame{index}"], halves[f"b_frame{index}"] = targets
        _write_frame(folder, index, result, np.mean(targets, axis=0).astype(np.float32),
                     settings.target_spp * settings.targets)
    oidn_seconds = _render_blender_oidn(scene, folder, [result.frame for result in results], settings, progress)
    if halves:
        np.savez_compressed(os.path.join(folder, "reference_halves.npz"), **halves)

    summary = {
        "scene_name": scene.name,
        "frames": len(results),
        "width": int(results[0].noisy.shape[1]),
        "height": int(results[0].noisy.shape[0]),
        "spp": settings.spp,
        "reference_spp": settings.target_spp * settings.targets,
        "target_renders": settings.targets,
        "seed": base_seed,
        # The scene's setting (the targets and Blender's own denoiser follow it; the input's
        # capture animates the seed whatever it is).
        "animated_seed": bool(scene.cycles.use_animated_seed),
        **_input_summary(),
        "seconds": {"input": input_seconds, "targets": target_seconds, **_input_seconds(run)},
        # SMAPE between the two independent target halves, per frame: the reference (their
        # mean) has roughly half this error's variance against the converged image.
        "target_half_smape": target_noise,
        "blender_oidn_seconds": oidn_seconds,
    }
    if settings.preroll_frames:
        _capture_preroll(scene, folder, settings, summary)
    _write_summary(folder, summary)
    return summary


def capture_input_draw(scene: Any, folder: str, reference_folder: str, draw: int, settings: CaptureSettings,
                       progress: Callable[[str], None] = lambda text: None) -> dict[str, Any]:
    """Another draw of a validation sequence's noise: the inputs, the pre-roll and Blender's own
    denoiser of ``scene`` captured into ``folder`` (created; must not hold frames yet) from the
    scene's current seed, which the caller has moved ``draw`` strides (``INPUT_DRAW_SEED_STRIDE``)
    from the seed of ``reference_folder``, a complete validation sequence of the same scene. The
    references, which no input seed changes, are taken from there. One draw of 8 frames scores a
    denoiser by the luck of its samples as much as by its skill; several draws of the same scene
    tell the two apart (docs/CYCLES_DATA.md, "Draws"). Returns the summary, also written."""
    summary = _read_summary(reference_folder, settings.spp)
    if int(scene.cycles.seed) != summary["seed"] + draw * INPUT_DRAW_SEED_STRIDE:
        raise ValueError(f"the scene's seed {scene.cycles.seed} is not draw {draw} of {reference_folder}'s "
                         f"seed {summary['seed']}")
    run, input_seconds = _capture_with_references(scene, folder, reference_folder, summary, settings, progress)
    _copy_extras(reference_folder, folder, ("reference_halves.npz",))
    summary.update(_input_summary(), input_draw=draw, input_seed=int(scene.cycles.seed),
                   references_from=os.path.abspath(reference_folder))
    # No target was rendered here (the references are the other sequence's).
    summary["seconds"].update({"input": input_seconds, "targets": 0.0, **_input_seconds(run)})
    summary["blender_oidn_seconds"] = _render_blender_oidn(scene, folder, [r.frame for r in run.results], settings,
                                                           progress)
    if settings.preroll_frames:
        _capture_preroll(scene, folder, settings, summary)
    _write_summary(folder, summary)
    return summary


def add_preroll(scene: Any, folder: str, settings: CaptureSettings) -> dict[str, Any]:
    """Adds ``preroll.npz`` to ``folder``, a complete sequence of ``scene`` made without one;
    everything else in it is kept. Returns the updated summary, also written."""
    summary = _read_summary(folder, settings.spp)
    _capture_preroll(scene, folder, settings, summary)
    _write_summary(folder, summary)
    return summary


def refresh_inputs(scene: Any, folder: str, old_folder: str, settings: CaptureSettings,
                   progress: Callable[[str], None] = lambda text: None) -> dict[str, Any]:
    """Captures the inputs of ``scene``'s frames again into ``folder`` (created; must not hold
    frames yet), taking each frame's reference and the sequence's other files from
    ``old_folder``, a complete sequence of the same scene from an older capture path: the
    targets and Blender's own denoiser do not depend on the capture, and cost most of the time.
    Returns the updated summary, also written to render_summary.json."""
    summary = _read_summary(old_folder, settings.spp)
    run, input_seconds = _capture_with_references(scene, folder, old_folder, summary, settings, progress)
    _copy_extras(old_folder, folder, ("blender_oidn.npz", "reference_halves.npz"))
    summary.update(_input_summary())
    summary["seconds"].update({"input": input_seconds, **_input_seconds(run)})
    if settings.preroll_frames:  # the pre-roll is an input: captured again
        _capture_preroll(scene, folder, settings, summary)
    _write_summary(folder, summary)
    return summary


def deepen_references(scene: Any, folder: str, old_folder: str, half_spp: int,
                      progress: Callable[[str], None] = lambda text: None) -> dict[str, Any]:
    """Adds samples to both reference halves of ``old_folder``, a complete validation sequence
    of ``scene``, until each half has ``half_spp``, and writes the sequence with the new
    references into ``folder`` (created; must not hold frames yet). The new samples come from
    renders with seeds no earlier target used, so the halves stay independent; the inputs and
    Blender's frames are copied unchanged. Returns the updated summary, also written to
    render_summary.json."""
    import affinity_core
    from affinity_core import metrics

    summary = _read_summary(old_folder)
    if summary.get("target_renders") != 2:
        raise ValueError(f"{old_folder} has no reference halves (not a validation sequence)")
    have = int(summary["reference_spp"]) // 2
    if half_spp <= have:
        raise ValueError(f"{old_folder} already has {have} samples per reference half, not fewer than {half_spp}")
    extra = half_spp - have
    seeds_used = int(summary.get("target_seeds_used", 2))  # seeds base + k * stride, k = 1..used
    _start_folder(folder)
    halves = dict(np.load(os.path.join(old_folder, "reference_halves.npz")))
    base_seed = int(summary["seed"])
    seconds_total, noise = 0.0, []
    for index, path in enumerate(affinity_core.list_frame_files(old_folder)):
        scene.frame_set(scene.frame_start + index)
        progress(f"references, frame {scene.frame_start + index}")
        for k, half in enumerate("ab", start=seeds_used + 1):
            image, seconds = render_combined(scene, extra, base_seed + k * TARGET_SEED_STRIDE, denoise=False)
            seconds_total += seconds
            key = f"{half}_frame{index}"
            halves[key] = ((halves[key] * have + image * extra) / half_spp).astype(np.float32)
        a, b = halves[f"a_frame{index}"], halves[f"b_frame{index}"]
        noise.append(metrics.smape(a, b))
        frame = affinity_core.read_frame(path)
        frame["reference"] = ((a + b) / 2).astype(np.float32)
        frame["info"]["reference_spp"] = 2 * half_spp
        affinity_core.write_frame(os.path.join(folder, os.path.basename(path)), frame)
    np.savez_compressed(os.path.join(folder, "reference_halves.npz"), **halves)
    _copy_extras(old_folder, folder, ("blender_oidn.npz", "preroll.npz"))
    summary.update(reference_spp=2 * half_spp, target_seeds_used=seeds_used + 2, target_half_smape=noise)
    summary["seconds"]["targets"] = summary["seconds"]["targets"] + seconds_total
    _write_summary(folder, summary)
    return summary


def _capture_inputs(scene: Any, folder: str, settings: CaptureSettings,
                    progress: Callable[[str], None]) -> tuple[pipeline.DenoiseRender, float]:
    """Every frame of ``scene`` (frame_start..frame_end) through the extension's capture, its
    per-sample data kept; the run and its wall seconds. No pre-roll: a frame file holds its own
    samples only, so the first one has no history."""
    frames = list(range(scene.frame_start, scene.frame_end + 1))
    return _run_extension(scene, folder, frames, settings.spp, 0, lambda text: progress(f"input {text}"))


def _capture_preroll(scene: Any, folder: str, settings: CaptureSettings, summary: dict[str, Any]) -> None:
    """The extension's pre-roll of the first frame (settings.preroll_frames frames, S samples
    each, from the seeds the extension uses; the benchmark pools them, in order, into the
    extension's pre-roll frames: two of the cache's 8 make its default one frame of 16) into
    ``folder``/preroll.npz, written atomically;
    ``summary`` records its frames and wall seconds. With the Tabulated Sobol pattern a
    pre-roll frame's first s samples are what the extension renders at s samples per frame
    (one-sample sub-renders at offsets 0..s-1 of the same seed); with Automatic on Blender
    4.5 and 5.3 the size of a sample set changes its samples, as it does for the frames' own
    (docs/CYCLES_DATA.md, "Capture"). The first frame itself is rendered again by the run and
    dropped (its frame file is the inputs')."""
    run, seconds = _run_extension(scene, folder, [scene.frame_start], settings.spp,
                                  settings.preroll_frames, lambda text: None)
    groups = {f"group{g}": frame["samples"] for g, frame in enumerate(run.results[0].preroll_data, start=1)}
    if len(groups) != settings.preroll_frames:
        raise RuntimeError(f"the extension rendered {len(groups)} pre-roll frames, not {settings.preroll_frames}")
    temporary = os.path.join(folder, "preroll.tmp.npz")
    np.savez_compressed(temporary, **groups)
    os.replace(temporary, os.path.join(folder, "preroll.npz"))
    summary["preroll_frames"] = settings.preroll_frames
    summary["seconds"]["preroll"] = seconds


def _capture_with_references(scene: Any, folder: str, source: str, summary: dict[str, Any],
                             settings: CaptureSettings, progress: Callable[[str], None]
                             ) -> tuple[pipeline.DenoiseRender, float]:
    """The inputs of ``scene``'s frames captured into ``folder`` (created; must not hold frames
    yet), each frame written with the reference of ``source``'s frame, a complete sequence of
    the same scene whose summary is ``summary``; the run and its wall seconds."""
    import affinity_core

    _start_folder(folder)
    run, input_seconds = _capture_inputs(scene, folder, settings, progress)
    if len(run.results) != summary["frames"]:
        raise ValueError(f"{source} has {summary['frames']} frames, the scene {len(run.results)}")
    for index, result in enumerate(run.results):
        old = affinity_core.read_frame(os.path.join(source, affinity_core.frame_file_name(index)))
        _write_frame(folder, index, result, old["reference"], old["info"]["reference_spp"])
    return run, input_seconds


def _render_blender_oidn(scene: Any, folder: str, frames: list[int], settings: CaptureSettings,
                         progress: Callable[[str], None]) -> dict[str, list[float]]:
    """Blender's own denoiser at each of settings.blender_oidn_spp, every frame rendered from the
    scene's seed, into ``folder``/blender_oidn.npz (none: nothing written); the wall seconds of
    each render, by sample count."""
    images: dict[str, np.ndarray] = {}
    seconds: dict[str, list[float]] = {str(spp): [] for spp in settings.blender_oidn_spp}
    for index, frame in enumerate(frames):
        scene.frame_set(frame)
        progress(f"Blender's denoiser, frame {frame}")
        for spp in settings.blender_oidn_spp:
            images[f"spp{spp}_frame{index}"], took = render_combined(scene, spp, int(scene.cycles.seed), denoise=True)
            seconds[str(spp)].append(took)
    if images:
        np.savez_compressed(os.path.join(folder, "blender_oidn.npz"), **images)
    return seconds


def _run_extension(scene: Any, folder: str, frames: list[int], spp: int, preroll_frames: int,
                   progress: Callable[[str], None]) -> tuple[pipeline.DenoiseRender, float]:
    """The extension's render of ``frames``, every frame's (and pre-roll frame's) input to the
    core kept; the run and its wall seconds. Its own denoised frames go to a scratch folder in
    ``folder``, removed after."""
    scratch = os.path.join(folder, "extension_output")
    start = time.perf_counter()
    run = pipeline.DenoiseRender(
        scene, scene.view_layers[0], frames,
        pipeline.Settings(samples_per_frame=spp, output_folder=scratch, preroll_frames=preroll_frames,
                          preroll_samples=spp),
        progress=lambda done, total, text: progress(text))
    run.keep_frames = True
    run.run()
    seconds = time.perf_counter() - start
    shutil.rmtree(scratch, ignore_errors=True)
    return run, seconds


def _copy_extras(old_folder: str, folder: str, names: tuple[str, ...]) -> None:
    """The files of ``names`` that ``old_folder`` has, copied into ``folder``."""
    for name in names:
        if os.path.isfile(os.path.join(old_folder, name)):
            shutil.copyfile(os.path.join(old_folder, name), os.path.join(folder, name))


def _write_frame(folder: str, index: int, result: Any, reference: np.ndarray, reference_spp: int) -> None:
    """Frame ``index`` of a capture (``result``: its kept frame data) with its reference, as a
    frame file of ``folder``."""
    import affinity_core

    frame = result.frame_data
    assert frame is not None
    frame["reference"] = reference
    frame["info"]["reference_spp"] = reference_spp
    frame["info"]["frame_index"] = index
    affinity_core.write_frame(os.path.join(folder, affinity_core.frame_file_name(index)), frame)


def _input_summary() -> dict[str, Any]:
    """What a summary records of the capture that made its inputs."""
    return {
        "capture_version": CAPTURE_VERSION,
        "blender_version": ".".join(str(v) for v in __import__("bpy").app.version),
    }


def _input_seconds(run: pipeline.DenoiseRender) -> dict[str, float]:
    timings = run.timings
    return {
        "sub_renders": float(np.sum(timings.sub_renders)),
        "features": float(np.sum(timings.features)),
        "motion": float(np.sum(timings.motion)),
        "denoise": float(np.sum(timings.denoise)),
    }


def _start_folder(folder: str) -> None:
    """Creates the folder a sequence is written into, refusing one that already holds frames."""
    import affinity_core

    os.makedirs(folder, exist_ok=True)
    if affinity_core.list_frame_files(folder):
        raise FileExistsError(f"{folder} already holds frame files")


def _read_summary(folder: str, spp: int | None = None) -> dict[str, Any]:
    """A complete sequence's summary; with ``spp``, refusing one with another sample count."""
    with open(os.path.join(folder, "render_summary.json")) as handle:
        summary = json.load(handle)
    if spp is not None and summary["spp"] != spp:
        raise ValueError(f"{folder} has {summary['spp']} samples per frame, not {spp}")
    return summary


def _write_summary(folder: str, summary: dict[str, Any]) -> None:
    """render_summary.json, written last and atomically: its presence marks a complete sequence."""
    with open(os.path.join(folder, "render_summary.json.tmp"), "w") as handle:
        json.dump(summary, handle, indent=1)
    os.replace(os.path.join(folder, "render_summary.json.tmp"),
               os.path.join(folder, "render_summary.json"))

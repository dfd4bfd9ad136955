"""A denoise-render: per frame, S one-sample Cycles sub-renders -> features -> core -> files.

``DenoiseRender.steps()`` is a generator that does one sub-render per step, so the same job
runs to completion from a script (``run()``) or one step per timer tick from a modal operator
(which can cancel between steps by closing the generator). Every temporary change to the scene,
its view layer and its materials is undone in ``finally`` blocks, also on error or cancel.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Generator, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from . import backend, compositor, engine, features, materials, motion, output, passes
from .overrides import Overrides

MAX_SAMPLES_PER_FRAME = 8
#: A sequence's first frame has no history, so a temporal denoiser does worst there. Before it,
#: the capture renders that frame this many more times with other samples and denoises them as
#: frames of a still camera: the first frame then starts with a history. Costs this many frames'
#: sub-renders once per sequence (docs/BLENDER.md, "Pre-roll").
DEFAULT_PREROLL_FRAMES = 1
MAX_PREROLL_FRAMES = 8
#: Samples of each pre-roll frame: AUTO_PREROLL_SAMPLES (the setting's default) takes
#: PREROLL_FRAMES_OF_SAMPLES times the frames' own count, at least MIN_AUTO_PREROLL_SAMPLES and
#: at most MAX_PREROLL_SAMPLES (16 at 1 and 2 samples per frame, 32 at 4, 64 from 8), for a cost
#: paid once per sequence. A history of eight frames' samples lifted ColorVideoVDP at 4 and 8
#: samples per frame over a fixed 16; at 2, 32 or 64 scored below 16 (docs/BLENDER.md, "Pre-roll").
AUTO_PREROLL_SAMPLES = 0
PREROLL_FRAMES_OF_SAMPLES = 8
MIN_AUTO_PREROLL_SAMPLES = 16
#: The core's limit on a frame's samples (affinity/frame.h, kMaxSpp).
MAX_PREROLL_SAMPLES = 64
#: Added to the scene's seed (times the pre-roll frame's number) for the pre-roll's renders.
PREROLL_SEED_STEP = 7_919_111


def automatic_preroll_samples(samples_per_frame: int) -> int:
    """The pre-roll frame's samples that AUTO_PREROLL_SAMPLES stands for."""
    return min(MAX_PREROLL_SAMPLES, max(MIN_AUTO_PREROLL_SAMPLES, PREROLL_FRAMES_OF_SAMPLES * samples_per_frame))


def preroll_seed(seed: int, group: int, block: int) -> int:
    """The seed of pre-roll frame ``group`` (from 1), samples ``block`` x S to (block + 1) x S - 1:
    the scene's plus PREROLL_SEED_STEP x group for the first S (so an S-sample pre-roll frame is
    one set of S), another step per further block, distinct from every other frame's."""
    return (seed + PREROLL_SEED_STEP * (group + (MAX_PREROLL_FRAMES + 1) * block)) % 2**31


#: Blender versions whose sample subsets were checked to render exactly one sample of the set.
#: A behaviour check, not an API one: bpy 4.2.23 and the Blender 4.3.2 program have
#: ``use_sample_subset`` but ignore ``sample_subset_length`` (a subset at offset k renders samples
#: k..samples-1, so offset 0 is the whole render); there ``samples = 1`` with ``sample_offset``
#: gives one distinct sample per offset. From 4.5 on subsets are exact and that route renders the
#: same sample at every offset (4.4: not measured). See docs/BLENDER.md, "Blender versions".
SAMPLE_SUBSETS_VERIFIED_FROM = (4, 5, 0)


def uses_sample_subsets(cycles_settings: Any) -> bool:
    import bpy

    return (hasattr(cycles_settings, "use_sample_subset")
            and bpy.app.version >= SAMPLE_SUBSETS_VERIFIED_FROM)


#: Names of Blender's built-in engines (their RNA enum has no items in background mode).
_ENGINE_NAMES = {"BLENDER_EEVEE": "EEVEE", "BLENDER_EEVEE_NEXT": "EEVEE",
                 "BLENDER_WORKBENCH": "Workbench"}


def engine_name(identifier: str) -> str:
    """The user interface's name of a render engine."""
    import bpy

    for engine_class in bpy.types.RenderEngine.__subclasses__():
        if getattr(engine_class, "bl_idname", None) == identifier:
            return str(engine_class.bl_label)
    return _ENGINE_NAMES.get(identifier, identifier)


def cycles_problem(scene: Any) -> str:
    """Empty when ``scene`` renders with Cycles (or Cycles + Affinity Denoiser); else the
    message that says it must."""
    if scene.render.engine in ("CYCLES", engine.DENOISING_ENGINE):
        return ""
    return (f"The Affinity Denoiser needs Cycles as the render engine, not "
            f"{engine_name(scene.render.engine)}: choose Cycles + Affinity Denoiser (or Cycles) "
            f"in Render Properties")


#: Passes Cycles writes for the sample at offset 0 only (the others hold the no-hit value):
#: the denoised frame's copy of them is that sample's, not the samples' mean. Measured on bpy
#: 5.0.1: Depth is 1e10 and Position 0 everywhere at offset 1.
FIRST_SAMPLE_PASSES = frozenset({"Depth", "Z", "Position", "Object Index", "IndexOB",
                                 "Material Index", "IndexMA"})


class Cancelled(RuntimeError):
    """The render was cancelled (Esc, or the render job reported a break)."""


@dataclass
class Settings:
    samples_per_frame: int = 4
    model_path: str = ""
    precision: str = "auto"
    temporal: bool = True
    output_folder: str = ""
    keep_sample_frames: bool = False
    preroll_frames: int = DEFAULT_PREROLL_FRAMES
    preroll_samples: int = AUTO_PREROLL_SAMPLES

    @classmethod
    def from_properties(cls, props: Any) -> Settings:
        return cls(
            samples_per_frame=props.samples_per_frame,
            model_path=props.model_path,
            precision=props.precision,
            temporal=props.temporal,
            output_folder=props.output_folder,
            keep_sample_frames=props.keep_sample_frames,
            preroll_frames=props.preroll_frames,
            preroll_samples=props.preroll_samples,
        )

    def check(self) -> None:
        """Raises ValueError naming a setting the capture cannot run with."""
        if not 1 <= self.samples_per_frame <= MAX_SAMPLES_PER_FRAME:
            raise ValueError(f"samples per frame must be 1 to {MAX_SAMPLES_PER_FRAME}")
        if not 0 <= self.preroll_frames <= MAX_PREROLL_FRAMES:
            raise ValueError(f"pre-roll frames must be 0 to {MAX_PREROLL_FRAMES}")
        if not 0 <= self.preroll_samples <= MAX_PREROLL_SAMPLES:
            raise ValueError(f"pre-roll samples must be 0 (automatic) to {MAX_PREROLL_SAMPLES}")

    def preroll_sample_count(self) -> int:
        """Samples of each pre-roll frame: the setting, or the automatic count where it is 0."""
        if self.preroll_samples == AUTO_PREROLL_SAMPLES:
            return automatic_preroll_samples(self.samples_per_frame)
        return self.preroll_samples


@dataclass
class DenoisedFrame:
    """One frame captured and denoised: what writing and presenting it need."""

    frame: int
    rgba: np.ndarray  # (H, W, 4): the denoised radiance, alpha the samples' mean
    noisy: np.ndarray  # (H, W, 3) mean of the samples' radiance
    mean: dict[str, np.ndarray]  # every captured pass: the samples' mean (FIRST_SAMPLE_PASSES: sample 0)
    frame_data: dict[str, Any]  # the core's input (its samples None when they were streamed)
    report: dict[str, Any]  # the denoiser's report of the frame
    #: The core's input for each pre-roll frame before this one, where frames are kept.
    preroll_data: list[dict[str, Any]] = field(default_factory=list)


@dataclass
class FrameResult:
    frame: int
    denoised_path: str
    final_path: str
    sample_frame_path: str | None
    noisy: np.ndarray  # (H, W, 3) mean of the samples' radiance
    denoised: np.ndarray  # (H, W, 3)
    denoiser_report: dict[str, Any]
    frame_data: dict[str, Any] | None = None  # the core's input, kept when keep_frames is set
    preroll_data: list[dict[str, Any]] = field(default_factory=list)  # likewise, its pre-roll's


@dataclass
class Timings:
    sub_renders: list[float] = field(default_factory=list)  # including reading the passes
    read_passes: list[float] = field(default_factory=list)
    features: list[float] = field(default_factory=list)
    motion: list[float] = field(default_factory=list)  # object matrices, then the vectors
    denoise: list[float] = field(default_factory=list)
    present: list[float] = field(default_factory=list)
    write: list[float] = field(default_factory=list)


def _activate_view_layer(overrides: Overrides, view_layer: Any) -> None:
    import bpy

    window = bpy.context.window
    if window is not None and window.view_layer != view_layer:
        overrides.set(window, "view_layer", view_layer)


@contextmanager
def capture_setup(scene: Any, view_layer: Any, settings: Settings) -> Iterator[bool]:
    """Sets ``scene`` up for one-sample sub-renders of ``view_layer`` through the capture
    engine and yields the user's ``use_compositing``; every change is undone on leaving, also
    on error or cancel, and the current frame is put back."""
    import bpy

    original_frame = (scene.frame_current, scene.frame_subframe)
    try:
        with Overrides() as overrides, passes.shader_aovs(view_layer), \
                materials.surface_aovs(bpy.data):
            render, cycles = scene.render, scene.cycles
            use_compositing = bool(render.use_compositing)
            passes.enable_passes(overrides, view_layer)
            overrides.set(render, "engine", engine.IDNAME)
            overrides.set(render, "use_persistent_data", True)
            overrides.set(render, "use_single_layer", True)
            overrides.set(render, "use_compositing", False)
            overrides.set(render, "use_sequencer", False)
            overrides.set(render, "use_border", False)  # features and motion cover the whole frame
            overrides.set(cycles, "use_denoising", False)
            overrides.set(cycles, "use_adaptive_sampling", False)
            if uses_sample_subsets(cycles):  # samples = the whole set, one of them per render
                overrides.set(cycles, "samples", settings.samples_per_frame)
                overrides.set(cycles, "use_sample_subset", True)
                overrides.set(cycles, "sample_subset_length", 1)
            else:  # render 1 sample starting at sample_offset
                overrides.set_if_present(cycles, "use_sample_subset", False)
                overrides.set(cycles, "samples", 1)
            overrides.set(cycles, "sample_offset", 0)
            # New noise every frame, whatever the scene's setting: the history averages frames'
            # samples, which a pattern repeated on still surfaces would defeat.
            overrides.set(cycles, "use_animated_seed", True)
            # The denoise-render replaces the view layer's sample count, if it has one.
            overrides.set_if_present(view_layer, "samples", 0)
            _activate_view_layer(overrides, view_layer)
            yield use_compositing
    finally:
        engine.session.sink = None
        engine.session.present = None
        scene.frame_set(original_frame[0], subframe=original_frame[1])


class SequenceCapture:
    """Captures and denoises successive frames of one view layer: per frame, S one-sample
    sub-renders through the capture engine, their features to the core's Denoiser, which
    carries the sequence's history. Runs inside ``capture_setup``."""

    def __init__(self, scene: Any, view_layer: Any, settings: Settings, timings: Timings,
                 keep_frames: bool = False) -> None:
        import bpy

        settings.check()
        self.scene = scene
        self.view_layer = view_layer
        self.settings = settings
        self.timings = timings
        #: Keep each frame's per-sample data (frame files, tests): no streaming to the core.
        self.keep_frames = keep_frames
        self.denoiser = backend.create_denoiser(settings.model_path, settings.precision)
        motion.scene_camera(scene, bpy.context.evaluated_depsgraph_get())  # fail early
        self._previous: motion.FrameGeometry | None = None
        self._names: dict[str, str] | None = None
        #: The last frame denoised since the history began; None with no history.
        self.last_frame: int | None = None
        #: The scene camera of that frame: another camera (a cut by camera markers), or a jump of
        #: this one that the core would not carry its history across (its continues_sequence),
        #: starts a new sequence, pre-rolled like the first.
        self._camera_name: str | None = None

    def reset(self) -> None:
        """Forgets the history: the next frame starts a new sequence."""
        self.denoiser.reset()
        self._previous = None
        self.last_frame = None
        self._camera_name = None

    def frame(self, frame: int,
              before_sample: Callable[[int], None] | None = None) -> Generator[int, None, DenoisedFrame]:
        """Renders and denoises ``frame``; yields the number of its sub-renders done after each
        one and returns the DenoisedFrame (``denoised = yield from capture.frame(f)``)."""
        import bpy

        scene, spp = self.scene, self.settings.samples_per_frame
        scene.frame_set(frame)
        depsgraph = bpy.context.evaluated_depsgraph_get()
        camera = motion.scene_camera(scene, depsgraph)
        if self.last_frame is not None and (
                scene.camera.name != self._camera_name
                or not self.denoiser.continues_sequence(camera.width, camera.height,
                                                        camera.world_to_camera.astype(np.float32))):
            self.reset()  # a camera cut: nothing before it is history
        start = time.perf_counter()
        transforms = motion.object_transforms(depsgraph)
        self.timings.motion.append(time.perf_counter() - start)
        ray_start = motion.ray_start_distance(camera)
        denoiser = self.denoiser
        # Streaming hands each sample to the core as it is rendered, so the frame's
        # per-sample features are never held together (at 4K, 8 spp: 4.8 GB); the whole
        # frame is kept only where it is asked for.
        stream = hasattr(denoiser, "add_samples") and not self.keep_frames
        if stream and denoiser.pending_samples:
            denoiser.discard_samples()  # left by an interrupted frame
        prerolled = self.settings.temporal and self.last_frame is None and self.settings.preroll_frames > 0
        preroll_data = []
        if prerolled:
            preroll_data = yield from self._preroll(frame, camera, ray_start, stream, before_sample)
        samples = None if stream else self._sample_buffer(camera)
        radiance = np.zeros((camera.height, camera.width, 3), np.float32)
        streaming_seconds = 0.0  # the denoiser's share of the sample loop
        sums: dict[str, np.ndarray] = {}
        first: dict[str, np.ndarray] = {}
        geometry = None
        for sample in range(spp):
            if before_sample is not None:
                before_sample(sample)
            captured = self._sub_render(sample)
            sample_features = self._sample_features(captured, camera, ray_start)
            names = self._names
            radiance += sample_features[..., 0:3]
            radiance += sample_features[..., 3:6]
            if samples is None:
                start = time.perf_counter()
                denoiser.add_samples(sample_features)
                streaming_seconds += time.perf_counter() - start
            else:
                samples[:, :, sample] = sample_features
            if sample == 0:  # Cycles writes Z for the sample at offset 0 only
                geometry = self._geometry(captured, names, camera, transforms)
            else:
                assert geometry is not None
                geometry.add_surfaces(captured[names["aov_distance"]][..., 0],
                                      captured[names["aov_object"]][..., 0],
                                      captured[names["aov_local"]][..., :3])
            # Blender 5.2 writes float32's largest value where a ray misses (Denoising Depth):
            # its sum is inf, as it should be, and no error.
            with np.errstate(over="ignore"):
                for name, image in captured.items():
                    if name in FIRST_SAMPLE_PASSES:
                        if sample == 0:
                            first[name] = image.copy()
                    elif name in sums:
                        sums[name] += image
                    else:
                        sums[name] = image.copy()
            yield sample + 1
        assert geometry is not None
        start = time.perf_counter()
        motion_vectors, valid = motion.scene_motion(geometry, self._previous)
        if prerolled:  # the frame before was this one (the pre-roll), from the same camera
            motion_vectors, valid = np.zeros_like(motion_vectors), np.ones_like(valid)
        self.timings.motion.append(time.perf_counter() - start)
        self._previous = geometry
        frame_data = features.frame_dict(samples, motion_vectors, valid, camera,
                                         scene.name, frame, scene.cycles.seed)
        mean = {name: total / np.float32(spp) for name, total in sums.items()}
        mean.update(first)
        noisy = radiance / np.float32(spp)

        if not self.settings.temporal:
            denoiser.reset()
        start = time.perf_counter()
        denoised = self._denoise(frame_data)
        self.timings.denoise.append(streaming_seconds + time.perf_counter() - start)
        if denoised.shape != noisy.shape:
            raise RuntimeError(f"the denoiser returned shape {denoised.shape}, "
                               f"expected {noisy.shape}")
        self.last_frame = frame
        self._camera_name = scene.camera.name
        combined_name = passes.PASS_NAMES["combined"][0]
        alpha = mean[combined_name][..., 3:4] if combined_name in mean else np.ones_like(noisy[..., :1])
        rgba = np.concatenate([denoised, alpha], axis=-1)
        return DenoisedFrame(frame, rgba, noisy, mean, frame_data,
                             dict(getattr(denoiser, "last_report", {})),
                             preroll_data if self.keep_frames else [])

    def _preroll(self, frame: int, camera: motion.Camera, ray_start: np.ndarray, stream: bool,
                 before_sample: Callable[[int], None] | None) -> Generator[int, None, list[dict[str, Any]]]:
        """Renders ``frame`` preroll_frames more times, each with another seed (independent
        samples) and ``preroll_sample_count()`` samples, and denoises each as a frame of a still camera,
        the output unused: the frame proper then starts with a history (DEFAULT_PREROLL_FRAMES).
        Yields 0 after each sub-render (none of the frame's own samples is done yet); returns the
        pre-roll frames' input to the core (their samples None where they were streamed). Another
        seed, not sample offsets past S: a larger sample set changes which samples the first S
        are, and on Blender 5.3 made them far noisier (docs/BLENDER.md, "Pre-roll")."""
        cycles = self.scene.cycles
        seed = cycles.seed
        frames = []
        try:
            for group in range(1, self.settings.preroll_frames + 1):
                frames.append((yield from self._preroll_frame(frame, camera, ray_start, stream,
                                                              before_sample, group, seed)))
        finally:
            cycles.seed = seed
        return frames

    def _preroll_frame(self, frame: int, camera: motion.Camera, ray_start: np.ndarray, stream: bool,
                       before_sample: Callable[[int], None] | None, group: int,
                       seed: int) -> Generator[int, None, dict[str, Any]]:
        """Pre-roll frame ``group`` (from 1): ``preroll_sample_count()`` one-sample sub-renders at offsets
        0..S-1 of the frames' sample set, S at a time, each block of S from a seed of its own
        (``preroll_seed``): where a sub-render is one sample of a set of S (sample subsets),
        an offset past S renders nothing, and a larger set would change the frames' samples."""
        spp, denoiser = self.settings.preroll_sample_count(), self.denoiser
        set_size = self.settings.samples_per_frame
        still = np.zeros((camera.height, camera.width, 2), np.float32)
        samples = None if stream else self._sample_buffer(camera, spp)
        for sample in range(spp):
            if before_sample is not None:
                before_sample(0)
            if sample % set_size == 0:
                self.scene.cycles.seed = preroll_seed(seed, group, sample // set_size)
            sample_features = self._sample_features(self._sub_render(sample % set_size), camera, ray_start)
            if samples is None:
                denoiser.add_samples(sample_features)
            else:
                samples[:, :, sample] = sample_features
            yield 0
        # The first pre-roll frame starts the history; each later one follows the one before.
        valid = np.full((camera.height, camera.width), 1.0 if group > 1 else 0.0, np.float32)
        frame_data = features.frame_dict(samples, still, valid, camera, self.scene.name, frame,
                                         self.scene.cycles.seed)
        start = time.perf_counter()
        self._denoise(frame_data)
        self.timings.denoise.append(time.perf_counter() - start)
        return frame_data

    def _sample_buffer(self, camera: motion.Camera, spp: int | None = None) -> np.ndarray:
        """Room for a frame's per-sample features (``spp``, or the frames' own count) where they
        are kept, not streamed."""
        return np.empty((camera.height, camera.width, spp or self.settings.samples_per_frame,
                         features.FEATURE_COUNT), np.float32)

    def _sample_features(self, captured: dict[str, np.ndarray], camera: motion.Camera,
                         ray_start: np.ndarray) -> np.ndarray:
        """One sub-render's passes -> its 18 features per pixel (the pass names resolved on the
        first)."""
        start = time.perf_counter()
        if self._names is None:
            self._names = passes.resolve(captured)
        sample_features = features.sample_features(passes.by_role(captured, self._names), camera, ray_start)
        self.timings.features.append(time.perf_counter() - start)
        return sample_features

    def _denoise(self, frame_data: dict[str, Any]) -> np.ndarray:
        """The frame through the core: its streamed samples finished, or the whole frame."""
        if frame_data["samples"] is None:
            rest = {key: value for key, value in frame_data.items() if key != "samples"}
            return np.asarray(self.denoiser.finish_frame(rest), dtype=np.float32)
        return np.asarray(self.denoiser.denoise(frame_data), dtype=np.float32)

    @staticmethod
    def _geometry(captured: dict[str, np.ndarray], names: dict[str, str], camera: motion.Camera,
                  transforms: motion.ObjectTransforms) -> motion.FrameGeometry:
        """What motion needs of the sample at offset 0 (copies: the passes are views)."""
        written = captured[names["aov_distance"]][..., 0] > 0.0  # our AOVs reached the hit
        depth = captured[names["depth"]][..., 0].copy()
        normal = captured[names["denoising_normal"]][..., :3]
        return motion.FrameGeometry(
            camera=camera,
            depth=depth,
            object_key=np.where(written, captured[names["aov_object"]][..., 0], np.nan),
            object_local=captured[names["aov_local"]][..., :3].copy(),
            transforms=transforms,
            scattered=(depth >= motion.MISS_DEPTH) & np.any(normal != 0.0, axis=-1),
        )

    def _sub_render(self, sample: int) -> dict[str, np.ndarray]:
        self.scene.cycles.sample_offset = sample
        # With persistent data Cycles silently repeats the previous sample without this.
        self.scene.update_tag()

        def read(result: Any) -> dict[str, np.ndarray]:
            start = time.perf_counter()
            captured = passes.read_result(result)
            self.timings.read_passes.append(time.perf_counter() - start)
            return captured

        captured, seconds = engine.render_and_capture(read, self.scene.name, self.view_layer.name)
        self.timings.sub_renders.append(seconds)
        if captured is None:
            raise Cancelled("the render was cancelled")
        return captured


ProgressCallback = Callable[[int, int, str], None]


def run_frame(rendering: Generator[int, None, DenoisedFrame]) -> DenoisedFrame:
    """Runs ``SequenceCapture.frame`` to its end where nothing waits between sub-renders."""
    while True:
        try:
            next(rendering)
        except StopIteration as finished:
            return finished.value


class DenoiseRender:
    """Renders and denoises ``frames`` of ``scene`` (its ``view_layer`` only)."""

    def __init__(
        self,
        scene: Any,
        view_layer: Any,
        frames: list[int],
        settings: Settings,
        progress: ProgressCallback | None = None,
    ) -> None:
        if not frames:
            raise ValueError("no frames to render")
        settings.check()
        self.scene = scene
        self.view_layer = view_layer
        self.frames = list(frames)
        self.settings = settings
        self.progress = progress or (lambda done, total, text: None)
        self.results: list[FrameResult] = []
        self.timings = Timings()
        #: The folder the settings ask for, and the one the run writes into: the same, or
        #: ``<base_folder>_NNN`` when the first has files of these frames already.
        self.base_folder = ""
        self.folder = ""
        #: Keep each frame's per-sample data in its FrameResult (tests, inspection).
        self.keep_frames = False

    @property
    def total_steps(self) -> int:
        return len(self.frames) * self.settings.samples_per_frame

    def run(self) -> list[FrameResult]:
        for _ in self.steps():
            pass
        return self.results

    def _file_names(self, frame: int) -> list[str]:
        names = [output.denoised_name(frame), self._final_name(frame)]
        if self.settings.keep_sample_frames:
            names.append(output.sample_frame_name(frame))
        return names

    def _final_name(self, frame: int) -> str:
        # A movie format cannot hold one frame per file: those frames are saved as PNG.
        extension = ".png" if self.scene.render.is_movie_format else self.scene.render.file_extension
        return output.final_name(frame, extension)

    def steps(self) -> Iterator[int]:
        """Yields the number of sub-renders done so far, after each one."""
        scene = self.scene
        problem = cycles_problem(scene)
        if problem:
            raise RuntimeError(problem)
        capture = SequenceCapture(scene, self.view_layer, self.settings, self.timings,
                                  keep_frames=self.settings.keep_sample_frames or self.keep_frames)
        if self.settings.keep_sample_frames:
            backend.load_core(need_denoiser=False)  # the core writes frame files: fail early
        self.base_folder = output.base_folder(scene, self.settings.output_folder)
        self.folder = output.choose_run_folder(
            self.base_folder, [n for f in self.frames for n in self._file_names(f)]
        )
        created = output.prepare_folder(self.folder)  # an unwritable folder fails here
        try:
            with capture_setup(scene, self.view_layer, self.settings) \
                    as use_compositing:
                spp = self.settings.samples_per_frame
                for number, frame in enumerate(self.frames):
                    def before_sample(sample: int, number: int = number, frame: int = frame) -> None:
                        self.progress(number * spp + sample, self.total_steps,
                                      f"frame {frame} ({number + 1}/{len(self.frames)}), "
                                      f"sample {sample + 1}/{spp}")

                    rendering = capture.frame(frame, before_sample)
                    while True:
                        try:
                            done = next(rendering)
                        except StopIteration as finished:
                            denoised: DenoisedFrame = finished.value
                            break
                        yield number * spp + done
                    self._finish_frame(denoised, use_compositing)
        finally:
            if not self.results:
                output.remove_empty_folders(created)
        if self.results:
            first = self.results[0]
            compositor.update_denoised_node(scene, first.denoised_path, first.frame,
                                            len(self.results))

    def _finish_frame(self, denoised: DenoisedFrame, use_compositing: bool) -> None:
        """Writes the denoised frame and presents it: Blender composites it, and the
        composited image is saved as the frame's final file."""
        import bpy

        frame, rgba = denoised.frame, denoised.rgba
        start = time.perf_counter()
        denoised_path = os.path.join(self.folder, output.denoised_name(frame))
        output.write_float_exr(denoised_path, rgba)
        sample_frame_path = None
        if self.settings.keep_sample_frames:
            sample_frame_path = os.path.join(self.folder, output.sample_frame_name(frame))
            output.write_atomic(sample_frame_path,
                                lambda tmp: backend.write_sample_frame(tmp, denoised.frame_data))
        self.timings.write.append(time.perf_counter() - start)

        start = time.perf_counter()
        engine.session.present = dict(denoised.mean)
        engine.session.present[passes.PASS_NAMES["combined"][0]] = rgba
        self.scene.render.use_compositing = use_compositing
        try:
            bpy.ops.render.render()
        finally:
            engine.session.present = None
            self.scene.render.use_compositing = False
        final_path = os.path.join(self.folder, self._final_name(frame))
        if self.scene.render.is_movie_format:
            with Overrides() as png:
                settings = self.scene.render.image_settings
                png.set_if_present(settings, "media_type", "IMAGE")
                png.set(settings, "file_format", "PNG")
                output.write_render_result(final_path, self.scene)
        else:
            output.write_render_result(final_path, self.scene)
        self.timings.present.append(time.perf_counter() - start)

        self.results.append(FrameResult(frame, denoised_path, final_path, sample_frame_path,
                                        denoised.noisy, rgba[..., :3], denoised.report,
                                        denoised.frame_data if self.keep_frames else None,
                                        denoised.preroll_data))

"""The "Cycles + Affinity Denoiser" engine: Blender's own render (F12, ``-a``) gives denoised
frames through Blender's pipeline, identical to the operator's; farm chunks warm up; two
processes on one folder render every frame once."""

from __future__ import annotations

import glob
import os
import subprocess
import sys
import tempfile
import textwrap
from typing import Any

import bpy
import numpy as np
import pytest
import scenes
from conftest import CORE_AVAILABLE, CORE_PATH, ROOT

from affinity_denoiser import frame_claims, pipeline, render_engine, render_job, worker

pytestmark = pytest.mark.skipif(not CORE_AVAILABLE, reason="the engine's worker needs the core")

FRAMES = 4


def _scene(tmp_path: Any, frames: int = FRAMES) -> Any:
    scene = scenes.build_scene(width=32, height=24, frames=frames, spp=2)
    scene.affinity_denoiser.samples_per_frame = 2
    scene.render.engine = render_engine.IDNAME
    scene.render.filepath = str(tmp_path / "engine" / "frame_")
    return scene


def _frames(folder: Any, pattern: str = "frame_*.png") -> dict[int, np.ndarray]:
    images = {}
    for path in sorted(glob.glob(os.path.join(str(folder), pattern))):
        images[int(os.path.basename(path).split("_")[-1].split(".")[0])] = scenes.read_image(path)
    return images


def _workers_left() -> list[str]:
    """Render-worker folders that still exist, and workers still held by the engine."""
    copy = [render_engine._copy[0]] if render_engine._copy is not None else []
    return [job.folder for job in render_engine._jobs.values()] + copy


@pytest.mark.parametrize(("last", "frame", "start", "step", "warmup", "expected"), [
    (4, 5, 1, 1, 8, ([], False)),  # continues the history
    (None, 5, 1, 1, 3, ([2, 3, 4], True)),  # a chunk's first frame
    (None, 3, 1, 1, 8, ([1, 2], True)),  # not before the animation's first frame
    (None, 1, 1, 1, 8, ([], True)),  # the first frame has no history to warm up
    (None, 9, 1, 2, 2, ([5, 7], True)),  # frame step 2: the animation's own frames
    (None, 10, 1, 2, 2, ([7, 9], True)),  # a frame off the grid: warm-up frames on it
    (3, 9, 1, 2, 2, ([5, 7], True)),  # a jump restarts the history
    (None, 6, 1, 1, 0, ([], True)),  # no warm-up asked
])
def test_warm_up_frames_are_the_animations_frames_before_the_chunk(
        last: int | None, frame: int, start: int, step: int, warmup: int,
        expected: tuple[list[int], bool]) -> None:
    assert worker.frames_to_render(last, frame, start, step, warmup) == expected


def test_an_animation_render_writes_the_operators_frames_through_blenders_output(
        tmp_path: Any) -> None:
    scene = _scene(tmp_path)
    scenes.add_exposure_compositor(scene, 1.0)  # Blender's compositor runs on our frames
    assert bpy.ops.render.render(animation=True) == {"FINISHED"}
    engine_frames = _frames(tmp_path / "engine")
    assert sorted(engine_frames) == [1, 2, 3, 4]  # Blender's names, in Blender's output folder
    assert not _workers_left()

    scene.render.engine = "CYCLES"
    scene.render.filepath = str(tmp_path / "operator" / "frame_")
    assert bpy.ops.affinity_denoiser.render_animation() == {"FINISHED"}
    operator_frames = _frames(tmp_path / "operator" / "affinity_denoised", "final_*.png")
    for frame in range(1, FRAMES + 1):
        np.testing.assert_array_equal(engine_frames[frame], operator_frames[frame])

    # And they are denoised: plain Cycles at the same samples gives other frames.
    scene.render.filepath = str(tmp_path / "cycles" / "frame_")
    scene.frame_end = 1
    assert bpy.ops.render.render(animation=True) == {"FINISHED"}
    plain = _frames(tmp_path / "cycles")[1]
    assert np.abs(plain - engine_frames[1]).mean() > 0.01


def test_f12_on_a_later_frame_warms_up_to_the_continuous_runs_frame(tmp_path: Any) -> None:
    scene = _scene(tmp_path, frames=3)
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_depth = "32"
    assert bpy.ops.render.render(animation=True) == {"FINISHED"}
    continuous = _frames(tmp_path / "engine", "frame_*.exr")

    scene.frame_set(3)
    results = {}
    for warmup in (0, 2):
        scene.affinity_denoiser.warmup_frames = warmup
        scene.render.filepath = str(tmp_path / f"still_{warmup}.exr")
        assert bpy.ops.render.render(write_still=True) == {"FINISHED"}
        results[warmup] = scenes.read_image(str(tmp_path / f"still_{warmup}.exr"))
    # Frames 1 and 2 rendered first: exactly the continuous run's frame 3.
    np.testing.assert_array_equal(results[2], continuous[3])
    # Cold, it is another image (no history).
    assert np.abs(results[0] - continuous[3]).mean() > 1e-3
    assert not _workers_left()


def test_a_failing_worker_stops_the_render_with_its_message(tmp_path: Any) -> None:
    scene = _scene(tmp_path)
    scene.affinity_denoiser.model_path = str(tmp_path / "missing.affw")
    with pytest.raises(RuntimeError, match="Affinity Denoiser: .*missing.affw"):
        bpy.ops.render.render(animation=True)
    assert not os.path.exists(tmp_path / "engine" / "frame_0001.png")
    assert not _workers_left()


def test_cycles_panels_are_shown_for_the_engine() -> None:
    assert render_engine.IDNAME in bpy.types.CYCLES_RENDER_PT_sampling.COMPAT_ENGINES
    assert render_engine.IDNAME in bpy.types.CYCLES_RENDER_PT_light_paths.COMPAT_ENGINES


_FARM_SCRIPT = textwrap.dedent("""
    import os
    import sys
    import bpy
    import affinity_denoiser
    from affinity_denoiser import frame_claims
    affinity_denoiser.register()
    bpy.ops.wm.open_mainfile(filepath=sys.argv[1])
    scene = bpy.context.scene
    rendered = []  # the frames this process rendered (not those it found claimed)
    bpy.app.handlers.render_pre.append(
        lambda *_: frame_claims.frame_lost() or rendered.append(scene.frame_current))
    if len(sys.argv) > 3:  # a chunk: the farm's -s / -e
        scene.frame_start, scene.frame_end = int(sys.argv[2]), int(sys.argv[3])
    bpy.ops.render.render(animation=True)
    print("RENDERED", *rendered, flush=True)
    # bpy 4.2 and 4.5 as modules crash or hang when Python exits after a property with a getter
    # (the settings' last_output_folder) was registered (docs/BLENDER.md, "Blender versions").
    os._exit(0)
""")


def _farm_process(blend: str, *frame_range: int) -> subprocess.Popen[str]:
    environment = dict(os.environ)
    environment["PYTHONPATH"] = os.pathsep.join(
        [os.path.join(ROOT, "blender_addon"), CORE_PATH]
        + [p for p in environment.get("PYTHONPATH", "").split(os.pathsep) if p])
    return subprocess.Popen([sys.executable, "-c", _FARM_SCRIPT, blend, *map(str, frame_range)],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env=environment)


def _rendered(process: subprocess.Popen[str]) -> list[int]:
    output, _ = process.communicate(timeout=600)
    assert process.returncode == 0, output[-3000:]
    lines = [line for line in output.splitlines() if line.startswith("RENDERED")]
    return [int(frame) for frame in lines[-1].split()[1:]]


def test_a_farm_chunk_matches_the_continuous_run(tmp_path: Any) -> None:
    scene = _scene(tmp_path)
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_depth = "32"
    scene.affinity_denoiser.warmup_frames = 2
    blend = str(tmp_path / "shot.blend")
    bpy.ops.wm.save_as_mainfile(filepath=blend)
    assert bpy.ops.render.render(animation=True) == {"FINISHED"}
    continuous = _frames(tmp_path / "engine", "frame_*.exr")

    scene.render.filepath = str(tmp_path / "chunk" / "frame_")
    bpy.ops.wm.save_as_mainfile(filepath=blend)
    assert _rendered(_farm_process(blend, 3, 4)) == [3, 4]
    chunk = _frames(tmp_path / "chunk", "frame_*.exr")
    assert sorted(chunk) == [3, 4]  # warm-up frames are rendered, not written
    for frame in (3, 4):
        np.testing.assert_array_equal(chunk[frame], continuous[frame])


def test_two_processes_on_one_folder_render_every_frame_once(tmp_path: Any) -> None:
    scene = _scene(tmp_path, frames=6)
    scene.render.use_placeholder = True
    scene.render.use_overwrite = False
    scene.affinity_denoiser.warmup_frames = 0
    blend = str(tmp_path / "shot.blend")
    bpy.ops.wm.save_as_mainfile(filepath=blend)
    processes = [_farm_process(blend), _farm_process(blend)]
    rendered = [_rendered(process) for process in processes]
    assert sorted(rendered[0] + rendered[1]) == list(range(1, 7)), rendered
    frames = _frames(tmp_path / "engine")
    assert sorted(frames) == list(range(1, 7))
    assert all(image[..., :3].mean() > 0.05 for image in frames.values())  # no placeholder left
    assert not glob.glob(str(tmp_path / "engine" / ".*"))  # no claim left


def test_a_frame_claimed_by_another_process_is_neither_rendered_nor_written(
        tmp_path: Any) -> None:
    # The moment two processes pass Blender's placeholder check together, held still: the
    # other process has claimed frame 2 and not yet written it.
    scene = _scene(tmp_path, frames=3)
    scene.render.use_placeholder = True
    scene.render.use_overwrite = False
    blend = str(tmp_path / "shot.blend")
    bpy.ops.wm.save_as_mainfile(filepath=blend)
    claim = frame_claims.claim_path(str(tmp_path / "engine" / "frame_0002.png"))
    os.makedirs(os.path.dirname(claim))
    open(claim, "w").close()
    assert _rendered(_farm_process(blend)) == [1, 3]
    # Frame 2: the placeholder Blender made (empty), for the other process to fill.
    assert os.path.getsize(tmp_path / "engine" / "frame_0002.png") == 0
    assert sorted(_frames(tmp_path / "engine", "frame_000[13].png")) == [1, 3]
    assert os.path.exists(claim)  # the other process's claim is its own to remove
    assert not glob.glob(os.path.join(tempfile.gettempdir(), "affinity-lost-frame-*"))


def test_esc_kills_the_worker_and_leaves_nothing(tmp_path: Any) -> None:
    scene = _scene(tmp_path)
    blend = str(tmp_path / "shot.blend")
    bpy.ops.wm.save_as_mainfile(filepath=blend)
    job = render_job.RenderJob(blend, scene.name, scene.view_layers[0].name,
                               render_job.JobSettings(pipeline.Settings(samples_per_frame=2), 0))
    try:
        first = job.render(1, ["Combined"], lambda fraction, text: None, lambda: False)
        assert first is not None and first["Combined"].shape == (24, 32, 4)
        calls = []

        def escape_after_the_first_progress() -> bool:  # Esc while frame 2 renders
            calls.append(1)
            return len(calls) > 1

        assert job.render(2, ["Combined"], lambda fraction, text: None,
                          escape_after_the_first_progress) is None
        assert job._process.poll() is not None  # the worker is gone
        assert not os.path.exists(job.folder)
    finally:
        job.close()


def test_a_worker_that_cannot_start_is_an_error_that_leaves_nothing(
        tmp_path: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(render_job, "_command", lambda arguments: [str(tmp_path / "no-blender")])
    before = set(glob.glob(os.path.join(tempfile.gettempdir(), "affinity-render-*")))
    with pytest.raises(render_job.WorkerFailed, match="cannot start the render worker: .*no-blender"):
        render_job.RenderJob(str(tmp_path / "shot.blend"), "Scene", "ViewLayer",
                             render_job.JobSettings(pipeline.Settings(), 0))
    assert set(glob.glob(os.path.join(tempfile.gettempdir(), "affinity-render-*"))) == before

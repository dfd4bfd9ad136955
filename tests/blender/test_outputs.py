"""Nothing the user had is overwritten; cancel and errors leave no partial file and restore
the scene and its materials."""

from __future__ import annotations

import os
from typing import Any

import bpy
import numpy as np
import pytest
import scenes
from conftest import CORE_IO_AVAILABLE, material_snapshot

from affinity_denoiser import backend, engine, output, pipeline


def _files(folder: Any) -> dict[str, bytes]:
    found = {}
    for directory, _, names in os.walk(folder):
        for name in names:
            path = os.path.join(directory, name)
            with open(path, "rb") as handle:
                found[os.path.relpath(path, folder)] = handle.read()
    return found


def _scene(tmp_path: Any, frames: int = 2) -> Any:
    scene = scenes.build_scene(width=32, height=24, frames=frames, spp=2)
    scene.render.filepath = str(tmp_path / "render" / "frame_")
    return scene


def _job(scene: Any, frames: list[int], **settings: Any) -> pipeline.DenoiseRender:
    return pipeline.DenoiseRender(scene, scene.view_layers[0], frames,
                                  pipeline.Settings(samples_per_frame=2, **settings))


def test_existing_files_are_never_overwritten(tmp_path: Any) -> None:
    scene = _scene(tmp_path)
    user_files = {
        "render/frame_0001.png": b"the user's own render",
        "render/affinity_denoised/denoised_0001.exr": b"an earlier denoised frame",
        "render/affinity_denoised/final_0001.png": b"an earlier final frame",
    }
    for name, content in user_files.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_bytes(content)
    job = _job(scene, [1])
    job.run()
    assert job.folder == str(tmp_path / "render" / "affinity_denoised_001")
    files = _files(tmp_path)
    for name, content in user_files.items():
        assert files[name] == content
    assert set(files) - set(user_files) == {
        "render/affinity_denoised_001/denoised_0001.exr",
        "render/affinity_denoised_001/final_0001.png",
    }
    # A second run of another frame fits into the first folder again.
    job = _job(scene, [2])
    job.run()
    assert job.folder == str(tmp_path / "render" / "affinity_denoised")


def test_a_chosen_output_folder_and_sample_frames(tmp_path: Any) -> None:
    scene = _scene(tmp_path)
    if not CORE_IO_AVAILABLE:
        pytest.skip("writing sample frames needs the affinity core")
    job = _job(scene, [1, 2], output_folder=str(tmp_path / "chosen"), keep_sample_frames=True)
    job.run()
    assert sorted(_files(tmp_path / "chosen")) == [
        "denoised_0001.exr", "denoised_0002.exr", "final_0001.png", "final_0002.png",
        os.path.join("samples", "frame_0001.exr"), os.path.join("samples", "frame_0002.exr"),
    ]


def _assert_restored(scene: Any, materials_before: Any) -> None:
    assert material_snapshot() == materials_before
    assert scene.render.engine == "CYCLES"
    assert not scene.render.use_persistent_data
    assert scene.cycles.samples == 2 and scene.cycles.sample_offset == 0
    assert [a.name for a in scene.view_layers[0].aovs] == []
    assert engine.session.sink is None and engine.session.present is None


def test_cancel_leaves_no_partial_file_and_restores_everything(tmp_path: Any) -> None:
    scene = _scene(tmp_path)
    before = material_snapshot()
    job = _job(scene, [1, 2], preroll_frames=0)
    steps = job.steps()
    for _ in range(3):  # frame 1 (2 sub-renders, then written), one sub-render of frame 2
        next(steps)
    steps.close()
    assert sorted(_files(tmp_path / "render")) == [
        "affinity_denoised/denoised_0001.exr", "affinity_denoised/final_0001.png"]
    _assert_restored(scene, before)
    assert scene.frame_current == 1


class _FailingDenoiser(backend.MeanDenoiser):
    calls = 0

    def denoise(self, frame: dict[str, Any]) -> np.ndarray:
        type(self).calls += 1
        if type(self).calls == 2:
            raise RuntimeError("denoiser failed on purpose")
        return super().denoise(frame)


def test_an_error_restores_everything_and_leaves_finished_frames(tmp_path: Any) -> None:
    scene = _scene(tmp_path)
    before = material_snapshot()
    previous = backend._factory
    backend.set_denoiser_factory(_FailingDenoiser)
    try:
        with pytest.raises(RuntimeError, match="on purpose"):
            _job(scene, [1, 2], preroll_frames=0).run()
    finally:
        backend.set_denoiser_factory(previous)
    assert sorted(_files(tmp_path / "render")) == [
        "affinity_denoised/denoised_0001.exr", "affinity_denoised/final_0001.png"]
    _assert_restored(scene, before)


def test_cancel_during_the_preroll_leaves_nothing_and_restores_everything(tmp_path: Any) -> None:
    scene = _scene(tmp_path)
    before = material_snapshot()
    samples_before, seed_before = scene.cycles.samples, scene.cycles.seed
    job = _job(scene, [1, 2], preroll_frames=2)
    steps = job.steps()
    for _ in range(3):  # the first pre-roll frame and one sub-render of the second
        assert next(steps) == 0
    steps.close()
    assert not _files(tmp_path / "render")
    _assert_restored(scene, before)
    assert (scene.cycles.samples, scene.cycles.seed) == (samples_before, seed_before)


def test_atomic_write_removes_a_partial_file(tmp_path: Any) -> None:
    def half_then_fail(temporary: str) -> None:
        with open(temporary, "wb") as handle:
            handle.write(b"partial")
        raise OSError("disk full")

    with pytest.raises(OSError, match="disk full"):
        output.write_atomic(str(tmp_path / "a.exr"), half_then_fail)
    assert os.listdir(tmp_path) == []
    (tmp_path / "b.exr").write_bytes(b"keep")
    with pytest.raises(FileExistsError):
        output.write_atomic(str(tmp_path / "b.exr"), lambda t: open(t, "wb").close())
    assert sorted(os.listdir(tmp_path)) == ["b.exr"]
    assert (tmp_path / "b.exr").read_bytes() == b"keep"


def test_non_cycles_scene_is_refused(tmp_path: Any) -> None:
    scene = _scene(tmp_path)
    scene.render.engine = "BLENDER_WORKBENCH"
    with pytest.raises(RuntimeError, match="Cycles"):
        _job(scene, [1]).run()
    assert not os.path.exists(tmp_path / "render")
    assert bpy.data.materials["Floor"].node_tree.nodes.get("affinity_tmp_1") is None


def test_movie_output_format_gives_png_frames(tmp_path: Any) -> None:
    scene = _scene(tmp_path)
    settings = scene.render.image_settings
    if hasattr(settings, "media_type"):  # Blender 5: choose the media type first
        settings.media_type = "VIDEO"
    settings.file_format = "FFMPEG"
    assert scene.render.is_movie_format
    job = _job(scene, [1])
    job.run()
    assert sorted(os.listdir(job.folder)) == ["denoised_0001.exr", "final_0001.png"]
    assert scenes.read_image(job.results[0].final_path).shape == (24, 32, 4)
    assert settings.file_format == "FFMPEG" and scene.render.is_movie_format


def test_default_folder_is_beside_the_render_output(tmp_path: Any) -> None:
    scene = _scene(tmp_path)
    for render_path in (str(tmp_path / "shots" / "frame_"), str(tmp_path / "shots") + os.sep):
        scene.render.filepath = render_path
        assert output.base_folder(scene, "") == str(tmp_path / "shots" / "affinity_denoised")
    assert output.base_folder(scene, str(tmp_path / "chosen")) == str(tmp_path / "chosen")
    assert output.choose_run_folder(str(tmp_path / "none_yet"), ["a.exr"]) == str(
        tmp_path / "none_yet")


@pytest.mark.parametrize("case", ["parent_is_a_file", "under_proc", "default_under_proc",
                                  "read_only_folder"])
def test_an_unwritable_output_folder_is_named_before_any_rendering(tmp_path: Any,
                                                                   case: str) -> None:
    """Issue 40, item 5: the run rendered, then failed on the first write ("Could not write
    image: Invalid argument"). Root writes into a 0555 folder, so that case runs only for a
    user who cannot (or root without CAP_DAC_OVERRIDE); a path under a regular file or under
    /proc fails for everyone."""
    scene = _scene(tmp_path)
    setting = ""
    if case == "parent_is_a_file":
        (tmp_path / "a_file").write_bytes(b"not a folder")
        folder = setting = str(tmp_path / "a_file" / "denoised")
    elif case == "under_proc":
        folder = setting = "/proc/affinity_denoiser_test/denoised"
    elif case == "default_under_proc":
        scene.render.filepath = "/proc/affinity_denoiser_test/frame_"
        folder = "/proc/affinity_denoiser_test/affinity_denoised"
    else:
        read_only = tmp_path / "read_only"
        read_only.mkdir()
        read_only.chmod(0o555)
        folder = setting = str(read_only)
        try:
            (read_only / "probe").mkdir()
        except PermissionError:
            pass
        else:
            (read_only / "probe").rmdir()
            read_only.chmod(0o755)
            pytest.skip("this user writes into read-only folders (root)")
    before = material_snapshot()
    progress: list[Any] = []
    job = pipeline.DenoiseRender(scene, scene.view_layers[0], [1, 2],
                                 pipeline.Settings(samples_per_frame=2, output_folder=setting),
                                 lambda *step: progress.append(step))
    try:
        with pytest.raises(RuntimeError) as failure:
            job.run()
    finally:
        if case == "read_only_folder":
            (tmp_path / "read_only").chmod(0o755)
    message = str(failure.value)
    assert message.startswith(f"the output folder {folder} is not writable"), message
    assert progress == [] and job.timings.sub_renders == []
    _assert_restored(scene, before)
    assert sorted(os.listdir(tmp_path)) == (["read_only"] if case == "read_only_folder" else
                                            ["a_file"] if case == "parent_is_a_file" else [])


def test_a_run_that_writes_nothing_leaves_no_empty_folder(tmp_path: Any) -> None:
    """The folder is made (and a test file written and removed) before the first sub-render;
    a run cancelled before its first frame removes the folders it made."""
    scene = _scene(tmp_path)
    job = _job(scene, [1, 2], output_folder=str(tmp_path / "new" / "denoised"))
    steps = job.steps()
    try:
        next(steps)
        assert os.listdir(tmp_path / "new" / "denoised") == []
    finally:
        steps.close()
    assert os.listdir(tmp_path) == []

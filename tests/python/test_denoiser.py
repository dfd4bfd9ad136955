"""affinity_core.Denoiser from Python: numpy in, numpy out, temporal state, errors, GIL release."""

from __future__ import annotations

import copy
import os
import pathlib
import pickle
import signal
import subprocess
import threading
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from gil_check import python_ticks_during
from tiled_frame import tiled_frame

import affinity_core

BUILD = pathlib.Path(os.environ.get("AFFINITY_BUILD_DIR", pathlib.Path(__file__).parents[2] / "build"))
CLI = BUILD / "core" / "affinity"
CYCLES_MODEL = pathlib.Path(__file__).parents[2] / "blender_addon" / "affinity_denoiser" / "models" / "cycles.affw"


@pytest.fixture(scope="module")
def sequence(tmp_path_factory: pytest.TempPathFactory) -> list[dict]:
    out = tmp_path_factory.mktemp("seq") / "frames"
    subprocess.run([str(CLI), "render", "--scene", "glossy", "--frames", "3", "--spp", "2", "--size", "40x30",
                    "--reference-spp", "32", "--out", str(out)], check=True, capture_output=True, timeout=300)
    return [affinity_core.read_frame(f) for f in affinity_core.list_frame_files(out)]


def test_denoises_a_sequence_to_finite_images(sequence: list[dict]) -> None:
    denoiser = affinity_core.Denoiser()
    assert denoiser.model.parameter_count > 0
    for i, frame in enumerate(sequence):
        out = denoiser.denoise(frame)
        assert out.shape == (30, 40, 3) and out.dtype == np.float32
        assert np.isfinite(out).all()
        assert denoiser.last_report["used_history"] == (i > 0)


def test_reset_makes_the_next_frame_independent_of_the_past(sequence: list[dict]) -> None:
    a, b = affinity_core.Denoiser(), affinity_core.Denoiser()
    a.denoise(sequence[0])
    a.reset()
    np.testing.assert_array_equal(a.denoise(sequence[1]), b.denoise(sequence[1]))


def _moved(world_to_camera: np.ndarray, degrees: float, shift: float = 0.0) -> np.ndarray:
    """The camera turned about its own y axis by `degrees`, then moved `shift` along its x axis."""
    angle = np.radians(degrees)
    turn = np.eye(4)
    turn[[0, 0, 2, 2], [0, 2, 0, 2]] = [np.cos(angle), np.sin(angle), -np.sin(angle), np.cos(angle)]
    to_world = np.linalg.inv(world_to_camera.astype(np.float64)) @ turn
    to_world[:3, 3] += shift * to_world[:3, 0]
    return np.linalg.inv(to_world).astype(np.float32)


def test_a_frame_continues_the_sequence_unless_the_camera_jumps_as_at_a_cut(sequence: list[dict]) -> None:
    # Every sample at depth 10: the mean depth that a move is measured by.
    frame = {**sequence[0], "samples": sequence[0]["samples"].copy()}
    frame["samples"][..., 9] = 10.0
    camera = frame["info"]["world_to_camera"]
    denoiser = affinity_core.Denoiser()
    assert not denoiser.continues_sequence(40, 30, camera)  # no history yet
    denoiser.denoise(frame)
    assert denoiser.continues_sequence(40, 30, camera)
    assert not denoiser.continues_sequence(40, 31, camera)
    assert denoiser.continues_sequence(40, 30, _moved(camera, 44.0))
    assert not denoiser.continues_sequence(40, 30, _moved(camera, 46.0))
    assert not denoiser.continues_sequence(40, 30, _moved(camera, -46.0))
    assert denoiser.continues_sequence(40, 30, _moved(camera, 0.0, 4.9))
    assert not denoiser.continues_sequence(40, 30, _moved(camera, 0.0, 5.1))
    # What it answers is what denoising the frame does with the history.
    for jumped, kept in ((_moved(camera, 0.0, 4.9), True), (_moved(camera, 0.0, 5.1), False)):
        again = affinity_core.Denoiser()
        again.denoise(frame)
        again.denoise({**frame, "info": {**frame["info"], "world_to_camera": jumped}})
        assert again.last_report["used_history"] == kept
    denoiser.reset()
    assert not denoiser.continues_sequence(40, 30, camera)
    with pytest.raises(ValueError, match="world_to_camera has shape"):
        denoiser.continues_sequence(40, 30, np.eye(3, dtype=np.float32))


def test_bad_radiance_is_counted(sequence: list[dict]) -> None:
    frame = {**sequence[0], "samples": sequence[0]["samples"].copy()}
    frame["samples"][0, 0, 0, 0] = np.nan
    frame["samples"][1, 1, 1, 4] = -1.0
    denoiser = affinity_core.Denoiser()
    assert np.isfinite(denoiser.denoise(frame)).all()
    assert denoiser.last_report["invalid_radiance"] == 2


def test_wrong_shapes_name_the_key(sequence: list[dict]) -> None:
    frame = {**sequence[0], "motion": np.zeros((30, 40, 3), np.float32)}
    with pytest.raises(ValueError, match="motion"):
        affinity_core.Denoiser().denoise(frame)


def test_corrupt_model_file_raises_affinity_error(tmp_path: pathlib.Path) -> None:
    path = tmp_path / "broken.affw"
    path.write_bytes(b"AFFWGHTS" + b"\x00" * 40)
    with pytest.raises(affinity_core.Error, match="broken.affw"):
        affinity_core.Denoiser(path)


def test_the_gil_is_released_while_denoising(sequence: list[dict]) -> None:
    big = {**sequence[0], "samples": np.tile(sequence[0]["samples"], (8, 8, 1, 1)),
           "motion": np.zeros((240, 320, 2), np.float32), "valid": np.zeros((240, 320), np.float32),
           "reference": None}
    denoiser = affinity_core.Denoiser()
    during = python_ticks_during(lambda: denoiser.denoise(big))
    assert during > 1000  # Python code ran while the native denoiser worked


def test_bf16_precision_is_close_to_fp32_or_refused_by_name(sequence: list[dict]) -> None:
    with pytest.raises(affinity_core.Error, match="unknown precision 'fp16'"):
        affinity_core.Denoiser(precision="fp16")
    if not affinity_core.bfloat16_supported():
        with pytest.raises(affinity_core.Error, match="AVX512-BF16"):
            affinity_core.Denoiser(precision="bf16")
        return
    fp32, bf16 = affinity_core.Denoiser(precision="fp32"), affinity_core.Denoiser(precision="bf16")
    assert (fp32.model.precision, bf16.model.precision) == ("fp32", "bf16")
    for frame in sequence:
        a, b = fp32.denoise(frame), bf16.denoise(frame)
        assert not np.array_equal(a, b)  # the bfloat16 products ran
        # 8 significant bits in the products' factors, FP32 sums: the images stay within a few
        # thousandths of each other (SMAPE 6e-4 on the benchmark's scenes).
        assert np.mean(np.abs(a - b) / (np.abs(a) + np.abs(b) + 1e-2)) < 3e-3


def test_the_default_precision_is_bf16_exactly_where_supported_and_fp32_overrides_it(sequence: list[dict]) -> None:
    expected = "bf16" if affinity_core.bfloat16_supported() else "fp32"
    model_file = pathlib.Path(__file__).parents[2] / "core" / "models" / "default.affw"
    assert affinity_core.Denoiser().model.precision == expected
    assert affinity_core.Denoiser(model_file).model.precision == expected
    assert affinity_core.Model.built_in().precision == affinity_core.Model.from_file(model_file).precision == expected
    assert affinity_core.Denoiser(precision="auto").model.precision == expected
    assert affinity_core.Denoiser(precision="fp32").model.precision == "fp32"
    assert affinity_core.Denoiser(model_file, precision="fp32").model.precision == "fp32"
    by_default, resolved = affinity_core.Denoiser(), affinity_core.Denoiser(precision=expected)
    for frame in sequence:
        np.testing.assert_array_equal(by_default.denoise(frame), resolved.denoise(frame))


def test_ablations_are_named_and_unknown_ones_refused():
    model = affinity_core.Model.built_in()
    for ablation in affinity_core.Denoiser.ABLATIONS:
        assert affinity_core.Denoiser(model, ablation=ablation).ablation == ablation
    with pytest.raises(ValueError, match="unknown ablation 'no_unet'"):
        affinity_core.Denoiser(model, ablation="no_unet")


def test_single_frame_ablation_ignores_history_and_stages_are_timed(sequence: list[dict]) -> None:
    # The ablation keeps the sequence's exposure (set by frame 0's radiance) and nothing else of
    # it: after a frame 0 with the same radiance but frame 2's other features, the same output.
    ablated, other = affinity_core.Denoiser(ablation="single_frame"), affinity_core.Denoiser(ablation="single_frame")
    ablated.denoise(sequence[0])
    second = ablated.denoise(sequence[1])
    assert not ablated.last_report["used_history"]
    unlike = dict(sequence[0])
    unlike["samples"] = sequence[0]["samples"].copy()
    unlike["samples"][..., 6:] = sequence[2]["samples"][..., 6:]
    other.denoise(unlike)
    np.testing.assert_array_equal(second, other.denoise(sequence[1]))
    assert other.last_report["exposure"] == ablated.last_report["exposure"]
    full = affinity_core.Denoiser()
    full.denoise(sequence[0])
    assert np.abs(full.denoise(sequence[1]) - second).max() > 1e-3  # the ablation changed something
    stages = ablated.last_report["stage_ms"]
    assert list(stages)[0] == "embedding" and list(stages)[-3:] == ["temporal kernel", "peak guard", "input fallback"]
    assert all(ms >= 0.0 for ms in stages.values())


def test_a_scene_far_brighter_than_the_training_scenes_is_denoised_alike(sequence: list[dict]) -> None:
    # The rendered glossy scene times 100 and times 1000: both beyond the brightness the network
    # was trained on, so both are brought to its brightest (the exposure normalisation) and the
    # outputs differ by the factor 10 alone, up to float rounding.
    def brighter(frame: dict, factor: float) -> dict:
        samples = frame["samples"].copy()
        samples[..., :6] *= factor
        return {**frame, "samples": samples}

    a, b = affinity_core.Denoiser(), affinity_core.Denoiser()
    for frame in sequence:
        low, high = a.denoise(brighter(frame, 100.0)), b.denoise(brighter(frame, 1000.0))
        np.testing.assert_allclose(high, 10.0 * low, rtol=1e-4, atol=1e-3)
        assert b.last_report["exposure"] == pytest.approx(a.last_report["exposure"] / 10, rel=1e-5)
        assert a.last_report["exposure"] < 1.0


def test_any_array_layout_gives_the_same_output(sequence: list[dict]) -> None:
    """The denoiser reads C-contiguous float32 arrays in place and converts any other layout."""
    frame = sequence[0]
    strided = dict(frame)
    strided["samples"] = np.asfortranarray(frame["samples"])
    strided["motion"] = frame["motion"][::-1][::-1]  # a view with the same values
    strided["valid"] = np.ascontiguousarray(frame["valid"], dtype=np.float64).astype(np.float32)
    np.testing.assert_array_equal(affinity_core.Denoiser().denoise(strided), affinity_core.Denoiser().denoise(frame))
    assert frame["samples"].flags["C_CONTIGUOUS"]  # the input was not touched


def _with_sample0_depth(frame: dict, radiance: bool = False) -> dict:
    """Every sample at sample 0's depth (and radiance): the first batch's depth normalisation
    (and exposure) is the frame's."""
    samples = frame["samples"].copy()
    samples[..., 9] = samples[:, :, :1, 9]
    if radiance:
        samples[..., :6] = samples[:, :, :1, :6]
    return {**frame, "samples": samples}


def test_streamed_samples_equal_the_whole_frame(sequence: list[dict]) -> None:
    # The exposure comes from the first batch of the sequence's first frame.
    frames = [_with_sample0_depth(f, radiance=i == 0) for i, f in enumerate(sequence)]
    whole, stream = affinity_core.Denoiser(), affinity_core.Denoiser()
    for frame in frames:
        expected = whole.denoise(frame)
        spp = frame["samples"].shape[2]
        for s in range(spp):
            stream.add_samples(frame["samples"][:, :, s])  # (H, W, 18), a strided view
        assert stream.pending_samples == spp
        got = stream.finish_frame({k: v for k, v in frame.items() if k != "samples"})
        np.testing.assert_array_equal(got, expected)
        assert stream.pending_samples == 0
        assert stream.last_report["used_history"] == whole.last_report["used_history"]


def test_streamed_depth_normalisation_comes_from_the_first_batch(sequence: list[dict]) -> None:
    frame = sequence[0]
    expected = affinity_core.Denoiser().denoise(frame)
    stream = affinity_core.Denoiser()
    stream.add_samples(frame["samples"][:, :, :1])
    stream.add_samples(frame["samples"][:, :, 1:])
    got = stream.finish_frame({k: v for k, v in frame.items() if k != "samples"})
    assert not np.array_equal(got, expected)  # the renderer's depths vary within a pixel
    assert np.abs(got - expected).max() <= 0.02 * np.abs(expected).max()


def test_streaming_misuse_names_the_problem(sequence: list[dict]) -> None:
    frame = sequence[0]
    rest = {k: v for k, v in frame.items() if k != "samples"}
    denoiser = affinity_core.Denoiser()
    with pytest.raises(ValueError, match="no samples were added"):
        denoiser.finish_frame(rest)
    denoiser.add_samples(frame["samples"])
    with pytest.raises(ValueError, match="first batch was 30x40"):
        denoiser.add_samples(np.zeros((20, 40, 18), np.float32))
    with pytest.raises(ValueError, match="samples has shape"):
        denoiser.add_samples(np.zeros((30, 40, 17), np.float32))
    with pytest.raises(ValueError, match=r"frame\['motion'\] has shape"):
        denoiser.finish_frame({**rest, "motion": np.zeros((30, 41, 2), np.float32)})
    with pytest.raises(affinity_core.Error, match="wait for finishFrame"):
        denoiser.denoise(frame)
    denoiser.discard_samples()
    assert denoiser.pending_samples == 0
    np.testing.assert_array_equal(denoiser.denoise(frame), affinity_core.Denoiser().denoise(frame))


@pytest.fixture(scope="module")
def frame_files(tmp_path_factory: pytest.TempPathFactory) -> list[str]:
    out = tmp_path_factory.mktemp("files") / "frames"
    subprocess.run([str(CLI), "render", "--scene", "disocclusion", "--frames", "3", "--spp", "4", "--size", "36x24",
                    "--reference-spp", "16", "--out", str(out)], check=True, capture_output=True, timeout=300)
    return affinity_core.list_frame_files(out)


def test_denoise_file_equals_denoising_the_read_frame(frame_files: list[str]) -> None:
    from_files, from_frames = affinity_core.Denoiser(), affinity_core.Denoiser()
    for path in frame_files:
        expected = from_frames.denoise(affinity_core.read_frame(path))
        got, frame = from_files.denoise_file(path)
        np.testing.assert_array_equal(got, expected)
        assert from_files.last_report["used_history"] == from_frames.last_report["used_history"]
        assert from_files.pending_samples == 0
        read = affinity_core.read_frame(path)
        assert frame["samples"] is None
        for key in ("motion", "valid", "reference"):
            np.testing.assert_array_equal(frame[key], read[key])
        assert frame["info"]["frame_index"] == read["info"]["frame_index"]
        samples = read["samples"]
        noisy = (samples[..., 0:3] + samples[..., 3:6]).mean(axis=2)
        np.testing.assert_allclose(frame["noisy"], noisy, rtol=1e-6, atol=1e-7)


def test_denoise_file_failures_leave_nothing_waiting(frame_files: list[str], tmp_path: pathlib.Path) -> None:
    corrupt = tmp_path / "frame_0000.exr"
    data = bytearray(pathlib.Path(frame_files[0]).read_bytes())
    data[len(data) // 2] ^= 0xFF  # past the header: the samples are lent, then the read fails
    corrupt.write_bytes(bytes(data))
    denoiser = affinity_core.Denoiser()
    with pytest.raises(affinity_core.Error, match="frame_0000.exr"):
        denoiser.denoise_file(corrupt)
    assert denoiser.pending_samples == 0
    got, _ = denoiser.denoise_file(frame_files[0])
    np.testing.assert_array_equal(got, affinity_core.Denoiser().denoise(affinity_core.read_frame(frame_files[0])))
    denoiser.add_samples(affinity_core.read_frame(frame_files[1])["samples"])
    with pytest.raises(ValueError, match="wait for finish_frame"):
        denoiser.denoise_file(frame_files[1])
    assert denoiser.pending_samples == 4


def test_the_report_gives_the_memory_of_the_denoisers_buffers(frame_files: list[str]) -> None:
    denoiser = affinity_core.Denoiser()
    sizes = []
    for path in frame_files:
        denoiser.denoise_file(path)
        sizes.append(denoiser.last_report["buffer_bytes"])
    # More than the frame's own maps (36x24 pixels, 32 embedding channels, 4 bytes a float) and
    # steady once the history exists.
    assert sizes[1] > 36 * 24 * 32 * 4
    assert sizes[2] == sizes[1]


def _large_frame(frame: dict) -> dict:
    """640x480 from the 40x30 frame: a denoise long enough that another thread or a signal
    arrives while it runs."""
    return tiled_frame(frame, 16)


def test_a_second_call_while_one_runs_is_refused(sequence: list[dict]) -> None:
    """Issue 42, item 1: two threads on one Denoiser crashed or failed with internal errors."""
    frame = _large_frame(sequence[0])
    denoiser = affinity_core.Denoiser()
    start = threading.Barrier(2)
    outputs: list[np.ndarray] = []
    errors: list[Exception] = []

    def call() -> None:
        start.wait()
        try:
            outputs.append(denoiser.denoise(frame))
        except affinity_core.Error as error:
            errors.append(error)

    threads = [threading.Thread(target=call) for _ in range(2)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert len(outputs) == 1 and len(errors) == 1
    assert "the Denoiser is busy with another call" in str(errors[0])
    np.testing.assert_array_equal(outputs[0], affinity_core.Denoiser().denoise(frame))


def test_ctrl_c_stops_a_frame_and_the_next_starts_a_new_sequence(sequence: list[dict]) -> None:
    """Issue 42, item 11: KeyboardInterrupt came only when the native call returned. Now the
    frame is abandoned, so the frame after it has no history to use."""
    frames = [_large_frame(frame) for frame in sequence]
    denoiser = affinity_core.Denoiser()
    denoiser.denoise(frames[0])
    # A process started in the background (nohup, &) ignores SIGINT: Python's handler is put
    # in for the test, as an interactive shell has it.
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    timer = threading.Timer(0.05, os.kill, (os.getpid(), signal.SIGINT))
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            denoiser.denoise(frames[1])
    finally:
        timer.join()
        signal.signal(signal.SIGINT, previous)
    after = denoiser.denoise(frames[2])
    assert denoiser.last_report["used_history"] is False
    np.testing.assert_array_equal(after, affinity_core.Denoiser().denoise(frames[2]))


@pytest.mark.parametrize("copy_call", [copy.copy, copy.deepcopy, pickle.dumps], ids=["copy", "deepcopy", "pickle"])
def test_a_denoiser_cannot_be_copied(copy_call: Callable[[Any], Any]) -> None:
    """Issue 42, item 12: copy.copy shared the native history between two objects."""
    with pytest.raises(TypeError, match="cannot be copied or pickled"):
        copy_call(affinity_core.Denoiser())


def test_the_module_reports_its_version() -> None:
    """Issue 40, item 5: ``affinity_core.__version__`` is the version the wheel is built with: the
    CMake project version, which pyproject.toml reads with its own regex (one source of truth)."""
    import re
    import tomllib

    root = pathlib.Path(__file__).parents[2]
    with open(root / "pyproject.toml", "rb") as handle:
        (rule,) = tomllib.load(handle)["tool"]["dynamic-metadata"]
    assert rule["field"] == "version"
    match = re.search(rule["regex"], (root / rule["input"]).read_text(encoding="utf-8"))
    assert match is not None
    assert affinity_core.__version__ == match.group("value")


def grey_wall(radiance: np.ndarray, name: str, frame_index: int = 0, valid: float = 0.0) -> dict:
    """A frame of a still, flat diffuse wall facing the camera whose samples carry `radiance`
    (height x width x spp, grey): the same features in every sample."""
    height, width, spp = radiance.shape
    samples = np.zeros((height, width, spp, 18), np.float32)
    samples[..., 0:3] = radiance[..., None]
    samples[..., 6:9] = (0.0, 0.0, 1.0)  # normal
    samples[..., 9] = 3.0  # depth
    samples[..., 10:13] = 0.5  # albedo
    samples[..., 13] = 1.0  # roughness
    info = {"scene_name": name, "frame_index": frame_index, "reference_spp": 0, "seed": 0,
            "world_to_camera": np.eye(4, dtype=np.float32), "camera_to_clip": np.eye(4, dtype=np.float32)}
    return {"samples": samples, "motion": np.zeros((height, width, 2), np.float32),
            "valid": np.full((height, width), valid, np.float32), "info": info}


def test_light_restoration_gives_back_the_light_of_sparse_fireflies() -> None:
    # A dim, evenly lit diffuse wall (0.1) whose light is half in sparse fireflies (1 % of the
    # samples carry 5): the Cycles model's kernels leave most fireflies out (17 % of the light
    # when written); its file asks for the light restoration, which gives the light back at a
    # scale of 30 pixels, where 64,000 samples make the input's mean a steady estimate.
    rng = np.random.default_rng(1)
    height, width, spp = 160, 200, 2
    radiance = 0.1 + (rng.random((height, width, spp)) < 0.01) * 5.0
    frame = grey_wall(radiance, "fireflies on a wall")
    noisy = float(radiance.mean())
    model = affinity_core.Model.from_file(CYCLES_MODEL)
    assert model.light_restoration and not affinity_core.Model.built_in().light_restoration
    restored = float(affinity_core.Denoiser(model).denoise(frame).mean())
    kernels_only = float(affinity_core.Denoiser(model, ablation="no_light_restoration").denoise(frame).mean())
    assert abs(restored / noisy - 1.0) < 0.01
    assert kernels_only / noisy < 0.95


def test_input_fallback_keeps_a_shadow_on_a_wall_of_sparse_fireflies_dark() -> None:
    # A wall lit only by sparse fireflies of indirect light (1 % of the samples carry 2.0, 4 per
    # pixel) with a 12-pixel shadow whose samples are all black, the same features everywhere:
    # the kernels spread the wall's light into the shadow; the input fallback sees a departure
    # from an input that is black in every sample of the window, no noise to explain it, and
    # gives the shadow back (docs/MODEL.md section 10, "Input fallback").
    height, width, spp, shadow = 96, 128, 4, slice(58, 70)

    def frame(t: int) -> dict:
        rng = np.random.default_rng(100 + t)
        radiance = (rng.random((height, width, spp)) < 0.01) * 2.0
        radiance[:, shadow] = 0.0
        return grey_wall(radiance, "a shadow on a wall", frame_index=t, valid=1.0)

    model = affinity_core.Model.from_file(CYCLES_MODEL)
    light = {}
    for ablation in (None, "no_input_fallback"):
        denoiser = affinity_core.Denoiser(model, ablation=ablation)
        for t in range(6):
            output = denoiser.denoise(frame(t)).mean(axis=-1)
        inside = output[:, shadow.start + 2:shadow.stop - 2].mean()
        wall = np.concatenate([output[:, 10:shadow.start - 10], output[:, shadow.stop + 10:width - 10]], axis=1).mean()
        light[ablation] = (inside / wall, wall)
    assert light["no_input_fallback"][0] > 0.2  # the kernels alone fill the shadow
    assert light[None][0] < 0.12
    assert light[None][1] == pytest.approx(light["no_input_fallback"][1], rel=0.03)  # the wall keeps its light

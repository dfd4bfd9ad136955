"""Cycles training and benchmark data (training/cycles): a generated scene captured through the
extension's path, its files, its targets' independence, and the quality of the core's built-in
model and of the extension's Cycles model on it against the noisy input and Blender's own
denoiser."""

from __future__ import annotations

import json
import os
import pathlib
import shutil
import sys
from typing import Any

import numpy as np
import pytest
from conftest import CORE_AVAILABLE, ROOT

sys.path.append(os.path.join(ROOT, "training", "cycles"))

import capture  # noqa: E402
import scene_generator  # noqa: E402

pytestmark = pytest.mark.skipif(not CORE_AVAILABLE, reason="needs the affinity core")

#: A fixed tiny sequence: an interior (indirect light, a small bright bulb), 4 frames.
SEED, WIDTH, HEIGHT, FRAMES = 7, 64, 40, 4
SETTINGS = capture.CaptureSettings(spp=4, target_spp=64, targets=2, blender_oidn_spp=(4,), preroll_frames=2)


def build_test_scene() -> Any:
    """The fixed tiny sequence's scene, built anew, with its seed."""
    scene = scene_generator.build_scene(SEED, width=WIDTH, height=HEIGHT, frames=FRAMES, threads=2,
                                        kind="interior")
    scene.cycles.seed = SEED
    return scene


@pytest.fixture(scope="module")
def captured(tmp_path_factory: pytest.TempPathFactory) -> tuple[str, dict]:
    scene = build_test_scene()
    folder = str(tmp_path_factory.mktemp("cycles") / "sequence")
    return folder, capture.capture_sequence(scene, folder, SETTINGS)


def test_a_captured_sequence_has_every_file_and_frame(captured: tuple[str, dict]) -> None:
    import affinity_core

    folder, summary = captured
    files = affinity_core.list_frame_files(folder)
    assert [os.path.basename(f) for f in files] == [f"frame_{i:04d}.exr" for i in range(FRAMES)]
    assert sorted(os.listdir(folder)) == sorted(
        [os.path.basename(f) for f in files] + ["blender_oidn.npz", "preroll.npz", "reference_halves.npz",
                                                "render_summary.json"])
    with open(os.path.join(folder, "render_summary.json")) as handle:
        assert json.load(handle) == json.loads(json.dumps(summary))
    assert summary["reference_spp"] == 128 and summary["frames"] == FRAMES
    for index, path in enumerate(files):
        frame = affinity_core.read_frame(path)
        assert frame["samples"].shape == (HEIGHT, WIDTH, 4, 18)
        assert frame["info"]["reference_spp"] == 128 and frame["info"]["frame_index"] == index
        assert np.isfinite(frame["reference"]).all() and frame["reference"].mean() > 0
        if index == 0:  # no previous frame: no history anywhere
            assert not frame["valid"].any()
        else:
            assert frame["valid"].mean() > 0.5


def test_the_reference_is_the_mean_of_two_independent_targets(captured: tuple[str, dict]) -> None:
    import affinity_core
    from affinity_core import metrics

    folder, summary = captured
    halves = np.load(os.path.join(folder, "reference_halves.npz"))
    for index, path in enumerate(affinity_core.list_frame_files(folder)):
        frame = affinity_core.read_frame(path)
        a, b = halves[f"a_frame{index}"], halves[f"b_frame{index}"]
        np.testing.assert_allclose(frame["reference"], (a + b) / 2, rtol=1e-6, atol=1e-7)
        # Other seeds than the input's and each other's: the halves differ by noise only, and
        # the input's samples are not a part of either.
        assert 0.0 < metrics.smape(a, b) == pytest.approx(summary["target_half_smape"][index])
        noisy = frame["samples"][..., 0:3].mean(2) + frame["samples"][..., 3:6].mean(2)
        assert metrics.smape(noisy, a) > metrics.smape(b, a)
        # Equal brightness up to noise: tone-mapped, so that a firefly (this interior has a small
        # bright bulb) cannot swing the mean.
        assert abs((a / (1 + a)).mean() / (b / (1 + b)).mean() - 1) < 0.05


def test_the_preroll_is_the_extensions_own(captured: tuple[str, dict]) -> None:
    """preroll.npz: the extension's pre-roll frames of the first frame, each from its own seed,
    as the extension gives them to the core."""

    import affinity_core
    from affinity_denoiser import pipeline

    folder, summary = captured
    assert summary["preroll_frames"] == 2 and summary["seconds"]["preroll"] > 0
    groups = np.load(os.path.join(folder, "preroll.npz"))
    assert sorted(groups.files) == ["group1", "group2"]
    first = affinity_core.read_frame(affinity_core.list_frame_files(folder)[0])
    own = first["samples"]
    for name in groups.files:
        assert groups[name].shape == own.shape and np.isfinite(groups[name]).all()
    # Other seeds: other radiance than the frame's own samples and each other's, the same
    # light on average (tone-mapped, so that a firefly cannot swing the mean).
    def radiance(samples: np.ndarray) -> np.ndarray:
        return samples[..., 0:3] + samples[..., 3:6]
    assert not np.array_equal(radiance(groups["group1"]), radiance(own))
    assert not np.array_equal(radiance(groups["group1"]), radiance(groups["group2"]))
    def tone_mapped_light(samples: np.ndarray) -> float:
        light = radiance(samples).mean(2)
        return float((light / (1 + light)).mean())
    for name in groups.files:
        print(name, tone_mapped_light(groups[name]), tone_mapped_light(own))
        assert abs(tone_mapped_light(groups[name]) / tone_mapped_light(own) - 1) < 0.1

    def same_light(a: np.ndarray, b: np.ndarray) -> float:
        """The share of lit values that are equal. Not all: another render of the same
        samples differs in part of its light sampling (0.43-1.0 equal over runs on bpy 4.5 and
        5.0 with the same sample positions, as equal geometry shows; another seed 0.035)."""
        lit = (radiance(a) != 0) | (radiance(b) != 0)
        return float((radiance(a) == radiance(b))[lit].mean())

    def extension_preroll(spp: int, pattern: str | None = None) -> np.ndarray:
        """The samples of the extension's one pre-roll frame at ``spp`` samples per frame."""
        scene = build_test_scene()
        if pattern is not None:
            scene.cycles.sampling_pattern = pattern
        run = pipeline.DenoiseRender(scene, scene.view_layers[0], [scene.frame_start],
                                     pipeline.Settings(samples_per_frame=spp, preroll_frames=1, preroll_samples=spp,
                                                       output_folder=os.path.join(folder, "..", f"check{spp}")))
        run.keep_frames = True
        run.run()
        (frame,) = run.results[0].preroll_data
        return frame["samples"]

    # The extension's first pre-roll frame at the capture's 4 samples is group1.
    extension = extension_preroll(4)
    np.testing.assert_array_equal(extension[..., 6:], groups["group1"][..., 6:])
    assert same_light(extension, groups["group1"]) > 0.2
    assert same_light(extension, groups["group2"]) < 0.1
    # With the Tabulated Sobol pattern (bpy 5.0.1's default, which made the suite's data) its
    # first 2 samples are what the extension renders at 2 samples per frame, as the suite uses
    # them. (Not with 4.5's and 5.3's default, Automatic: there the size of a sample set
    # changes its samples, for the frames' own samples too.)
    four, two = extension_preroll(4, "TABULATED_SOBOL"), extension_preroll(2, "TABULATED_SOBOL")
    np.testing.assert_array_equal(two[..., 6:], four[:, :, :2, 6:])
    assert same_light(two, four[:, :, :2]) > 0.2


def test_make_data_adds_a_missing_preroll_and_keeps_the_rest(captured: tuple[str, dict], tmp_path: Any) -> None:
    """A validation sequence captured before pre-rolls were kept gets preroll.npz added in
    place; its frames, references and Blender's frames are not touched."""
    import argparse

    import make_data

    folder, summary = captured
    summary = json.loads(json.dumps(summary))  # the fixture's stays as it is
    old = str(tmp_path / "old")
    shutil.copytree(folder, old)
    os.remove(os.path.join(old, "preroll.npz"))
    del summary["preroll_frames"], summary["seconds"]["preroll"]
    with open(os.path.join(old, "render_summary.json"), "w") as handle:
        json.dump(summary, handle)
    args = argparse.Namespace(preroll_frames=2)
    assert make_data.missing_preroll("val", old, args)
    assert not make_data.missing_preroll("train", old, args)
    assert not make_data.missing_preroll("val", folder, args)
    before = {name: pathlib.Path(old, name).read_bytes() for name in os.listdir(old)}
    scene = build_test_scene()
    with pytest.raises(ValueError, match="has 4 samples per frame, not 2"):
        capture.add_preroll(scene, old, capture.CaptureSettings(spp=2, preroll_frames=2))
    new_summary = capture.add_preroll(scene, old, SETTINGS)
    assert not make_data.missing_preroll("val", old, args)
    assert new_summary["preroll_frames"] == 2
    assert sorted(os.listdir(old)) == sorted(list(before) + ["preroll.npz"])
    for name, content in before.items():
        if name != "render_summary.json":
            assert pathlib.Path(old, name).read_bytes() == content
    assert np.load(os.path.join(old, "preroll.npz"))["group1"].shape == (HEIGHT, WIDTH, 4, 18)


def test_refreshed_inputs_keep_the_targets_and_blenders_frames(
        captured: tuple[str, dict], tmp_path: Any) -> None:
    """make_data --refresh-inputs: a sequence of an older capture path gets its inputs captured
    again; its references and Blender's frames are kept, not rendered again."""
    import make_data

    import affinity_core

    folder, summary = captured
    assert make_data.capture_version(folder) == capture.CAPTURE_VERSION
    old = str(tmp_path / "old")
    shutil.copytree(folder, old)
    del summary["capture_version"]  # as written before the field existed
    with open(os.path.join(old, "render_summary.json"), "w") as handle:
        json.dump(summary, handle)
    assert make_data.capture_version(old) == 1
    assert make_data.capture_version(str(tmp_path / "missing")) is None
    scene = build_test_scene()
    with pytest.raises(ValueError, match="has 4 samples per frame, not 2"):
        capture.refresh_inputs(scene, str(tmp_path / "wrong"), old,
                               capture.CaptureSettings(spp=2, target_spp=64, targets=2))
    refreshed = str(tmp_path / "refreshed")
    new_summary = capture.refresh_inputs(scene, refreshed, old, SETTINGS)
    assert make_data.capture_version(refreshed) == capture.CAPTURE_VERSION
    assert new_summary["target_half_smape"] == summary["target_half_smape"]
    for name in ("blender_oidn.npz", "reference_halves.npz"):
        with open(os.path.join(old, name), "rb") as a, open(os.path.join(refreshed, name), "rb") as b:
            assert a.read() == b.read()
    # The pre-roll is an input: captured again, with the same geometry.
    assert new_summary["preroll_frames"] == 2
    before, after = np.load(os.path.join(old, "preroll.npz")), np.load(os.path.join(refreshed, "preroll.npz"))
    np.testing.assert_array_equal(after["group2"][..., 6:], before["group2"][..., 6:])
    paths = affinity_core.list_frame_files(refreshed)
    assert len(paths) == FRAMES
    for path, old_path in zip(paths, affinity_core.list_frame_files(old)):
        frame, before = affinity_core.read_frame(path), affinity_core.read_frame(old_path)
        np.testing.assert_array_equal(frame["reference"], before["reference"])
        # The same capture path and scene: the same geometry features. Not the same radiance
        # bit for bit: a scene built again in one process differs in Cycles' light sampling
        # (3-10 % of the radiance values in two runs).
        np.testing.assert_array_equal(frame["samples"][..., 6:], before["samples"][..., 6:])
        assert frame["info"]["frame_index"] == before["info"]["frame_index"]
    # A refresh stopped between its two renames: the sequence only in .old-*, put back whole.
    os.replace(old, old + ".old-123")
    assert make_data.restore_interrupted_refresh(old)
    assert make_data.capture_version(old) == 1 and not os.path.exists(old + ".old-123")
    assert not make_data.restore_interrupted_refresh(old)  # nothing to put back


def test_deepened_references_average_more_independent_samples(
        captured: tuple[str, dict], tmp_path: Any) -> None:
    """make_data --deepen-references: each reference half gets 64 more samples (64 -> 128), from
    seeds no target used; the inputs and Blender's frames stay as they were."""
    import affinity_core
    from affinity_core import metrics

    folder, summary = captured
    scene = build_test_scene()
    with pytest.raises(ValueError, match="already has 64 samples per reference half"):
        capture.deepen_references(scene, str(tmp_path / "fewer"), folder, 64)
    deeper = str(tmp_path / "deeper")
    new_summary = capture.deepen_references(scene, deeper, folder, 128)
    assert new_summary["reference_spp"] == 256 and new_summary["target_seeds_used"] == 4
    for name in ("blender_oidn.npz", "preroll.npz"):
        with open(os.path.join(folder, name), "rb") as a, open(os.path.join(deeper, name), "rb") as b:
            assert a.read() == b.read()
    old_halves = np.load(os.path.join(folder, "reference_halves.npz"))
    halves = np.load(os.path.join(deeper, "reference_halves.npz"))
    for index, (path, old_path) in enumerate(zip(affinity_core.list_frame_files(deeper),
                                                 affinity_core.list_frame_files(folder))):
        frame, before = affinity_core.read_frame(path), affinity_core.read_frame(old_path)
        np.testing.assert_array_equal(frame["samples"], before["samples"])
        a, b = halves[f"a_frame{index}"], halves[f"b_frame{index}"]
        np.testing.assert_allclose(frame["reference"], (a + b) / 2, rtol=1e-6)
        assert frame["info"]["reference_spp"] == 256
        # Each half holds its old 64 samples and 64 new ones, which are not the other half's.
        assert not np.array_equal(a, old_halves[f"a_frame{index}"])
        assert metrics.smape(a, b) > 0.0
    # Twice the samples per half: the halves disagree less in every frame.
    assert all(new < old for new, old in zip(new_summary["target_half_smape"], summary["target_half_smape"]))


def test_an_input_draw_keeps_the_references_and_draws_other_noise(
        captured: tuple[str, dict], tmp_path: Any, capsys: pytest.CaptureFixture[str]) -> None:
    """make_data --input-draw: the inputs, the pre-roll and Blender's frames captured again from
    another seed, the references copied; the new input's noise is not the old one's."""
    import make_data

    import affinity_core

    folder, summary = captured
    scene = build_test_scene()
    scene.cycles.seed = SEED + capture.INPUT_DRAW_SEED_STRIDE
    with pytest.raises(ValueError, match="is not draw 2 of"):
        capture.capture_input_draw(scene, str(tmp_path / "wrong"), folder, 2, SETTINGS)
    drawn = str(tmp_path / "draw1")
    new_summary = capture.capture_input_draw(scene, drawn, folder, 1, SETTINGS)
    assert new_summary["input_draw"] == 1 and new_summary["input_seed"] == SEED + 1_000_003
    assert new_summary["seed"] == summary["seed"] and new_summary["seconds"]["targets"] == 0.0
    assert new_summary["reference_spp"] == summary["reference_spp"] and new_summary["preroll_frames"] == 2
    assert sorted(os.listdir(drawn)) == sorted(os.listdir(folder))
    with open(os.path.join(folder, "reference_halves.npz"), "rb") as a, \
            open(os.path.join(drawn, "reference_halves.npz"), "rb") as b:
        assert a.read() == b.read()
    before_oidn, after_oidn = np.load(os.path.join(folder, "blender_oidn.npz")), np.load(
        os.path.join(drawn, "blender_oidn.npz"))
    assert sorted(after_oidn.files) == sorted(before_oidn.files)
    assert not np.array_equal(after_oidn["spp4_frame1"], before_oidn["spp4_frame1"])
    # The same seed captured again (refresh_inputs) for contrast.
    same_seed = str(tmp_path / "same_seed")
    capture.refresh_inputs(build_test_scene(), same_seed, folder, SETTINGS)

    def distances(other: str) -> list[float]:
        """Per frame, the mean squared distance between the two captures' pixel means."""
        result = []
        for path, old_path in zip(affinity_core.list_frame_files(other), affinity_core.list_frame_files(folder),
                                  strict=True):
            frame, before = affinity_core.read_frame(path), affinity_core.read_frame(old_path)
            np.testing.assert_array_equal(frame["reference"], before["reference"])
            means = [(f["samples"][..., 0:3] + f["samples"][..., 3:6]).mean(2) for f in (frame, before)]
            result.append(float(np.mean((means[0] - means[1]) ** 2)))
        return result

    # Measured 23 against 1.05 summed over the 4 frames (8-56x per frame): a capture with the same
    # seed differs only where Cycles' light sampling does from one build of the scene to the next.
    drawn_distances, same_distances = distances(drawn), distances(same_seed)
    assert sum(drawn_distances) > 10 * sum(same_distances), (drawn_distances, same_distances)
    # make_data's checks: the draw needs its references' cache, complete, and another output.
    for argv, message in ((["--input-draw", "1"], "go together"),
                          (["--input-draw", "1", "--references-from", str(tmp_path), "--out", str(tmp_path)],
                           "another cache"),
                          (["--input-draw", "1", "--references-from", str(tmp_path / "none"), "--out",
                            str(tmp_path / "out"), "--val-seeds", "9000"], "lacks the complete validation")):
        with pytest.raises(SystemExit):
            make_data.main(argv)
        assert message in capsys.readouterr().err


#: ours / Blender's OIDN SMAPE on this sequence when it was recorded (bpy 5.0.1, the capture
#: animating the seed): the core's built-in model 0.2036 / 0.1909 (0.1971 before, with the
#: scene's static seed); the extension's Cycles model (backend.CYCLES_MODEL) 0.2078 / 0.1906 and
#: 0.1996 / 0.1902 in two captures with its light restoration (docs/MODEL.md section 10), 0.1988 /
#: 0.1900 without: on this 64x40 frame the restoration's windows hold few samples.
RECORDED_RATIO_TO_BLENDER = {"built-in": 1.07, "extension": 1.09}


@pytest.mark.parametrize("model", ["built-in", "extension"])
def test_the_models_beat_the_noisy_input_and_keep_their_margin_to_blender(captured: tuple[str, dict],
                                                                          model: str) -> None:
    import affinity_core
    from affinity_core import metrics
    from affinity_denoiser import backend

    folder, _ = captured
    oidn = np.load(os.path.join(folder, "blender_oidn.npz"))
    denoiser = affinity_core.Denoiser(backend.CYCLES_MODEL if model == "extension" else None)
    ours, noisy, blender = [], [], []
    for index, path in enumerate(affinity_core.list_frame_files(folder)):
        frame = affinity_core.read_frame(path)
        reference = frame["reference"]
        output = denoiser.denoise(frame)
        ours.append(metrics.smape(output, reference))
        noisy.append(metrics.smape(frame["samples"][..., 0:3].mean(2) + frame["samples"][..., 3:6].mean(2),
                                   reference))
        blender.append(metrics.smape(oidn[f"spp4_frame{index}"], reference))
    ours_mean, noisy_mean, blender_mean = map(float, (np.mean(ours), np.mean(noisy), np.mean(blender)))
    print(f"SMAPE at 4 spp: noisy {noisy_mean:.4f}, ours ({model}) {ours_mean:.4f}, Blender's OIDN {blender_mean:.4f}")
    assert ours_mean < 0.6 * noisy_mean
    # A model that loses more ground to Blender's own denoiser than it did when this was
    # recorded fails here.
    assert ours_mean < RECORDED_RATIO_TO_BLENDER[model] * 1.05 * blender_mean

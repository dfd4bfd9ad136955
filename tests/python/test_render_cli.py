"""`affinity render` end to end: real renders read back through the Python module, and the
command line's refusals (unknown scene, bad size, existing frames)."""

from __future__ import annotations

import json
import os
import pathlib
import signal
import subprocess
import time

import numpy as np
import pytest

import affinity_core

BUILD = pathlib.Path(os.environ.get("AFFINITY_BUILD_DIR", pathlib.Path(__file__).parents[2] / "build"))
CLI = BUILD / "core" / "affinity"


def render(out: pathlib.Path, *extra: str, scene: str = "disocclusion") -> subprocess.CompletedProcess:
    args = [str(CLI), "render", "--scene", scene, "--frames", "2", "--spp", "3", "--size", "24x16",
            "--reference-spp", "16", "--seed", "5", "--out", str(out), *extra]
    return subprocess.run(args, capture_output=True, text=True, timeout=300)


def test_render_writes_frames_the_module_reads(tmp_path: pathlib.Path) -> None:
    result = render(tmp_path / "seq", "--previews")
    assert result.returncode == 0, result.stderr
    frames = affinity_core.list_frame_files(tmp_path / "seq")
    assert [pathlib.Path(f).name for f in frames] == ["frame_0000.exr", "frame_0001.exr"]
    first, second = (affinity_core.read_frame(f) for f in frames)
    assert first["samples"].shape == (16, 24, 3, 18)
    assert first["reference"].shape == (16, 24, 3)
    assert first["info"]["scene_name"] == "disocclusion"
    assert second["info"]["frame_index"] == 1 and second["info"]["reference_spp"] == 16
    assert second["info"]["seed"] == 5
    assert not first["valid"].any()            # no history for the first frame
    assert second["valid"].mean() > 0.5        # a static camera keeps most of it
    radiance = first["samples"][..., 0:3] + first["samples"][..., 3:6]
    assert np.isfinite(radiance).all() and (radiance >= 0).all() and radiance.mean() > 0
    summary = json.loads((tmp_path / "seq" / "render_summary.json").read_text())
    assert summary["frames"] == 2 and summary["rays_per_second"] > 0
    assert 0 < summary["per_frame"][0]["noisy_smape"] < 1
    for name in ("noisy_0000.png", "reference_0001.png", "scene.json"):
        assert (tmp_path / "seq" / name).stat().st_size > 0


def test_same_seed_gives_identical_frames(tmp_path: pathlib.Path) -> None:
    assert render(tmp_path / "a", scene="procedural:3").returncode == 0
    assert render(tmp_path / "b", scene="procedural:3").returncode == 0
    a = affinity_core.read_frame(tmp_path / "a" / "frame_0001.exr")
    b = affinity_core.read_frame(tmp_path / "b" / "frame_0001.exr")
    np.testing.assert_array_equal(a["samples"], b["samples"])
    np.testing.assert_array_equal(a["reference"], b["reference"])


def test_unknown_scene_lists_the_known_ones(tmp_path: pathlib.Path) -> None:
    result = render(tmp_path / "x", scene="no_such_scene")
    assert result.returncode == 1
    assert "unknown scene 'no_such_scene'" in result.stderr
    assert "glossy" in result.stderr and "refraction" in result.stderr
    assert not (tmp_path / "x").exists()


@pytest.mark.parametrize("size", ["0x16", "24x", "24x-3", "abc", "20000x10"])
def test_invalid_size_is_refused(tmp_path: pathlib.Path, size: str) -> None:
    result = render(tmp_path / "x", "--size", size)
    assert result.returncode == 1
    assert "--size" in result.stderr


def test_existing_frames_are_not_overwritten_without_force(tmp_path: pathlib.Path) -> None:
    out = tmp_path / "seq"
    assert render(out).returncode == 0
    before = (out / "frame_0000.exr").read_bytes()
    result = render(out, "--spp", "1")
    assert result.returncode == 1
    assert "--force" in result.stderr
    assert (out / "frame_0000.exr").read_bytes() == before
    assert render(out, "--spp", "1", "--force").returncode == 0
    assert affinity_core.read_frame(out / "frame_0000.exr")["samples"].shape[2] == 1


def test_cycles_feature_convention_keeps_the_paths_and_changes_the_features(tmp_path: pathlib.Path) -> None:
    """--feature-convention cycles (docs/BLENDER.md): same radiance and reference, other features;
    the default is the renderer's own convention."""
    assert render(tmp_path / "default", scene="glossy").returncode == 0
    assert render(tmp_path / "ours", "--feature-convention", "renderer", scene="glossy").returncode == 0
    assert render(tmp_path / "cycles", "--feature-convention", "cycles", scene="glossy").returncode == 0
    default, ours, cycles = (affinity_core.read_frame(tmp_path / name / "frame_0001.exr")
                             for name in ("default", "ours", "cycles"))
    np.testing.assert_array_equal(default["samples"], ours["samples"])
    np.testing.assert_array_equal(ours["reference"], cycles["reference"])
    total = ours["samples"][..., 0:3] + ours["samples"][..., 3:6]
    np.testing.assert_allclose(cycles["samples"][..., 0:3] + cycles["samples"][..., 3:6], total, rtol=1e-5, atol=1e-6)
    assert not np.array_equal(ours["samples"][..., 6:], cycles["samples"][..., 6:])
    summary = json.loads((tmp_path / "cycles" / "render_summary.json").read_text())
    assert summary["feature_convention"] == "cycles"
    result = render(tmp_path / "x", "--feature-convention", "blender")
    assert result.returncode == 1 and "renderer or cycles" in result.stderr


@pytest.mark.parametrize("flag", ["--help", "-h"])
def test_help_after_the_command_prints_its_usage(tmp_path: pathlib.Path, flag: str) -> None:
    """`affinity render --help` is a request, not an unknown option: the command's usage on
    stdout, exit 0, and nothing rendered even when other options come with it."""
    result = subprocess.run([str(CLI), "render", flag], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith("usage: affinity render ")
    for option in ("--scene", "--frames", "--spp", "--size", "--reference-spp", "--out", "--force"):
        assert option in result.stdout
    assert "--in DIR" not in result.stdout  # render's usage, not denoise's
    assert result.stderr == ""
    with_options = render(tmp_path / "seq", flag)
    assert with_options.returncode == 0 and with_options.stdout == result.stdout
    assert not (tmp_path / "seq").exists()


def test_force_replaces_a_longer_sequence_entirely(tmp_path: pathlib.Path) -> None:
    """--force over a longer sequence (issue 42, item 5): the folder holds exactly the new one,
    so `denoise` cannot take the old frames as part of it; files `render` does not write stay."""
    out = tmp_path / "seq"
    assert render(out, "--frames", "4", "--previews").returncode == 0
    others = {"notes.txt": "mine", "frame_1.exr": "x", "frame_0001.exr.bak": "x", "noisy_0002.jpg": "x",
              "denoised_0003.exr": "x", "frame_0002.png": "x"}
    for name, text in others.items():
        (out / name).write_text(text)
    (out / "frame_0007.exr").mkdir()  # a folder, not a frame file: left alone
    result = render(out, "--frames", "2", "--force")  # no previews this time
    assert result.returncode == 0, result.stderr
    names = sorted(p.name for p in out.iterdir())
    assert names == sorted(["frame_0000.exr", "frame_0001.exr", "scene.json", "render_summary.json",
                            "frame_0007.exr", *others])
    assert [pathlib.Path(f).name for f in affinity_core.list_frame_files(out)] == ["frame_0000.exr", "frame_0001.exr"]
    assert json.loads((out / "render_summary.json").read_text())["frames"] == 2
    for name, text in others.items():
        assert (out / name).read_text() == text
    # A later first frame: the earlier frames before it go too.
    assert render(out, "--frames", "1", "--first-frame", "5", "--previews", "--force").returncode == 0
    assert [pathlib.Path(f).name for f in affinity_core.list_frame_files(out)] == ["frame_0005.exr"]
    assert sorted(p.name for p in out.glob("*.png")) == ["frame_0002.png", "noisy_0005.png", "reference_0005.png"]


def test_a_run_needing_more_memory_than_the_machine_has_is_refused_before_writing(tmp_path: pathlib.Path) -> None:
    """16384x16384 at 64 spp is within the options' limits but needs over a TiB (issue 42,
    item 8): refused up front, naming what it needs and what there is, with nothing written."""
    out = tmp_path / "huge"
    result = render(out, "--size", "16384x16384", "--spp", "64", "--reference-spp", "0", "--frames", "1")
    assert result.returncode == 1, result.stderr
    assert "needs about" in result.stderr and "GiB of memory" in result.stderr
    assert "is available" in result.stderr and "--size" in result.stderr
    assert "internal error" not in result.stderr
    assert not out.exists()
    # An existing folder stays as it was.
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    result = render(out, "--size", "16384x16384", "--spp", "64", "--reference-spp", "0", "--frames", "1", "--force")
    assert result.returncode == 1 and "needs about" in result.stderr
    assert [p.name for p in out.iterdir()] == ["notes.txt"]


def test_a_run_that_fails_before_its_first_frame_leaves_nothing_half_made(tmp_path: pathlib.Path) -> None:
    """A failure after scene.json is written but before any frame is (here: frame_0000.exr is
    a folder, so the frame cannot be written) takes scene.json back: no folder describing
    frames it does not hold."""
    out = tmp_path / "seq"
    (out / "frame_0000.exr").mkdir(parents=True)
    result = render(out)
    assert result.returncode == 1, result.stderr
    assert "frame_0000.exr" in result.stderr
    assert [p.name for p in out.iterdir()] == ["frame_0000.exr"]


def _interrupt_render(tmp_path: pathlib.Path, wait_for: str) -> tuple[subprocess.Popen, str, pathlib.Path]:
    """A long render, sent Ctrl-C once `wait_for` (a file in its folder) exists."""
    out = tmp_path / "out"
    run = subprocess.Popen([str(CLI), "render", "--scene", "disocclusion", "--frames", "50", "--spp", "4",
                            "--size", "320x240", "--reference-spp", "64", "--out", str(out)],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 300
    while not (out / wait_for).exists() and time.monotonic() < deadline and run.poll() is None:
        time.sleep(0.005)
    run.send_signal(signal.SIGINT)
    _, stderr = run.communicate(timeout=300)
    return run, stderr, out


def test_ctrl_c_keeps_finished_frames_and_writes_their_summary(tmp_path: pathlib.Path) -> None:
    """Issue 42, item 4: an interrupted render left *.tmp-PID-N files and no summary."""
    run, stderr, out = _interrupt_render(tmp_path, "frame_0000.exr")
    assert run.returncode == 130, stderr
    assert not list(out.glob("*.tmp-*"))
    frames = affinity_core.list_frame_files(out)
    assert 0 < len(frames) < 50
    summary = json.loads((out / "render_summary.json").read_text())
    assert summary["interrupted"] is True and summary["requested_frames"] == 50
    assert summary["frames"] == len(summary["per_frame"]) == len(frames)
    for path in frames:  # every frame kept is whole
        assert affinity_core.read_frame(path)["samples"].shape == (240, 320, 4, affinity_core.FEATURE_COUNT)
    assert "interrupted after" in stderr


def test_ctrl_c_before_the_first_frame_leaves_nothing(tmp_path: pathlib.Path) -> None:
    run, stderr, out = _interrupt_render(tmp_path, "scene.json")
    assert run.returncode == 130, stderr
    assert not out.exists()

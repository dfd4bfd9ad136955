"""affinity_core.Svgf from Python: settings, finite output, history, and better than the noisy input."""

from __future__ import annotations

import os
import pathlib
import subprocess

import numpy as np
import pytest
from gil_check import python_ticks_during

import affinity_core

BUILD = pathlib.Path(os.environ.get("AFFINITY_BUILD_DIR", pathlib.Path(__file__).parents[2] / "build"))
CLI = BUILD / "core" / "affinity"


@pytest.fixture(scope="module")
def sequence(tmp_path_factory: pytest.TempPathFactory) -> list[dict]:
    out = tmp_path_factory.mktemp("seq") / "frames"
    subprocess.run([str(CLI), "render", "--scene", "disocclusion", "--frames", "8", "--spp", "2", "--size", "48x36",
                    "--reference-spp", "64", "--out", str(out)], check=True, capture_output=True, timeout=300)
    return [affinity_core.read_frame(f) for f in affinity_core.list_frame_files(out)]


def noisy(frame: dict) -> np.ndarray:
    samples = frame["samples"]
    return np.nan_to_num(samples[..., 0:3] + samples[..., 3:6]).clip(min=0).mean(axis=2)


def relmse(image: np.ndarray, reference: np.ndarray) -> float:
    return float(np.mean((image - reference) ** 2 / (reference**2 + 1e-2)))


def test_settings_default_to_the_paper_and_are_checked() -> None:
    settings = affinity_core.Svgf().settings
    assert settings["atrous_iterations"] == 5 and settings["history_cap"] == 32
    assert settings["sigma_depth"] == 1.0 and settings["sigma_normal"] == 128.0
    assert settings["sigma_luminance"] == 4.0
    assert settings["alpha_color"] == 0.2 and settings["alpha_moments"] == 0.2
    custom = affinity_core.Svgf(sigma_luminance=2.5, atrous_iterations=3, alpha_color=0.3).settings
    assert custom["atrous_iterations"] == 3 and custom["alpha_color"] == 0.3
    assert affinity_core.Svgf(**custom).settings == custom  # settings round-trip through the dict
    with pytest.raises(affinity_core.Error, match="alphaColor"):
        affinity_core.Svgf(alpha_color=0.0)
    with pytest.raises(TypeError):
        affinity_core.Svgf(5)  # keyword-only


def test_filters_a_rendered_sequence_closer_to_the_reference(sequence: list[dict]) -> None:
    svgf = affinity_core.Svgf()
    noisy_error, svgf_error = [], []
    for frame in sequence:
        out = svgf.denoise(frame)
        assert out.shape == (36, 48, 3) and out.dtype == np.float32
        assert np.isfinite(out).all() and (out >= 0).all()
        noisy_error.append(relmse(noisy(frame), frame["reference"]))
        svgf_error.append(relmse(out, frame["reference"]))
    # Every frame, and clearly so once history has accumulated.
    assert all(s < n for s, n in zip(svgf_error, noisy_error)), (svgf_error, noisy_error)
    assert np.mean(svgf_error[4:]) < 0.5 * np.mean(noisy_error[4:]), (svgf_error, noisy_error)


def test_reset_makes_the_next_frame_independent_of_the_past(sequence: list[dict]) -> None:
    a, b = affinity_core.Svgf(), affinity_core.Svgf()
    a.denoise(sequence[0])
    a.reset()
    np.testing.assert_array_equal(a.denoise(sequence[1]), b.denoise(sequence[1]))
    c = affinity_core.Svgf()
    c.denoise(sequence[0])
    assert not np.array_equal(c.denoise(sequence[1]), b.denoise(sequence[1]))


def test_hand_made_frame_with_bad_radiance_gives_finite_output() -> None:
    rng = np.random.default_rng(1)
    h, w, spp = 5, 7, 2
    samples = np.zeros((h, w, spp, affinity_core.FEATURE_COUNT), np.float32)
    samples[..., 0:3] = rng.uniform(0, 1, (h, w, spp, 3))
    samples[..., 8] = 1.0  # normal +Z
    samples[..., 9] = 3.0  # depth
    samples[..., 10:13] = 0.5  # albedo
    samples[0, 0, 0, 0] = np.nan
    samples[1, 1, 1, 4] = np.inf
    samples[2, 2, 0, 2] = -1.0
    frame = {
        "samples": samples,
        "motion": np.zeros((h, w, 2), np.float32),
        "valid": np.ones((h, w), np.float32),
        "reference": None,
        "info": {"scene_name": "hand", "frame_index": 0, "reference_spp": 0, "seed": 0,
                 "world_to_camera": np.eye(4, dtype=np.float32), "camera_to_clip": np.eye(4, dtype=np.float32)},
    }
    svgf = affinity_core.Svgf()
    for _ in range(3):
        out = svgf.denoise(frame)
        assert out.shape == (h, w, 3) and np.isfinite(out).all()
    with pytest.raises(ValueError, match="motion"):
        svgf.denoise({**frame, "motion": np.zeros((h, w, 3), np.float32)})


def test_the_gil_is_released_while_denoising(sequence: list[dict]) -> None:
    frame = sequence[0]
    big = {**frame, "samples": np.tile(frame["samples"], (8, 8, 1, 1)),
           "motion": np.zeros((288, 384, 2), np.float32), "valid": np.zeros((288, 384), np.float32),
           "reference": None}
    svgf = affinity_core.Svgf()
    during = python_ticks_during(lambda: [svgf.denoise(big) for _ in range(3)])
    assert during > 1000  # Python code ran while the native filter worked

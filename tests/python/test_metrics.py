"""affinity_core.metrics: every definition on small images with values worked out by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from affinity_core import metrics


def image(*values: float) -> np.ndarray:
    """A 1 x N image whose pixels are grey (all three channels = value)."""
    return np.repeat(np.array(values, np.float32)[None, :, None], 3, axis=2)


def test_smape_by_hand() -> None:
    # per channel: |1-0|/(1+0+0.01), |0-0|/0.01 = 0, |2-1|/(2+1+0.01)
    assert metrics.smape(image(1, 0, 2), image(0, 0, 1)) == pytest.approx((1 / 1.01 + 1 / 3.01) / 3, rel=1e-6)
    assert metrics.smape(image(3), image(3)) == 0.0


def test_relmse_by_hand() -> None:
    # 0.5 * mean((1-0)^2/0.01, (3-1)^2/1.01)
    assert metrics.relmse(image(1, 3), image(0, 1)) == pytest.approx(0.25 * (100 + 4 / 1.01), rel=1e-6)


def test_psnr_by_hand() -> None:
    # tone-mapped 1 -> 0.5, 0 -> 0: MSE over (1, 0) vs (0, 0) is 0.125
    assert metrics.psnr(image(1, 0), image(0, 0)) == pytest.approx(-10 * math.log10(0.125), rel=1e-6)
    assert metrics.psnr(image(2), image(2)) == math.inf


def test_metrics_accept_float64_and_reject_mismatched_shapes() -> None:
    assert metrics.smape(np.ones((2, 2, 3)), np.ones((2, 2, 3))) == 0.0
    with pytest.raises(ValueError, match="shape"):
        metrics.smape(np.ones((2, 2, 3), np.float32), np.ones((2, 3, 3), np.float32))


def half_pixel_sequence() -> dict[str, np.ndarray]:
    # 3x1 frames: previous output (1, 3, 5), current 2, every pixel moved half a pixel right, so
    # the warped previous output is 2 at x=0, 4 at x=1; x=2 looks at 2.5, outside the image.
    return {
        "output": image(2, 2, 2),
        "previous_output": image(1, 3, 5),
        "reference": image(0, 0, 0),
        "previous_reference": image(0, 0, 0),
        "motion": np.array([[[0.5, 0.0]] * 3], np.float32),
        "valid": np.ones((1, 3), np.float32),
    }


def test_temporal_error_by_hand() -> None:
    s = half_pixel_sequence()
    assert metrics.temporal_error(**s) == pytest.approx(1.0)  # (|2-2| + |2-4|) / 2 pixels
    s["reference"][0, 1, 0] = 1.0  # reference changes by +1 in red at x=1: |(2-1) - 4| = 3
    assert metrics.temporal_error(**s) == pytest.approx((3 + 2 + 2) / 6)
    s["valid"][0, 0] = 0.0  # x=0 no longer counts
    assert metrics.temporal_error(**s) == pytest.approx((3 + 2 + 2) / 3)
    s["valid"][0, 1] = 0.0
    assert math.isnan(metrics.temporal_error(**s))


def test_temporal_error_is_zero_when_the_output_follows_the_reference() -> None:
    rng = np.random.default_rng(1)
    reference, previous = rng.random((6, 5, 3), np.float32), rng.random((6, 5, 3), np.float32)
    motion = rng.uniform(-1, 1, (6, 5, 2)).astype(np.float32)
    valid = np.ones((6, 5), np.float32)
    same = metrics.temporal_error(reference, previous, reference, previous, motion, valid)
    assert same == pytest.approx(0.0, abs=1e-6)
    with pytest.raises(ValueError, match="motion"):
        metrics.temporal_error(reference, previous, reference, previous, motion[:, :, :1], valid)


def test_tonemapped_temporal_error_by_hand() -> None:
    # Still 1x1 frames: a lamp of 100 flickering to 120 and a shadow of 0 flickering to 1, against
    # references that do not change. Linear: |20| and |1|. Tone-mapped: 120/121 - 100/101 and 1/2.
    still = {"motion": np.zeros((1, 1, 2), np.float32), "valid": np.ones((1, 1), np.float32)}
    lamp = {"output": image(120), "previous_output": image(100), "reference": image(100),
            "previous_reference": image(100), **still}
    shadow = {"output": image(1), "previous_output": image(0), "reference": image(0),
              "previous_reference": image(0), **still}
    assert metrics.temporal_error(**lamp) == pytest.approx(20.0)
    # float32 tone map
    assert metrics.tonemapped_temporal_error(**lamp) == pytest.approx(120 / 121 - 100 / 101, abs=1e-7)
    assert metrics.tonemapped_temporal_error(**shadow) == pytest.approx(0.5, rel=1e-6)
    # Negative radiance is clamped to 0 first, as for PSNR.
    shadow["output"] = image(-3)
    assert metrics.tonemapped_temporal_error(**shadow) == 0.0


def test_warping_error_by_hand() -> None:
    s = half_pixel_sequence()
    # Tone-mapped previous output (1/2, 3/4, 5/6), warped: x=0 5/8, x=1 19/24; the output 2 tone-maps
    # to 2/3. Squared differences summed over 3 channels, mean over the 2 counted pixels.
    pair = {"image": s["output"], "previous_image": s["previous_output"], "motion": s["motion"], "valid": s["valid"]}
    assert metrics.warping_error(**pair) == pytest.approx((3 / 24**2 + 3 / 8**2) / 2, rel=1e-5)
    pair["valid"] = np.array([[0, 1, 1]], np.float32)  # x=1 alone
    assert metrics.warping_error(**pair) == pytest.approx(3 / 8**2, rel=1e-5)
    pair["valid"] = np.array([[0, 0, 1]], np.float32)  # x=2 looks outside: nothing counts
    assert math.isnan(metrics.warping_error(**pair))
    with pytest.raises(ValueError, match="previous_image"):
        metrics.warping_error(s["output"], s["output"][:, :2], s["motion"], s["valid"])


def test_warping_error_of_a_still_sequence_is_its_squared_tonemapped_change() -> None:
    # No motion: the warp is the identity, so the error is the plain per-pixel change, computed
    # here with numpy alone.
    rng = np.random.default_rng(2)
    before = rng.uniform(-0.5, 4, (5, 7, 3)).astype(np.float32)
    after = rng.uniform(-0.5, 4, (5, 7, 3)).astype(np.float32)
    still, valid = np.zeros((5, 7, 2), np.float32), np.ones((5, 7), np.float32)
    expected = np.mean(np.sum((metrics.tonemap(after) - metrics.tonemap(before)).astype(np.float64) ** 2, axis=2))
    assert metrics.warping_error(after, before, still, valid) == pytest.approx(expected, rel=1e-5)
    assert metrics.warping_error(after, after, still, valid) == 0.0


def test_flip_is_zero_for_identical_images_and_grows_with_the_error() -> None:
    rng = np.random.default_rng(2)
    reference = rng.random((32, 32, 3), np.float32)
    assert metrics.flip(reference, reference) == 0.0
    small, large = metrics.flip(reference * 1.1, reference), metrics.flip(reference * 3.0, reference)
    assert 0.0 < small < large <= 1.0


def test_ms_per_megapixel_by_hand() -> None:
    assert metrics.ms_per_megapixel(0.5, 1000, 500) == pytest.approx(1000.0)  # 500 ms on 0.5 Mpx

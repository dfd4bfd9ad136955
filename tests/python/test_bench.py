"""The benchmark (python -m affinity_bench, the repository's affinity_bench/) in its tiny
configuration, end to end: what must hold of every run, plus the pieces with hand-checkable
behaviour. Needs the repository root on the path beside the built module (scripts/test.sh)."""

from __future__ import annotations

import csv
import math
import pathlib
import subprocess
import sys

import numpy as np
import pytest

import affinity_core
from affinity_bench import data, report

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
NUMERIC_COLUMNS = ("smape", "relmse", "psnr", "flip", "temporal_error", "temporal_error_tonemapped", "warping_error",
                   "ms_per_frame", "ms_per_mpx",
                   "render_s_per_frame", "total_s_per_frame")


def run_bench(*arguments: str) -> subprocess.CompletedProcess[str]:
    done = subprocess.run([sys.executable, "-m", "affinity_bench", "--config", "tiny", *arguments],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stdout + done.stderr
    return done


@pytest.fixture(scope="module")
def bench(tmp_path_factory: pytest.TempPathFactory) -> tuple[pathlib.Path, pathlib.Path, str]:
    root = tmp_path_factory.mktemp("bench")
    out, cache = root / "results", root / "data"
    return out, cache, run_bench("--out", str(out), "--data", str(cache)).stdout


def read_rows(path: pathlib.Path) -> list[dict[str, str]]:
    with path.open(newline="") as handle:
        return list(csv.DictReader(handle))


def test_every_method_ran_and_every_metric_is_finite(bench: tuple[pathlib.Path, pathlib.Path, str]) -> None:
    out, _, _ = bench
    rows = read_rows(out / "results.csv")
    methods = {row["method"] for row in rows}
    expected = {"noisy", "oidn", "svgf", "ours-small", "ours-small+preroll", "ours-tiny", "ours-tiny+preroll",
                "small-single_frame", "small-no_temporal_kernel", "small-one_kernel", "small-no_input_fallback",
                "small-no_peak_guard", "small-no_history_guard"}
    # The ladder's other rungs run by default wherever their weights are in the checkout.
    models = pathlib.Path(__file__).resolve().parents[2] / "core" / "models"
    expected |= {"ours-medium", "ours-medium+preroll"} if (models / "medium.affw").is_file() else set()
    assert methods == expected
    # 2 sequences x 2 spp x every method, plus noisy and oidn at the equal-time chart's 8 spp.
    assert len(rows) == 2 * 2 * len(methods) + 2 * 2
    for row in rows:
        for column in NUMERIC_COLUMNS:
            assert math.isfinite(float(row[column])), (row["method"], row["sequence"], row["spp"], column)
    for row in read_rows(out / "per_frame.csv"):
        values = [row[c] for c in ("smape", "relmse", "psnr", "flip", "ms")]
        assert all(math.isfinite(float(v)) for v in values), row
        for column in ("temporal_error", "temporal_error_tonemapped", "warping_error"):
            assert (row[column] == "nan") == (row["frame"] == "0"), row


def test_ours_beats_the_noisy_input_on_every_scene_at_every_spp(bench: tuple[pathlib.Path, pathlib.Path, str]) -> None:
    out, _, _ = bench
    rows = read_rows(out / "results.csv")
    noisy = {(r["sequence"], r["spp"]): float(r["smape"]) for r in rows if r["method"] == "noisy"}
    ours = [r for r in rows if r["family"] == "ours"]
    assert {(r["sequence"], r["spp"]) for r in ours} == {(s, p) for s in ("glossy", "disocclusion") for p in ("2", "4")}
    for r in ours:
        assert float(r["smape"]) < noisy[(r["sequence"], r["spp"])], (r["method"], r["sequence"], r["spp"])


def test_ours_flickers_less_than_the_noisy_input(bench: tuple[pathlib.Path, pathlib.Path, str]) -> None:
    # The warping error needs no reference: the output against its own warped previous frame.
    out, _, _ = bench
    rows = read_rows(out / "results.csv")
    noisy = {(r["sequence"], r["spp"]): float(r["warping_error"]) for r in rows if r["method"] == "noisy"}
    for r in rows:
        if r["method"] == "ours-small":
            assert float(r["warping_error"]) < 0.5 * noisy[(r["sequence"], r["spp"])], (r["sequence"], r["spp"])
    for r in read_rows(out / "reference_noise.csv"):  # a 64-spp reference flickers less than 2 spp
        assert float(r["warping_error"]) < noisy[(r["sequence"], "2")], r


def test_a_second_reference_measures_the_references_own_noise(bench: tuple[pathlib.Path, pathlib.Path, str]) -> None:
    out, _, log = bench
    assert "rendered the second reference of glossy" in log
    rows = read_rows(out / "reference_noise.csv")
    assert [r["sequence"] for r in rows] == ["glossy", "disocclusion"]
    noisy = {(r["sequence"], r["spp"]): float(r["smape"]) for r in read_rows(out / "results.csv")
             if r["method"] == "noisy"}
    for row in rows:
        assert all(math.isfinite(float(row[m])) for m in report.METRICS), row
        # Other random numbers, so not the same image; 64 spp each, so far closer to each other
        # than a 2-spp input is to either.
        assert 0.0 < float(row["smape"]) < 0.5 * noisy[(row["sequence"], "2")], row
        assert float(row["temporal_error"]) > 0.0, row
    assert "## Reference noise" in (out / "results.md").read_text()


def test_tables_and_charts_are_written(bench: tuple[pathlib.Path, pathlib.Path, str]) -> None:
    out, _, _ = bench
    markdown = (out / "results.md").read_text()
    assert "| `ours-small` |" in markdown and "## Equal time" in markdown
    charts = ["error_vs_time_2spp.png", "error_vs_time_4spp.png", "equal_time.png"]
    charts += [f"{kind}_{scene}.png" for kind in ("temporal_error", "crops") for scene in ("glossy", "disocclusion")]
    for name in charts:
        content = (out / name).read_bytes()
        assert content.startswith(PNG_SIGNATURE) and len(content) > 5000, name
    assert not list(out.glob(".*.tmp"))  # no temporary file left behind


def test_rendered_sequences_are_cached_and_reused(bench: tuple[pathlib.Path, pathlib.Path, str]) -> None:
    out, cache, first_log = bench
    assert "rendered glossy" in first_log and "rendered disocclusion" in first_log
    second = run_bench("--out", str(out.parent / "again"), "--data", str(cache), "--methods", "noisy")
    assert "rendered" not in second.stdout
    assert {r["method"] for r in read_rows(out.parent / "again" / "results.csv")} == {"noisy"}


def test_an_s_spp_input_is_the_first_s_samples_without_the_reference() -> None:
    samples = np.arange(2 * 3 * 4 * 18, dtype=np.float32).reshape(2, 3, 4, 18)
    frame = {"samples": samples, "motion": np.zeros((2, 3, 2), np.float32), "valid": np.ones((2, 3), np.float32),
             "reference": np.ones((2, 3, 3), np.float32), "info": {}}
    subset = data.with_spp(frame, 2)
    np.testing.assert_array_equal(subset["samples"], samples[:, :, :2])
    assert subset["samples"].flags.c_contiguous and subset["reference"] is None
    with pytest.raises(ValueError):
        data.with_spp(frame, 5)


def test_crops_sit_where_the_error_is_largest() -> None:
    error = np.zeros((10, 12))
    error[6, 9] = 1.0
    y, x = report.worst_window(error, 4)
    assert y <= 6 < y + 4 and x <= 9 < x + 4


def test_spp_option_replaces_the_sample_counts_and_keeps_the_crops_on_a_listed_one() -> None:
    from affinity_bench.__main__ import configure, parse_arguments, parse_spp_list

    assert parse_spp_list("16, 1,16") == (1, 16)
    for bad in ("0", "65", "a", "4,,8"):
        with pytest.raises(Exception, match="is not a sample count"):
            parse_spp_list(bad)
    config = configure(parse_arguments(["--out", "x", "--spp", "1,16,32"]))
    assert config.spp == (1, 16, 32)
    assert config.chart_spp == 1  # the config's 4 is not listed
    assert config.render_spp == 32  # the cached renders still serve
    config = configure(parse_arguments(["--out", "x", "--spp", "4,16"]))
    assert (config.spp, config.chart_spp) == ((4, 16), 4)
    assert configure(parse_arguments(["--out", "x"])).spp == (2, 4, 8)


CYCLES_DATA = pathlib.Path(__file__).resolve().parents[1] / "data" / "cycles_tiny"
#: spp -> (ours / noisy, ours / blender-oidn) SMAPE with the built-in model when the sequence was
#: made (noisy 0.2729 / 0.2067, ours 0.1303 / 0.1339, Blender's 0.1196 / 0.1082 at 2 / 4 spp).
CYCLES_TINY_RECORDED = {2: (0.477, 1.089), 4: (0.648, 1.237)}


def test_the_cycles_suite_scores_blender_s_denoiser_beside_ours(tmp_path: pathlib.Path) -> None:
    """A fixed tiny Cycles sequence (tests/data/cycles_tiny, made by training/cycles/make_data.py
    --out tests/data/cycles_tiny --val-seeds 9000 --train-seeds '' --size 48x32 --frames 3 --spp 4
    --val-target-spp 64 --blender-oidn-spp 2,4): read, never rendered; Blender's stored frames
    scored as a method, the reference halves as the reference noise."""
    out, frames = tmp_path / "results", tmp_path / "frames"
    done = subprocess.run([sys.executable, "-m", "affinity_bench", "--config", "cycles", "--data", str(CYCLES_DATA),
                           "--sequences", "cycles_09000", "--spp", "2,4", "--model", "small=builtin",
                           "--methods", "noisy,oidn,ours-small", "--out", str(out), "--save-outputs", str(frames)],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stdout + done.stderr
    rows = {(row["method"], int(row["spp"])): row for row in read_rows(out / "results.csv")}
    assert set(rows) == {(m, s) for m in ("noisy", "oidn", "ours-small", "blender-oidn") for s in (2, 4)}
    stored = np.load(CYCLES_DATA / "val" / "cycles_09000" / "blender_oidn.npz")
    reference = np.stack([f["reference"] for f in map(affinity_core.read_frame, affinity_core.list_frame_files(
        CYCLES_DATA / "val" / "cycles_09000"))])
    for spp in (2, 4):
        # Blender's frames are scored as they were stored, against the mean of the two halves.
        blender = np.stack([stored[f"spp{spp}_frame{i}"] for i in range(3)])
        np.testing.assert_array_equal(np.load(frames / "cycles_09000" / f"blender-oidn_{spp}spp.npy"), blender)
        expected = np.mean([affinity_core.metrics.smape(blender[i], reference[i]) for i in range(3)])
        assert float(rows[("blender-oidn", spp)]["smape"]) == pytest.approx(expected, rel=1e-5)
        # Its time is its own render's, not a lookup's.
        assert float(rows[("blender-oidn", spp)]["render_s_per_frame"]) > 0.01
        # Margins recorded with the built-in model on this dim interior: a model that loses
        # ground to the noisy input or to Blender's denoiser by more than 5 % fails.
        ours, noisy = float(rows[("ours-small", spp)]["smape"]), float(rows[("noisy", spp)]["smape"])
        blender_smape = float(rows[("blender-oidn", spp)]["smape"])
        to_noisy, to_blender = CYCLES_TINY_RECORDED[spp]
        assert ours < 1.05 * to_noisy * noisy
        assert ours < 1.05 * to_blender * blender_smape
        brightness = float(rows[("ours-small", spp)]["brightness"])
        assert 0.5 < brightness < 1.5
    noise = read_rows(out / "reference_noise.csv")
    assert [row["sequence"] for row in noise] == ["cycles_09000"] and float(noise[0]["smape"]) > 0


def test_the_preroll_gives_the_first_frame_a_history_from_its_spare_samples() -> None:
    """methods.PrerollRunner, as the Blender extension's pre-roll: with no spare samples it is
    the plain denoiser; with the tiny Cycles sequence's spare samples (4 rendered, 2 judged) the
    first frame starts with a history and comes out closer to the reference."""
    from affinity_bench import methods

    frames = [affinity_core.read_frame(p) for p in affinity_core.list_frame_files(CYCLES_DATA / "val" / "cycles_09000")]
    inputs = [data.with_spp(f, 2) for f in frames]
    model = affinity_core.Model.built_in()

    def run(groups: list[np.ndarray] | None) -> list[np.ndarray]:
        runner = methods.PrerollRunner(model)
        if groups is not None:
            runner.preroll(inputs[0], groups)
        return [runner(f) for f in inputs]

    plain = [affinity_core.Denoiser(model).denoise(f) for f in inputs[:1]]
    assert data.preroll_groups(frames[0], 4) == []  # no sample left after 4
    np.testing.assert_array_equal(run([])[0], plain[0])
    spare = data.preroll_groups(frames[0], 2)  # 2 spare samples: one frame of 2, short of 16
    assert len(spare) == 1
    np.testing.assert_array_equal(spare[0], frames[0]["samples"][:, :, 2:4])
    prerolled, without = run(spare), run(None)
    np.testing.assert_array_equal(without[0], plain[0])
    error = affinity_core.metrics.smape(prerolled[0], frames[0]["reference"])
    error_without = affinity_core.metrics.smape(without[0], frames[0]["reference"])
    print(f"first frame SMAPE at 2 spp: pre-roll {error:.4f}, none {error_without:.4f}")
    assert error < error_without
    assert np.abs(prerolled[1] - without[1]).mean() > 0


def test_a_captured_preroll_is_used_as_the_extension_renders_it() -> None:
    """data.preroll_groups with the extension's own pre-roll (capture.py's preroll.npz, groups
    of the capture's 8 samples): its samples pooled, in order, into the extension's pre-roll
    frames, whatever the samples per frame and whatever the frame itself holds; the spare
    samples of the frame likewise where none was captured."""
    frame = {"samples": np.random.default_rng(9).random((4, 5, 40, 18), dtype=np.float32)}
    captured = [np.random.default_rng(g).random((4, 5, 8, 18), dtype=np.float32) for g in range(8)]
    # The extension's default: one frame of 8 x the samples per frame, 16 to 64.
    assert data.PREROLL_FRAMES == 1
    assert [data.preroll_samples(spp) for spp in (1, 2, 4, 8, 16)] == [16, 16, 32, 64, 64]
    for spp, pooled in ((2, 2), (4, 4), (8, 8)):
        groups = data.preroll_groups(frame, spp, captured)
        assert len(groups) == 1 and groups[0].shape[2] == 8 * pooled
        for g in range(pooled):
            np.testing.assert_array_equal(groups[0][:, :, 8 * g:8 * (g + 1)], captured[g])
        two = data.preroll_groups(frame, spp, captured, preroll_frames=2, preroll_spp=8)
        for group, source in zip(two, captured[:2], strict=True):
            np.testing.assert_array_equal(group, source)
        spare = data.preroll_groups(frame, spp)  # 40 - spp spare samples, the one frame of them
        assert len(spare) == 1
        count = min(data.preroll_samples(spp), 40 - spp)
        np.testing.assert_array_equal(spare[0], frame["samples"][:, :, spp:spp + count])
    three = data.preroll_groups(frame, 8, preroll_frames=3, preroll_spp=12)  # 32 spare: 12, 12, 8
    assert [g.shape[2] for g in three] == [12, 12, 8]
    np.testing.assert_array_equal(three[2], frame["samples"][:, :, 32:40])
    captured = captured[:2]
    with pytest.raises(ValueError, match="holds 16 samples per pixel, fewer than the 1 x 24 asked"):
        data.preroll_groups(frame, 2, captured, preroll_spp=24)

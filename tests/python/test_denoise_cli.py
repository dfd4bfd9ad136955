"""`affinity denoise` end to end: the same output as the Python denoiser on the same frames,
per-frame EXR + PNG and a summary, inputs never touched, clear refusals."""

from __future__ import annotations

import hashlib
import json
import os
import pathlib
import shutil
import signal
import subprocess
import time

import numpy as np
import pytest
from tiled_frame import tiled_frame

import affinity_core
from affinity_core import metrics

BUILD = pathlib.Path(os.environ.get("AFFINITY_BUILD_DIR", pathlib.Path(__file__).parents[2] / "build"))
CLI = BUILD / "core" / "affinity"
EXR_MAGIC = bytes([0x76, 0x2F, 0x31, 0x01])
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def frames_dir(tmp_path_factory: pytest.TempPathFactory) -> pathlib.Path:
    out = tmp_path_factory.mktemp("cli") / "frames"
    subprocess.run([str(CLI), "render", "--scene", "disocclusion", "--frames", "3", "--spp", "2", "--size", "36x24",
                    "--reference-spp", "32", "--seed", "5", "--out", str(out)], check=True, capture_output=True,
                   timeout=300)
    return out


def denoise(*arguments: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([str(CLI), "denoise", *arguments], capture_output=True, text=True, timeout=300)


def checksums(folder: pathlib.Path) -> dict[str, str]:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.iterdir())}


def large_sequence(source: pathlib.Path, folder: pathlib.Path, frames: int, tiles: int = 12) -> pathlib.Path:
    """`frames` copies of `source`'s first frame tiled `tiles` x `tiles` times (432x288 from
    36x24): a run long enough to be interrupted while it works."""
    frame = tiled_frame(affinity_core.read_frame(affinity_core.list_frame_files(source)[0]), tiles)
    folder.mkdir()
    affinity_core.write_frame(folder / "frame_0000.exr", frame, compression="none")
    for i in range(1, frames):
        os.link(folder / "frame_0000.exr", folder / affinity_core.frame_file_name(i))
    return folder


def test_outputs_follow_the_input_files(frames_dir: pathlib.Path, tmp_path: pathlib.Path) -> None:
    """Issue 42, item 2: two shots holding frame numbers 0-2, copied into one folder as
    frame_0000-0005, gave three outputs named by the stored numbers, the first shot's lost."""
    both = tmp_path / "both"
    both.mkdir()
    inputs = affinity_core.list_frame_files(frames_dir)
    for i, path in enumerate(inputs + inputs):
        shutil.copy(path, both / affinity_core.frame_file_name(i))
    done = denoise("--in", str(both), "--out", str(tmp_path / "out"))
    assert done.returncode == 0, done.stderr
    assert sorted(p.name for p in (tmp_path / "out").glob("denoised_*.exr")) == [
        f"denoised_{i:04d}.exr" for i in range(6)]
    summary = json.loads((tmp_path / "out" / "denoise_summary.json").read_text())
    assert [(e["input"], e["output"], e["frame"]) for e in summary["per_frame"]] == [
        (f"frame_{i:04d}.exr", f"denoised_{i:04d}.exr", i % 3) for i in range(6)]


def test_a_refused_run_leaves_no_output_folder(frames_dir: pathlib.Path, tmp_path: pathlib.Path) -> None:
    """Issue 42, item 6: the output folder was made before the model and frames were read."""
    missing_model = denoise("--in", str(frames_dir), "--out", str(tmp_path / "a"), "--model", str(tmp_path / "no.affw"))
    assert missing_model.returncode == 1 and "no.affw" in missing_model.stderr
    assert not (tmp_path / "a").exists()
    broken = tmp_path / "broken"
    broken.mkdir()
    (broken / "frame_0000.exr").write_bytes((frames_dir / "frame_0000.exr").read_bytes()[:5000])
    truncated = denoise("--in", str(broken), "--out", str(tmp_path / "b"))
    assert truncated.returncode == 1 and "frame_0000.exr" in truncated.stderr
    assert not (tmp_path / "b").exists()


def test_an_output_folder_that_cannot_be_made_is_a_user_error(frames_dir: pathlib.Path, tmp_path: pathlib.Path) -> None:
    """Issue 42, item 7: 'internal error: filesystem error ...', exit 3."""
    (tmp_path / "a_file").write_text("not a folder")
    out = tmp_path / "a_file" / "out"
    done = denoise("--in", str(frames_dir), "--out", str(out))
    assert done.returncode == 1, done.stderr
    assert f"cannot create the output folder {out}" in done.stderr and "internal error" not in done.stderr


@pytest.mark.parametrize("signals", [1, 2], ids=["ctrl-c", "ctrl-c-twice"])
def test_ctrl_c_keeps_finished_frames_and_leaves_no_temporary_file(
        frames_dir: pathlib.Path, tmp_path: pathlib.Path, signals: int) -> None:
    """Issue 42, item 4: an interrupted run left *.tmp-PID-N files and no summary. The first
    signal stops between a frame's steps and writes the summary of what was finished; a second
    one ends the run at once, removing the file being written."""
    source = large_sequence(frames_dir, tmp_path / "frames", 40)
    out = tmp_path / "out"
    run = subprocess.Popen([str(CLI), "denoise", "--in", str(source), "--out", str(out)],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while not (out / "denoised_0000.png").exists() and time.monotonic() < deadline and run.poll() is None:
        time.sleep(0.005)
    for _ in range(signals):
        run.send_signal(signal.SIGINT)
    _, stderr = run.communicate(timeout=120)
    assert run.returncode == 130, stderr
    assert not list(out.glob("*.tmp-*"))
    finished = sorted(out.glob("denoised_*.exr"))
    assert 0 < len(finished) < 40
    if signals == 1:
        summary = json.loads((out / "denoise_summary.json").read_text())
        assert summary["interrupted"] is True and summary["input_frames"] == 40
        assert [e["output"] for e in summary["per_frame"]] == [p.name for p in finished]
        assert len(list(out.glob("denoised_*.png"))) == len(finished)
        assert "interrupted after" in stderr


def test_the_cli_denoises_as_the_python_denoiser_does(frames_dir: pathlib.Path, tmp_path: pathlib.Path) -> None:
    before = checksums(frames_dir)
    done = denoise("--in", str(frames_dir), "--out", str(tmp_path / "out"))
    assert done.returncode == 0, done.stderr
    assert checksums(frames_dir) == before  # inputs untouched
    summary = json.loads((tmp_path / "out" / "denoise_summary.json").read_text())
    assert summary["frames"] == 3 and summary["model"]

    # The same frames through affinity_core.Denoiser: the summary's errors are of the same output.
    denoiser = affinity_core.Denoiser()
    for entry, path in zip(summary["per_frame"], affinity_core.list_frame_files(frames_dir)):
        frame = affinity_core.read_frame(path)
        output = denoiser.denoise(frame)
        report = denoiser.last_report
        assert entry["used_history"] == report["used_history"] == (entry["frame"] > 0)
        assert entry["exposure"] == pytest.approx(report["exposure"], rel=1e-7)
        assert entry["denoised"]["smape"] == pytest.approx(metrics.smape(output, frame["reference"]), rel=1e-9)
        assert entry["denoised"]["psnr"] == pytest.approx(metrics.psnr(output, frame["reference"]), rel=1e-9)
        noisy = frame["samples"][..., :3].mean(axis=2) + frame["samples"][..., 3:6].mean(axis=2)
        assert entry["noisy"]["smape"] == pytest.approx(metrics.smape(noisy, frame["reference"]), rel=1e-5)
        assert entry["denoised"]["smape"] < 0.6 * entry["noisy"]["smape"]
        index = entry["frame"]
        assert (tmp_path / "out" / f"denoised_{index:04d}.exr").read_bytes()[:4] == EXR_MAGIC
        assert (tmp_path / "out" / f"denoised_{index:04d}.png").read_bytes()[:8] == PNG_SIGNATURE


def test_the_cli_refuses_to_overwrite_and_names_the_problem(frames_dir: pathlib.Path, tmp_path: pathlib.Path) -> None:
    same = denoise("--in", str(frames_dir), "--out", str(frames_dir))
    assert same.returncode != 0 and "inputs are never overwritten" in same.stderr
    out = tmp_path / "out"
    assert denoise("--in", str(frames_dir), "--out", str(out)).returncode == 0
    first = checksums(out)
    again = denoise("--in", str(frames_dir), "--out", str(out))
    assert again.returncode != 0 and "--force" in again.stderr
    assert checksums(out) == first  # the refused run wrote nothing
    assert denoise("--in", str(frames_dir), "--out", str(out), "--force").returncode == 0
    (tmp_path / "empty").mkdir()
    empty = denoise("--in", str(tmp_path / "empty"), "--out", str(tmp_path / "o2"))
    assert empty.returncode != 0 and "holds no frame files" in empty.stderr
    corrupt = tmp_path / "model.affw"
    corrupt.write_bytes(b"AFFWGHTS" + bytes(40))
    bad = denoise("--in", str(frames_dir), "--out", str(tmp_path / "o3"), "--model", str(corrupt))
    assert bad.returncode != 0 and str(corrupt) in bad.stderr
    assert np.all([not (tmp_path / "o3" / f"denoised_{i:04d}.exr").exists() for i in range(3)])


def test_the_cli_takes_a_precision_and_names_a_wrong_one(frames_dir: pathlib.Path, tmp_path: pathlib.Path) -> None:
    wrong = denoise("--in", str(frames_dir), "--out", str(tmp_path / "o1"), "--precision", "fp16")
    assert wrong.returncode != 0 and "unknown precision 'fp16'" in wrong.stderr
    assert not (tmp_path / "o1").exists()
    # The default is auto: bf16 exactly where the CPU has AVX512-BF16; --precision fp32 overrides it.
    expected = "bf16" if affinity_core.bfloat16_supported() else "fp32"
    cases = (((), expected), (("--precision", "auto"), expected), (("--precision", "fp32"), "fp32"))
    for arguments, precision in cases:
        out = tmp_path / f"o-{'-'.join(arguments) or 'default'}"
        run = denoise("--in", str(frames_dir), "--out", str(out), *arguments)
        assert run.returncode == 0, run.stderr
        assert json.loads((out / "denoise_summary.json").read_text())["precision"] == precision, arguments
    done = denoise("--in", str(frames_dir), "--out", str(tmp_path / "bf16"), "--precision", "bf16")
    if not affinity_core.bfloat16_supported():
        assert done.returncode != 0 and "AVX512-BF16" in done.stderr
        return
    assert done.returncode == 0, done.stderr
    summary = json.loads((tmp_path / "bf16" / "denoise_summary.json").read_text())
    assert summary["precision"] == "bf16"
    denoiser = affinity_core.Denoiser(precision="bf16")
    for entry, path in zip(summary["per_frame"], affinity_core.list_frame_files(frames_dir)):
        frame = affinity_core.read_frame(path)
        output = denoiser.denoise(frame)
        assert entry["denoised"]["smape"] == pytest.approx(metrics.smape(output, frame["reference"]), rel=1e-9)


@pytest.mark.parametrize("flag", ["--help", "-h"])
def test_help_after_the_command_prints_its_usage(tmp_path: pathlib.Path, flag: str) -> None:
    """`affinity denoise --help`: the command's usage on stdout, exit 0, nothing written."""
    result = denoise(flag)
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith("usage: affinity denoise ")
    for option in ("--in", "--out", "--model", "--precision", "--force"):
        assert option in result.stdout
    assert "--scene" not in result.stdout  # denoise's usage, not render's
    assert result.stderr == ""
    with_options = denoise("--in", str(tmp_path / "in"), "--out", str(tmp_path / "out"), flag)
    assert with_options.returncode == 0 and with_options.stdout == result.stdout
    assert not (tmp_path / "out").exists()

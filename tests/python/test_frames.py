"""affinity_core.read_frame / write_frame: exact round trips and clear errors."""

from __future__ import annotations

import os
import pathlib

import numpy as np
import pytest

import affinity_core


def random_frame(rng: np.random.Generator, h: int = 7, w: int = 11, spp: int = 3,
                 with_reference: bool = True) -> dict:
    def floats(*shape: int) -> np.ndarray:
        return rng.standard_normal(shape).astype(np.float32) * 50

    return {
        "samples": floats(h, w, spp, 18),
        "motion": floats(h, w, 2),
        "valid": (rng.random((h, w)) < 0.5).astype(np.float32),
        "reference": floats(h, w, 3) if with_reference else None,
        "info": {
            "scene_name": "living_room_k\u00fcche",
            "frame_index": 42,
            "reference_spp": 1024 if with_reference else 0,
            "seed": 2**64 - 3,  # far above 2**53: must not pass through a double
            "world_to_camera": floats(4, 4),
            "camera_to_clip": floats(4, 4),
        },
    }


def assert_same_frame(expected: dict, actual: dict) -> None:
    assert set(actual) == {"samples", "motion", "valid", "reference", "info"}
    for key in ("samples", "motion", "valid"):
        assert actual[key].dtype == np.float32, key
        np.testing.assert_array_equal(actual[key], expected[key], err_msg=key)
    if expected.get("reference") is None:
        assert actual["reference"] is None
    else:
        np.testing.assert_array_equal(actual["reference"], expected["reference"])
    info, expected_info = actual["info"], expected["info"]
    assert set(info) == set(expected_info)
    for key in ("scene_name", "frame_index", "reference_spp", "seed"):
        assert info[key] == expected_info[key], key
        assert type(info[key]) is type(expected_info[key]), key
    for key in ("world_to_camera", "camera_to_clip"):
        assert info[key].shape == (4, 4) and info[key].dtype == np.float32
        np.testing.assert_array_equal(info[key], expected_info[key], err_msg=key)


@pytest.mark.parametrize("compression", ["none", "zip", "piz"])
def test_round_trip_is_exact(tmp_path: pathlib.Path, compression: str) -> None:
    frame = random_frame(np.random.default_rng(1))
    path = tmp_path / "frame_0000.exr"
    affinity_core.write_frame(path, frame, compression=compression)
    back = affinity_core.read_frame(path)
    assert_same_frame(frame, back)
    assert back["samples"].shape == (7, 11, 3, 18)
    assert back["samples"].flags.writeable and back["samples"].flags.c_contiguous


def test_round_trip_keeps_every_bit(tmp_path: pathlib.Path) -> None:
    # NaN payloads, infinities, denormals and -0 all survive.
    frame = random_frame(np.random.default_rng(2), h=3, w=4, spp=2)
    bits = np.random.default_rng(3).integers(0, 2**32, size=frame["samples"].shape, dtype=np.uint32)
    frame["samples"] = bits.view(np.float32)
    affinity_core.write_frame(str(tmp_path / "bits.exr"), frame)
    back = affinity_core.read_frame(str(tmp_path / "bits.exr"))
    np.testing.assert_array_equal(back["samples"].view(np.uint32), bits)


def test_without_reference_and_strided_input(tmp_path: pathlib.Path) -> None:
    frame = random_frame(np.random.default_rng(4), with_reference=False)
    # A non-contiguous view is accepted (and copied), with the same values.
    wide = np.zeros((7, 11, 4), np.float32)
    wide[:, :, ::2] = frame["motion"]
    frame["motion"] = wide[:, :, ::2]
    del frame["reference"]
    affinity_core.write_frame(tmp_path / "f.exr", frame)
    back = affinity_core.read_frame(tmp_path / "f.exr")
    assert back["reference"] is None
    frame["reference"] = None
    assert_same_frame(frame, back)


def test_seed_limits(tmp_path: pathlib.Path) -> None:
    for seed in (0, 2**53 + 1, 2**64 - 1, np.uint64(2**63 + 5)):
        frame = random_frame(np.random.default_rng(5), h=1, w=1, spp=1)
        frame["info"]["seed"] = seed
        affinity_core.write_frame(tmp_path / "s.exr", frame)
        assert affinity_core.read_frame(tmp_path / "s.exr")["info"]["seed"] == int(seed)
    for bad in (-1, 2**64):
        frame["info"]["seed"] = bad
        with pytest.raises(ValueError, match=r"seed"):
            affinity_core.write_frame(tmp_path / "s.exr", frame)


def zeros(*shape: int) -> np.ndarray:
    return np.zeros(shape, np.float32)


@pytest.mark.parametrize(
    ("key", "value", "message"),
    [
        ("samples", zeros(7, 11, 3, 17), r"frame\['samples'\] has shape \(7, 11, 3, 17\)"),
        ("samples", zeros(7, 11, 18), r"frame\['samples'\] has shape"),
        ("samples", zeros(7, 11, 65, 18), r"frame\['samples'\].*1\.\.64"),
        ("motion", zeros(7, 11, 3), r"frame\['motion'\] has shape \(7, 11, 3\), expected \(7, 11, 2"),
        ("motion", zeros(11, 7, 2), r"frame\['motion'\]"),
        ("valid", zeros(7, 12), r"frame\['valid'\]"),
        ("reference", zeros(7, 11, 4), r"frame\['reference'\]"),
    ],
)
def test_wrong_shape_names_the_key(
    tmp_path: pathlib.Path, key: str, value: np.ndarray, message: str
) -> None:
    frame = random_frame(np.random.default_rng(6))
    frame[key] = value
    with pytest.raises(ValueError, match=message):
        affinity_core.write_frame(tmp_path / "bad.exr", frame)
    assert not os.listdir(tmp_path)


def test_wrong_dtype_or_type_names_the_key(tmp_path: pathlib.Path) -> None:
    frame = random_frame(np.random.default_rng(7))
    frame["valid"] = frame["valid"].astype(np.float64)
    with pytest.raises(TypeError, match=r"frame\['valid'\] must have dtype float32, got float64"):
        affinity_core.write_frame(tmp_path / "bad.exr", frame)
    frame = random_frame(np.random.default_rng(7))
    frame["motion"] = frame["motion"].tolist()
    with pytest.raises(TypeError, match=r"frame\['motion'\] must be a numpy float32 array"):
        affinity_core.write_frame(tmp_path / "bad.exr", frame)
    frame = random_frame(np.random.default_rng(7))
    frame["info"]["world_to_camera"] = np.eye(4)
    with pytest.raises(TypeError, match=r"frame\['info'\]\['world_to_camera'\].*float64"):
        affinity_core.write_frame(tmp_path / "bad.exr", frame)
    frame = random_frame(np.random.default_rng(7))
    frame["info"]["frame_index"] = 1.5
    with pytest.raises(TypeError, match=r"frame\['info'\]\['frame_index'\] must be an int"):
        affinity_core.write_frame(tmp_path / "bad.exr", frame)


def test_missing_and_unknown_keys(tmp_path: pathlib.Path) -> None:
    frame = random_frame(np.random.default_rng(8))
    del frame["motion"]
    with pytest.raises(KeyError, match=r"missing 'motion'"):
        affinity_core.write_frame(tmp_path / "bad.exr", frame)
    frame = random_frame(np.random.default_rng(8))
    del frame["info"]["seed"]
    with pytest.raises(KeyError, match=r"frame\['info'\] is missing 'seed'"):
        affinity_core.write_frame(tmp_path / "bad.exr", frame)
    frame = random_frame(np.random.default_rng(8))
    frame["info"]["scene"] = "typo"
    with pytest.raises(ValueError, match=r"unknown key 'scene'"):
        affinity_core.write_frame(tmp_path / "bad.exr", frame)
    frame = random_frame(np.random.default_rng(8))
    with pytest.raises(ValueError, match=r"compression"):
        affinity_core.write_frame(tmp_path / "bad.exr", frame, compression="lz4")


def test_corrupt_file_raises_affinity_error_with_path(tmp_path: pathlib.Path) -> None:
    path = tmp_path / "frame_0000.exr"
    affinity_core.write_frame(path, random_frame(np.random.default_rng(9)), compression="none")
    data = bytearray(path.read_bytes())
    data[len(data) // 2 : len(data) // 2 + 8] = b"\xa5" * 8
    corrupt = tmp_path / "corrupt.exr"
    corrupt.write_bytes(bytes(data))
    with pytest.raises(affinity_core.Error, match="corrupt.exr") as error:
        affinity_core.read_frame(corrupt)
    assert isinstance(error.value, RuntimeError)

    truncated = tmp_path / "truncated.exr"
    truncated.write_bytes(bytes(data[: len(data) // 2]))
    with pytest.raises(affinity_core.Error, match="truncated.exr"):
        affinity_core.read_frame(truncated)

    garbage = tmp_path / "garbage.exr"
    garbage.write_bytes(os.urandom(1000))
    with pytest.raises(affinity_core.Error, match="garbage.exr.*not an OpenEXR file"):
        affinity_core.read_frame(garbage)

    with pytest.raises(affinity_core.Error, match="missing.exr.*does not exist"):
        affinity_core.read_frame(tmp_path / "missing.exr")


def test_write_into_missing_folder_raises_affinity_error(tmp_path: pathlib.Path) -> None:
    with pytest.raises(affinity_core.Error, match="nowhere"):
        affinity_core.write_frame(tmp_path / "nowhere" / "f.exr", random_frame(np.random.default_rng(0)))


def test_feature_names() -> None:
    names = affinity_core.FEATURE_NAMES
    assert len(names) == 18 == affinity_core.FEATURE_COUNT
    assert len(set(names)) == 18
    assert names[0] == "diffuse.R" and names[17] == "specular_bounce.Y"
    assert affinity_core.MAX_SPP == 64


def test_frame_files(tmp_path: pathlib.Path) -> None:
    assert affinity_core.frame_file_name(7) == "frame_0007.exr"
    for i in (3, 1, 20):
        (tmp_path / affinity_core.frame_file_name(i)).write_bytes(b"x")
    (tmp_path / "other.exr").write_bytes(b"x")
    assert affinity_core.list_frame_files(tmp_path) == [
        str(tmp_path / affinity_core.frame_file_name(i)) for i in (1, 3, 20)
    ]
    with pytest.raises(affinity_core.Error, match="does not exist"):
        affinity_core.list_frame_files(tmp_path / "missing")

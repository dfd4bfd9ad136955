"""The extension package: Blender's own validator and builder accept it, it bundles the core's
wheels for CPython 3.11 and 3.13 (built by scripts/build_extension.sh), and the one for this
Python works on its own and inside an installed extension."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tomllib
import zipfile
from typing import Any

import bpy
import numpy as np
import pytest
from conftest import CORE_PATH, ROOT

from affinity_denoiser import backend

PACKAGE = os.path.join(ROOT, "blender_addon", "affinity_denoiser")
TESTS = os.path.dirname(os.path.abspath(__file__))


def _manifest() -> dict[str, Any]:
    with open(os.path.join(PACKAGE, "blender_manifest.toml"), "rb") as handle:
        return tomllib.load(handle)


#: The Pythons of the Blenders the extension supports: 3.11 (4.2 to 5.0), 3.13 (5.1 and later).
PYTHON_TAGS = ("cp311", "cp313")
#: This interpreter's tag: Blender installs the wheel with it.
THIS_PYTHON = f"cp{sys.version_info[0]}{sys.version_info[1]}"


def _bundled_wheels() -> dict[str, str]:
    """The wheels the manifest lists, by Python tag; each must exist."""
    paths = {}
    for wheel in _manifest().get("wheels", []):
        path = os.path.normpath(os.path.join(PACKAGE, wheel))
        assert os.path.isfile(path), f"{path} is missing: run scripts/build_extension.sh"
        paths[os.path.basename(path).split("-")[2]] = path
    return paths


def _bundled_wheel() -> str:
    """The listed wheel for this Python."""
    wheels = _bundled_wheels()
    assert THIS_PYTHON in wheels, f"no wheel for {THIS_PYTHON} in {sorted(wheels.values())}"
    return wheels[THIS_PYTHON]


def _cmake_project_version() -> str:
    with open(os.path.join(ROOT, "CMakeLists.txt"), encoding="utf-8") as handle:
        match = re.search(r"project\(affinity VERSION ([0-9.]+)", handle.read())
    assert match
    return match.group(1)


def _blender_ext() -> str | None:
    """Blender's extension command line (``blender --command extension``) as a script."""
    path = os.path.join(bpy.utils.system_resource("SCRIPTS"), "addons_core", "bl_pkg", "cli",
                        "blender_ext.py")
    return path if os.path.isfile(path) else None


def test_manifest_fields() -> None:
    manifest = _manifest()
    assert manifest["schema_version"] == "1.0.0"
    assert manifest["id"] == "affinity_denoiser"
    assert manifest["type"] == "add-on"
    assert manifest["blender_version_min"] == "4.2.0"
    for key in ("version", "name", "tagline", "maintainer", "license"):
        assert manifest[key]


def _run(*args: str) -> subprocess.CompletedProcess[str]:
    script = _blender_ext()
    assert script is not None, "this bpy has no bl_pkg/cli/blender_ext.py"
    return subprocess.run([sys.executable, script, *args], capture_output=True, text=True,
                          timeout=120)


def test_blender_validates_the_package() -> None:
    result = _run("validate", PACKAGE)
    assert result.returncode == 0, result.stdout + result.stderr


def _build_archive(output_dir: Any) -> str:
    os.makedirs(output_dir, exist_ok=True)
    result = _run("build", "--source-dir", PACKAGE, "--output-dir", str(output_dir))
    assert result.returncode == 0, result.stdout + result.stderr
    archive = os.path.join(str(output_dir), "affinity_denoiser-0.1.0.zip")
    assert os.path.isfile(archive)
    return archive


def test_blender_builds_a_valid_archive_with_the_wheels(tmp_path: Any) -> None:
    archive = _build_archive(tmp_path)
    result = _run("validate", archive)
    assert result.returncode == 0, result.stdout + result.stderr
    wheels = sorted(_bundled_wheels().values())
    with zipfile.ZipFile(archive) as packed:
        assert sorted(n for n in packed.namelist() if n.startswith("wheels/")) == [
            "wheels/" + os.path.basename(w) for w in wheels]
        for wheel in wheels:
            with open(wheel, "rb") as handle:
                assert packed.read("wheels/" + os.path.basename(wheel)) == handle.read()
        # The model the extension denoises with by default travels inside it.
        with open(os.path.join(PACKAGE, "models", "cycles.affw"), "rb") as handle:
            assert packed.read("models/cycles.affw") == handle.read()


def test_manifest_lists_exactly_the_built_wheels() -> None:
    manifest = _manifest()
    wheels = _bundled_wheels()
    names = [os.path.basename(wheels[tag]) for tag in PYTHON_TAGS if tag in wheels]
    assert manifest["wheels"] == [f"./wheels/{name}" for name in names]
    # Blender installs the listed wheel matching its Python; the builder packs every file in
    # the folder.
    assert sorted(os.listdir(os.path.join(PACKAGE, "wheels"))) == sorted(names)
    # One per Blender Python on Linux x86-64, versioned like the CMake project, and both for
    # glibc 2.34 (the cp313 one built by the same host toolchain, not Debian 13's).
    assert sorted(wheels) == sorted(PYTHON_TAGS), names
    for tag, name in zip(PYTHON_TAGS, names):
        assert re.fullmatch(rf"affinity_core-{re.escape(_cmake_project_version())}-{tag}-{tag}-"
                            r"manylinux_2_34_x86_64\.whl", name), name
    assert manifest["platforms"] == ["linux-x64"]


@pytest.mark.parametrize("tag", PYTHON_TAGS)
def test_wheel_holds_the_package_and_the_libraries_it_needs(tag: str) -> None:
    wheels = _bundled_wheels()
    assert tag in wheels, sorted(wheels.values())
    with zipfile.ZipFile(wheels[tag]) as wheel:
        names = wheel.namelist()
    # Every Python file of the package, as python_bindings/CMakeLists.txt installs them.
    source = os.path.join(ROOT, "python_bindings")
    expected = {
        os.path.relpath(os.path.join(directory, name), source).replace(os.sep, "/")
        for directory, dirs, files in os.walk(os.path.join(source, "affinity_core"))
        for name in files if name.endswith(".py")
    }
    assert {n for n in names if n.startswith("affinity_core/") and n.endswith(".py")} == expected
    # The benchmark is a development tool of the repository (affinity_bench/), never shipped.
    assert not [n for n in names if n.startswith(("affinity_core/bench/", "affinity_bench/"))], names
    assert [n for n in names if n.startswith("affinity_core/_core")] == [
        f"affinity_core/_core.cpython-{tag.removeprefix('cp')}-x86_64-linux-gnu.so"]
    # auditwheel copied in what a Blender machine may not have (OpenEXR, Imath, libgomp).
    vendored = [n.removeprefix("affinity_core.libs/") for n in names if n.startswith("affinity_core.libs/")]
    for library in ("libOpenEXR-", "libImath-", "libgomp-"):
        assert any(v.startswith(library) for v in vendored), (library, vendored)


# Runs in a Python that has only the installed wheel (and numpy): reads, writes and denoises.
_WHEEL_ALONE = """
import json, os, sys
import numpy as np
import affinity_core

rng = np.random.default_rng(1)
h, w, spp = 12, 16, 2
samples = rng.random((h, w, spp, affinity_core.FEATURE_COUNT), dtype=np.float32)
frame = {
    "samples": samples,
    "motion": np.zeros((h, w, 2), np.float32),
    "valid": np.zeros((h, w), np.float32),
    "reference": None,
    "info": {"scene_name": "wheel", "frame_index": 0, "reference_spp": 0, "seed": 1,
             "world_to_camera": np.eye(4, dtype=np.float32),
             "camera_to_clip": np.eye(4, dtype=np.float32)},
}
path = os.path.join(sys.argv[1], "frame_0000.exr")
affinity_core.write_frame(path, frame)
back = affinity_core.read_frame(path)
denoiser = affinity_core.Denoiser()
outputs = [denoiser.denoise(back), denoiser.denoise(back)]
with open("/proc/self/maps") as handle:
    exr = sorted({line.split()[-1] for line in handle if "libOpenEXR" in line})
print(json.dumps({
    "affinity": affinity_core.__file__,
    "version": affinity_core.__version__,
    "core": affinity_core._core.__file__,
    "numpy": np.__version__,
    "same_samples": bool(np.array_equal(back["samples"], samples)),
    "shapes": [list(o.shape) for o in outputs],
    "dtypes": [str(o.dtype) for o in outputs],
    "finite": all(bool(np.isfinite(o).all()) for o in outputs),
    "used_history": denoiser.last_report["used_history"],
    "openexr": exr,
}))
"""


def test_the_wheel_alone_reads_writes_and_denoises(tmp_path: Any) -> None:
    site = tmp_path / "site"
    subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "--no-index", "-q",
                    "--disable-pip-version-check", "--target", str(site), _bundled_wheel()],
                   check=True, capture_output=True, text=True, timeout=120)
    # PYTHONPATH names only the installed wheel: not build/python, not the add-on.
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env["PYTHONPATH"] = str(site)
    result = subprocess.run([sys.executable, "-W", "error", "-c", _WHEEL_ALONE, str(tmp_path)],
                            env=env, cwd=str(tmp_path), capture_output=True, text=True,
                            timeout=300)
    assert result.returncode == 0, result.stdout + result.stderr
    report = json.loads(result.stdout.strip().splitlines()[-1])
    assert report["affinity"] == str(site / "affinity_core" / "__init__.py")
    assert report["version"] == _cmake_project_version()  # from the wheel's metadata
    assert report["core"].startswith(str(site / "affinity_core" / f"_core.cpython-{THIS_PYTHON[2:]}-"))
    # bpy's numpy (1.26 with Blender 5.0, 2.2 with 5.3); the module was built with numpy 2.
    assert report["numpy"] == np.__version__
    assert report["same_samples"]
    assert report["shapes"] == [[12, 16, 3], [12, 16, 3]]
    assert report["dtypes"] == ["float32", "float32"]
    assert report["finite"] and report["used_history"]
    # The OpenEXR inside the wheel, not the system's.
    assert report["openexr"] and all(p.startswith(str(site / "affinity_core.libs")) for p in
                                     report["openexr"]), report["openexr"]


# Runs in a fresh bpy with its own user folders: installs the extension zip as an artist would,
# then renders one denoised frame with the add-on's operator.
_INSTALLED_EXTENSION = """
import json, os, sys
import numpy as np
import bpy
import scenes

archive, out = sys.argv[1], sys.argv[2]
scenes.build_scene(width=32, height=24, frames=2, spp=2)  # factory settings first: they disable add-ons
assert bpy.ops.extensions.package_install_files(
    filepath=archive, repo="user_default", enable_on_install=True) == {"FINISHED"}
scene = bpy.context.scene
scene.render.filepath = os.path.join(out, "frame_")
scene.affinity_denoiser.samples_per_frame = 2
scene.frame_set(1)
assert bpy.ops.affinity_denoiser.render_frame() == {"FINISHED"}
image = scenes.read_image(os.path.join(out, "affinity_denoised", "denoised_0001.exr"))
core = sys.modules["affinity_core"]
backend = sys.modules["bl_ext.user_default.affinity_denoiser.backend"]
print("RESULT " + json.dumps({
    "affinity": core.__file__,
    "core": core._core.__file__,
    "site": backend.bundled_site_packages(),
    "extensions": bpy.utils.user_resource("EXTENSIONS"),
    "addons": sorted(m for m in sys.modules if m.endswith(".affinity_denoiser")),
    "shape": list(image.shape),
    "finite": bool(np.isfinite(image).all()),
}))
"""


def test_installed_extension_denoises_with_its_bundled_core(tmp_path: Any) -> None:
    archive = _build_archive(tmp_path / "dist")
    env = dict(os.environ)
    env["BLENDER_USER_RESOURCES"] = str(tmp_path / "blender")
    # A development build of the core is on the path too: the bundled wheel must win.
    env["PYTHONPATH"] = os.pathsep.join([CORE_PATH, TESTS])
    result = subprocess.run([sys.executable, "-c", _INSTALLED_EXTENSION, archive,
                             str(tmp_path / "render")], env=env, cwd=str(tmp_path),
                            capture_output=True, text=True, timeout=300)
    lines = [line for line in result.stdout.splitlines() if line.startswith("RESULT ")]
    assert result.returncode == 0 and lines, result.stdout[-3000:] + result.stderr[-3000:]
    report = json.loads(lines[-1].removeprefix("RESULT "))
    # Blender installed this Python's wheel below its user extensions folder, and the add-on
    # found it there (from sys.path, whatever Blender's layout) and preferred it.
    extensions = str(tmp_path / "blender" / "extensions")
    assert report["extensions"].rstrip(os.sep) == extensions
    site = report["site"]
    assert site and site.startswith(extensions + os.sep), report
    assert report["affinity"] == os.path.join(site, "affinity_core", "__init__.py")
    assert os.path.basename(report["core"]).startswith(f"_core.cpython-{THIS_PYTHON[2:]}-")
    assert report["addons"] == ["bl_ext.user_default.affinity_denoiser"]
    assert report["shape"] == [24, 32, 4] and report["finite"]


def test_cpu_check_names_the_missing_x86_64_v3_features() -> None:
    cpuinfo = "processor\t: 0\nflags\t\t: fpu sse2 avx fma bmi1 f16c movbe abm\n"
    assert backend.missing_cpu_features(cpuinfo) == ["avx2", "bmi2"]
    assert backend.missing_cpu_features(cpuinfo.replace("abm", "abm avx2 bmi2")) == []
    assert backend.missing_cpu_features("no flags here") == []


def test_a_cpu_without_x86_64_v3_is_a_clear_error(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delitem(sys.modules, "affinity_core", raising=False)
    monkeypatch.setattr(backend, "_cpu_problem", lambda: "needs an x86-64-v3 CPU; lacks avx2")
    with pytest.raises(backend.CoreMissing, match="x86-64-v3"):
        backend.load_core()


def test_wheel_build_requirements_match_the_pins() -> None:
    with open(os.path.join(ROOT, "pyproject.toml"), "rb") as handle:
        requires = tomllib.load(handle)["build-system"]["requires"]
    with open(os.path.join(ROOT, "requirements.txt"), encoding="utf-8") as handle:
        pins = {line.strip() for line in handle if "==" in line and not line.startswith("#")}
    assert requires and all(r in pins for r in requires), (requires, sorted(pins))

"""The extension package: Blender's own validator and builder accept it."""

from __future__ import annotations

import os
import subprocess
import sys
import tomllib
from typing import Any

import bpy

from conftest import ROOT

PACKAGE = os.path.join(ROOT, "blender_addon", "affinity_denoiser")


def _blender_ext() -> str | None:
    """Blender's extension command line (``blender --command extension``) as a script."""
    path = os.path.join(bpy.utils.system_resource("SCRIPTS"), "addons_core", "bl_pkg", "cli",
                        "blender_ext.py")
    return path if os.path.isfile(path) else None


def test_manifest_fields() -> None:
    with open(os.path.join(PACKAGE, "blender_manifest.toml"), "rb") as handle:
        manifest = tomllib.load(handle)
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


def test_blender_builds_a_valid_archive(tmp_path: Any) -> None:
    result = _run("build", "--source-dir", PACKAGE, "--output-dir", str(tmp_path))
    assert result.returncode == 0, result.stdout + result.stderr
    archive = tmp_path / "affinity_denoiser-0.1.0.zip"
    assert archive.is_file()
    result = _run("validate", str(archive))
    assert result.returncode == 0, result.stdout + result.stderr

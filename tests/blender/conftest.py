"""Fixtures for the Blender extension tests: real ``bpy`` (PyPI wheel), headless, tiny scenes.

Run with ``PYTHONPATH=build/python:blender_addon .venv-blender/bin/python -m pytest tests/blender``.
When the affinity core cannot be imported (or has no Denoiser yet) the pipeline tests run
against the stand-in ``backend.MeanDenoiser`` and the report header says so.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
# Appended, so that PYTHONPATH (e.g. another build of the core) comes first.
for path in (os.path.join(ROOT, "blender_addon"), os.path.join(ROOT, "build", "python"),
             os.path.dirname(os.path.abspath(__file__))):
    if path not in sys.path:
        sys.path.append(path)

import bpy  # noqa: E402

import affinity_denoiser  # noqa: E402
from affinity_denoiser import backend, engine, passes  # noqa: E402


def _core_problem() -> str:
    try:
        affinity = backend.load_core()
        affinity.Denoiser()
    except Exception as exc:  # any failure means: use the stand-in
        return str(exc)
    return ""


def _core_io_available() -> bool:
    try:
        backend.load_core(need_denoiser=False)
    except backend.CoreMissing:
        return False
    return True


def _core_path() -> str:
    """The folder that holds the development build of the core this Python imports."""
    module = sys.modules.get("affinity_core")
    if module is not None and getattr(module, "__file__", None):
        return os.path.dirname(os.path.dirname(os.path.abspath(module.__file__)))
    return os.path.join(ROOT, "build", "python")


CORE_PROBLEM = _core_problem()
#: The core's Denoiser works (otherwise the pipeline tests use the stand-in).
CORE_AVAILABLE = not CORE_PROBLEM
#: The core can at least read and write frame files.
CORE_IO_AVAILABLE = _core_io_available()
#: For child processes' PYTHONPATH: build/python, or on another Python the build for it that
#: PYTHONPATH named (scripts/test.sh: build-py313/python for bpy 5.3).
CORE_PATH = _core_path()


def pytest_configure(config: Any) -> None:
    # scripts/test.sh sets it: there a run on the stand-in would test less than it says.
    if os.environ.get("AFFINITY_REQUIRE_CORE") == "1" and not CORE_AVAILABLE:
        raise pytest.UsageError(f"AFFINITY_REQUIRE_CORE=1 but the core is unavailable: {CORE_PROBLEM}")


def pytest_report_header(config: Any) -> str:
    version = bpy.app.version_string
    if CORE_AVAILABLE:
        return f"bpy {version}; denoiser: affinity core"
    return f"bpy {version}; denoiser: stand-in MeanDenoiser (core unavailable: {CORE_PROBLEM})"


@pytest.fixture(scope="session", autouse=True)
def addon() -> Any:
    affinity_denoiser.register()
    if not CORE_AVAILABLE:
        backend.set_denoiser_factory(backend.MeanDenoiser)
    yield affinity_denoiser
    backend.set_denoiser_factory(None)
    affinity_denoiser.unregister()


def capture(scene: Any, setup: Callable[[Any], None] | None = None) -> dict[str, np.ndarray]:
    """One plain render of the current frame through the capture engine, every pass in memory.

    Changes the scene (engine, and whatever ``setup`` does): use on scenes built for the test.
    """
    scene.render.engine = engine.IDNAME
    if setup is not None:
        setup(scene)
    captured: list[dict[str, np.ndarray]] = []
    engine.session.sink = lambda result: captured.append(passes.read_result(result))
    try:
        bpy.ops.render.render()
    finally:
        engine.session.sink = None
        scene.render.engine = "CYCLES"
    assert captured, "the capture engine delivered no result"
    return captured[0]


def material_snapshot() -> dict[str, Any]:
    """Everything about every material's node tree that a user could see."""

    def value(socket: Any) -> Any:
        if not hasattr(socket, "default_value"):
            return None
        v = socket.default_value
        try:
            return tuple(v)
        except TypeError:
            return v

    snapshot = {}
    for material in bpy.data.materials:
        tree = material.node_tree
        if tree is None:
            snapshot[material.name] = None
            continue
        nodes = [
            (n.name, n.bl_idname, n.label, tuple(n.location), n.select, n.mute,
             tuple((s.identifier, value(s)) for s in n.inputs))
            for n in tree.nodes
        ]
        links = sorted(
            (link.from_node.name, link.from_socket.identifier, link.to_node.name, link.to_socket.identifier)
            for link in tree.links
        )
        active = tree.nodes.active.name if tree.nodes.active else None
        snapshot[material.name] = (nodes, links, active, material.is_evaluated)
    return snapshot

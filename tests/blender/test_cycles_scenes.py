"""The procedural Cycles scene generator (training/cycles/scene_generator.py): same seed, same scene;
every kind is drawn and builds; the camera and objects move; render settings are a user's
defaults; one tiny render per kind is finite and not black."""

from __future__ import annotations

import json
import math
import os
import sys
from typing import Any

import bpy
import numpy as np
import pytest
from conftest import ROOT

sys.path.append(os.path.join(ROOT, "training", "cycles"))

import scene_generator as generator  # noqa: E402

#: One seed per kind for the per-kind tests (any seed builds any kind when asked).
SEED = 3


def _value(value: Any) -> Any:
    try:
        return tuple(value)
    except TypeError:
        return value


def _matrix(obj: bpy.types.Object) -> tuple:
    return tuple(tuple(row) for row in obj.matrix_world)


def snapshot(scene: bpy.types.Scene) -> dict:
    """Everything a render depends on that the generator sets: objects and their motion,
    modifiers, materials' nodes, lights, camera, world, render settings."""
    first, last = scene.frame_start, scene.frame_end
    objects: dict = {}
    for frame in (first, last):
        scene.frame_set(frame)
        for obj in scene.objects:
            objects.setdefault(obj.name, {"type": obj.type, "matrix": []})["matrix"].append(
                _matrix(obj))
    for obj in scene.objects:
        entry = objects[obj.name]
        entry["parent"] = obj.parent.name if obj.parent else None
        entry["modifiers"] = [
            (m.type, *(_value(getattr(m, p)) for p in ("width", "segments", "levels",
                                                       "render_levels", "strength",
                                                       "thickness", "count") if hasattr(m, p)),
             getattr(getattr(m, "texture", None), "name", None))
            for m in getattr(obj, "modifiers", ())]
        entry["constraints"] = [(c.type, c.target.name if c.target else None)
                                for c in obj.constraints]
        data = obj.data
        if obj.type == "MESH":
            entry["mesh"] = (len(data.vertices), len(data.polygons),
                             tuple(round(c, 6) for v in data.vertices[:50] for c in v.co))
            entry["materials"] = [m.name for m in data.materials]
        elif obj.type == "LIGHT":
            entry["light"] = (data.type, data.energy, tuple(data.color), data.shadow_soft_size,
                              getattr(data, "size", None), getattr(data, "size_y", None),
                              getattr(data, "angle", None), data.cycles.is_portal)
        elif obj.type == "CAMERA":
            entry["camera"] = (data.lens, data.dof.use_dof, data.dof.aperture_fstop,
                               data.dof.focus_object.name if data.dof.focus_object else None)
    materials = {m.name: _tree(m.node_tree) for m in bpy.data.materials}
    textures = {t.name: (t.type, getattr(t, "noise_scale", None)) for t in bpy.data.textures}
    render = scene.render
    settings = (render.engine, render.resolution_x, render.resolution_y, render.use_motion_blur,
                render.motion_blur_shutter, scene.cycles.samples, scene.frame_start,
                scene.frame_end, dict(scene.items()).get("affinity_kind"))
    return {"objects": objects, "materials": materials, "textures": textures,
            "world": _tree(scene.world.node_tree) if scene.world else None,
            "settings": settings}


def _tree(tree: bpy.types.NodeTree | None) -> Any:
    if tree is None:
        return None
    nodes = []
    for node in sorted(tree.nodes, key=lambda n: n.name):
        inputs = tuple((s.identifier, _value(s.default_value)) for s in node.inputs
                       if hasattr(s, "default_value"))
        extra = tuple(_value(getattr(node, p)) for p in ("sky_type", "sun_elevation",
                                                           "sun_rotation", "wave_type")
                      if hasattr(node, p))
        ramp = ()
        if node.bl_idname == "ShaderNodeValToRGB":
            ramp = tuple((e.position, tuple(e.color)) for e in node.color_ramp.elements)
        nodes.append((node.name, node.bl_idname, inputs, extra, ramp))
    links = sorted((link.from_node.name, link.from_socket.identifier, link.to_node.name,
                    link.to_socket.identifier) for link in tree.links)
    return nodes, links


def _moves(scene: bpy.types.Scene, obj: bpy.types.Object) -> bool:
    scene.frame_set(scene.frame_start)
    before = obj.matrix_world.copy()
    scene.frame_set(scene.frame_end)
    after = obj.matrix_world.copy()
    scene.frame_set(scene.frame_start)
    return any(abs(before[i][j] - after[i][j]) > 1e-4 for i in range(4) for j in range(4))


def test_every_kind_is_drawn_over_seeds() -> None:
    drawn = [generator.scene_kind(seed) for seed in range(200)]
    assert set(drawn) == set(generator.KINDS)
    assert drawn == [generator.scene_kind(seed) for seed in range(200)]  # deterministic
    for kind in generator.KINDS:  # none is a rarity
        assert drawn.count(kind) >= 10, (kind, drawn.count(kind))


@pytest.mark.parametrize("seed", [0, 11, 42])
def test_the_same_seed_builds_the_same_scene(seed: int) -> None:
    first = snapshot(generator.build_scene(seed, frames=5))
    second = snapshot(generator.build_scene(seed, frames=5))
    assert first == second
    assert len(first["objects"]) >= 6


def test_different_seeds_build_different_scenes() -> None:
    kind = "interior"
    a = snapshot(generator.build_scene(1, kind=kind))
    b = snapshot(generator.build_scene(2, kind=kind))
    assert a != b
    assert a["materials"] != b["materials"]
    assert ({k: v["matrix"] for k, v in a["objects"].items()}
            != {k: v["matrix"] for k, v in b["objects"].items()})


def test_the_natural_kind_is_built_when_none_is_given() -> None:
    for seed in range(4):
        scene = generator.build_scene(seed, width=32, height=18, frames=2)
        assert scene["affinity_kind"] == generator.scene_kind(seed)
        assert scene["affinity_seed"] == seed


def test_an_unknown_kind_is_refused() -> None:
    with pytest.raises(ValueError, match="unknown scene kind"):
        generator.build_scene(0, kind="moon_base")


@pytest.mark.parametrize("kind", generator.KINDS)
def test_each_kind_builds_with_user_defaults_and_motion(kind: str) -> None:
    # The factory scene's, which build_scene starts from (a scene made by bpy.data.scenes.new
    # gets Filmic in Blender 4.2, whose factory scene has AgX).
    bpy.ops.wm.read_factory_settings(use_empty=True)
    default_view = bpy.context.scene.view_settings.view_transform
    scene = generator.build_scene(SEED, width=96, height=54, frames=6, threads=1, kind=kind)
    render, cycles = scene.render, scene.cycles
    assert (render.engine, cycles.device) == ("CYCLES", "CPU")
    assert (render.resolution_x, render.resolution_y, render.resolution_percentage) == (96, 54, 100)
    assert (render.threads_mode, render.threads) == ("FIXED", 1)
    assert not cycles.use_denoising and not cycles.use_adaptive_sampling
    assert (scene.frame_start, scene.frame_end) == (1, 6)
    assert scene.view_settings.view_transform == default_view
    assert scene.view_settings.exposure == 0.0
    assert (scene["affinity_seed"], scene["affinity_kind"]) == (SEED, kind)

    summary = generator.describe(scene)
    json.dumps(summary)  # JSON-able
    assert summary["kind"] == kind and summary["seed"] == SEED
    assert summary["lights"] or summary["emitters"], "a scene needs light"
    movers = [o for o in scene.objects if o.type != "CAMERA" and _moves(scene, o)]
    assert movers, "at least one object moves"
    assert set(summary["moving_objects"]) >= {o.name for o in movers if o.type != "EMPTY"}
    if summary["camera"]["motion"] != "static":
        assert _moves(scene, scene.camera)


@pytest.mark.parametrize("kind", generator.KINDS)
def test_the_camera_moves_in_most_scenes_of_each_kind(kind: str) -> None:
    moving = 0
    for seed in range(6):
        scene = generator.build_scene(seed, width=32, height=18, frames=4, kind=kind)
        moving += _moves(scene, scene.camera)
    assert moving >= 3


def test_features_are_spread_over_seeds() -> None:
    counts: dict[str, int] = {}
    for seed in range(40):
        features = generator.describe(generator.build_scene(seed, width=32, height=18,
                                                            frames=3))["features"]
        for name, present in features.items():
            counts[name] = counts.get(name, 0) + bool(present)
    for name in ("dof", "motion_blur", "volume", "thin", "glass", "sparks", "window",
                 "shaded_lamp", "displacement", "camera_moves"):
        assert counts.get(name, 0) > 0, (name, counts)
    assert 3 <= counts["dof"] <= 20 and 3 <= counts["motion_blur"] <= 20, counts
    assert counts["thin"] >= 30, counts


@pytest.mark.parametrize("kind", generator.KINDS)
def test_a_tiny_render_of_each_kind_is_finite_and_not_black(kind: str, tmp_path) -> None:
    scene = generator.build_scene(SEED, width=32, height=18, frames=3, threads=1, kind=kind)
    scene.cycles.samples = 2
    scene.frame_set(2)
    settings = scene.render.image_settings
    settings.file_format = "OPEN_EXR"
    settings.color_depth = "32"
    path = str(tmp_path / f"{kind}.exr")
    scene.render.filepath = path
    bpy.ops.render.render(write_still=True)
    image = bpy.data.images.load(path)
    try:
        pixels = np.empty(image.size[0] * image.size[1] * 4, np.float32)
        image.pixels.foreach_get(pixels)
    finally:
        bpy.data.images.remove(image)
    rgb = pixels.reshape(-1, 4)[:, :3]
    assert rgb.shape[0] == 32 * 18
    assert np.isfinite(rgb).all()
    assert rgb.mean() > 1e-4 and (rgb.max(axis=1) > 0).mean() > 0.1, (kind, rgb.mean())
    assert not math.isnan(float(rgb.mean()))

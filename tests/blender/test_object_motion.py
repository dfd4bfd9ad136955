"""Motion vectors that follow moving objects: a cube translating 0.2 units in x per frame, a cube
turning 10 degrees per frame with a parented sphere, an object that appears at frame 2, a static
floor; a static and a moving camera. The pipeline's motion is checked against the analytic
motion of each sample's hit point and against Cycles' Vector pass of the same sample."""

from __future__ import annotations

import math
import types
from typing import Any

import bpy
import numpy as np
import pytest
from conftest import capture, material_snapshot

from affinity_denoiser import materials, motion, passes, pipeline

WIDTH, HEIGHT, FRAMES, SPP = 64, 48, 3, 4
STEP = 0.2  # the mover's x per frame
TURN = math.radians(10.0)  # the spinner's z rotation per frame
SPINNER_CENTRE = np.array([1.3, 0.0, 0.6])
# Object indices (Cycles' Object Index pass tells the test which object each pixel shows).
FLOOR, MOVER, SPINNER, CHILD, POPPER = 1, 2, 3, 4, 5
#: Motion error allowed against the Vector pass and the analytic motion, in pixels.
TOLERANCE_PX = 1e-3


def _material(name: str, color: tuple[float, float, float]) -> bpy.types.Material:
    material = bpy.data.materials.new(name)
    if material.node_tree is None:  # Blender < 5 creates the node tree on request
        material.use_nodes = True
    material.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = color + (1.0,)
    return material


def _mesh(primitive: str, name: str, material: bpy.types.Material, index: int,
          **kwargs: Any) -> bpy.types.Object:
    getattr(bpy.ops.mesh, primitive)(**kwargs)
    obj = bpy.context.object
    obj.name = name
    obj.data.materials.append(material)
    obj.pass_index = index
    return obj


def build_scene(moving_camera: bool, folder: Any) -> bpy.types.Scene:
    """The scene; its render output (and so the denoised files) goes into ``folder``."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    render = scene.render
    render.filepath = str(folder / "render" / "frame_")
    render.engine = "CYCLES"
    render.resolution_x, render.resolution_y, render.resolution_percentage = WIDTH, HEIGHT, 100
    render.threads_mode, render.threads = "FIXED", 2
    scene.cycles.device = "CPU"
    scene.cycles.samples = SPP
    scene.frame_start, scene.frame_end = 1, FRAMES
    world = bpy.data.worlds.new("World")
    scene.world = world
    if world.node_tree is None:
        world.use_nodes = True
    world.node_tree.nodes["Background"].inputs[0].default_value = (0.05, 0.07, 0.1, 1.0)

    _mesh("primitive_plane_add", "Floor", _material("Floor", (0.8, 0.6, 0.4)), FLOOR, size=20)
    red = _material("Red", (0.8, 0.1, 0.1))
    mover = _mesh("primitive_cube_add", "Mover", red, MOVER, size=1.0)
    spinner = _mesh("primitive_cube_add", "Spinner", _material("Green", (0.1, 0.8, 0.1)),
                    SPINNER, size=0.8, location=tuple(SPINNER_CENTRE))
    child = _mesh("primitive_uv_sphere_add", "Child", red, CHILD, radius=0.25, segments=12,
                  ring_count=6)
    child.parent = spinner
    child.location = (0.0, -0.7, 0.0)
    popper = _mesh("primitive_cube_add", "Popper", red, POPPER, size=0.4,
                   location=(-0.2, -1.0, 1.6))
    bpy.ops.object.light_add(type="SUN", rotation=(0.5, 0.3, 0.0))
    bpy.context.object.data.energy = 3.0
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    scene.collection.objects.link(camera)
    scene.camera = camera
    for i in range(FRAMES):
        frame = 1 + i  # every frame is keyed, so the values there are exact
        mover.location = (-1.2 + STEP * i, 0.0, 0.5)
        mover.keyframe_insert("location", frame=frame)
        spinner.rotation_euler = (0.0, 0.0, TURN * i)
        spinner.keyframe_insert("rotation_euler", frame=frame)
        popper.hide_render = popper.hide_viewport = frame == 1  # appears at frame 2
        popper.keyframe_insert("hide_render", frame=frame)
        popper.keyframe_insert("hide_viewport", frame=frame)
        camera.location = (0.15 * i if moving_camera else 0.0, -7.0, 1.5)
        camera.rotation_euler = (math.radians(85.0), 0.0,
                                 math.radians(1.5 * i) if moving_camera else 0.0)
        camera.keyframe_insert("location", frame=frame)
        camera.keyframe_insert("rotation_euler", frame=frame)
    scene.frame_set(1)
    return scene


def _previous_position(index: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Where the world points (N, 3) on the objects ``index`` were one frame earlier."""
    before = points.copy()
    before[index == MOVER] -= np.array([STEP, 0.0, 0.0])
    turning = (index == SPINNER) | (index == CHILD)  # the child turns with its parent
    c, s = math.cos(-TURN), math.sin(-TURN)
    rotation = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    before[turning] = (points[turning] - SPINNER_CENTRE) @ rotation.T + SPINNER_CENTRE
    return before


def _first_sample_passes(scene: Any) -> None:
    """The sample the pipeline renders first, with the Vector, Position and Object Index passes;
    persistent data and motion blur off (the Vector pass needs both)."""
    layer = scene.view_layers[0]
    if pipeline.uses_sample_subsets(scene.cycles):
        scene.cycles.samples = SPP
        scene.cycles.use_sample_subset = True
        scene.cycles.sample_subset_length = 1
    else:
        scene.cycles.samples = 1
    scene.cycles.sample_offset = 0
    scene.render.use_persistent_data = False
    scene.render.use_motion_blur = False
    layer.use_pass_vector = layer.use_pass_z = True
    layer.use_pass_position = layer.use_pass_object_index = True


def _object_index(captured: dict[str, np.ndarray]) -> np.ndarray:
    """Cycles' Object Index pass (named IndexOB before Blender 5) as integers."""
    name = "Object Index" if "Object Index" in captured else "IndexOB"
    return np.rint(captured[name][..., 0]).astype(int)


def _add_fog(scene: bpy.types.Scene, density: float) -> None:
    """A homogeneous world volume: camera rays scatter in it before reaching a surface."""
    tree = scene.world.node_tree
    scatter = tree.nodes.new("ShaderNodeVolumeScatter")
    scatter.inputs["Density"].default_value = density
    tree.links.new(scatter.outputs["Volume"], tree.nodes["World Output"].inputs["Volume"])


def _run(moving_camera: bool, folder: Any, fog_density: float = 0.0) -> dict[str, Any]:
    scene = build_scene(moving_camera, folder)
    if fog_density > 0.0:
        _add_fog(scene, fog_density)
    job = pipeline.DenoiseRender(scene, scene.view_layers[0], [1, 2, 3],
                                 pipeline.Settings(samples_per_frame=SPP))
    job.keep_frames = True
    job.run()
    frames: dict[int, dict[str, Any]] = {}
    for frame in job.frames:
        scene.frame_set(frame)
        camera = motion.scene_camera(scene, bpy.context.evaluated_depsgraph_get())
        captured = capture(scene, _first_sample_passes)
        frames[frame] = {
            "camera": camera,
            "index": _object_index(captured),
            "position": captured["Position"][..., :3].astype(np.float64),
            "hit": captured["Depth"][..., 0] < motion.MISS_DEPTH,
            # Blender's Vector pass: (x, y) motion into the previous frame, y up.
            "vector": np.stack([captured["Vector"][..., 0], -captured["Vector"][..., 1]], -1),
        }
    for result in job.results:
        frames[result.frame]["motion"] = result.frame_data["motion"]
        frames[result.frame]["valid"] = result.frame_data["valid"]
    return frames


@pytest.fixture(scope="module")
def static_camera(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    return _run(False, tmp_path_factory.mktemp("static_camera"))


@pytest.fixture(scope="module")
def moving_camera(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    return _run(True, tmp_path_factory.mktemp("moving_camera"))


def _analytic_motion(frames: dict[int, dict[str, Any]], frame: int) -> np.ndarray:
    """The motion of each pixel's hit point (Cycles' Position pass) from the known animation."""
    now, before = frames[frame], frames[frame - 1]
    points = now["position"].reshape(-1, 3)
    homogeneous = np.concatenate([points, np.ones((len(points), 1))], axis=1)
    previous = np.concatenate(
        [_previous_position(now["index"].ravel(), points), np.ones((len(points), 1))], axis=1)
    x, y, _ = motion.project(now["camera"], homogeneous)
    x_before, y_before, _ = motion.project(before["camera"], previous)
    return np.stack([x_before - x, y_before - y], -1).reshape(HEIGHT, WIDTH, 2)


def _check_moving_objects(frames: dict[int, dict[str, Any]]) -> None:
    for frame in (2, 3):
        now = frames[frame]
        analytic = _analytic_motion(frames, frame)
        for index in (MOVER, SPINNER, CHILD):
            on = now["index"] == index
            assert on.sum() > 20, f"object {index} covers too few pixels"
            ours = now["motion"][on]
            assert np.abs(ours - analytic[on]).max() < TOLERANCE_PX
            assert np.abs(ours - now["vector"][on]).max() < TOLERANCE_PX
            # Camera-only motion would be far off: the objects really move on screen.
            camera_only = np.linalg.norm(analytic[on] - _camera_only(frames, frame)[on], axis=-1)
            assert camera_only.mean() > 0.5
            assert now["valid"][on].mean() > 0.8


def _camera_only(frames: dict[int, dict[str, Any]], frame: int) -> np.ndarray:
    now, before = frames[frame], frames[frame - 1]
    points = np.concatenate([now["position"], np.ones((HEIGHT, WIDTH, 1))], axis=-1)
    x, y, _ = motion.project(now["camera"], points)
    x_before, y_before, _ = motion.project(before["camera"], points)
    return np.stack([x_before - x, y_before - y], -1)


def test_moving_objects_follow_the_analytic_motion_and_the_vector_pass(
        static_camera: dict[str, Any]) -> None:
    _check_moving_objects(static_camera)


def test_static_surfaces_and_the_background_do_not_move(static_camera: dict[str, Any]) -> None:
    for frame in (2, 3):
        now = static_camera[frame]
        still = (now["index"] == FLOOR) | ~now["hit"]
        assert still.sum() > 0.5 * WIDTH * HEIGHT
        assert np.abs(now["motion"][still]).max() < 1e-4


def test_uncovered_pixels_are_invalid(static_camera: dict[str, Any]) -> None:
    for frame in (2, 3):
        now, before = static_camera[frame], static_camera[frame - 1]
        # The camera stands still: the floor or sky seen now was hidden by a moving object.
        static_now = (now["index"] == FLOOR) | ~now["hit"]
        uncovered = static_now & np.isin(before["index"], (MOVER, SPINNER, CHILD, POPPER))
        assert uncovered.sum() >= 10
        assert not now["valid"][uncovered].any()
        assert now["valid"][static_now & ~uncovered].mean() > 0.95


def test_fog_keeps_the_history_of_surfaces_behind_it(static_camera: dict[str, Any],
                                                     tmp_path: Any) -> None:
    """In fog, the sample at offset 0 of many pixels scatters before the floor and writes no
    depth; the later samples that reach the floor give it, so those pixels keep their history
    instead of being dropped at random."""
    fog = _run(False, tmp_path, fog_density=0.05)
    for frame in (2, 3):
        before, now = static_camera[frame - 1], static_camera[frame]  # the same frames, no fog
        floor = (now["index"] == FLOOR) & (before["index"] == FLOOR)
        assert floor.sum() > 0.3 * WIDTH * HEIGHT
        # The fog is thick enough that the first sample misses the floor in many pixels.
        assert (~fog[frame]["hit"][floor]).mean() > 0.2
        assert fog[frame]["valid"][floor].mean() > 0.95
        # A later sample may hit a mover at the floor's edge within the pixel.
        assert (np.abs(fog[frame]["motion"][floor]).max(axis=-1) < 1e-4).mean() > 0.99


def test_an_object_that_appears_has_no_history(static_camera: dict[str, Any]) -> None:
    appeared = static_camera[2]["index"] == POPPER
    assert appeared.sum() > 20 and not static_camera[2]["valid"][appeared].any()
    # One frame later it has a history (it does not move: camera-only motion, zero here).
    there = static_camera[3]["index"] == POPPER
    assert static_camera[3]["valid"][there].mean() > 0.9
    assert np.abs(static_camera[3]["motion"][there]).max() < 1e-4


def test_a_moving_camera_with_moving_objects(moving_camera: dict[str, Any]) -> None:
    _check_moving_objects(moving_camera)
    for frame in (2, 3):
        now = moving_camera[frame]
        hit = now["hit"] & ((now["index"] != POPPER) | (frame != 2))  # new: no Cycles motion
        assert np.abs(now["motion"] - now["vector"])[hit].max() < TOLERANCE_PX
        floor = now["index"] == FLOOR
        assert np.linalg.norm(now["motion"][floor], axis=-1).mean() > 0.3  # the camera moves


def _user_state(scene: Any) -> dict[str, Any]:
    layer = scene.view_layers[0]
    return {
        "materials": material_snapshot(),
        "aovs": [(a.name, a.type) for a in layer.aovs],
        "pass_index": {o.name: o.pass_index for o in bpy.data.objects},
        "passes": {name: getattr(layer, name) for name in dir(layer)
                   if name.startswith("use_pass_")},
        "denoising_passes": layer.cycles.denoising_store_passes,
        "motion_blur": scene.render.use_motion_blur,
        "persistent": scene.render.use_persistent_data,
    }


def test_user_materials_aovs_and_passes_are_restored_exactly(tmp_path: Any) -> None:
    scene = build_scene(False, tmp_path)
    layer = scene.view_layers[0]
    mine = layer.aovs.add()  # the user's own AOV, written by a node of their own
    mine.name, mine.type = "user_mask", "VALUE"
    tree = bpy.data.materials["Red"].node_tree
    info = tree.nodes.new("ShaderNodeObjectInfo")
    output = tree.nodes.new("ShaderNodeOutputAOV")
    output.aov_name = "user_mask"
    tree.links.new(info.outputs["Object Index"], output.inputs["Value"])
    layer.use_pass_object_index = True
    scene.render.use_motion_blur = True
    before = _user_state(scene)

    job = pipeline.DenoiseRender(scene, layer, [1, 2], pipeline.Settings(samples_per_frame=2))
    job.run()
    assert _user_state(scene) == before

    cancelled = pipeline.DenoiseRender(scene, layer, [1, 2], pipeline.Settings(samples_per_frame=2))
    steps = cancelled.steps()
    next(steps)
    steps.close()
    assert _user_state(scene) == before


def test_motion_blur_keeps_object_motion(tmp_path: Any) -> None:
    """With motion blur on, Cycles' Vector pass is zero; the hit point in object space does not
    depend on the shutter time, so the mover still gets its motion."""
    scene = build_scene(False, tmp_path)
    scene.render.use_motion_blur = True
    layer = scene.view_layers[0]

    def one_sample(s: Any) -> None:
        s.cycles.samples = 1
        layer.use_pass_z = layer.use_pass_object_index = layer.use_pass_vector = True
        layer.cycles.denoising_store_passes = True  # the Denoising Normal tells a volume apart

    geometry, captured = {}, {}
    with passes.shader_aovs(layer), materials.surface_aovs(bpy.data):
        for frame in (1, 2):
            scene.frame_set(frame)
            depsgraph = bpy.context.evaluated_depsgraph_get()
            captured[frame] = capture(scene, one_sample)
            names = {role: passes.PASS_NAMES[role][0]
                     for role in ("depth", "denoising_normal", "aov_distance", "aov_object",
                                  "aov_local")}
            geometry[frame] = pipeline.SequenceCapture._geometry(
                captured[frame], names, motion.scene_camera(scene, depsgraph),
                motion.object_transforms(depsgraph))
    assert not captured[2]["Vector"].any()
    ours, valid = motion.scene_motion(geometry[2], geometry[1])
    mover = _object_index(captured[2]) == MOVER
    # The mover moves along the camera's x axis: a point at planar depth z moves by
    # -STEP * focal length (pixels) / z, whatever the shutter time it was hit at.
    camera = bpy.data.cameras["Camera"]
    focal_px = camera.lens / camera.sensor_width * WIDTH
    expected = -STEP * focal_px / geometry[2].depth[mover]
    assert np.abs(ours[mover][:, 0] - expected).max() < TOLERANCE_PX
    assert np.abs(ours[mover][:, 1]).max() < TOLERANCE_PX
    assert valid[mover].mean() > 0.8


@pytest.mark.parametrize("camera_type", ["PERSP", "ORTHO"])
def test_view_distance_made_planar_is_the_z_pass(camera_type: str, tmp_path: Any) -> None:
    """A sample's View Distance AOV, made planar, equals its Z pass: how a later sample gives its
    depth to a pixel whose first sample scattered in fog."""
    scene = build_scene(False, tmp_path)
    scene.camera.data.type = camera_type
    scene.camera.data.ortho_scale = 8.0
    layer = scene.view_layers[0]

    def one_sample(s: Any) -> None:
        s.cycles.samples = 1
        layer.use_pass_z = True

    with passes.shader_aovs(layer), materials.surface_aovs(bpy.data):
        scene.frame_set(2)
        captured = capture(scene, one_sample)
        camera = motion.scene_camera(scene, bpy.context.evaluated_depsgraph_get())
    depth, distance = captured["Depth"][..., 0], captured[passes.AOV_DISTANCE][..., 0]
    both = (distance > 0) & (depth < motion.MISS_DEPTH)
    assert both.mean() > 0.2
    planar = motion.depth_from_distance(camera, distance)
    # Within 1e-3: the conversion takes the pixel centre's ray, the sample was jittered in it.
    np.testing.assert_allclose(planar[both], depth[both], rtol=1e-3)
    assert np.abs(distance[both] / depth[both] - 1.0).max() > 1e-3  # the conversion matters


def test_shared_keys_fall_back_to_camera_motion() -> None:
    """Two objects whose Object Info Random coincide cannot be told apart: their pixels keep
    the camera-only motion."""
    def instance(name: str, x: float) -> Any:
        matrix = np.eye(4)
        matrix[0, 3] = x
        return types.SimpleNamespace(object=types.SimpleNamespace(name=name, type="MESH"),
                                     is_instance=True, random_id=12345, matrix_world=matrix)

    table = motion.object_transforms(types.SimpleNamespace(
        object_instances=[instance("A", 0.0), instance("B", 1.0)]))
    assert len(table.keys) == 1 and table.ambiguous.all()
    camera = motion.Camera(np.eye(4), np.eye(4), 4, 3, True, 0.0)
    key = np.full((3, 4), motion.object_key(12345), np.float32)
    depth = np.full((3, 4), 1.0)
    geometry = motion.FrameGeometry(camera, depth, key, np.zeros((3, 4, 3)), table)
    moved = motion.object_transforms(types.SimpleNamespace(
        object_instances=[instance("A", 0.5), instance("B", 2.0)]))
    ours = motion.scene_motion(motion.FrameGeometry(camera, depth, key, np.zeros((3, 4, 3)), moved),
                               geometry)
    expected = motion.camera_motion(camera, depth, camera, depth)
    np.testing.assert_array_equal(ours[0], expected[0])
    np.testing.assert_array_equal(ours[1], expected[1])


def test_object_keys_match_the_object_info_random_value(tmp_path: Any) -> None:
    """The object table names every object and instance by the value Cycles' Object Info
    "Random" has on it, and its matrix takes the object-space AOV to Cycles' Position pass."""
    scene = build_scene(False, tmp_path)
    prototype = bpy.data.collections.new("Prototype")  # a collection instance ...
    holder = bpy.data.objects.new("Holder", None)
    holder.instance_type, holder.instance_collection = "COLLECTION", prototype
    holder.location, holder.rotation_euler = (0.4, -2.0, 1.2), (0.3, 0.2, 0.1)
    scene.collection.objects.link(holder)
    bpy.ops.mesh.primitive_cube_add(size=0.3)
    cube = bpy.context.object
    cube.data.materials.append(bpy.data.materials["Green"])
    for collection in cube.users_collection:
        collection.objects.unlink(cube)
    prototype.objects.link(cube)
    bpy.ops.mesh.primitive_plane_add(size=1.0, location=(-1.6, -2.5, 1.9))  # ... and dupli-verts
    grid = bpy.context.object
    grid.instance_type = "VERTS"
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.12, segments=8, ring_count=4)
    ball = bpy.context.object
    ball.data.materials.append(bpy.data.materials["Floor"])
    ball.parent = grid
    layer = scene.view_layers[0]

    def one_sample(s: Any) -> None:
        s.cycles.samples = 1
        layer.use_pass_position = True

    with passes.shader_aovs(layer), materials.surface_aovs(bpy.data):
        captured = capture(scene, one_sample)
    table = motion.object_transforms(bpy.context.evaluated_depsgraph_get())
    instances = {(i.parent.name, float(motion.object_key(i.random_id))) for i in
                 bpy.context.evaluated_depsgraph_get().object_instances if i.is_instance}
    key = captured[passes.AOV_OBJECT][..., 0]
    hit = captured[passes.AOV_DISTANCE][..., 0] > 0
    seen = set(np.unique(key[hit]).tolist())
    expected = {float(motion.object_key(motion.cycles_name_hash(name)))
                for name in ("Floor", "Mover", "Spinner", "Child")}
    assert expected <= seen and seen <= set(table.keys.tolist())
    assert {"Holder", "Plane"} <= {parent for parent, value in instances if value in seen}
    assert len(seen & {value for _, value in instances}) >= 3  # some balls are hidden
    assert not table.ambiguous.any()
    index = table.find(key[hit])
    assert (index >= 0).all()
    local = captured[passes.AOV_LOCAL][..., :3][hit].astype(np.float64)
    world = np.einsum("nij,nj->ni", table.matrices[index][:, :3, :3], local)
    world += table.matrices[index][:, :3, 3]
    assert np.abs(world - captured["Position"][..., :3][hit]).max() < 1e-5


def test_depth_slope_follows_a_ramp_and_ignores_edges() -> None:
    """On a plane whose depth grows 0.3 per column and 0.1 per row the slope is 0.4 everywhere;
    a step of 5 in depth does not widen it on either side, nor does a miss."""
    rows, cols = np.mgrid[0:6, 0:8]
    depth = 2.0 + 0.3 * cols + 0.1 * rows
    depth[:, 4:] += 5.0
    depth[0, 0] = 1.0e10
    miss = depth >= motion.MISS_DEPTH
    slope = motion.depth_slope(depth, miss)
    assert np.allclose(slope[~miss], 0.4)
    assert slope[0, 0] == 0.0

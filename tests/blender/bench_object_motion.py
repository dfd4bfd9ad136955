"""What following moving objects costs: one-sample sub-renders with and without the two motion
AOVs (object-space position, Object Info Random), and the object table plus the motion vectors.

    PYTHONPATH=build/python:blender_addon .venv-blender/bin/python tests/blender/bench_object_motion.py \
        [--sizes 64x48,320x240] [--spp 4] [--repeats 5] [--threads 2] [--instances 10000]

The two variants alternate within each repeat (same process, same scene settings as the
pipeline: persistent data, sample subsets, the feature passes). Prints, per size, the S
sub-renders' total in milliseconds, wall clock and CPU time of all threads: the fastest of the
repeats for each variant, and the median over the repeats of the ratio with / without within
a repeat (the pairing cancels most of the drift of a shared machine); then the per-frame cost of
``motion.object_transforms`` and of the vectors: ``motion.camera_motion`` (what the pipeline
computed before) and ``motion.scene_motion``. With ``--instances N``, also the object table of
the test scene plus N dupli-vert instances (a grid's vertices), and how many keys they share.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from typing import Any

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
sys.path[:0] = [HERE, os.path.join(ROOT, "blender_addon"), os.path.join(ROOT, "build", "python")]

import bpy  # noqa: E402
import scenes  # noqa: E402

import affinity_denoiser  # noqa: E402
from affinity_denoiser import materials, motion, passes, pipeline  # noqa: E402

_MOTION_AOVS = (passes.AOV_OBJECT, passes.AOV_LOCAL)
_MOTION_NODES = ("ShaderNodeObjectInfo", "ShaderNodeTexCoord")


def _drop_motion_aovs(layer: Any) -> None:
    """Takes the motion AOVs and their nodes out again (what the pipeline wrote before)."""
    for material in materials.editable_materials(bpy.data):
        nodes = material.node_tree.nodes
        for node in list(nodes):
            if not node.name.startswith(materials.NODE_PREFIX):
                continue
            if node.bl_idname in _MOTION_NODES or getattr(node, "aov_name", "") in _MOTION_AOVS:
                nodes.remove(node)
    for name in _MOTION_AOVS:
        layer.aovs.remove(layer.aovs[name])


def _sub_renders(width: int, height: int, spp: int, threads: int,
                 with_motion: bool) -> tuple[float, float, float, float, float]:
    """Seconds for S sub-renders of frame 2 (wall clock, and CPU time of all threads), for the
    object table, and for the camera-only and the object-following vectors."""
    scene = scenes.build_scene(width, height, frames=2, spp=spp, threads=threads)
    layer = scene.view_layers[0]
    settings = pipeline.Settings(samples_per_frame=spp)
    with pipeline.capture_setup(scene, layer, settings):
        job = pipeline.SequenceCapture(scene, layer, settings, pipeline.Timings())
        if not with_motion:
            _drop_motion_aovs(layer)
        geometry = {}
        for frame in (1, 2):
            scene.frame_set(frame)
            depsgraph = bpy.context.evaluated_depsgraph_get()
            start = time.perf_counter()
            transforms = motion.object_transforms(depsgraph)
            table = time.perf_counter() - start
            job.timings.sub_renders.clear()
            cpu = time.process_time()
            captured = [job._sub_render(sample) for sample in range(spp)]
            cpu = time.process_time() - cpu
            assert (passes.AOV_OBJECT in captured[0]) == with_motion
            if with_motion:
                names = passes.resolve(captured[0])
                camera = motion.scene_camera(scene, depsgraph)
                geometry[frame] = job._geometry(captured[0], names, camera, transforms)
        renders = sum(job.timings.sub_renders)
        camera_only = vectors = 0.0
        if with_motion:
            start = time.perf_counter()
            motion.camera_motion(geometry[2].camera, geometry[2].depth,
                                 geometry[1].camera, geometry[1].depth)
            camera_only = time.perf_counter() - start
            start = time.perf_counter()
            motion.scene_motion(geometry[2], geometry[1])
            vectors = time.perf_counter() - start
    return renders, cpu, table, camera_only, vectors


def _instances(count: int, repeats: int) -> None:
    scenes.build_scene(frames=1)
    side = max(1, round(count ** 0.5))
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=side, y_subdivisions=side, size=10.0)
    grid = bpy.context.object
    grid.instance_type = "VERTS"
    bpy.ops.mesh.primitive_cube_add(size=0.02)
    bpy.context.object.parent = grid
    depsgraph = bpy.context.evaluated_depsgraph_get()
    seconds = []
    for _ in range(repeats):
        start = time.perf_counter()
        table = motion.object_transforms(depsgraph)
        seconds.append(time.perf_counter() - start)
    print(f"object table of {len(table.keys)} keys ({len(grid.data.vertices)} instances): "
          f"{1000.0 * statistics.median(seconds):.1f} ms (median of {repeats}), "
          f"{int(table.ambiguous.sum())} keys shared by two or more")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sizes", default="64x48,320x240")
    parser.add_argument("--spp", type=int, default=4)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--instances", type=int, default=0)
    args = parser.parse_args()

    affinity_denoiser.register()
    print(f"bpy {bpy.app.version_string}, {args.threads} threads, {args.spp} one-sample "
          f"sub-renders of frame 2 of the test scene; {args.repeats} repeats, ms")
    print("size       min wall: without  with  ratio  paired  min cpu: without  with  ratio  "
          "paired   object_table  camera_motion  scene_motion")
    for size in args.sizes.split(","):
        width, height = (int(v) for v in size.split("x"))
        wall: dict[bool, list[float]] = {False: [], True: []}
        cpu: dict[bool, list[float]] = {False: [], True: []}
        table, camera_only, vectors = [], [], []
        for repeat in range(args.repeats):
            for with_motion in ((False, True) if repeat % 2 == 0 else (True, False)):
                renders, c, t, o, v = _sub_renders(width, height, args.spp, args.threads,
                                                   with_motion)
                wall[with_motion].append(renders)
                cpu[with_motion].append(c)
                if with_motion:
                    table.append(t)
                    camera_only.append(o)
                    vectors.append(v)
        columns = []
        for times in (wall, cpu):
            fastest = [1000.0 * min(times[False]), 1000.0 * min(times[True])]
            paired = statistics.median(w / wo for w, wo in zip(times[True], times[False]))
            columns.append(f"{fastest[0]:>17.1f} {fastest[1]:>5.1f} "
                           f"{fastest[1] / fastest[0]:>6.3f} {paired:>7.3f}")
        ms = [1000.0 * statistics.median(x) for x in (table, camera_only, vectors)]
        print(f"{size:<10} {columns[0]}  {columns[1]}"
              f"   {ms[0]:>12.2f}  {ms[1]:>13.2f}  {ms[2]:>12.2f}")
    if args.instances:
        _instances(args.instances, args.repeats)


if __name__ == "__main__":
    main()

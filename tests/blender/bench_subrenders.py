"""Timing of the Blender path: S one-sample sub-renders vs one S-sample render, pass access
in memory vs through a multilayer EXR, and what the features and the denoiser add.

    PYTHONPATH=build/python:blender_addon .venv-blender/bin/python tests/blender/bench_subrenders.py \
        [--sizes 64x48,640x480] [--spp 4] [--repeats 3] [--threads 2] [--triangles N]

--triangles adds a finely tessellated sphere of about N triangles to the test scene (the
issue's "about a million triangles" case: --sizes 960x540 --triangles 1000000).

Prints one line per size; every number is the median of the repeats, in milliseconds per frame.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
sys.path[:0] = [HERE, os.path.join(ROOT, "blender_addon"), os.path.join(ROOT, "build", "python")]

import bpy  # noqa: E402
import scenes  # noqa: E402

import affinity_denoiser  # noqa: E402
from affinity_denoiser import backend, engine, passes, pipeline  # noqa: E402


def _ms(seconds: list[float]) -> float:
    return 1000.0 * statistics.median(seconds)


def _full_render(scene: bpy.types.Scene, spp: int) -> float:
    """One ordinary Cycles render at spp samples with the same passes the pipeline uses."""
    layer = scene.view_layers[0]
    for name in ("use_pass_z", "use_pass_diffuse_direct", "use_pass_diffuse_indirect",
                 "use_pass_diffuse_color", "use_pass_emit"):
        setattr(layer, name, True)
    layer.cycles.denoising_store_passes = True
    scene.cycles.samples = spp
    start = time.perf_counter()
    bpy.ops.render.render()
    return time.perf_counter() - start


def _add_dense_mesh(triangles: int) -> int:
    """A UV sphere of about `triangles` triangles (2 x segments x rings), with a rough
    material, in front of the other objects. Returns its exact triangle count."""
    rings = max(3, int((triangles / 4) ** 0.5))
    segments = max(3, triangles // (2 * rings))
    bpy.ops.mesh.primitive_uv_sphere_add(segments=segments, ring_count=rings, radius=0.8,
                                         location=(0.0, 0.5, 0.8))
    obj = bpy.context.object
    material = bpy.data.materials.new("Dense")
    if material.node_tree is None:
        material.use_nodes = True
    obj.data.materials.append(material)
    mesh = obj.data
    mesh.calc_loop_triangles()
    return len(mesh.loop_triangles)


def _in_memory_vs_exr(scene: bpy.types.Scene, folder: str) -> tuple[float, float]:
    """One 1-spp render read in memory, and the same render written as a multilayer EXR
    (uncompressed, 32-bit float, every pass)."""
    scene.cycles.samples = 1
    scene.render.engine = engine.IDNAME
    captured = []
    engine.session.sink = lambda result: captured.append(passes.read_result(result))
    start = time.perf_counter()
    bpy.ops.render.render()
    memory = time.perf_counter() - start
    engine.session.sink = None
    scene.render.engine = "CYCLES"
    settings = scene.render.image_settings
    if hasattr(settings, "media_type"):  # Blender 5: choose the media type first
        settings.media_type = "MULTI_LAYER_IMAGE"
    settings.file_format = "OPEN_EXR_MULTILAYER"
    settings.color_depth = "32"
    settings.exr_codec = "NONE"
    scene.render.filepath = os.path.join(folder, "multilayer_")
    start = time.perf_counter()
    bpy.ops.render.render(write_still=True)
    exr = time.perf_counter() - start
    # Reading it back is not timed: in background mode bpy gives no pixels of a loaded
    # multilayer EXR, so that path would need another EXR reader on top.
    for name in os.listdir(folder):
        if name.startswith("multilayer_"):  # a still is saved without frame number
            os.remove(os.path.join(folder, name))
    if hasattr(settings, "media_type"):
        settings.media_type = "IMAGE"
    settings.file_format = "PNG"
    return memory, exr


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sizes", default="64x48,640x480")
    parser.add_argument("--spp", type=int, default=4)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--triangles", type=int, default=0)
    args = parser.parse_args()

    affinity_denoiser.register()
    problem = backend.core_status()
    if problem:
        backend.set_denoiser_factory(backend.MeanDenoiser)
    print(f"bpy {bpy.app.version_string}, {args.threads} threads, {args.spp} spp, "
          f"denoiser: {'stand-in (core unavailable)' if problem else 'affinity core'}")
    print("size       full_render  sub_renders(sum)  ratio  (pass_reads)  features  setup+motion  "
          "denoise  present+write  1spp_render_in_memory  1spp_render_write_multilayer_exr")
    for size in args.sizes.split(","):
        width, height = (int(v) for v in size.split("x"))
        full, subs, read, feats, other, denoise, present, memory, exr = ([] for _ in range(9))
        with tempfile.TemporaryDirectory() as folder:
            for _ in range(args.repeats):
                scene = scenes.build_scene(width, height, frames=1, spp=args.spp,
                                           threads=args.threads)
                if args.triangles:
                    count = _add_dense_mesh(args.triangles)
                    if len(full) == 0:
                        print(f"{size}: dense sphere of {count} triangles added")
                scene.render.filepath = os.path.join(folder, "render_")
                full.append(_full_render(scene, args.spp))
                job = pipeline.DenoiseRender(scene, scene.view_layers[0], [1],
                                             pipeline.Settings(samples_per_frame=args.spp))
                start = time.perf_counter()
                job.run()
                total = time.perf_counter() - start
                t = job.timings
                subs.append(sum(t.sub_renders))
                read.append(sum(t.read_passes))
                feats.append(sum(t.features))
                denoise.append(sum(t.denoise))
                present.append(sum(t.present) + sum(t.write))
                other.append(total - subs[-1] - feats[-1] - denoise[-1] - present[-1])
                m, e = _in_memory_vs_exr(scene, folder)
                memory.append(m)
                exr.append(e)
        print(f"{size:<10} {_ms(full):>11.1f}  {_ms(subs):>16.1f}  {_ms(subs) / _ms(full):>5.2f}"
              f"  {_ms(read):>12.1f}  {_ms(feats):>8.1f}  {_ms(other):>12.1f}"
              f"  {_ms(denoise):>7.1f}  {_ms(present):>13.1f}"
              f"  {_ms(memory):>21.1f}  {_ms(exr):>32.1f}")


if __name__ == "__main__":
    main()

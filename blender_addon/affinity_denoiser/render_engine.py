"""The "Cycles + Affinity Denoiser" render engine: Blender's ordinary render buttons and command
line (F12, Ctrl+F12, ``blender -b scene.blend -a``) give denoised frames.

Chosen in Render Properties like Cycles, it is Cycles everywhere but in final renders: the
viewport, material previews and every Cycles panel are Cycles' own. A final render of a frame
is done by a worker process (render_job.py): S one-sample sub-renders, denoised with the
sequence's history, whose passes fill Blender's render result. Blender then composites and
writes the frame as usual: its output path and format, frame numbering, placeholders and
overwrite settings, progress and Esc. An animation keeps one worker, and so one history, from
its first frame to its last.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from typing import Any

from . import engine, frame_claims, pipeline, render_job

IDNAME = engine.DENOISING_ENGINE

_engine_class: type | None = None
#: The workers of the render job under way, one per (scene, view layer).
_jobs: dict[tuple[str, str], render_job.RenderJob] = {}
#: The copy of an unsaved or modified file that the render job's workers open (one for all its
#: view layers), removed with them: its folder and path.
_copy: tuple[str, str] | None = None


def close_jobs(*_: Any) -> None:
    """Stops every worker (a render job has ended or a new one begins)."""
    global _copy
    while _jobs:
        _, job = _jobs.popitem()
        job.close()
    if _copy is not None:
        shutil.rmtree(_copy[0], ignore_errors=True)
        _copy = None


def _blend_for_worker() -> str:
    """The .blend a worker opens: the open file when it is saved as it is, else a copy of the
    data as it is now (a render started from a script that changed it)."""
    global _copy
    import bpy

    if bpy.data.filepath and not bpy.data.is_dirty:
        return bpy.data.filepath
    if _copy is None:
        folder = tempfile.mkdtemp(prefix="affinity-blend-")
        path = os.path.join(folder, os.path.basename(bpy.data.filepath) or "untitled.blend")
        _copy = (folder, path)
        # Every scene with what it uses; relative paths (textures, caches) made absolute, since
        # the copy lives elsewhere.
        bpy.data.libraries.write(path, set(bpy.data.scenes), path_remap="ABSOLUTE")
    return _copy[1]


def _job(scene: Any, view_layer: Any) -> render_job.RenderJob:
    import bpy

    key = (scene.name, view_layer.name)
    job = _jobs.get(key)
    if job is None:
        settings = scene.affinity_denoiser
        job = render_job.RenderJob(
            _blend_for_worker(), scene.name, view_layer.name,
            render_job.JobSettings(pipeline.Settings.from_properties(settings),
                                   warmup_frames=settings.warmup_frames,
                                   saved_blend=bpy.data.filepath))
        _jobs[key] = job
    return job


def _crop(image: Any, scene: Any, width: int, height: int) -> Any:
    """The part of a whole-frame ``image`` a border render with Crop asks for."""
    full_height, full_width = image.shape[:2]
    if (width, height) == (full_width, full_height):
        return image
    render = scene.render
    x0 = round(render.border_min_x * full_width)
    y0 = round(render.border_min_y * full_height)  # from the bottom, as Blender counts
    top = full_height - y0 - height
    if not render.use_border or x0 + width > full_width or top < 0:
        raise RuntimeError(f"the render result is {width}x{height}, the frame "
                           f"{full_width}x{full_height}: no border explains it")
    return image[top:top + height, x0:x0 + width]


def _render_final(engine_instance: Any, depsgraph: Any) -> None:
    scene, view_layer = depsgraph.scene, depsgraph.view_layer
    width, height = engine_instance.resolution_x, engine_instance.resolution_y
    job = _job(scene, view_layer)

    def progress(fraction: float, text: str) -> None:
        engine_instance.update_progress(fraction)
        engine_instance.update_stats("Affinity Denoiser", text)

    result = engine_instance.begin_result(0, 0, width, height, layer=view_layer.name)
    cancelled = True
    try:
        names = [render_pass.name for render_pass in result.layers[0].passes]
        images = job.render(scene.frame_current, names, progress, engine_instance.test_break)
        if images is None:  # Esc: the worker is stopped, Blender ends the job
            _jobs.pop((scene.name, view_layer.name), None)
            return
        engine.fill_passes(result, {name: _crop(image, scene, width, height)
                                    for name, image in images.items()}, width, height)
        cancelled = False
    finally:
        engine_instance.end_result(result, cancel=cancelled)


def _hooks(cycles_methods: dict[str, Any]) -> engine.Hooks:
    def update(self: Any, data: Any, depsgraph: Any) -> None:
        # A final render's scene is synced by the worker's Cycles, not here.
        if self.is_preview:
            cycles_methods["update"](self, data, depsgraph)

    def render(self: Any, depsgraph: Any) -> None:
        if self.is_preview:
            cycles_methods["render"](self, depsgraph)
            return
        if frame_claims.frame_lost():  # another process renders this frame
            return
        try:
            _render_final(self, depsgraph)
        except Exception as exc:  # the boundary: Blender shows the message and stops
            close_jobs()
            message = f"Affinity Denoiser: {exc}"
            self.report({"ERROR"}, message)
            self.error_set(message)

    def render_frame_finish(self: Any) -> None:
        if self.is_preview:
            cycles_methods["render_frame_finish"](self)

    return {"update": update, "render": render, "render_frame_finish": render_frame_finish}


def _cycles_panels() -> list[Any]:
    """Every panel (Cycles' and Blender's) shown for Cycles: they are shown for this engine."""
    import bpy

    panels = []
    for panel in bpy.types.Panel.__subclasses__():
        compatible = getattr(panel, "COMPAT_ENGINES", None)
        if isinstance(compatible, set) and "CYCLES" in compatible:
            panels.append(panel)
    return panels


#: (handler list, function): workers end with their render job; frames are claimed.
_HANDLERS = (("render_init", close_jobs), ("render_complete", close_jobs),
             ("render_cancel", close_jobs), *frame_claims.HANDLERS)


def register() -> None:
    global _engine_class
    import bpy

    if _engine_class is None:
        _engine_class = engine.cycles_based_engine(
            "AffinityDenoiserEngine", IDNAME, "Cycles + Affinity Denoiser",
            "Cycles, each final frame denoised by the Affinity Denoiser.", _hooks)
    bpy.utils.register_class(_engine_class)
    for panel in _cycles_panels():
        panel.COMPAT_ENGINES.add(IDNAME)
    for name, function in _HANDLERS:
        bpy.app.handlers.persistent(function)  # kept when a file is loaded
        getattr(bpy.app.handlers, name).append(function)


def unregister() -> None:
    global _engine_class
    import bpy

    close_jobs()
    for name, function in _HANDLERS:
        handlers = getattr(bpy.app.handlers, name)
        if function in handlers:
            handlers.remove(function)
    for panel in _cycles_panels():
        panel.COMPAT_ENGINES.discard(IDNAME)
    if _engine_class is not None:
        bpy.utils.unregister_class(_engine_class)
        _engine_class = None

"""Operators: denoise-render the current frame or the whole animation.

From a script or ``blender -b``: ``bpy.ops.affinity_denoiser.render_animation()`` runs to the
end (``execute``). From the user interface the operator runs modally, one sub-render per timer
tick, so the progress bar moves and Esc cancels between sub-renders.
"""

from __future__ import annotations

import sys
from typing import Any

import bpy

from .pipeline import DenoiseRender, Settings


def _console(text: str) -> None:
    print(f"affinity_denoiser: {text}", file=sys.stdout, flush=True)


class _DenoiseRenderBase:
    bl_options = {"REGISTER"}

    _job: DenoiseRender | None = None
    _steps: Any = None
    _timer: Any = None

    def frames(self, scene: Any) -> list[int]:
        raise NotImplementedError

    @classmethod
    def poll(cls, context: Any) -> bool:
        return context.scene is not None and context.scene.render.engine == "CYCLES"

    def _make_job(self, context: Any) -> DenoiseRender:
        scene = context.scene
        wm = context.window_manager

        def progress(done: int, total: int, text: str) -> None:
            wm.progress_update(done)
            _console(f"{text} [{done}/{total} sub-renders]")

        return DenoiseRender(scene, context.view_layer, self.frames(scene),
                             Settings.from_properties(scene.affinity_denoiser), progress)

    def _fail(self, exc: BaseException) -> set[str]:
        message = str(exc) or type(exc).__name__
        _console(f"error: {message}")
        self.report({"ERROR"}, message)
        return {"CANCELLED"}

    def _succeed(self, job: DenoiseRender) -> set[str]:
        message = f"denoised {len(job.results)} frame(s) into {job.folder}"
        _console(message)
        self.report({"INFO"}, message)
        return {"FINISHED"}

    def execute(self, context: Any) -> set[str]:
        wm = context.window_manager
        try:
            job = self._make_job(context)
            wm.progress_begin(0, job.total_steps)
            try:
                job.run()
            finally:
                wm.progress_end()
        except Exception as exc:  # the boundary: every failure becomes a report
            return self._fail(exc)
        return self._succeed(job)

    def invoke(self, context: Any, event: Any) -> set[str]:
        if bpy.app.background or context.window is None:
            return self.execute(context)
        try:
            self._job = self._make_job(context)
            self._steps = self._job.steps()
        except Exception as exc:
            return self._fail(exc)
        context.window_manager.progress_begin(0, self._job.total_steps)
        self._timer = context.window_manager.event_timer_add(0.01, window=context.window)
        context.window_manager.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def _stop(self, context: Any) -> None:
        wm = context.window_manager
        if self._timer is not None:
            wm.event_timer_remove(self._timer)
            self._timer = None
        if self._steps is not None:
            self._steps.close()  # runs the pipeline's finally blocks: everything restored
            self._steps = None
        wm.progress_end()

    def modal(self, context: Any, event: Any) -> set[str]:
        if event.type == "ESC":
            self._stop(context)
            self.report({"WARNING"}, "denoise-render cancelled")
            return {"CANCELLED"}
        if event.type != "TIMER":
            return {"RUNNING_MODAL"}  # like Blender's own render: no edits while rendering
        try:
            next(self._steps)
        except StopIteration:
            self._steps = None
            self._stop(context)
            return self._succeed(self._job)
        except Exception as exc:
            self._steps = None
            self._stop(context)
            return self._fail(exc)
        return {"RUNNING_MODAL"}


class AFFINITY_DENOISER_OT_render_frame(_DenoiseRenderBase, bpy.types.Operator):
    """Render the current frame with Cycles and denoise it with the Affinity Denoiser"""

    bl_idname = "affinity_denoiser.render_frame"
    bl_label = "Denoise-Render Frame"

    def frames(self, scene: Any) -> list[int]:
        return [scene.frame_current]


class AFFINITY_DENOISER_OT_render_animation(_DenoiseRenderBase, bpy.types.Operator):
    """Render the animation with Cycles and denoise it as a sequence (temporal history)"""

    bl_idname = "affinity_denoiser.render_animation"
    bl_label = "Denoise-Render Animation"

    def frames(self, scene: Any) -> list[int]:
        return list(range(scene.frame_start, scene.frame_end + 1, max(1, scene.frame_step)))


classes = (AFFINITY_DENOISER_OT_render_frame, AFFINITY_DENOISER_OT_render_animation)


def register() -> None:
    for cls in classes:
        bpy.utils.register_class(cls)


def unregister() -> None:
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)

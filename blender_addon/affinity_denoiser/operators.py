"""Operators: denoise-render the current frame or the whole animation.

From a script or ``blender -b``: ``bpy.ops.affinity_denoiser.render_animation()`` runs to the
end (``execute``). From the user interface the operator runs modally, one sub-render per timer
tick, so the progress bar moves and Esc cancels between sub-renders.

With another engine than Cycles the poll fails with a message saying so (and ``execute``, run
anyway, reports it). Where the frames went is in the report and, for scripts, in
``scene.affinity_denoiser.last_output_folder`` (also after an error or a cancel, when frames
were written).
"""

from __future__ import annotations

import sys
from typing import Any

import bpy

from .pipeline import DenoiseRender, Settings, cycles_problem
from .properties import record_output_folder


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
        if context.scene is None:
            return False
        problem = cycles_problem(context.scene)
        if problem:
            # Blender shows it in the button's tooltip and in the error of bpy.ops calls.
            cls.poll_message_set(problem)
            return False
        return True

    def _make_job(self, context: Any) -> DenoiseRender:
        scene = context.scene
        wm = context.window_manager
        problem = cycles_problem(scene)
        if problem:
            raise RuntimeError(problem)

        def progress(done: int, total: int, text: str) -> None:
            wm.progress_update(done)
            _console(f"{text} [{done}/{total} sub-renders]")

        return DenoiseRender(scene, context.view_layer, self.frames(scene),
                             Settings.from_properties(scene.affinity_denoiser), progress)

    @staticmethod
    def _where(job: DenoiseRender | None) -> str:
        """Records and describes where the run wrote its frames; empty when it wrote none."""
        if job is None or not job.results:
            return ""
        record_output_folder(job.scene, job.folder)
        where = f"{len(job.results)} frame(s) into {job.folder}"
        if job.folder != job.base_folder:
            where += (f" ({job.base_folder} has files of these frames already; nothing was "
                      "overwritten)")
        return where

    def _fail(self, exc: BaseException, job: DenoiseRender | None = None) -> set[str]:
        message = str(exc) or type(exc).__name__
        where = self._where(job)
        if where:
            message += f"; finished: {where}"
        _console(f"error: {message}")
        self.report({"ERROR"}, message)
        return {"CANCELLED"}

    def _succeed(self, job: DenoiseRender) -> set[str]:
        message = f"denoised {self._where(job)}"
        _console(message)
        self.report({"INFO"}, message)
        return {"FINISHED"}

    def execute(self, context: Any) -> set[str]:
        wm = context.window_manager
        job = None
        try:
            job = self._make_job(context)
            wm.progress_begin(0, job.total_steps)
            try:
                job.run()
            finally:
                wm.progress_end()
        except Exception as exc:  # the boundary: every failure becomes a report
            return self._fail(exc, job)
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
            where = self._where(self._job)
            self.report({"WARNING"}, "denoise-render cancelled" +
                        (f"; finished: {where}" if where else ""))
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
            return self._fail(exc, self._job)
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

"""The Affinity Denoiser panel in Render Properties (shown when Cycles is the engine): the
settings, the two buttons, and where the last run wrote its frames."""

from __future__ import annotations

from typing import Any

import bpy

from . import backend, engine


class AFFINITY_DENOISER_PT_render(bpy.types.Panel):
    bl_label = "Affinity Denoiser"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "render"
    bl_options = {"DEFAULT_CLOSED"}

    @classmethod
    def poll(cls, context: Any) -> bool:
        return context.scene is not None and context.scene.render.engine in (
            "CYCLES", engine.DENOISING_ENGINE)

    def draw(self, context: Any) -> None:
        settings = context.scene.affinity_denoiser
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        column = layout.column()
        column.prop(settings, "samples_per_frame")
        column.prop(settings, "model_path")
        column.prop(settings, "precision")
        column.prop(settings, "temporal")
        column.prop(settings, "warmup_frames")
        column.prop(settings, "preroll_frames")
        column.prop(settings, "preroll_samples")
        column.prop(settings, "output_folder")
        column.prop(settings, "keep_sample_frames")
        problem = backend.core_status()
        if problem:
            layout.label(text="Core missing: see the console", icon="ERROR")
        row = layout.row(align=True)
        row.enabled = not problem
        row.operator("affinity_denoiser.render_frame", icon="RENDER_STILL")
        row.operator("affinity_denoiser.render_animation", icon="RENDER_ANIMATION")
        if settings.last_output_folder:
            layout.label(text=f"Last output: {settings.last_output_folder}", icon="FILE_FOLDER")


def register() -> None:
    bpy.utils.register_class(AFFINITY_DENOISER_PT_render)


def unregister() -> None:
    bpy.utils.unregister_class(AFFINITY_DENOISER_PT_render)

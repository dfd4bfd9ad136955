"""The Affinity Denoiser panel in Render Properties (shown when Cycles is the engine)."""

from __future__ import annotations

from typing import Any

import bpy

from . import backend


class AFFINITY_DENOISER_PT_render(bpy.types.Panel):
    bl_label = "Affinity Denoiser"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "render"
    bl_options = {"DEFAULT_CLOSED"}

    @classmethod
    def poll(cls, context: Any) -> bool:
        return context.scene is not None and context.scene.render.engine == "CYCLES"

    def draw_header(self, context: Any) -> None:
        self.layout.prop(context.scene.affinity_denoiser, "enabled", text="")

    def draw(self, context: Any) -> None:
        settings = context.scene.affinity_denoiser
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        column = layout.column()
        column.active = settings.enabled
        column.prop(settings, "samples_per_frame")
        column.prop(settings, "model_path")
        column.prop(settings, "fast_arithmetic")
        column.prop(settings, "temporal")
        column.prop(settings, "output_folder")
        column.prop(settings, "keep_sample_frames")
        problem = backend.core_status()
        if problem:
            layout.label(text="Core missing: see the console", icon="ERROR")
        row = layout.row(align=True)
        row.enabled = settings.enabled and not problem
        row.operator("affinity_denoiser.render_frame", icon="RENDER_STILL")
        row.operator("affinity_denoiser.render_animation", icon="RENDER_ANIMATION")


def register() -> None:
    bpy.utils.register_class(AFFINITY_DENOISER_PT_render)


def unregister() -> None:
    bpy.utils.unregister_class(AFFINITY_DENOISER_PT_render)

"""Settings of the Affinity Denoiser, stored on the scene (``scene.affinity_denoiser``)."""

from __future__ import annotations

import bpy

from .pipeline import MAX_SAMPLES_PER_FRAME


class AffinityDenoiserSettings(bpy.types.PropertyGroup):
    enabled: bpy.props.BoolProperty(
        name="Affinity Denoiser",
        description="Denoise renders with the Affinity Denoiser (Render > Denoise-Render)",
        default=False,
    )
    samples_per_frame: bpy.props.IntProperty(
        name="Samples per Frame",
        description="One-sample sub-renders per frame, each a separate set of features",
        default=4,
        min=1,
        max=MAX_SAMPLES_PER_FRAME,
    )
    model_path: bpy.props.StringProperty(
        name="Model",
        description="Weights file (.affw) of the denoiser; empty for the built-in model",
        default="",
        subtype="FILE_PATH",
    )
    fast_arithmetic: bpy.props.BoolProperty(
        name="Fast Arithmetic",
        description="Compute the network's products in bfloat16 on CPUs with AVX512-BF16 (Zen 4, "
        "Sapphire Rapids and later): about a fifth faster, the same quality within 0.5 %; other CPUs "
        "compute in full precision",
        default=False,
    )
    temporal: bpy.props.BoolProperty(
        name="Temporal",
        description="Carry history from frame to frame (stable animation); off denoises "
        "each frame alone",
        default=True,
    )
    output_folder: bpy.props.StringProperty(
        name="Output Folder",
        description="Folder for denoised frames; empty for 'affinity_denoised' beside the "
        "render output",
        default="",
        subtype="DIR_PATH",
    )
    keep_sample_frames: bpy.props.BoolProperty(
        name="Keep Sample Frames",
        description="Also write each frame's per-sample features (affinity frame files)",
        default=False,
    )


def register() -> None:
    bpy.utils.register_class(AffinityDenoiserSettings)
    bpy.types.Scene.affinity_denoiser = bpy.props.PointerProperty(type=AffinityDenoiserSettings)


def unregister() -> None:
    del bpy.types.Scene.affinity_denoiser
    bpy.utils.unregister_class(AffinityDenoiserSettings)

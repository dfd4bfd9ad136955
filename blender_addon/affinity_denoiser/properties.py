"""Settings of the Affinity Denoiser, stored on the scene (``scene.affinity_denoiser``).

There is no on / off switch: the engine "Cycles + Affinity Denoiser" denoises every final
render (F12, ``-a``), and the panel's buttons (the operators) denoise-render with either
engine. ``last_output_folder`` (read-only) tells a script where the last denoise-render of the
scene wrote its frames.
"""

from __future__ import annotations

from typing import Any

import bpy

from .pipeline import (
    AUTO_PREROLL_SAMPLES,
    DEFAULT_PREROLL_FRAMES,
    MAX_PREROLL_FRAMES,
    MAX_PREROLL_SAMPLES,
    MAX_SAMPLES_PER_FRAME,
)

#: Where ``last_output_folder``'s value is kept (an ID property of the settings, saved with the
#: .blend); the property itself has a getter only, so that scripts cannot set it.
_LAST_OUTPUT_KEY = "_last_output_folder"


def _last_output_folder(settings: Any) -> str:
    return str(settings.get(_LAST_OUTPUT_KEY, ""))


def record_output_folder(scene: Any, folder: str) -> None:
    """Remembers where a denoise-render of ``scene`` wrote its frames."""
    scene.affinity_denoiser[_LAST_OUTPUT_KEY] = folder


class AffinityDenoiserSettings(bpy.types.PropertyGroup):
    samples_per_frame: bpy.props.IntProperty(
        name="Samples per Frame",
        description="One-sample sub-renders per frame, each a separate set of features",
        default=4,
        min=1,
        max=MAX_SAMPLES_PER_FRAME,
    )
    model_path: bpy.props.StringProperty(
        name="Model",
        description="Weights file (.affw) of the denoiser; empty for the Cycles model that comes with the extension",
        default="",
        subtype="FILE_PATH",
    )
    # The name and values of the CLI's --precision and Python's precision= (affinity/precision.h).
    # Replaces the boolean "Fast Arithmetic": a .blend that stored it on gets "auto", which is
    # what it meant; one that stored it off gets the new default, auto.
    precision: bpy.props.EnumProperty(
        name="Precision",
        description="Arithmetic of the network's products",
        items=[
            ("auto", "Auto", "bfloat16 on CPUs with AVX512-BF16 (Zen 4, Sapphire Rapids and later): "
             "faster, the same quality to the fourth digit; FP32 on other CPUs, so the file renders anywhere"),
            ("fp32", "FP32", "Full precision on every CPU: the same bits on every machine"),
        ],
        default="auto",
    )
    temporal: bpy.props.BoolProperty(
        name="Temporal",
        description="Carry history from frame to frame (stable animation); off denoises "
        "each frame alone",
        default=True,
    )
    warmup_frames: bpy.props.IntProperty(
        name="Warm-up Frames",
        description="With the Cycles + Affinity Denoiser engine, a render that starts after "
        "the animation's first frame (a render farm's chunk, or F12 on a later frame) first "
        "renders up to this many frames before it, not saved, so that its history matches an "
        "uninterrupted render of the whole animation",
        default=8,
        min=0,
        max=64,
    )
    preroll_frames: bpy.props.IntProperty(
        name="Pre-roll Frames",
        description="The first frame of a sequence has no history: before it, render it this "
        "many more times with other samples, not saved, so that it starts with one. Costs "
        "this many frames' render time once per sequence",
        default=DEFAULT_PREROLL_FRAMES,
        min=0,
        max=MAX_PREROLL_FRAMES,
    )
    preroll_samples: bpy.props.IntProperty(
        name="Pre-roll Samples",
        description="Samples of each pre-roll frame: more give the first frame a cleaner "
        "history. 0: automatic, 8 times the samples per frame (16 to 64)",
        default=AUTO_PREROLL_SAMPLES,
        min=0,
        max=MAX_PREROLL_SAMPLES,
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
    last_output_folder: bpy.props.StringProperty(
        name="Last Output Folder",
        description="Where the last denoise-render of this scene wrote its frames (read-only; "
        "empty before the first). The Output Folder, or a new folder beside it with a number "
        "when it had files of the same frames already",
        get=_last_output_folder,
    )


def register() -> None:
    bpy.utils.register_class(AffinityDenoiserSettings)
    bpy.types.Scene.affinity_denoiser = bpy.props.PointerProperty(type=AffinityDenoiserSettings)


def unregister() -> None:
    del bpy.types.Scene.affinity_denoiser
    bpy.utils.unregister_class(AffinityDenoiserSettings)

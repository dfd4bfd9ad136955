"""Cycles passes of one sample -> the 18 per-sample features of docs/FEATURES.md.

Each choice, and where Cycles cannot give a feature exactly as our renderer defines it, is
documented in docs/BLENDER.md ("Feature mapping").
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .motion import Camera

FEATURE_COUNT = 18
# Channel offsets, in the order of docs/FEATURES.md.
DIFFUSE, SPECULAR, NORMAL, DEPTH, ALBEDO = 0, 3, 6, 9, 10
ROUGHNESS, EMISSIVE, METALLIC, TRANSMISSIVE, SPECULAR_BOUNCE = 13, 14, 15, 16, 17
#: kRoughnessFloor in core/include/affinity/features.h.
ROUGHNESS_FLOOR = 0.02
#: Cycles' denoising normal is in its camera space, whose Z axis points forward.
_CYCLES_CAMERA_TO_BLENDER_CAMERA = np.diag([1.0, 1.0, -1.0])
#: From this Blender version on Cycles measures its denoising depth from the eye; before it, from
#: where the camera ray starts (the near plane). docs/BLENDER.md, "Blender versions".
DENOISING_DEPTH_FROM_EYE_FROM = (5, 3, 0)
#: The path went past its first hit when the denoising depth exceeds the hit's distance by this
#: fraction (both are float32 sums of the same segments).
_BOUNCE_TOLERANCE = 1e-3


def denoising_depth_from_eye() -> bool:
    """Whether this Blender's Cycles measures the Denoising Depth pass from the eye."""
    import bpy

    return bpy.app.version >= DENOISING_DEPTH_FROM_EYE_FROM


def sample_features(p: dict[str, np.ndarray], camera: Camera, ray_start: np.ndarray) -> np.ndarray:
    """The (H, W, 18) float32 features of one sample from its passes keyed by role.

    ``ray_start`` is ``motion.ray_start_distance(camera)``: Cycles measures its denoising depth
    from the near plane before ``DENOISING_DEPTH_FROM_EYE_FROM``, the schema from the eye.
    Computed channel by channel into planar storage (twice as fast as working on the interleaved
    layout); the result is a view.
    """
    height, width = p["combined"].shape[:2]
    out = np.empty((FEATURE_COUNT, height, width), np.float32)

    def channel(role: str, c: int) -> np.ndarray:
        return p[role][..., c]

    # Radiance: Cycles' light passes are stored divided by their colour pass.
    for c in range(3):
        diffuse = out[DIFFUSE + c]
        np.add(channel("diffuse_direct", c), channel("diffuse_indirect", c), out=diffuse)
        diffuse *= channel("diffuse_color", c)
        specular = out[SPECULAR + c]
        np.subtract(channel("combined", c), diffuse, out=specular)
        np.maximum(specular, 0.0, out=specular)

    # v is where Cycles wrote its denoising features: the first hit that is not (near) specular.
    n = [channel("denoising_normal", c) for c in range(3)]
    length = np.sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2])
    reached_v = length > 0.5
    rotation = (camera.camera_to_world[:3, :3] @ _CYCLES_CAMERA_TO_BLENDER_CAMERA).astype(np.float32)
    scale = np.where(reached_v, 1.0 / np.maximum(length, 1e-12), 0.0).astype(np.float32)
    for row in range(3):
        normal = out[NORMAL + row]
        np.multiply(n[0], rotation[row, 0], out=normal)
        normal += n[1] * rotation[row, 1]
        normal += n[2] * rotation[row, 2]
        normal *= scale

    first_distance = p["aov_distance"][..., 0]
    has_surface_aov = first_distance > 0.0
    emission = p["emission"]  # (max over the last axis of a strided view is slow in numpy)
    emitter_first = np.maximum(np.maximum(emission[..., 0], emission[..., 1]), emission[..., 2]) > 0
    # Nothing with a BSDF was reached and the first hit does not emit: the path escaped
    # (directly or through mirrors / clear glass).
    miss = ~reached_v & ~emitter_first

    if "denoising_depth" in p:
        denoising_depth = p["denoising_depth"][..., 0]
        start = 0.0 if denoising_depth_from_eye() else ray_start
        # A direct miss: 0 up to 5.1, the largest float32 in 5.2 (which must not reach a sum),
        # about the far clip distance in 5.3 (left to the miss test below).
        reached = (denoising_depth > 0.0) & (denoising_depth < np.finfo(np.float32).max)
        path_length = np.where(reached, denoising_depth, 0.0) + np.where(reached, start, 0.0)
    else:  # Cycles without a denoising depth pass: the first hit's distance
        path_length = first_distance
    out[DEPTH] = np.where(miss, 0.0, path_length)

    for c in range(3):
        albedo = out[ALBEDO + c]
        np.clip(channel("denoising_albedo", c), 0.0, 1.0, out=albedo)
        albedo *= reached_v

    surface = p["aov_surface"]
    roughness = np.where(has_surface_aov, np.clip(surface[..., 0], ROUGHNESS_FLOOR, 1.0), 1.0)
    out[ROUGHNESS] = np.where(miss, 0.0, roughness)
    out[EMISSIVE] = miss | emitter_first
    out[METALLIC] = ~miss & has_surface_aov & (surface[..., 1] > 0.5)
    out[TRANSMISSIVE] = has_surface_aov & (surface[..., 2] > 0.5)

    went_on = path_length > first_distance * (1.0 + _BOUNCE_TOLERANCE) + 1e-4
    out[SPECULAR_BOUNCE] = has_surface_aov & (went_on | miss)
    return out.transpose(1, 2, 0)


def frame_dict(
    samples: np.ndarray | None,
    motion: np.ndarray,
    valid: np.ndarray,
    camera: Camera,
    scene_name: str,
    frame_index: int,
    seed: int,
) -> dict[str, Any]:
    """A frame in the layout of affinity_core.read_frame / write_frame (docs/FRAME_FILES.md);
    samples None when they were streamed to the denoiser instead."""
    return {
        "samples": None if samples is None else np.ascontiguousarray(samples, dtype=np.float32),
        "motion": np.ascontiguousarray(motion, dtype=np.float32),
        "valid": np.ascontiguousarray(valid, dtype=np.float32),
        "reference": None,
        "info": {
            "scene_name": scene_name,
            "frame_index": int(frame_index),
            "reference_spp": 0,
            "seed": int(seed) & 0xFFFFFFFFFFFFFFFF,
            "world_to_camera": camera.world_to_camera.astype(np.float32),
            "camera_to_clip": camera.camera_to_clip.astype(np.float32),
        },
    }

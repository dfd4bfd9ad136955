"""Camera matrices, per-pixel camera rays, and camera-motion vectors with history validity.

Cycles' Vector pass forces a full re-sync of the scene on every render when persistent data
is on, and is all zero when motion blur is on, so motion is computed here from the camera
matrices of consecutive frames and the depth of the sample at offset 0 (Cycles writes its
Z pass only for that sample). Only camera motion is captured; see docs/BLENDER.md.

Conventions are those of docs/FRAME_FILES.md: matrices act on column vectors, the camera looks
down -Z with +Y up (Blender's and OpenGL's convention), pixels are x right, y down.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

#: Cycles writes this depth (and larger) where a camera ray hits nothing.
MISS_DEPTH = 1.0e9
#: A reprojected point is "still visible" when the previous depth agrees within this fraction.
DEPTH_TOLERANCE = 0.02


class CameraError(RuntimeError):
    """The camera cannot be handled (e.g. a panoramic camera)."""


@dataclass
class Camera:
    """One frame's camera: float64 matrices plus what is needed to build pixel rays."""

    world_to_camera: np.ndarray  # (4, 4)
    camera_to_clip: np.ndarray  # (4, 4)
    width: int
    height: int
    orthographic: bool
    clip_start: float

    @property
    def camera_to_world(self) -> np.ndarray:
        return np.linalg.inv(self.world_to_camera)


def render_size(scene: Any) -> tuple[int, int]:
    render = scene.render
    scale = render.resolution_percentage / 100.0
    return int(render.resolution_x * scale), int(render.resolution_y * scale)


def scene_camera(scene: Any, depsgraph: Any) -> Camera:
    """The scene camera at the current frame, as the renderer sees it."""
    camera_object = scene.camera
    if camera_object is None:
        raise CameraError("the scene has no camera")
    evaluated = camera_object.evaluated_get(depsgraph)
    camera_data = evaluated.data
    if camera_data.type not in ("PERSP", "ORTHO"):
        raise CameraError(f"camera type {camera_data.type} is not supported "
                          "(perspective and orthographic only)")
    width, height = render_size(scene)
    matrix = np.array(evaluated.matrix_world, dtype=np.float64)
    # The renderer ignores the camera object's scale: take the rotation and translation only.
    matrix[:3, :3] /= np.linalg.norm(matrix[:3, :3], axis=0, keepdims=True)
    projection = evaluated.calc_matrix_camera(
        depsgraph,
        x=width,
        y=height,
        scale_x=scene.render.pixel_aspect_x,
        scale_y=scene.render.pixel_aspect_y,
    )
    return Camera(
        world_to_camera=np.linalg.inv(matrix),
        camera_to_clip=np.array(projection, dtype=np.float64),
        width=width,
        height=height,
        orthographic=camera_data.type == "ORTHO",
        clip_start=float(camera_data.clip_start),
    )


def near_plane_points(camera: Camera) -> np.ndarray:
    """Camera-space points (H, W, 3) where the rays through the pixel centres meet the near plane."""
    xs = (np.arange(camera.width) + 0.5) / camera.width * 2.0 - 1.0
    ys = 1.0 - (np.arange(camera.height) + 0.5) / camera.height * 2.0
    ndc = np.empty((camera.height, camera.width, 4))
    ndc[..., 0] = xs[None, :]
    ndc[..., 1] = ys[:, None]
    ndc[..., 2] = -1.0
    ndc[..., 3] = 1.0
    points = ndc @ np.linalg.inv(camera.camera_to_clip).T
    return points[..., :3] / points[..., 3:4]


def ray_start_distance(camera: Camera) -> np.ndarray:
    """(H, W) distance from the eye to where Cycles starts each camera ray (the near plane)."""
    if camera.orthographic:
        return np.full((camera.height, camera.width), camera.clip_start)
    return np.linalg.norm(near_plane_points(camera), axis=-1)


def world_points(camera: Camera, planar_depth: np.ndarray) -> np.ndarray:
    """Homogeneous world points (H, W, 4) of the surfaces at the given camera-space Z depth.

    Where nothing was hit (depth >= MISS_DEPTH or <= 0) the result is a direction (w = 0), so
    that the environment moves with the camera's rotation only.
    """
    near = near_plane_points(camera)
    miss = (planar_depth >= MISS_DEPTH) | (planar_depth <= 0)
    points = np.empty(near.shape[:2] + (4,))
    if camera.orthographic:
        points[..., :2] = near[..., :2]
        points[..., 2] = -planar_depth
        points[..., 3] = 1.0
        direction = np.broadcast_to(np.array([0.0, 0.0, -1.0]), near.shape)
    else:
        scale = np.where(miss, 1.0, planar_depth) / -near[..., 2]
        points[..., :3] = near * scale[..., None]
        points[..., 3] = 1.0
        direction = near / np.linalg.norm(near, axis=-1, keepdims=True)
    points[miss, :3] = direction[miss]
    points[miss, 3] = 0.0
    return points @ camera.camera_to_world.T


def project(camera: Camera, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pixel x, pixel y (y down) and camera-space depth (positive in front) of world points."""
    in_camera = points @ camera.world_to_camera.T
    clip = in_camera @ camera.camera_to_clip.T
    w = clip[..., 3]
    safe_w = np.where(np.abs(w) > 1e-12, w, 1e-12)
    px = (clip[..., 0] / safe_w + 1.0) * 0.5 * camera.width
    py = (1.0 - clip[..., 1] / safe_w) * 0.5 * camera.height
    return px, py, -in_camera[..., 2]


def camera_motion(
    camera: Camera,
    depth: np.ndarray,
    previous_camera: Camera | None,
    previous_depth: np.ndarray | None,
) -> tuple[np.ndarray, np.ndarray]:
    """Motion (H, W, 2) in pixels into the previous frame and validity (H, W), as float32.

    ``depth`` is Cycles' planar Z pass of this frame (top row first), ``previous_depth`` that of
    the previous frame. A pixel is valid when its surface lands on screen, in front of the
    previous camera, and one of the four previous pixels around the landing point saw the same
    depth (or, for the environment, saw the environment too). The first frame has zero motion
    and no valid pixel.
    """
    shape = (camera.height, camera.width)
    if previous_camera is None or previous_depth is None:
        return np.zeros(shape + (2,), np.float32), np.zeros(shape, np.float32)
    if (previous_camera.width, previous_camera.height) != (camera.width, camera.height):
        return np.zeros(shape + (2,), np.float32), np.zeros(shape, np.float32)

    points = world_points(camera, depth)
    px, py, expected_depth = project(previous_camera, points)
    xs = np.arange(camera.width) + 0.5
    ys = np.arange(camera.height) + 0.5
    motion = np.stack([px - xs[None, :], py - ys[:, None]], axis=-1)

    miss = points[..., 3] == 0.0
    in_front = (points @ previous_camera.world_to_camera.T)[..., 2] < 0.0
    if previous_camera.orthographic:
        in_front = in_front | miss
    on_screen = (px >= 0) & (px < camera.width) & (py >= 0) & (py < camera.height)

    previous_miss = (previous_depth >= MISS_DEPTH) | (previous_depth <= 0)
    matches = np.zeros(shape, bool)
    base_x = np.floor(px - 0.5).astype(np.int64)
    base_y = np.floor(py - 0.5).astype(np.int64)
    for dy in (0, 1):
        for dx in (0, 1):
            sx = np.clip(base_x + dx, 0, camera.width - 1)
            sy = np.clip(base_y + dy, 0, camera.height - 1)
            seen = previous_depth[sy, sx]
            seen_miss = previous_miss[sy, sx]
            same_depth = np.abs(seen - expected_depth) <= DEPTH_TOLERANCE * np.abs(expected_depth)
            matches |= np.where(miss, seen_miss, ~seen_miss & same_depth)
    valid = on_screen & in_front & matches
    motion[~np.isfinite(motion)] = 0.0
    return motion.astype(np.float32), valid.astype(np.float32)

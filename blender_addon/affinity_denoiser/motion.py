"""Camera matrices, per-pixel camera rays, and motion vectors with history validity.

Cycles' Vector pass forces a full re-sync of the scene on every render when persistent data
is on, and is all zero when motion blur is on, so motion is computed here. Static surfaces are
reprojected from the camera matrices of consecutive frames and the depth of the sample at
offset 0 (Cycles writes its Z pass only for that sample; where it scattered in a volume, a later
sample's). Surfaces of objects that moved are
reprojected through the object's own transform: materials.py writes the hit point in object
space and the object's Object Info "Random" value (which identifies the object or instance)
as shader AOVs, and the object's world matrix at the previous frame carries the point there.
What is exact and what is not: docs/BLENDER.md, "Motion and validity".

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
#: A previous pixel vouches for a reprojected point only if a bilinear fetch there weighs it more.
MIN_FETCH_WEIGHT = 1e-3


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


def depth_from_distance(camera: Camera, distance: np.ndarray) -> np.ndarray:
    """(H, W) camera-space Z depth of points at the given distance from the eye (Camera Data's
    View Distance) on the rays through the pixel centres, as Cycles' Z pass measures depth."""
    near = near_plane_points(camera)
    if camera.orthographic:  # the rays are parallel; the eye sits at the camera's origin
        return np.sqrt(np.maximum(distance.astype(np.float64) ** 2
                                  - near[..., 0] ** 2 - near[..., 1] ** 2, 0.0))
    return distance * (-near[..., 2] / np.linalg.norm(near, axis=-1))


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


def _camera_to_pixels(camera: Camera, in_camera: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixel x and pixel y (y down) of homogeneous camera-space points (..., 4)."""
    clip = in_camera @ camera.camera_to_clip.T
    w = clip[..., 3]
    safe_w = np.where(np.abs(w) > 1e-12, w, 1e-12)
    px = (clip[..., 0] / safe_w + 1.0) * 0.5 * camera.width
    py = (1.0 - clip[..., 1] / safe_w) * 0.5 * camera.height
    return px, py


def project(camera: Camera, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pixel x, pixel y (y down) and camera-space depth (positive in front) of world points."""
    in_camera = points @ camera.world_to_camera.T
    px, py = _camera_to_pixels(camera, in_camera)
    return px, py, -in_camera[..., 2]


def depth_slope(depth: np.ndarray, miss: np.ndarray) -> np.ndarray:
    """(H, W) how much the depth changes across one pixel: per axis the smaller of the changes to
    the two neighbours (the smooth side, so that a depth edge does not count), summed.

    A pixel's depth is that of one sample somewhere in it, and two frames' samples fall at
    different places in the pixel; on a surface seen at a grazing angle their depths differ by
    up to this much, more than DEPTH_TOLERANCE.
    """
    values = np.where(miss, np.nan, depth.astype(np.float64))
    padded = np.pad(values, 1, constant_values=np.nan)  # a border pixel has one side
    slope = np.zeros(depth.shape)
    for before, after in ((padded[1:-1, :-2], padded[1:-1, 2:]), (padded[:-2, 1:-1], padded[2:, 1:-1])):
        change = np.fmin(np.abs(values - before), np.abs(values - after))
        slope += np.nan_to_num(change, nan=0.0)
    return slope


@dataclass(frozen=True)
class _PreviousDepth:
    """The previous frame's depth as the validity test reads it, computed once per frame pair
    (the camera's test and the moving objects' share it)."""
    depth: np.ndarray
    miss: np.ndarray
    tolerance: np.ndarray

    @staticmethod
    def of(depth: np.ndarray) -> _PreviousDepth:
        miss = (depth >= MISS_DEPTH) | (depth <= 0)
        return _PreviousDepth(depth, miss, DEPTH_TOLERANCE * depth + depth_slope(depth, miss))


def _seen_before(
    px: np.ndarray,
    py: np.ndarray,
    expected_depth: np.ndarray,
    miss: np.ndarray,
    previous: _PreviousDepth,
) -> np.ndarray:
    """Whether the previous frame saw the surface at (px, py): one of the pixels that a bilinear
    fetch at that point reads saw the expected planar depth (for the environment: saw it too).

    Only pixels with a weight in the fetch count: a point landing on a pixel centre reads that
    pixel alone, and its right and lower neighbours must not vouch for it.
    """
    previous_depth, previous_miss, tolerance = previous.depth, previous.miss, previous.tolerance
    height, width = previous_depth.shape
    matches = np.zeros(px.shape, bool)
    base_x = np.floor(px - 0.5)
    base_y = np.floor(py - 0.5)
    fraction_x, fraction_y = px - 0.5 - base_x, py - 0.5 - base_y
    base_x, base_y = base_x.astype(np.int64), base_y.astype(np.int64)
    for dy, weight_y in ((0, 1.0 - fraction_y), (1, fraction_y)):
        for dx, weight_x in ((0, 1.0 - fraction_x), (1, fraction_x)):
            sx = np.clip(base_x + dx, 0, width - 1)
            sy = np.clip(base_y + dy, 0, height - 1)
            seen = previous_depth[sy, sx]
            seen_miss = previous_miss[sy, sx]
            same_depth = np.abs(seen - expected_depth) <= np.maximum(
                DEPTH_TOLERANCE * np.abs(expected_depth), tolerance[sy, sx])
            read = weight_x * weight_y > MIN_FETCH_WEIGHT
            matches |= read & np.where(miss, seen_miss, ~seen_miss & same_depth)
    return matches


def camera_motion(
    camera: Camera,
    depth: np.ndarray,
    previous_camera: Camera | None,
    previous_depth: np.ndarray | None,
) -> tuple[np.ndarray, np.ndarray]:
    """Motion (H, W, 2) in pixels into the previous frame and validity (H, W), as float32,
    for a static scene: only the camera moves.

    ``depth`` is Cycles' planar Z pass of this frame (top row first), ``previous_depth`` that of
    the previous frame. A pixel is valid when its surface lands on screen, in front of the
    previous camera, and a previous pixel that a bilinear fetch at the landing point reads saw
    the same depth (or, for the environment, saw the environment too). The first frame has zero
    motion and no valid pixel.
    """
    return _camera_motion(camera, depth, previous_camera,
                          None if previous_depth is None else _PreviousDepth.of(previous_depth))


def _camera_motion(
    camera: Camera,
    depth: np.ndarray,
    previous_camera: Camera | None,
    previous: _PreviousDepth | None,
) -> tuple[np.ndarray, np.ndarray]:
    shape = (camera.height, camera.width)
    if previous_camera is None or previous is None:
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
    valid = on_screen & in_front & _seen_before(px, py, expected_depth, miss, previous)
    motion[~np.isfinite(motion)] = 0.0
    return motion.astype(np.float32), valid.astype(np.float32)


# --- Objects -------------------------------------------------------------------------------

#: Object types that never have a surface a camera ray could hit.
_NO_SURFACE = frozenset({"EMPTY", "LIGHT", "LIGHT_PROBE", "LIGHTPROBE", "CAMERA", "SPEAKER",
                         "ARMATURE", "LATTICE"})
_UINT32 = 0xFFFFFFFF


#: lookup3's ``final`` mix on the state (a, b, c): (x, y, k) is ``x ^= y; x -= rot(y, k)``.
_FINAL_MIX = ((2, 1, 14), (0, 2, 11), (1, 0, 25), (2, 1, 16), (0, 2, 4), (1, 0, 14), (2, 1, 24))


def cycles_name_hash(name: str) -> int:
    """Cycles' random id of an object that is not an instance: ``hash_uint2(hash_string(name),
    0)`` (Cycles' util/hash.h: Bob Jenkins' lookup3 ``final`` over a * 37 + byte string hash)."""
    key = 0
    for byte in name.encode("utf-8"):
        key = (key * 37 + byte) & _UINT32
    start = (0xDEADBEEF + (2 << 2) + 13) & _UINT32
    state = [(start + key) & _UINT32, start, start]
    for x, y, k in _FINAL_MIX:
        rotated = ((state[y] << k) | (state[y] >> (32 - k))) & _UINT32
        state[x] = ((state[x] ^ state[y]) - rotated) & _UINT32
    return state[2]


def object_key(random_id: int) -> np.float32:
    """What Cycles' Object Info "Random" output gives for an object with this random id:
    ``float(random_id) * (1 / (float)0xFFFFFFFF)``, and that float is exactly 2^-32."""
    return np.float32(random_id & _UINT32) * np.float32(2.0 ** -32)


@dataclass
class ObjectTransforms:
    """Every object and instance of one frame that can be hit, by its key (``object_key``)."""

    keys: np.ndarray  # (K,) float32, sorted, unique
    matrices: np.ndarray  # (K, 4, 4) float64 world matrices; NaN where two objects share a key

    def find(self, keys: np.ndarray) -> np.ndarray:
        """Index of each key in this table, -1 where it is absent (and for NaN)."""
        if len(self.keys) == 0:
            return np.full(np.shape(keys), -1, np.int64)
        index = np.minimum(np.searchsorted(self.keys, keys), len(self.keys) - 1)
        return np.where(self.keys[index] == keys, index, -1)

    @property
    def ambiguous(self) -> np.ndarray:
        return np.isnan(self.matrices[:, 0, 0])


def object_transforms(depsgraph: Any) -> ObjectTransforms:
    """The world matrix of every object and instance in ``depsgraph``, by the value the
    Object Info "Random" output has on it in Cycles.

    Cycles gives an instance the random id Blender gives it (``DepsgraphObjectInstance.random_id``)
    and any other object the hash of its name. Float keys of different objects can coincide
    (the id is rounded to 24 bits); such keys are kept but marked ambiguous.
    """
    random_ids: list[int] = []
    matrices: list[np.ndarray] = []
    for instance in depsgraph.object_instances:
        obj = instance.object
        if obj.type in _NO_SURFACE:
            continue
        random_ids.append(instance.random_id & _UINT32 if instance.is_instance
                          else cycles_name_hash(obj.name))
        matrices.append(np.array(instance.matrix_world, dtype=np.float64))
    if not random_ids:
        return ObjectTransforms(np.empty(0, np.float32), np.empty((0, 4, 4)))
    # As object_key, for all at once: uint32 -> float32 rounds to nearest, as C's cast does.
    keys = np.array(random_ids, np.uint32).astype(np.float32) * np.float32(2.0 ** -32)
    unique, first, counts = np.unique(keys, return_index=True, return_counts=True)
    unique_matrices = np.stack(matrices)[first]
    unique_matrices[counts > 1] = np.nan
    return ObjectTransforms(unique, unique_matrices)


@dataclass
class FrameGeometry:
    """What motion needs of one frame. Without the object fields only the camera moves."""

    camera: Camera
    #: (H, W) planar depth: Cycles' Z pass of the sample at offset 0, or where that sample
    #: scattered in a volume, the first later sample's that reached a surface (add_surfaces).
    depth: np.ndarray
    #: (H, W) the Object Info "Random" value of the object hit by the same sample, NaN where
    #: unknown (a miss, a surface without our AOVs).
    object_key: np.ndarray | None = None
    object_local: np.ndarray | None = None  # (H, W, 3) that hit point in object space
    transforms: ObjectTransforms | None = None
    #: (H, W) bool: no sample so far reached a surface, and the one at offset 0 scattered in a
    #: volume (Cycles wrote no depth but a denoising normal: a miss writes neither).
    scattered: np.ndarray | None = None

    def add_surfaces(self, distance: np.ndarray, object_key: np.ndarray,
                     object_local: np.ndarray) -> None:
        """Gives the pixels where every sample so far scattered in a volume the surface that a
        later sample reached: its view distance (0 where our AOVs were not written), object key
        and object-space point.

        In fog, a camera ray that scatters before the first surface writes no Z and no AOV: the
        sample at offset 0 alone would leave those pixels, scattered at random, as misses; the
        validity test would then drop their history at random from frame to frame, and a moving
        camera would move them as the environment. Pixels where every sample scattered stay
        misses.
        """
        if self.scattered is None:
            return
        filled = self.scattered & (distance > 0.0)
        if not filled.any():
            return
        self.depth[filled] = depth_from_distance(self.camera, distance)[filled]
        if self.object_key is not None and self.object_local is not None:
            self.object_key[filled] = object_key[filled]
            self.object_local[filled] = object_local[filled]
        self.scattered &= ~filled


def _object_to_camera(camera: Camera, matrices: np.ndarray) -> np.ndarray:
    """(K, 4, 4): each object's space -> this camera's space."""
    return np.einsum("ij,kjl->kil", camera.world_to_camera, matrices)


def _transform(matrices: np.ndarray, index: np.ndarray, points: np.ndarray) -> np.ndarray:
    """matrices[index[n]] applied to the points (N, 3), giving homogeneous (N, 4); one column
    at a time, so memory stays O(N) rather than a (N, 4, 4) gather."""
    out = matrices[index, :, 3].copy()
    for j in range(3):
        out += matrices[index, :, j] * points[:, j:j + 1]
    return out


def scene_motion(current: FrameGeometry,
                 previous: FrameGeometry | None) -> tuple[np.ndarray, np.ndarray]:
    """Motion (H, W, 2) into the previous frame and validity (H, W), float32, with moving objects.

    Every pixel starts with the camera-only motion of ``camera_motion``. Where the sample at
    offset 0 hit an object whose world matrix changed since the previous frame, its hit point
    p (object space) is reprojected through the object instead: motion = P_prev(M_prev p) -
    P(M p), valid when M_prev p lands on screen, in front of the previous camera, at the depth
    the previous frame saw there. Pixels on an object that did not exist in the previous frame
    are invalid. Objects whose key two objects share keep the camera-only motion.
    """
    previous_depth = _PreviousDepth.of(previous.depth) if previous else None
    motion, valid = _camera_motion(current.camera, current.depth,
                                   previous.camera if previous else None, previous_depth)
    if (previous is None or previous.depth.shape != valid.shape
            or current.object_key is None or current.object_local is None
            or current.transforms is None or previous.transforms is None
            or len(current.transforms.keys) == 0):
        return motion, valid
    now, before = current.transforms, previous.transforms
    if len(before.keys) == 0:  # index 0 below must exist; nothing will be found in it
        before = ObjectTransforms(np.full(1, np.nan, np.float32), np.full((1, 4, 4), np.nan))
    # Per key of this frame: where it is in the previous frame's table, and what happened.
    before_index = before.find(now.keys)
    known_now = ~now.ambiguous
    absent_before = before_index < 0
    known_before = ~absent_before & ~before.ambiguous[np.maximum(before_index, 0)]
    previous_matrices = before.matrices[np.maximum(before_index, 0)]
    moved = known_now & known_before & np.any(previous_matrices != now.matrices, axis=(1, 2))

    index = now.find(current.object_key)
    has_key = index >= 0
    key_index = np.maximum(index, 0)
    appeared = has_key & known_now[key_index] & absent_before[key_index]
    valid[appeared] = 0.0

    moving = has_key & moved[key_index]
    if not moving.any():
        return motion, valid
    rows, cols = np.nonzero(moving)
    keys = index[rows, cols]
    local = current.object_local[rows, cols].astype(np.float64)
    here = _transform(_object_to_camera(current.camera, now.matrices), keys, local)
    there = _transform(_object_to_camera(previous.camera, previous_matrices), keys, local)
    x_now, y_now = _camera_to_pixels(current.camera, here)
    x_before, y_before = _camera_to_pixels(previous.camera, there)
    object_motion = np.stack([x_before - x_now, y_before - y_now], axis=-1)
    expected_depth = -there[:, 2]
    width, height = current.camera.width, current.camera.height
    visible = ((x_before >= 0) & (x_before < width) & (y_before >= 0) & (y_before < height)
               & (there[:, 2] < 0.0) & np.isfinite(object_motion).all(axis=-1)
               & _seen_before(x_before, y_before, expected_depth,
                              np.zeros(len(keys), bool), previous_depth))
    object_motion[~np.isfinite(object_motion)] = 0.0
    motion[rows, cols] = object_motion
    valid[rows, cols] = visible
    return motion, valid

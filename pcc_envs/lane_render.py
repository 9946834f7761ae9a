"""Pure camera model and analytic road renderer of the lane-keeping domain.

The lane-keeping car carries a forward-looking pinhole camera. The road is a flat straight
strip ``|y| <= half_width`` of the ground plane ``z = 0`` running along the world ``x`` axis,
so the camera image of the road is the perspective projection of that strip. This module
computes it in closed form (clip the strip against the camera's near and far planes, project
the corners, fill the polygon), which gives exactly the segmentation mask Bullet's
TinyRenderer draws for the same camera (Bullet's ``computeViewMatrix(eye, eye + forward,
(0, 0, 1))`` and ``computeProjectionMatrixFOV(fov, W / H, near, far)``; the lane-keeping
tests compare the two), about a hundred times faster and with no simulator state.

Conventions: world frame ``x`` along the road, ``y`` to the left, ``z`` up. A car pose is
``(lateral offset y, heading)``, heading measured from ``+x`` counter-clockwise (positive
turns left). Images are ``(H, W)`` with row 0 at the top; road pixels are 255, others 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

__all__ = [
    "CameraParams",
    "camera_frames",
    "render_road_masks",
]

_SUBPIXEL_BITS = 4


@dataclass(frozen=True)
class CameraParams:
    """A pinhole camera rigidly mounted on the car.

    Attributes:
        forward: Mount position ahead of the car's reference point (rear axle), metres.
        height: Mount height above the road, metres.
        pitch: Downward tilt of the optical axis, radians.
        fov: Vertical field of view, degrees (square pixels, so the horizontal one for a
            square image is the same).
        near: Near clipping distance along the optical axis, metres.
        far: Far clipping distance along the optical axis, metres (Bullet draws nothing
            beyond it; the analytic renderer clips the road there too).
        image_shape: ``(H, W)`` of the rendered mask.
    """

    forward: float = 0.5
    height: float = 1.0
    pitch: float = 0.55
    fov: float = 100.0
    near: float = 0.05
    far: float = 60.0
    image_shape: tuple[int, int] = (80, 80)

    @property
    def focal(self) -> float:
        """Focal length in pixels."""
        return 0.5 * self.image_shape[0] / np.tan(np.deg2rad(self.fov) / 2.0)


def camera_frames(
    offsets: np.ndarray, headings: np.ndarray, camera: CameraParams
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Camera centre and axes in the world for a batch of car poses (car at ``x = 0``).

    Args:
        offsets: ``(N,)`` lateral offsets of the car's reference point, metres.
        headings: ``(N,)`` headings relative to the road, radians.
        camera: The camera mount.

    Returns:
        ``(eye, forward, right, up)``, each ``(N, 3)``: the optical centre and the unit
        optical axis, image-right and image-up directions (the frame OpenGL's ``lookAt``
        builds from the world ``z`` axis as its up hint).
    """
    offsets = np.asarray(offsets, dtype=np.float64)
    headings = np.asarray(headings, dtype=np.float64)
    cos_h, sin_h = np.cos(headings), np.sin(headings)
    zeros = np.zeros_like(offsets)
    eye = np.stack(
        [camera.forward * cos_h, offsets + camera.forward * sin_h, zeros + camera.height], -1
    )
    cos_p, sin_p = np.cos(camera.pitch), np.sin(camera.pitch)
    forward = np.stack([cos_p * cos_h, cos_p * sin_h, zeros - sin_p], -1)
    right = np.stack([sin_h, -cos_h, zeros], -1)
    up = np.stack([sin_p * cos_h, sin_p * sin_h, zeros + cos_p], -1)
    return eye, forward, right, up


def _clip_depth(polygon: np.ndarray, depth: float, keep_greater: bool) -> np.ndarray:
    """Sutherland-Hodgman clip of a camera-frame polygon ``(K, 3)`` against ``z = depth``."""
    if len(polygon) == 0:
        return polygon
    sign = 1.0 if keep_greater else -1.0
    dist = sign * (polygon[:, 2] - depth)
    out = []
    for i in range(len(polygon)):
        a, b = polygon[i], polygon[(i + 1) % len(polygon)]
        da, db = dist[i], dist[(i + 1) % len(polygon)]
        if da >= 0:
            out.append(a)
        if (da >= 0) != (db >= 0):
            out.append(a + (b - a) * (da / (da - db)))
    return np.asarray(out).reshape(-1, 3)


def render_road_masks(
    offsets: np.ndarray,
    headings: np.ndarray,
    half_width: float,
    camera: CameraParams,
    road_start: float = -5.0,
    road_end: float = 200.0,
) -> np.ndarray:
    """Binary road images seen from a batch of car poses, by exact projection.

    Args:
        offsets: ``(N,)`` lateral offsets of the car, metres.
        headings: ``(N,)`` headings relative to the road, radians.
        half_width: Half the road width, metres.
        camera: The camera mount and intrinsics.
        road_start: World ``x`` where the road begins (behind the car).
        road_end: World ``x`` where the road ends (the far plane usually cuts it first).

    Returns:
        ``uint8`` array ``(N, H, W)``: 255 on road pixels, 0 elsewhere.
    """
    height, width = camera.image_shape
    eye, forward, right, up = camera_frames(offsets, headings, camera)
    corners = np.array(
        [
            [road_start, -half_width, 0.0],
            [road_end, -half_width, 0.0],
            [road_end, half_width, 0.0],
            [road_start, half_width, 0.0],
        ]
    )
    focal = camera.focal
    masks = np.zeros((len(eye), height, width), dtype=np.uint8)
    scale = float(1 << _SUBPIXEL_BITS)
    for i in range(len(eye)):
        rel = corners - eye[i]
        cam = np.stack([rel @ right[i], rel @ up[i], rel @ forward[i]], axis=-1)
        cam = _clip_depth(cam, camera.near, keep_greater=True)
        cam = _clip_depth(cam, camera.far, keep_greater=False)
        if len(cam) < 3:
            continue
        # Pixel (r, c) covers [c, c + 1) x [r, r + 1); fillPoly puts pixel centres on integers.
        cols = width / 2.0 + focal * cam[:, 0] / cam[:, 2] - 0.5
        rows = height / 2.0 - focal * cam[:, 1] / cam[:, 2] - 0.5
        points = np.round(np.stack([cols, rows], axis=-1) * scale).astype(np.int64)
        limit = 1 << 28
        points = np.clip(points, -limit, limit).astype(np.int32)
        cv2.fillPoly(masks[i], [points], 255, lineType=cv2.LINE_8, shift=_SUBPIXEL_BITS)
    return masks

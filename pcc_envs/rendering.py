"""Pure, batched renderers: true states ``(N, state_dim)`` to ``uint8`` frames ``(N, H, W)``.

Every picture is white (255) shapes on black (0) with antialiased edges (intensity falls
linearly from 255 to 0 over one pixel across a shape's boundary). Pixel ``(row, col)`` covers
``[col, col + 1) x [row, row + 1)`` in image coordinates, so its centre is at
``(col + 0.5, row + 0.5)``.

Speed matters: the dataset sampler renders three frames per transition. Shapes whose picture
depends on one angle (the pendulum rod, the cart-pole's pole) are drawn once per angle bin
by the exact distance-field renderer :func:`segment_coverage` and cached (``functools.cache``
on the frozen view and physics parameters); a frame is then a table look-up, plus a
whole-pixel placement for the cart. The quantization is stated per view (angle bins,
sub-pixel phases) and is far below one pixel. The arms are drawn with OpenCV's antialiased
lines at 1/16-pixel precision, and the planar agent is a cached antialiased disk placed at
1/8-pixel precision over the obstacle background.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import cv2
import numpy as np

from pcc_envs.physics import (
    ArmParams,
    CartPoleParams,
    PendulumParams,
    PlanarParams,
    arm_joint_positions,
)

__all__ = [
    "ArmView",
    "CartPoleView",
    "PendulumView",
    "PlanarView",
    "SCHEMATIC_CARTPOLE_VIEW",
    "render_arm",
    "render_cartpole",
    "render_pendulum",
    "render_planar",
    "segment_coverage",
]


def segment_coverage(
    cols: np.ndarray,
    rows: np.ndarray,
    start: np.ndarray,
    end: np.ndarray,
    half_width: float,
) -> np.ndarray:
    """Antialiased coverage in ``[0, 1]`` of a thick segment (a capsule) on a pixel grid.

    Args:
        cols: Pixel-centre columns, broadcastable against ``rows`` (e.g. ``(1, H, W)``).
        rows: Pixel-centre rows.
        start: Segment start points ``(N, 2)`` as ``(col, row)``.
        end: Segment end points ``(N, 2)``.
        half_width: Half the stroke width in pixels.

    Returns:
        ``(N, H, W)`` float coverage ``clip(half_width + 0.5 - distance, 0, 1)``.
    """
    sx, sy = start[:, 0, None, None], start[:, 1, None, None]
    dx = (end[:, 0] - start[:, 0])[:, None, None]
    dy = (end[:, 1] - start[:, 1])[:, None, None]
    length2 = np.maximum(dx**2 + dy**2, 1e-12)
    t = np.clip(((cols - sx) * dx + (rows - sy) * dy) / length2, 0.0, 1.0)
    dist = np.hypot(cols - sx - t * dx, rows - sy - t * dy)
    return np.clip(half_width + 0.5 - dist, 0.0, 1.0)


def _grid(height: int, width: int) -> tuple[np.ndarray, np.ndarray]:
    rows, cols = np.mgrid[0:height, 0:width].astype(np.float64) + 0.5
    return cols[None], rows[None]


def _angle_bin(angle: np.ndarray, bins: int) -> np.ndarray:
    return np.rint((np.asarray(angle) + np.pi) * (bins / (2.0 * np.pi))).astype(np.int64) % bins


def _bin_angles(bins: int) -> np.ndarray:
    return np.arange(bins) * (2.0 * np.pi / bins) - np.pi


def _to_uint8(coverage: np.ndarray) -> np.ndarray:
    return np.rint(coverage * 255.0).astype(np.uint8)


# --------------------------------------------------------------------------- pendulum
@dataclass(frozen=True)
class PendulumView:
    """Camera of the pendulum picture.

    Attributes:
        size: Frame side in pixels (48).
        pixels_per_metre: Scale (40: the 0.5 m rod is 20 pixels long).
        rod_width: Rod stroke width in pixels (3).
        angle_bins: Angles are rendered at ``2 pi / angle_bins`` resolution (4096: the tip
            moves at most 0.015 pixel inside a bin).
    """

    size: int = 48
    pixels_per_metre: float = 40.0
    rod_width: float = 3.0
    angle_bins: int = 4096


@functools.cache
def _pendulum_table(params: PendulumParams, view: PendulumView) -> np.ndarray:
    cols, rows = _grid(view.size, view.size)
    centre = view.size / 2.0
    length = params.length * view.pixels_per_metre
    angles = _bin_angles(view.angle_bins)
    table = np.empty((view.angle_bins, view.size, view.size), dtype=np.uint8)
    for lo in range(0, view.angle_bins, 512):
        a = angles[lo : lo + 512]
        start = np.full((a.size, 2), centre)
        end = np.stack([centre + length * np.sin(a), centre - length * np.cos(a)], axis=-1)
        table[lo : lo + 512] = _to_uint8(
            segment_coverage(cols, rows, start, end, view.rod_width / 2.0)
        )
    table.setflags(write=False)
    return table


def render_pendulum(
    states: np.ndarray, params: PendulumParams, view: PendulumView = PendulumView()
) -> np.ndarray:
    """Pendulum frames: a rod from the frame centre (the pivot) at angle ``states[:, 0]``."""
    table = _pendulum_table(params, view)
    return table[_angle_bin(np.asarray(states)[:, 0], view.angle_bins)]


# --------------------------------------------------------------------------- cart-pole
@dataclass(frozen=True)
class CartPoleView:
    """Camera of the cart-pole picture (the camera is fixed; the cart moves across it).

    The defaults draw everything to one scale (the ``"physical"`` picture). The
    ``"schematic"`` picture (:data:`SCHEMATIC_CARTPOLE_VIEW`) draws the pole longer and wider
    than to scale, as the PCC authors' code does.

    Attributes:
        size: Frame side in pixels (80).
        pixels_per_metre: Cart position scale (15: the 2 x 2.4 m track spans 72 pixels).
        cart_half_width, cart_half_height: Cart rectangle half sizes in pixels (3.5, 2.5).
        cart_row: Image row of the cart centre (52).
        pole_width: Pole stroke width in pixels (2.5).
        pole_pixels: Pole length in pixels; ``None`` draws it to scale (2 x half-length x
            ``pixels_per_metre``: 15 pixels).
        angle_bins: Pole angle resolution ``2 pi / angle_bins`` (1024: < 0.1 pixel at the tip
            of a 15-pixel pole).
        phases: Sub-pixel positions of the cart per pixel (4: the cart is placed at quarter
            pixels, 1/60 m).
    """

    size: int = 80
    pixels_per_metre: float = 15.0
    cart_half_width: float = 3.5
    cart_half_height: float = 2.5
    cart_row: float = 52.0
    pole_width: float = 2.5
    pole_pixels: float | None = None
    angle_bins: int = 1024
    phases: int = 4

    def pole_length(self, params: CartPoleParams) -> float:
        """The pole's length in pixels."""
        if self.pole_pixels is not None:
            return self.pole_pixels
        return 2.0 * params.pole_half_length * self.pixels_per_metre


#: The PCC authors' cart-pole picture: a 52-pixel pole 6 pixels wide (0.65 of the frame) on a
#: 16 x 8 pixel cart near the bottom, the track spanning the frame less the cart. Its tip moves
#: 3.5 times as far per step as the tip of the 15-pixel pole drawn to scale, and it covers
#: about 8 times as many pixels. 4096 angle bins keep the tip's resolution under 0.1 pixel; the
#: sprite table is then about 150 MB, built once per process (about 5 s).
SCHEMATIC_CARTPOLE_VIEW = CartPoleView(
    pixels_per_metre=32.0 / 2.4, cart_half_width=8.0, cart_half_height=4.0, cart_row=70.0,
    pole_width=6.0, pole_pixels=52.0, angle_bins=4096,
)


@functools.cache
def _cartpole_table(params: CartPoleParams, view: CartPoleView) -> tuple[np.ndarray, int, int]:
    """Cart + pole sprites ``(angle_bins, phases, rows, cols)``, ``reach``, first image row.

    Local column ``reach`` holds the cart centre's whole pixel.
    """
    pole = view.pole_length(params)
    reach = int(np.ceil(max(pole, view.cart_half_width) + view.pole_width + 2))
    top = int(np.floor(view.cart_row - view.cart_half_height - pole - view.pole_width - 2))
    bottom = int(np.ceil(view.cart_row + max(view.cart_half_height, pole) + view.pole_width + 2))
    top, bottom = max(top, 0), min(bottom, view.size)
    height, width = bottom - top, 2 * reach + 1
    cols, rows = _grid(height, width)
    rows = rows + top
    pivot_row = view.cart_row - view.cart_half_height
    angles = _bin_angles(view.angle_bins)
    table = np.empty((view.angle_bins, view.phases, height, width), dtype=np.uint8)
    for phase in range(view.phases):
        cx = reach + phase / view.phases  # cart centre in local columns
        cart = np.clip(view.cart_half_width + 0.5 - np.abs(cols - cx), 0, 1) * np.clip(
            view.cart_half_height + 0.5 - np.abs(rows - view.cart_row), 0, 1
        )
        start = np.tile([cx, pivot_row], (view.angle_bins, 1))
        end = np.stack([cx + pole * np.sin(angles), pivot_row - pole * np.cos(angles)], axis=-1)
        for lo in range(0, view.angle_bins, 256):
            rod = segment_coverage(
                cols, rows, start[lo : lo + 256], end[lo : lo + 256], view.pole_width / 2.0
            )
            table[lo : lo + 256, phase] = _to_uint8(np.maximum(rod, cart))
    table.setflags(write=False)
    return table, reach, top


def render_cartpole(
    states: np.ndarray, params: CartPoleParams, view: CartPoleView = CartPoleView()
) -> np.ndarray:
    """Cart-pole frames: the cart at ``states[:, 2]`` m and the pole at ``states[:, 0]``."""
    states = np.asarray(states)
    table, reach, top = _cartpole_table(params, view)
    height, width = table.shape[2:]
    col = view.size / 2.0 + states[:, 2] * view.pixels_per_metre
    quarter = np.floor(col * view.phases).astype(np.int64)
    whole, phase = np.divmod(quarter, view.phases)
    if len(states) == 1:  # the env's step: plain slicing
        sprite = table[_angle_bin(states[0, 0], view.angle_bins), phase[0]]
        left = int(whole[0]) - reach
        lo, hi = max(left, 0), min(left + width, view.size)
        frames = np.zeros((1, view.size, view.size), dtype=np.uint8)
        if lo < hi:
            frames[0, top : top + height, lo:hi] = sprite[:, lo - left : hi - left]
        return frames
    bins = _angle_bin(states[:, 0], view.angle_bins)
    left = whole - reach
    frames = np.zeros((len(states), view.size, view.size), dtype=np.uint8)
    band = frames[:, top : top + height]
    # Paste the sprites group by group of equal whole-pixel column, clipped to the frame.
    for offset in np.unique(left).tolist():
        lo, hi = max(offset, 0), min(offset + width, view.size)
        if lo >= hi:
            continue
        idx = np.flatnonzero(left == offset)
        band[idx, :, lo:hi] = table[bins[idx], phase[idx], :, lo - offset : hi - offset]
    return frames


# --------------------------------------------------------------------------- arms
@dataclass(frozen=True)
class ArmView:
    """Camera of the N-link arm picture: the base at the frame centre.

    Attributes:
        size: Frame side in pixels (80).
        reach: Pixels from the base to the tip of the stretched arm (36), so the scale is
            ``reach / (num_links * link_length)`` pixels per metre.
        rod_width: Rod stroke width in pixels (3, OpenCV antialiased line thickness).
    """

    size: int = 80
    reach: float = 36.0
    rod_width: int = 3


_SHIFT = 4  # OpenCV fixed-point bits: end points at 1/16 pixel.


def render_arm(states: np.ndarray, params: ArmParams, view: ArmView = ArmView()) -> np.ndarray:
    """Arm frames: every link as a rod, from the base at the frame centre."""
    states = np.asarray(states)
    scale = view.reach / (params.num_links * params.link_length)
    # OpenCV puts integer coordinates at pixel centres; ours are at half-integers.
    centre = view.size / 2.0 - 0.5
    if len(states) == 1:  # the env's step: the same points in plain Python floats
        unit = (1 << _SHIFT) * scale * params.link_length
        x = y = centre * (1 << _SHIFT)
        phi = 0.0
        pts = [(round(x), round(y))]
        for angle in states[0, : params.num_links].tolist():
            phi += angle
            x, y = x + unit * math.sin(phi), y - unit * math.cos(phi)
            pts.append((round(x), round(y)))
        frame = np.zeros((1, view.size, view.size), dtype=np.uint8)
        polyline = np.array(pts, dtype=np.int32)
        cv2.polylines(frame[0], [polyline], False, 255, view.rod_width, cv2.LINE_AA, _SHIFT)
        return frame
    joints = arm_joint_positions(states[:, : params.num_links], params)
    points = np.empty((len(states), params.num_links + 1, 2))
    points[:, 0] = centre
    points[:, 1:, 0] = centre + scale * joints[..., 0]
    points[:, 1:, 1] = centre - scale * joints[..., 1]
    fixed = np.rint(points * (1 << _SHIFT)).astype(np.int32)
    frames = np.zeros((len(states), view.size, view.size), dtype=np.uint8)
    for frame, pts in zip(frames, fixed):
        cv2.polylines(frame, [pts], False, 255, view.rod_width, cv2.LINE_AA, _SHIFT)
    return frames


# --------------------------------------------------------------------------- planar
@dataclass(frozen=True)
class PlanarView:
    """Top view of the planar world: one world unit is one pixel.

    Attributes:
        obstacle_level: Grey level of the obstacles (100), below the agent's 255 so the two are
            told apart.
        phases: Sub-pixel positions of the agent per pixel and axis (8).
    """

    obstacle_level: int = 100
    phases: int = 8


_PAD = 3


@functools.cache
def _planar_assets(params: PlanarParams, view: PlanarView) -> tuple[np.ndarray, np.ndarray]:
    size = int(round(params.world_size))
    # Padded by PAD on the low side and PAD + 1 on the high side, so that an agent window
    # fits for every position in the closed world [0, size]^2 (the crop removes the padding).
    padded = size + 2 * _PAD + 1
    cols, rows = _grid(padded, padded)
    cols, rows = cols[0] - _PAD, rows[0] - _PAD
    background = np.zeros((padded, padded))
    for cx, cy in params.obstacles:
        disk = np.clip(params.obstacle_radius + 0.5 - np.hypot(cols - cx, rows - cy), 0, 1)
        background = np.maximum(background, disk)
    background = np.rint(background * view.obstacle_level).astype(np.uint8)
    # Agent patches: centre at (k + p / phases) within a (2 * PAD + 1)^2 window centred on k.
    patch = 2 * _PAD + 1
    offs = np.arange(patch) - _PAD + 0.5
    frac = np.arange(view.phases) / view.phases
    dy = offs[None, :, None] - frac[:, None, None]  # (P, patch, 1)
    dx = offs[None, None, :] - frac[:, None, None]  # (P, 1, patch)
    dist = np.hypot(dy[:, None, :, :], dx[None, :, :, :])  # (Py, Px, patch, patch)
    patches = _to_uint8(np.clip(params.agent_radius + 0.5 - dist, 0, 1))
    background.setflags(write=False)
    patches.setflags(write=False)
    return background, patches


def render_planar(
    states: np.ndarray, params: PlanarParams, view: PlanarView = PlanarView()
) -> np.ndarray:
    """Planar frames: the obstacles in grey and the agent as a white disk at ``(x, y)``.

    Raises:
        ValueError: A state outside the world ``[0, world_size]^2`` (or not finite).
    """
    states = np.asarray(states)
    inside = np.isfinite(states).all(-1) & (states >= 0).all(-1) & (
        states <= params.world_size).all(-1)
    if not inside.all():
        bad = states[~inside][0]
        raise ValueError(
            f"Cannot render the Planar state {bad.tolist()}: positions must lie in the "
            f"world [0, {params.world_size}]^2."
        )
    background, patches = _planar_assets(params, view)
    size = int(round(params.world_size))
    n = len(states)
    if n == 1:  # the env's step: plain slicing beats fancy indexing
        ((x, y),) = np.floor(states * view.phases).astype(np.int64).tolist()
        (col, phase_x), (row, phase_y) = divmod(x, view.phases), divmod(y, view.phases)
        canvas = background.copy()
        window = canvas[row : row + 2 * _PAD + 1, col : col + 2 * _PAD + 1]
        np.maximum(window, patches[phase_y, phase_x], out=window)
        return canvas[None, _PAD : _PAD + size, _PAD : _PAD + size].copy()
    scaled = np.floor(states * view.phases).astype(np.int64)
    whole, phase = np.divmod(scaled, view.phases)
    canvas = np.broadcast_to(background, (n, *background.shape)).copy()
    span = np.arange(2 * _PAD + 1)
    rows = (whole[:, 1, None, None] + span[:, None]).clip(0, background.shape[0] - 1)
    cols = (whole[:, 0, None, None] + span[None, :]).clip(0, background.shape[1] - 1)
    sample = np.arange(n)[:, None, None]
    region = canvas[sample, rows, cols]
    canvas[sample, rows, cols] = np.maximum(region, patches[phase[:, 1], phase[:, 0]])
    return np.ascontiguousarray(canvas[:, _PAD : _PAD + size, _PAD : _PAD + size])

"""Synthetic RGB-D frames for the object-labelling tests: a floor plus axis-aligned boxes, pinhole-rendered.

World frame: x forward, y left, z up, camera at height ``camera_height_m`` above the origin,
pitched down by ``pitch_rad``. Boxes are (x_centre, y_centre, depth_x, width_y, height) in metres.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from services.object_labelling import CameraIntrinsics, GroundPlane, make_intrinsics

Box = tuple[float, float, float, float, float]


def vga_intrinsics() -> CameraIntrinsics:
    """A 640x480 camera with a 1.012 rad (58 deg) horizontal field of view, like the article's Xtion."""
    fx = 320.0 / math.tan(1.012 / 2.0)
    return make_intrinsics(fx, fx, 319.5, 239.5, 640, 480)


def _rotation(pitch_rad: float) -> npt.NDArray[np.float64]:
    """Columns: the optical x, y, z axes in the world frame."""
    c, s = math.cos(pitch_rad), math.sin(pitch_rad)
    return np.array([[0.0, -s, c], [-1.0, 0.0, 0.0], [0.0, -c, -s]])


def true_plane(camera_height_m: float, pitch_rad: float) -> GroundPlane:
    """The floor in the optical frame of a camera at this height and pitch."""
    normal = _rotation(pitch_rad)[2]
    return GroundPlane((float(normal[0]), float(normal[1]), float(normal[2])), camera_height_m)


def render_depth(
    intrinsics: CameraIntrinsics,
    boxes: list[Box],
    *,
    camera_height_m: float = 1.0,
    pitch_rad: float = 0.25,
    floor_range_m: float = 8.0,
    noise_m: float = 0.0,
    seed: int = 0,
) -> npt.NDArray[np.uint16]:
    """16UC1 depth (mm) of the scene; floor farther than ``floor_range_m`` reads 0 (no return)."""
    rows, cols = np.mgrid[0 : intrinsics.height, 0 : intrinsics.width]
    rays = np.stack(
        ((cols - intrinsics.cx) / intrinsics.fx, (rows - intrinsics.cy) / intrinsics.fy, np.ones(rows.shape)), axis=-1
    ).reshape(-1, 3)
    world = rays @ _rotation(pitch_rad).T
    origin = np.array([0.0, 0.0, camera_height_m])
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(world[:, 2] < 0, -camera_height_m / world[:, 2], np.inf)
        floor_x = world[:, 0] * t
        t = np.where(floor_x > floor_range_m, np.inf, t)
        for x, y, dx, dy, h in boxes:
            lo = np.array([x - dx / 2, y - dy / 2, 0.0]) - origin
            hi = np.array([x + dx / 2, y + dy / 2, h]) - origin
            t1, t2 = lo / world, hi / world
            near = np.nanmax(np.minimum(t1, t2), axis=1)
            far = np.nanmin(np.maximum(t1, t2), axis=1)
            hit = (near <= far) & (near > 0)
            t = np.where(hit & (near < t), near, t)
    depth = t  # rays have optical z = 1, so t is the depth along z
    if noise_m:
        depth = depth + np.random.default_rng(seed).normal(0.0, noise_m, depth.shape)
    depth_mm = np.where(np.isfinite(depth), np.round(depth * 1000.0), 0.0)
    return np.clip(depth_mm, 0, 65535).astype(np.uint16).reshape(intrinsics.height, intrinsics.width)

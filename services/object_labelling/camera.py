"""Pinhole camera model and depth-image back-projection."""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt
from rosbags.typesys.stores.ros2_jazzy import sensor_msgs__msg__CameraInfo as CameraInfo

from services.object_labelling.errors import ObjectLabellingError


class CameraIntrinsics(NamedTuple):
    """Pinhole intrinsics in pixels; the optical frame has x right, y down, z forward."""

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int

    @property
    def horizontal_fov_rad(self) -> float:
        """Angle between the rays through the left edge of column 0 and the right edge of the last column."""
        return math.atan(self.cx / self.fx) + math.atan((self.width - self.cx) / self.fx)


def intrinsics_from_camera_info(message: CameraInfo) -> CameraIntrinsics:
    """Intrinsics of a sensor_msgs/CameraInfo ``message`` (its 3x3 ``k`` matrix and image size)."""
    k = np.asarray(message.k, dtype=np.float64).ravel()
    if k.size != 9:
        raise ObjectLabellingError(f"CameraInfo k must have 9 entries, got {k.size}")
    return make_intrinsics(k[0], k[4], k[2], k[5], int(message.width), int(message.height))


def make_intrinsics(fx: float, fy: float, cx: float, cy: float, width: int, height: int) -> CameraIntrinsics:
    """Validated :class:`CameraIntrinsics`: positive finite focal lengths and a non-empty image."""
    if not (math.isfinite(fx) and math.isfinite(fy) and fx > 0 and fy > 0):
        raise ObjectLabellingError(f"focal lengths must be positive and finite, got fx={fx}, fy={fy}")
    if not (math.isfinite(cx) and math.isfinite(cy)):
        raise ObjectLabellingError(f"principal point must be finite, got ({cx}, {cy})")
    if width <= 0 or height <= 0:
        raise ObjectLabellingError(f"image size must be positive, got {width}x{height}")
    return CameraIntrinsics(float(fx), float(fy), float(cx), float(cy), int(width), int(height))


def check_depth(depth_mm: npt.NDArray[Any], intrinsics: CameraIntrinsics) -> npt.NDArray[np.uint16]:
    """Reject a depth image that is not (height, width) uint16 matching ``intrinsics`` or holds no depth."""
    if depth_mm.dtype != np.uint16 or depth_mm.ndim != 2:
        raise ObjectLabellingError(
            f"depth image must be 2-D uint16 millimetres (16UC1), got {depth_mm.dtype} of shape {depth_mm.shape}"
        )
    if depth_mm.shape != (intrinsics.height, intrinsics.width):
        raise ObjectLabellingError(
            f"depth image is {depth_mm.shape[1]}x{depth_mm.shape[0]} px but the camera model is "
            f"{intrinsics.width}x{intrinsics.height} px"
        )
    if not depth_mm.any():
        raise ObjectLabellingError("depth image holds no depth (all pixels are 0)")
    return depth_mm


def depth_to_points(
    depth_mm: npt.NDArray[np.uint16], intrinsics: CameraIntrinsics, *, max_depth_m: float = 10.0
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.intp]]:
    """Back-project valid depth pixels to 3-D points in the optical frame.

    Parameters
    ----------
    depth_mm
        (height, width) uint16 depth in millimetres; 0 means no measurement.
    intrinsics
        Camera model of the same size.
    max_depth_m
        Pixels deeper than this (metres along z) are dropped.

    Returns
    -------
    points : numpy.ndarray
        (n, 3) float64 metres, x right, y down, z forward.
    pixels : numpy.ndarray
        (n, 2) intp (row, col) of each point.
    """
    check_depth(depth_mm, intrinsics)
    rows, cols = np.nonzero((depth_mm > 0) & (depth_mm <= max_depth_m * 1000.0))
    z = depth_mm[rows, cols].astype(np.float64) * 1e-3
    x = (cols - intrinsics.cx) * z / intrinsics.fx
    y = (rows - intrinsics.cy) * z / intrinsics.fy
    return np.column_stack((x, y, z)), np.column_stack((rows, cols))


def subsample(
    depth_mm: npt.NDArray[np.uint16], intrinsics: CameraIntrinsics, *, step: int
) -> tuple[npt.NDArray[np.uint16], CameraIntrinsics]:
    """Every ``step``-th row and column of a depth image, with the matching camera model."""
    if step < 1:
        raise ObjectLabellingError(f"subsampling step must be >= 1, got {step}")
    check_depth(depth_mm, intrinsics)
    sub = depth_mm[::step, ::step]
    return sub, CameraIntrinsics(
        intrinsics.fx / step,
        intrinsics.fy / step,
        (intrinsics.cx + 0.5) / step - 0.5,
        (intrinsics.cy + 0.5) / step - 0.5,
        sub.shape[1],
        sub.shape[0],
    )

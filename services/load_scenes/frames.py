"""Camera models and depth images from ROS messages, for the load-scene stage.

The object-labelling stage reads the same messages (``services.object_labelling.camera`` and ``.frames``); a stage
imports only ``shared`` and itself, so the few lines are here again (candidates for ``shared/``).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
import numpy.typing as npt
from rosbags.typesys.stores.ros2_jazzy import sensor_msgs__msg__CameraInfo as CameraInfo
from rosbags.typesys.stores.ros2_jazzy import sensor_msgs__msg__Image as Image

from services.load_scenes.errors import LoadScenesError

_DEPTH_ENCODINGS = ("16UC1", "mono16")


class Intrinsics(NamedTuple):
    """Pinhole intrinsics in pixels; the optical frame has x right, y down, z forward."""

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int


def intrinsics_from_camera_info(message: CameraInfo) -> Intrinsics:
    """The pinhole model of a sensor_msgs/CameraInfo (its ``k`` matrix and size), checked."""
    k = np.asarray(message.k, dtype=np.float64).ravel()
    if k.size != 9:
        raise LoadScenesError(f"CameraInfo k must have 9 entries, got {k.size}")
    fx, fy, cx, cy = float(k[0]), float(k[4]), float(k[2]), float(k[5])
    width, height = int(message.width), int(message.height)
    if not all(map(math.isfinite, (fx, fy, cx, cy))) or fx <= 0 or fy <= 0 or width <= 0 or height <= 0:
        raise LoadScenesError(f"camera model fx={fx}, fy={fy}, cx={cx}, cy={cy}, {width}x{height} px is not usable")
    return Intrinsics(fx, fy, cx, cy, width, height)


def decode_depth(message: Image) -> npt.NDArray[np.uint16]:
    """(h, w) uint16 millimetres of a ``16UC1`` sensor_msgs/Image, checked against its size and step."""
    if message.encoding not in _DEPTH_ENCODINGS:
        raise LoadScenesError(f"depth image encoding {message.encoding!r} is not 16UC1 (millimetres)")
    height, width, step = int(message.height), int(message.width), int(message.step)
    data = np.asarray(message.data, dtype=np.uint8).ravel()
    if height <= 0 or width <= 0 or step < 2 * width or data.size < step * height:
        raise LoadScenesError(f"depth image of {width}x{height} px needs step >= {2 * width} and {step * height} "
                              f"bytes, got step {step} and {data.size} bytes")
    rows = np.ascontiguousarray(data[: step * height].reshape(height, step)[:, : 2 * width])
    return rows.view(np.dtype(">u2" if message.is_bigendian else "<u2")).reshape(height, width).astype(np.uint16)

"""Decode sensor_msgs/Image payloads into validated RGB and depth arrays."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from rosbags.typesys.stores.ros2_jazzy import sensor_msgs__msg__Image as Image

from services.object_labelling.errors import ObjectLabellingError

_RGB_ENCODINGS = {"rgb8": False, "bgr8": True}
_DEPTH_ENCODINGS = ("16UC1", "mono16")


def _rows(message: Image, bytes_per_pixel: int) -> npt.NDArray[np.uint8]:
    height, width, step = int(message.height), int(message.width), int(message.step)
    data = np.asarray(message.data, dtype=np.uint8).ravel()
    if height <= 0 or width <= 0:
        raise ObjectLabellingError(f"image is {width}x{height} px")
    if step < width * bytes_per_pixel or data.size < step * height:
        raise ObjectLabellingError(
            f"image of {width}x{height} px at {bytes_per_pixel} B/px needs step >= {width * bytes_per_pixel} "
            f"and {step * height} bytes, got step {step} and {data.size} bytes"
        )
    return data[: step * height].reshape(height, step)[:, : width * bytes_per_pixel]


def decode_rgb(message: Image) -> npt.NDArray[np.uint8]:
    """(h, w, 3) uint8 RGB of an ``rgb8`` or ``bgr8`` sensor_msgs/Image."""
    if message.encoding not in _RGB_ENCODINGS:
        raise ObjectLabellingError(f"colour image encoding {message.encoding!r} is not one of {sorted(_RGB_ENCODINGS)}")
    rgb = _rows(message, 3).reshape(int(message.height), int(message.width), 3)
    return np.ascontiguousarray(rgb[:, :, ::-1] if _RGB_ENCODINGS[message.encoding] else rgb)


def decode_depth(message: Image) -> npt.NDArray[np.uint16]:
    """(h, w) uint16 millimetres of a ``16UC1`` sensor_msgs/Image."""
    if message.encoding not in _DEPTH_ENCODINGS:
        raise ObjectLabellingError(f"depth image encoding {message.encoding!r} is not 16UC1 (millimetres)")
    dtype = np.dtype(">u2" if message.is_bigendian else "<u2")
    rows = np.ascontiguousarray(_rows(message, 2))
    return rows.view(dtype).reshape(int(message.height), int(message.width)).astype(np.uint16)

from __future__ import annotations

import numpy as np
import pytest
from rosbags.typesys.stores.ros2_jazzy import sensor_msgs__msg__Image as Image

from services.object_labelling import ObjectLabellingError, decode_depth, decode_rgb
from shared.messages import header


def _message(array: np.ndarray, encoding: str, *, bigendian: bool = False) -> Image:
    height, width = array.shape[:2]
    data = np.ascontiguousarray(array).view(np.uint8).ravel()
    return Image(header=header(0, "camera"), height=height, width=width, step=data.size // height, encoding=encoding,
                 is_bigendian=int(bigendian), data=data)


def test_decode_rgb_reads_rgb8_and_swaps_bgr8() -> None:
    rgb = np.random.default_rng(0).integers(0, 256, (4, 5, 3), dtype=np.uint8)
    np.testing.assert_array_equal(decode_rgb(_message(rgb, "rgb8")), rgb)
    np.testing.assert_array_equal(decode_rgb(_message(rgb[:, :, ::-1], "bgr8")), rgb)


def test_decode_depth_reads_both_byte_orders() -> None:
    depth = np.array([[0, 1000], [2500, 65535]], dtype=np.uint16)
    np.testing.assert_array_equal(decode_depth(_message(depth, "16UC1")), depth)
    np.testing.assert_array_equal(decode_depth(_message(depth.astype(">u2"), "16UC1", bigendian=True)), depth)


def test_decoders_reject_wrong_encodings_and_short_data() -> None:
    with pytest.raises(ObjectLabellingError, match="32FC1"):
        decode_depth(_message(np.zeros((2, 2), np.float32), "32FC1"))
    with pytest.raises(ObjectLabellingError, match="mono8"):
        decode_rgb(_message(np.zeros((2, 2), np.uint8), "mono8"))
    short = _message(np.zeros((4, 4, 3), np.uint8), "rgb8")
    short.data = short.data[:-1]
    with pytest.raises(ObjectLabellingError, match="bytes"):
        decode_rgb(short)

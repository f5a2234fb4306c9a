"""LaserScan messages to validated arrays."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from services.occupancy_mapping import OccupancyMappingError, scan_angles, scan_arrays
from shared.messages import LASER_SCAN, message_class


def _scan(n: int = 5, **fields: Any) -> Any:
    values: dict[str, Any] = {
        "header": message_class("std_msgs/msg/Header")(
            stamp=message_class("builtin_interfaces/msg/Time")(sec=2, nanosec=5), frame_id="/laser"
        ),
        "angle_min": -1.0,
        "angle_max": 1.0,
        "angle_increment": 0.5,
        "time_increment": 0.0,
        "scan_time": 0.1,
        "range_min": 0.1,
        "range_max": 10.0,
        "ranges": np.array([1.0, np.nan, np.inf, 2.0, 3.0][:n], np.float32),
        "intensities": np.zeros(0, np.float32),
    }
    values.update(fields)
    return message_class(LASER_SCAN)(**values)


def test_scan_angles_step_from_angle_min() -> None:
    np.testing.assert_allclose(
        scan_angles(-math.pi, math.pi / 2, 4), [-math.pi, -math.pi / 2, 0, math.pi / 2]
    )
    assert scan_angles(0.0, 0.1, 0).size == 0


def test_scan_arrays_keeps_nan_and_inf_and_strips_frame_slash() -> None:
    arrays = scan_arrays(_scan())
    assert arrays.frame_id == "laser"
    assert arrays.stamp_ns == 2_000_000_005
    assert np.isnan(arrays.ranges[1]) and np.isinf(arrays.ranges[2])
    np.testing.assert_allclose(arrays.angles, [-1.0, -0.5, 0.0, 0.5, 1.0])


@pytest.mark.parametrize(
    ("fields", "match"),
    [
        ({"ranges": np.zeros(0, np.float32)}, "no ranges"),
        ({"angle_increment": 0.0}, "angle_increment 0"),
        ({"angle_max": 3.0}, "angle_max is 3.0000"),
        ({"range_min": 5.0, "range_max": 1.0}, r"range interval \[5.0, 1.0\]"),
    ],
)
def test_scan_arrays_rejects_inconsistent_scans(fields: dict[str, Any], match: str) -> None:
    with pytest.raises(OccupancyMappingError, match=match):
        scan_arrays(_scan(**fields))


def test_scan_angles_rejects_non_finite() -> None:
    with pytest.raises(OccupancyMappingError, match="finite"):
        scan_angles(math.nan, 0.1, 3)

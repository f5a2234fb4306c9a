"""Turn sensor_msgs/LaserScan messages into validated range and bearing arrays."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import numpy.typing as npt
from rosbags.typesys.stores.ros2_jazzy import sensor_msgs__msg__LaserScan as LaserScan

from services.occupancy_mapping.errors import OccupancyMappingError
from shared.messages import stamp_ns


class ScanArrays(NamedTuple):
    """A laser scan as arrays, in the scan's own frame.

    ``ranges`` and ``angles`` are float64 of equal length (metres, radians); ``ranges`` may hold
    NaN and +/-inf exactly as the driver sent them.
    """

    ranges: npt.NDArray[np.float64]
    angles: npt.NDArray[np.float64]
    range_min_m: float
    range_max_m: float
    frame_id: str
    stamp_ns: int


def scan_angles(angle_min_rad: float, angle_increment_rad: float, n: int) -> npt.NDArray[np.float64]:
    """Bearings of ``n`` beams starting at ``angle_min_rad`` with step ``angle_increment_rad``.

    Examples
    --------
    >>> scan_angles(-1.0, 0.5, 5).tolist()
    [-1.0, -0.5, 0.0, 0.5, 1.0]
    """
    if n < 0:
        raise OccupancyMappingError(f"beam count must be >= 0, got {n}")
    if not (np.isfinite(angle_min_rad) and np.isfinite(angle_increment_rad)):
        raise OccupancyMappingError(
            f"scan angles must be finite, got angle_min={angle_min_rad}, "
            f"angle_increment={angle_increment_rad}"
        )
    return angle_min_rad + angle_increment_rad * np.arange(n, dtype=np.float64)


def scan_arrays(message: LaserScan) -> ScanArrays:
    """Validated arrays of a sensor_msgs/LaserScan ``message``.

    Raises :class:`OccupancyMappingError` for an empty scan, a zero angle increment, a
    non-positive or inverted range interval, or an ``angle_max`` that disagrees with the beam
    count by more than one increment.
    """
    ranges = np.asarray(message.ranges, dtype=np.float64).ravel()
    n = ranges.size
    if n == 0:
        raise OccupancyMappingError("scan has no ranges")
    increment = float(message.angle_increment)
    if increment == 0.0 and n > 1:
        raise OccupancyMappingError(f"scan of {n} beams has angle_increment 0")
    angles = scan_angles(float(message.angle_min), increment, n)
    if n > 1 and abs(angles[-1] - float(message.angle_max)) > abs(increment) * 1.01 + 1e-6:
        raise OccupancyMappingError(
            f"scan of {n} beams from {message.angle_min:.4f} rad by {increment:.6f} rad ends at "
            f"{angles[-1]:.4f} rad, but angle_max is {message.angle_max:.4f} rad"
        )
    range_min, range_max = float(message.range_min), float(message.range_max)
    if not (np.isfinite(range_min) and np.isfinite(range_max) and 0.0 <= range_min < range_max):
        raise OccupancyMappingError(f"scan range interval [{range_min}, {range_max}] is not usable")
    return ScanArrays(ranges, angles, range_min, range_max, message.header.frame_id.lstrip("/"),
                      stamp_ns(message.header))

"""Simulated laser scans in a square room, for occupancy-mapping tests and benchmarks."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt


def room_ranges(
    x_m: float,
    y_m: float,
    yaw_rad: float,
    angles: npt.NDArray[np.float64],
    *,
    half_size_m: float = 3.0,
    centre_x_m: float = 0.0,
    centre_y_m: float = 0.0,
) -> npt.NDArray[np.float64]:
    """Exact ranges from (x, y, yaw) to the walls of an axis-aligned square room."""
    bearing = angles + yaw_rad
    c, s = np.cos(bearing), np.sin(bearing)
    dx, dy = x_m - centre_x_m, y_m - centre_y_m
    with np.errstate(divide="ignore", invalid="ignore"):
        tx = np.where(
            c > 1e-12, (half_size_m - dx) / c, np.where(c < -1e-12, (-half_size_m - dx) / c, np.inf)
        )
        ty = np.where(
            s > 1e-12, (half_size_m - dy) / s, np.where(s < -1e-12, (-half_size_m - dy) / s, np.inf)
        )
    return np.minimum(tx, ty)

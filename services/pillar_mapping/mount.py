"""Where the fisheye sits on the vehicle, and image bearings turned into vehicle bearings."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from shared.transforms import Transform, to_matrix

FloatArray = npt.NDArray[np.float64]

# The default downward mount: image up is vehicle forward, image right is vehicle right, so
# optical (x, y, z) = vehicle (-y, -x, -z).
_DEFAULT_ROTATION = np.array([[0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


class CameraMount(NamedTuple):
    """The optical frame in the vehicle frame: ``rotation`` (3, 3) maps optical vectors to vehicle ones;
    ``offset_xy_m`` (2,) is the lens centre's horizontal position on the vehicle, metres."""

    rotation: FloatArray
    offset_xy_m: FloatArray


def default_mount() -> CameraMount:
    """Camera at the vehicle origin looking straight down, image up = vehicle forward."""
    return CameraMount(_DEFAULT_ROTATION.copy(), np.zeros(2))


def mount_from_transform(vehicle_from_optical: Transform) -> CameraMount:
    """A :class:`CameraMount` from the tf transform of the optical frame into the vehicle frame."""
    matrix = to_matrix(vehicle_from_optical)
    return CameraMount(matrix[:3, :3].copy(), matrix[:2, 3].copy())


def vehicle_bearings(mount: CameraMount, optical_bearings_rad: npt.ArrayLike) -> FloatArray:
    """Bearings (radians, from vehicle +x, counter-clockwise) of uprights at optical azimuths.

    An upright parallel to the optical axis projects onto the radial line at its azimuth; its
    horizontal direction from the lens is that azimuth's optical direction rotated into the
    vehicle frame.
    """
    azimuth = np.asarray(optical_bearings_rad, dtype=np.float64)
    direction = mount.rotation[:2, :2] @ np.stack([np.cos(azimuth), np.sin(azimuth)])
    return np.asarray(np.arctan2(direction[1], direction[0]))


def sensor_pose(mount: CameraMount, vehicle_pose: FloatArray) -> FloatArray:
    """(x, y, yaw) of the lens centre in the map, bearings measured from the vehicle heading."""
    x, y, yaw = vehicle_pose
    c, s = np.cos(yaw), np.sin(yaw)
    ox, oy = mount.offset_xy_m
    return np.array([x + c * ox - s * oy, y + s * ox + c * oy, yaw])

"""The glue between a robot's bus traffic and the bearing-only mapper: decoded frames, their poses from tf.

A fisheye image waits for tf (:class:`Frame`); once tf reaches its stamp, :func:`frame_pose` looks up the
vehicle in the map, the camera's mount on the vehicle and, where tf has it, the vehicle in the odometry
frame, all at the image stamp. :func:`resumed_landmarks` turns the pillars stored before a restart back
into seed landmarks.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
import numpy.typing as npt
from rosbags.typesys.stores.ros2_jazzy import sensor_msgs__msg__Image as Image

from services.pillar_mapping.bag import image_bgr
from services.pillar_mapping.camera import FisheyeCamera
from services.pillar_mapping.errors import PillarMappingError
from services.pillar_mapping.mapper import LandmarkMap
from services.pillar_mapping.mount import CameraMount, mount_from_transform, sensor_pose
from shared.messages import stamp_ns
from shared.transforms import TransformBuffer, sensor_pose_2d

FloatArray = npt.NDArray[np.float64]

RESUMED_SIGMA_M = 0.03
"""Standard deviation given to a pillar read back from the store, metres."""
RESUMED_OBSERVATIONS = 10
"""Observations credited to a pillar read back from the store (enough to count as confirmed)."""


class Frame(NamedTuple):
    """A decoded image waiting for tf: stamp and wall-clock arrival (ns), optical frame, BGR pixels."""

    stamp_ns: int
    received_ns: int
    frame_id: str
    pixels: npt.NDArray[np.uint8]


@dataclass
class RobotView:
    """What the worker knows of one robot: its tf, its camera, and the image waiting for tf."""

    tf: TransformBuffer = field(default_factory=lambda: TransformBuffer(cache_s=10.0))
    camera: FisheyeCamera | None = None
    waiting: Frame | None = None


class FramePose(NamedTuple):
    """Where a frame was taken: the lens centre (x, y, yaw) in the map and, if tf has it, in the odometry
    frame (metres, radians), and the camera's mount on the vehicle."""

    sensor: FloatArray
    odometry: FloatArray | None
    mount: CameraMount


def robot_frame(namespace: str, name: str) -> str:
    """tf frame ``name`` of the robot under ``namespace`` (prefixed with it, as its tree is)."""
    return f"{namespace}/{name}" if namespace else name


def decode_frame(message: Image, received_ns: int, camera: FisheyeCamera | None) -> Frame:
    """The image's pixels as a :class:`Frame`; :class:`PillarMappingError` if its encoding or size is unusable."""
    try:
        pixels = image_bgr(message)
    except ValueError as err:
        raise PillarMappingError(str(err)) from err
    if camera is not None and pixels.shape[:2] != (camera.height, camera.width):
        raise PillarMappingError(f"image is {pixels.shape[1]}x{pixels.shape[0]} but the calibration is for "
                                 f"{camera.width}x{camera.height}")
    return Frame(stamp_ns(message.header), received_ns, str(message.header.frame_id), pixels)


def frame_due(robot: RobotView, frame: Frame, *, namespace: str, map_frame: str, base_frame: str, now_ns: int,
              wait_s: float) -> bool:
    """Whether ``frame`` is to be mapped now: the robot's tf has reached its stamp, or it has waited ``wait_s``
    seconds since it arrived (wall clock ``now_ns``)."""
    newest = robot.tf.newest_stamp_ns(map_frame, robot_frame(namespace, base_frame))
    return (newest is not None and newest >= frame.stamp_ns) or (now_ns - frame.received_ns) / 1e9 >= wait_s


def frame_pose(tf: TransformBuffer, frame: Frame, *, namespace: str, map_frame: str, base_frame: str,
               odom_frame: str) -> FramePose:
    """The pose of ``frame`` from the robot's ``tf`` at its stamp.

    Raises
    ------
    LookupError, ValueError
        When tf has no map pose of the vehicle or no mount of the camera at the stamp (a missing odometry
        pose only leaves ``odometry`` None).
    """
    base = robot_frame(namespace, base_frame)
    vehicle = sensor_pose_2d(tf.lookup(map_frame, base, frame.stamp_ns))
    mount = mount_from_transform(tf.lookup(base, frame.frame_id, frame.stamp_ns))
    try:
        odom = sensor_pose_2d(tf.lookup(robot_frame(namespace, odom_frame), base, frame.stamp_ns))
    except (LookupError, ValueError):
        odometry = None
    else:
        odometry = sensor_pose(mount, np.array(odom, dtype=np.float64))
    return FramePose(sensor_pose(mount, np.array(vehicle, dtype=np.float64)), odometry, mount)


def resumed_landmarks(points_xy_m: list[list[float]]) -> LandmarkMap:
    """Seed landmarks at stored pillar positions (n, 2), metres, each as precise and confirmed as a mapped one."""
    means = np.asarray(points_xy_m, dtype=np.float64).reshape(-1, 2)
    covs = np.tile(np.eye(2) * RESUMED_SIGMA_M**2, (len(means), 1, 1))
    return LandmarkMap(means, covs, np.full(len(means), RESUMED_OBSERVATIONS, dtype=np.int64))

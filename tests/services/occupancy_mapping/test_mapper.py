"""ScanMapper: scans placed by TF, odometry or a localisation pose topic."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from services.occupancy_mapping import OccupancyGrid
from services.occupancy_mapping.mapper import ScanMapper
from shared import messages
from tests.services.occupancy_mapping.simulate import room_ranges

cls = messages.message_class
ANGLES = np.linspace(-math.pi, math.pi, 360, endpoint=False)


def _header(stamp_ns: int, frame: str) -> Any:
    return cls("std_msgs/msg/Header")(
        stamp=cls("builtin_interfaces/msg/Time")(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9), frame_id=frame)


def _pose(x: float, y: float, yaw: float) -> Any:
    return cls("geometry_msgs/msg/Pose")(
        position=cls("geometry_msgs/msg/Point")(x=x, y=y, z=0.0),
        orientation=cls("geometry_msgs/msg/Quaternion")(x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2)))


def _odometry(stamp_ns: int, x: float, y: float, yaw: float) -> Any:
    zero = cls("geometry_msgs/msg/Vector3")(x=0.0, y=0.0, z=0.0)
    return cls(messages.ODOMETRY)(
        header=_header(stamp_ns, "odom"), child_frame_id="base_link",
        pose=cls("geometry_msgs/msg/PoseWithCovariance")(pose=_pose(x, y, yaw), covariance=np.zeros(36)),
        twist=cls("geometry_msgs/msg/TwistWithCovariance")(
            twist=cls("geometry_msgs/msg/Twist")(linear=zero, angular=zero), covariance=np.zeros(36)))


def _scan(stamp_ns: int, ranges: np.ndarray) -> Any:
    return cls(messages.LASER_SCAN)(
        header=_header(stamp_ns, "base_link"), angle_min=float(ANGLES[0]), angle_max=float(ANGLES[-1]),
        angle_increment=float(ANGLES[1] - ANGLES[0]), time_increment=0.0, scan_time=0.1, range_min=0.05,
        range_max=20.0, ranges=ranges.astype(np.float32), intensities=np.zeros(0, np.float32))


def test_localisation_poses_correct_drifting_odometry_into_the_map_frame() -> None:
    mapper = ScanMapper(OccupancyGrid(resolution_m=0.05))
    for i in range(40):
        stamp = 10**9 + i * 10**8
        x, y, yaw = 1.0 * math.cos(i / 6), 1.0 * math.sin(i / 6), i / 6
        drift = 0.02 * i  # odometry wanders off by up to 0.8 m and 0.4 rad
        mapper.add_odometry("robot1", _odometry(stamp, x + drift, y - drift, yaw + drift / 2))
        mapper.add_map_pose("robot1", cls(messages.POSE_STAMPED)(header=_header(stamp, "map"), pose=_pose(x, y, yaw)),
                            base_frame="base_link")
        mapper.add_scan("robot1", _scan(stamp, room_ranges(x, y, yaw, ANGLES)))
    mapper.add_odometry("robot1", _odometry(10**9 + 40 * 10**8, 1.0, 0.0, 0.0))
    mapper.drain(final=True)
    assert mapper.counts["scans_integrated"] >= 38
    layer = mapper.grid.to_layer("occupancy")
    rows, cols = np.nonzero(layer.data > 50)
    xs = layer.origin_x_m + (cols + 0.5) * layer.resolution_m
    ys = layer.origin_y_m + (rows + 0.5) * layer.resolution_m
    off_wall = np.minimum(np.abs(np.abs(xs) - 3.0), np.abs(np.abs(ys) - 3.0))
    assert np.mean(off_wall <= 0.1) > 0.95  # walls where the room is, not where odometry thought


def test_a_pose_without_odometry_places_the_robot_directly() -> None:
    mapper = ScanMapper(OccupancyGrid(resolution_m=0.05))
    for i in range(5):
        stamp = 10**9 + i * 10**8
        mapper.add_map_pose("", cls(messages.POSE_STAMPED)(header=_header(stamp, "map"), pose=_pose(0.5, 0.0, 0.0)),
                            base_frame="base_link")
        mapper.add_scan("", _scan(stamp, room_ranges(0.5, 0.0, 0.0, ANGLES)))
    mapper.drain(final=True)
    assert mapper.counts["scans_integrated"] == 5

"""Building a map from a rosbag2 the test writes itself."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer

from services.occupancy_mapping import OccupancyMappingError, build_map, build_map_with_stats
from shared.messages import LASER_SCAN, ODOMETRY, TF_MESSAGE, TYPESTORE, message_class, serialize
from shared.transforms import quaternion_from_yaw
from tests.services.occupancy_mapping.simulate import room_ranges

DATA = Path(__file__).resolve().parents[4] / "shared" / "data"
S = 1_000_000_000
MOUNT_YAW = math.pi / 2
N_BEAMS = 360


def _header(ns: int, frame: str) -> Any:
    stamp = message_class("builtin_interfaces/msg/Time")(sec=ns // S, nanosec=ns % S)
    return message_class("std_msgs/msg/Header")(stamp=stamp, frame_id=frame)


def _tf(ns: int, parent: str, child: str, *, x: float, y: float, yaw: float) -> Any:
    q = quaternion_from_yaw(yaw)
    return message_class("geometry_msgs/msg/TransformStamped")(
        header=_header(ns, parent),
        child_frame_id=child,
        transform=message_class("geometry_msgs/msg/Transform")(
            translation=message_class("geometry_msgs/msg/Vector3")(x=x, y=y, z=0.2),
            rotation=message_class("geometry_msgs/msg/Quaternion")(x=q[0], y=q[1], z=q[2], w=q[3]),
        ),
    )


def _odom(ns: int, x: float, y: float, yaw: float) -> Any:
    q = quaternion_from_yaw(yaw)
    v = message_class("geometry_msgs/msg/Vector3")
    return message_class(ODOMETRY)(
        header=_header(ns, "odom"),
        child_frame_id="base_link",
        pose=message_class("geometry_msgs/msg/PoseWithCovariance")(
            pose=message_class("geometry_msgs/msg/Pose")(
                position=message_class("geometry_msgs/msg/Point")(x=x, y=y, z=0.0),
                orientation=message_class("geometry_msgs/msg/Quaternion")(x=q[0], y=q[1], z=q[2], w=q[3]),
            ),
            covariance=np.zeros(36),
        ),
        twist=message_class("geometry_msgs/msg/TwistWithCovariance")(
            twist=message_class("geometry_msgs/msg/Twist")(
                linear=v(x=0.0, y=0.0, z=0.0), angular=v(x=0.0, y=0.0, z=0.0)
            ),
            covariance=np.zeros(36),
        ),
    )


def _write_room_bag(path: Path, *, namespace: str, storage: StoragePlugin) -> None:
    """A robot spinning and driving in a 6 m room; laser turned 90 deg; scans logged before poses."""
    angles = np.linspace(-math.pi, math.pi, N_BEAMS, endpoint=False)
    with Writer(path, version=9, storage_plugin=storage) as writer:
        scan_c = writer.add_connection(f"{namespace}/scan", LASER_SCAN, typestore=TYPESTORE)
        odom_c = writer.add_connection(f"{namespace}/odom", ODOMETRY, typestore=TYPESTORE)
        static_c = writer.add_connection(f"{namespace}/tf_static", TF_MESSAGE, typestore=TYPESTORE)
        tf_cls = message_class(TF_MESSAGE)
        writer.write(
            static_c,
            1,
            serialize(
                tf_cls(transforms=[_tf(0, "base_link", "laser", x=0.1, y=0.0, yaw=MOUNT_YAW)]), TF_MESSAGE
            ),
        )
        for i in range(40):
            ns = S + i * S // 10
            x, y, yaw = -1.5 + i * 0.07, 0.5 * math.sin(i / 6), i * 0.15
            lx, ly = x + 0.1 * math.cos(yaw), y + 0.1 * math.sin(yaw)
            ranges = room_ranges(lx, ly, yaw + MOUNT_YAW, angles, half_size_m=3.02).astype(np.float32)
            ranges[::17] = np.nan
            scan = message_class(LASER_SCAN)(
                header=_header(ns, "laser"),
                angle_min=float(angles[0]),
                angle_max=float(angles[-1]),
                angle_increment=float(angles[1] - angles[0]),
                time_increment=0.0,
                scan_time=0.1,
                range_min=0.05,
                range_max=20.0,
                ranges=ranges,
                intensities=np.zeros(0, np.float32),
            )
            writer.write(scan_c, ns, serialize(scan, LASER_SCAN))
            writer.write(odom_c, ns + S // 50, serialize(_odom(ns, x, y, yaw), ODOMETRY))


@pytest.mark.parametrize(
    ("namespace", "storage"), [("", StoragePlugin.SQLITE3), ("/robot1", StoragePlugin.MCAP)]
)
def test_build_map_places_walls_where_the_room_is(
    tmp_path: Path, namespace: str, storage: StoragePlugin
) -> None:
    bag = tmp_path / "bag"
    _write_room_bag(bag, namespace=namespace, storage=storage)
    grid, stats = build_map_with_stats(bag, resolution_m=0.05)
    assert stats.scans_integrated == 40 and stats.scans_dropped == 0
    occ = grid.occupancy()

    def at(x: float, y: float) -> np.ndarray:
        r = int((y - grid.origin_y_m) // 0.05)
        c = int((x - grid.origin_x_m) // 0.05)
        return occ[r - 1 : r + 2, c - 1 : c + 2]

    for t in np.arange(-2.5, 2.5, 0.25):
        for x, y in ((3.02, t), (-3.02, t), (t, 3.02), (t, -3.02)):
            assert at(x, y).max() > 65, (x, y)
    assert 0 <= at(0.0, 0.0).max() < 25
    assert at(4.0, 0.0).max() == -1


def test_build_map_rejects_missing_bag_and_missing_scan_topic(tmp_path: Path) -> None:
    with pytest.raises(OccupancyMappingError, match="does not exist"):
        build_map(tmp_path / "nope")
    bag = tmp_path / "bag"
    _write_room_bag(bag, namespace="", storage=StoragePlugin.SQLITE3)
    with pytest.raises(OccupancyMappingError, match="no LaserScan topic matching '/lidar'"):
        build_map(bag, scan_topic="/lidar")
    with pytest.raises(OccupancyMappingError, match="could be placed in fixed frame 'map'"):
        build_map(bag, fixed_frame="map")


@pytest.mark.skipif(
    not (DATA / "bags" / "mac_first_floor").is_dir(), reason="shared data folder ../shared/data absent"
)
def test_mac_bag_builds_a_map_in_odom() -> None:
    grid, stats = build_map_with_stats(DATA / "bags" / "mac_first_floor" / "bag", resolution_m=0.1)
    assert stats.scans_integrated >= 350
    assert np.count_nonzero(grid.occupancy() > 65) > 500

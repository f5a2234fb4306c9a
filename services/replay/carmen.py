"""Convert CARMEN laser logs (``FLASER`` lines) into a rosbag2 of LaserScan, Odometry and TF.

A ``FLASER`` line reads ``FLASER n r_1 .. r_n x y theta odom_x odom_y odom_theta ipc_timestamp
ipc_hostname logger_timestamp``: ``n`` ranges in metres over a 180 deg front field of view,
counter-clockwise from the robot's right, and the laser's (corrected) pose in the world.
CARMEN's convention for the beam layout (``carmen_laser_get_fov``): 181 and 361 beams span the
full 180 deg inclusive, 180 and 360 beams step 1 deg and 0.5 deg from -90 deg, last beam dropped.

The bag carries ``/scan`` (frame ``laser``), ``/odom`` (``odom`` -> ``base_link`` at the laser
pose), ``/tf`` with the same transform and a static identity ``base_link`` -> ``laser`` on
``/tf_static``, so ``build_map`` places every scan exactly at its logged pose.
"""

from __future__ import annotations

import gzip
import logging
import math
from collections.abc import Iterator
from pathlib import Path
from typing import Literal, NamedTuple

import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer, WriterError
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__Point as Point
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__Pose as Pose
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__PoseWithCovariance as PoseWithCovariance
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__Quaternion as Quaternion
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__Transform as Transform
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__TransformStamped as TransformStamped
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__Twist as Twist
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__TwistWithCovariance as TwistWithCovariance
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__Vector3 as Vector3
from rosbags.typesys.stores.ros2_jazzy import nav_msgs__msg__Odometry as Odometry
from rosbags.typesys.stores.ros2_jazzy import sensor_msgs__msg__LaserScan as LaserScan
from rosbags.typesys.stores.ros2_jazzy import std_msgs__msg__Header as Header
from rosbags.typesys.stores.ros2_jazzy import tf2_msgs__msg__TFMessage as TFMessage

from shared.messages import LASER_SCAN, ODOMETRY, TF_MESSAGE, TYPESTORE, header, serialize
from shared.transforms import quaternion_from_yaw

logger = logging.getLogger(__name__)

LASER_FRAME = "laser"
BASE_FRAME = "base_link"
ODOM_FRAME = "odom"


class CarmenError(ValueError):
    """A CARMEN log that cannot be converted."""


class CarmenImport(NamedTuple):
    """What :func:`import_carmen` wrote."""

    scans: int
    malformed_lines: int
    repaired_stamps: int


class _Flaser(NamedTuple):
    ranges: np.ndarray
    x_m: float
    y_m: float
    yaw_rad: float
    stamp_s: float


def beam_layout(n: int) -> tuple[float, float]:
    """(angle_min, angle_increment) in radians of an ``n``-beam CARMEN front laser (180 deg field of view)."""
    if n < 2:
        raise CarmenError(f"a laser line needs at least 2 beams, got {n}")
    if n % 2:
        return -math.pi / 2, math.pi / (n - 1)
    return -math.pi / 2, math.pi / n


def _lines(log_path: Path) -> Iterator[str]:
    opener = gzip.open if log_path.suffix == ".gz" else open
    try:
        with opener(log_path, "rt", encoding="ascii", errors="replace") as stream:
            yield from stream
    except FileNotFoundError as err:
        raise CarmenError(f"log {log_path} does not exist") from err
    except (OSError, EOFError) as err:
        raise CarmenError(f"log {log_path} is not readable: {err}") from err


def _parse_flaser(fields: list[str]) -> _Flaser:
    n = int(fields[1])
    if n < 2 or len(fields) < n + 2 + 9:
        raise ValueError(f"FLASER with {n} beams has {len(fields)} fields")
    values = np.array(fields[2 : n + 8], dtype=np.float64)
    ranges, pose = values[:n], values[n:]
    stamp = float(fields[n + 8])
    if not (np.all(np.isfinite(pose)) and np.all(np.isfinite(ranges))):
        raise ValueError("non-finite value")
    return _Flaser(ranges, float(pose[0]), float(pose[1]), float(pose[2]), stamp)


def _header(seconds: float, frame_id: str) -> Header:
    return header(round(seconds * 1e9), frame_id)


def _transform(seconds: float, parent: str, child: str, *, x: float, y: float, yaw: float) -> TransformStamped:
    q = quaternion_from_yaw(yaw)
    return TransformStamped(
        header=_header(seconds, parent),
        child_frame_id=child,
        transform=Transform(translation=Vector3(x=x, y=y, z=0.0), rotation=Quaternion(x=q[0], y=q[1], z=q[2], w=q[3])),
    )


def _scan(reading: _Flaser, seconds: float, max_range_m: float) -> LaserScan:
    n = reading.ranges.size
    angle_min, increment = beam_layout(n)
    ranges = np.where(reading.ranges >= max_range_m, np.inf, reading.ranges).astype(np.float32)
    return LaserScan(
        header=_header(seconds, LASER_FRAME),
        angle_min=angle_min,
        angle_max=angle_min + increment * (n - 1),
        angle_increment=increment,
        time_increment=0.0,
        scan_time=0.0,
        range_min=0.0,
        range_max=max_range_m,
        ranges=ranges,
        intensities=np.zeros(0, dtype=np.float32),
    )


def _odometry(reading: _Flaser, seconds: float) -> Odometry:
    q = quaternion_from_yaw(reading.yaw_rad)
    return Odometry(
        header=_header(seconds, ODOM_FRAME),
        child_frame_id=BASE_FRAME,
        pose=PoseWithCovariance(
            pose=Pose(position=Point(x=reading.x_m, y=reading.y_m, z=0.0),
                      orientation=Quaternion(x=q[0], y=q[1], z=q[2], w=q[3])),
            covariance=np.zeros(36),
        ),
        twist=TwistWithCovariance(
            twist=Twist(linear=Vector3(x=0.0, y=0.0, z=0.0), angular=Vector3(x=0.0, y=0.0, z=0.0)),
            covariance=np.zeros(36),
        ),
    )


def _topic(namespace: str, name: str) -> str:
    prefix = namespace.strip("/")
    return f"/{prefix}/{name}" if prefix else f"/{name}"


def import_carmen(
    log_path: Path,
    out_path: Path,
    *,
    storage: Literal["mcap", "sqlite3"] = "mcap",
    namespace: str = "",
    max_range_m: float = 81.9,
    fallback_period_s: float = 0.1,
) -> CarmenImport:
    """Write the ``FLASER`` lines of a CARMEN log (``.log`` or ``.log.gz``) as a rosbag2.

    Parameters
    ----------
    log_path : Path
        The CARMEN log.
    out_path : Path
        rosbag2 directory to create (must not exist).
    storage : {"mcap", "sqlite3"}
        rosbag2 storage plugin.
    namespace : str
        Topic prefix, e.g. ``"robot1"`` gives ``/robot1/scan``.
    max_range_m : float
        Ranges at or beyond this mean "no return" and are written as ``+inf``.
    fallback_period_s : float
        Some logs carry zero, garbage or too-coarse timestamps; a stamp that does not increase
        is replaced by the previous one plus this period, in seconds (counted in the result).

    Returns
    -------
    CarmenImport
        Scans written, malformed lines skipped, stamps repaired.
    """
    log_path, out_path = Path(log_path), Path(out_path)
    if storage not in {"mcap", "sqlite3"}:
        raise CarmenError(f"storage must be 'mcap' or 'sqlite3', got {storage!r}")
    if not (max_range_m > 0 and fallback_period_s > 0):
        raise CarmenError("max_range_m and fallback_period_s must be positive")
    readings: list[_Flaser] = []
    malformed = 0
    for line in _lines(log_path):
        fields = line.split()
        if not fields or fields[0] != "FLASER":
            continue
        try:
            readings.append(_parse_flaser(fields))
        except ValueError:
            malformed += 1
    if not readings:
        raise CarmenError(f"log {log_path} has no usable FLASER lines ({malformed} malformed)")
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    repaired = 0
    previous = -math.inf
    try:
        with Writer(out_path, version=9, storage_plugin=plugin) as writer:
            scan_conn = writer.add_connection(_topic(namespace, "scan"), LASER_SCAN, typestore=TYPESTORE)
            odom_conn = writer.add_connection(_topic(namespace, "odom"), ODOMETRY, typestore=TYPESTORE)
            tf_conn = writer.add_connection(_topic(namespace, "tf"), TF_MESSAGE, typestore=TYPESTORE)
            static_conn = writer.add_connection(
                _topic(namespace, "tf_static"), TF_MESSAGE, typestore=TYPESTORE
            )
            for reading in readings:
                seconds = reading.stamp_s
                if not (math.isfinite(seconds) and seconds > previous and seconds - previous > 1e-6):
                    seconds = (previous if math.isfinite(previous) else 0.0) + fallback_period_s
                    repaired += 1
                previous = seconds
                ns = round(seconds * 1e9)
                if reading is readings[0]:
                    static = TFMessage(
                        transforms=[_transform(seconds, BASE_FRAME, LASER_FRAME, x=0.0, y=0.0, yaw=0.0)]
                    )
                    writer.write(static_conn, ns, serialize(static, TF_MESSAGE))
                tf = TFMessage(
                    transforms=[
                        _transform(
                            seconds, ODOM_FRAME, BASE_FRAME, x=reading.x_m, y=reading.y_m, yaw=reading.yaw_rad
                        )
                    ]
                )
                writer.write(tf_conn, ns, serialize(tf, TF_MESSAGE))
                writer.write(odom_conn, ns, serialize(_odometry(reading, seconds), ODOMETRY))
                writer.write(scan_conn, ns, serialize(_scan(reading, seconds, max_range_m), LASER_SCAN))
    except (WriterError, OSError) as err:
        raise CarmenError(f"cannot write bag {out_path}: {err}") from err
    result = CarmenImport(len(readings), malformed, repaired)
    logger.info("imported %s into %s: %s", log_path, out_path, result)
    return result

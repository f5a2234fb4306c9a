"""ROS 2 messages of simulated sensor data, built with the shared typestore's classes."""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from shared.messages import CAMERA_INFO, IMAGE, LASER_SCAN, ODOMETRY, POSE_STAMPED, TF_MESSAGE, message_class
from shared.transforms import quaternion_from_yaw

_Time = message_class("builtin_interfaces/msg/Time")
_Header = message_class("std_msgs/msg/Header")
_Vector3 = message_class("geometry_msgs/msg/Vector3")
_Point = message_class("geometry_msgs/msg/Point")
_Quaternion = message_class("geometry_msgs/msg/Quaternion")
_Pose = message_class("geometry_msgs/msg/Pose")
_Twist = message_class("geometry_msgs/msg/Twist")
_Transform = message_class("geometry_msgs/msg/Transform")
_TransformStamped = message_class("geometry_msgs/msg/TransformStamped")
_PoseWithCovariance = message_class("geometry_msgs/msg/PoseWithCovariance")
_TwistWithCovariance = message_class("geometry_msgs/msg/TwistWithCovariance")
_RegionOfInterest = message_class("sensor_msgs/msg/RegionOfInterest")


def header(stamp_ns: int, frame_id: str) -> Any:
    """std_msgs/Header at ``stamp_ns`` nanoseconds."""
    sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
    return _Header(stamp=_Time(sec=sec, nanosec=nanosec), frame_id=frame_id)


def _quaternion(q: npt.NDArray[np.float64]) -> Any:
    return _Quaternion(x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3]))


def transform_stamped(stamp_ns: int, parent: str, child: str, translation: tuple[float, float, float],
                      rotation_xyzw: npt.NDArray[np.float64]) -> Any:
    """geometry_msgs/TransformStamped of ``child`` in ``parent``."""
    return _TransformStamped(
        header=header(stamp_ns, parent), child_frame_id=child,
        transform=_Transform(translation=_Vector3(x=float(translation[0]), y=float(translation[1]),
                                                  z=float(translation[2])),
                             rotation=_quaternion(rotation_xyzw)))


def planar_transform(stamp_ns: int, parent: str, child: str, pose: npt.NDArray[np.float64]) -> Any:
    """TransformStamped of a planar pose (x, y, yaw)."""
    return transform_stamped(stamp_ns, parent, child, (pose[0], pose[1], 0.0), quaternion_from_yaw(float(pose[2])))


def tf_message(transforms: list[Any]) -> tuple[str, Any]:
    """(type, tf2_msgs/TFMessage) of ``transforms``."""
    return TF_MESSAGE, message_class(TF_MESSAGE)(transforms=transforms)


def pose_stamped(stamp_ns: int, frame_id: str, pose: npt.NDArray[np.float64]) -> tuple[str, Any]:
    """(type, geometry_msgs/PoseStamped) of a planar pose."""
    return POSE_STAMPED, message_class(POSE_STAMPED)(
        header=header(stamp_ns, frame_id),
        pose=_Pose(position=_Point(x=float(pose[0]), y=float(pose[1]), z=0.0),
                   orientation=_quaternion(quaternion_from_yaw(float(pose[2])))))


def odometry(stamp_ns: int, frame_id: str, child_frame_id: str, pose: npt.NDArray[np.float64],
             twist: npt.NDArray[np.float64], *, position_var_m2: float, yaw_var_rad2: float) -> tuple[str, Any]:
    """(type, nav_msgs/Odometry) of a planar pose and (forward speed, turn rate) twist."""
    covariance = np.zeros(36)
    covariance[[0, 7]] = position_var_m2
    covariance[[14, 21, 28]] = 1e6  # z, roll, pitch are not estimated
    covariance[35] = yaw_var_rad2
    twist_cov = np.diag([1e-4, 1e-4, 1e6, 1e6, 1e6, 1e-4]).ravel()
    _, message = pose_stamped(stamp_ns, frame_id, pose)
    return ODOMETRY, message_class(ODOMETRY)(
        header=header(stamp_ns, frame_id), child_frame_id=child_frame_id,
        pose=_PoseWithCovariance(pose=message.pose, covariance=covariance),
        twist=_TwistWithCovariance(
            twist=_Twist(linear=_Vector3(x=float(twist[0]), y=0.0, z=0.0),
                         angular=_Vector3(x=0.0, y=0.0, z=float(twist[1]))), covariance=twist_cov))


def laser_scan(stamp_ns: int, frame_id: str, *, angle_min_rad: float, angle_increment_rad: float,
               scan_time_s: float, range_min_m: float, range_max_m: float, ranges: npt.NDArray[np.float64],
               intensities: npt.NDArray[np.float64]) -> tuple[str, Any]:
    """(type, sensor_msgs/LaserScan); beams without a return are +inf (REP 117)."""
    n = len(ranges)
    return LASER_SCAN, message_class(LASER_SCAN)(
        header=header(stamp_ns, frame_id), angle_min=angle_min_rad,
        angle_max=angle_min_rad + (n - 1) * angle_increment_rad, angle_increment=angle_increment_rad,
        time_increment=0.0, scan_time=scan_time_s, range_min=range_min_m, range_max=range_max_m,
        ranges=np.asarray(ranges, np.float32), intensities=np.asarray(intensities, np.float32))


def image(stamp_ns: int, frame_id: str, pixels: npt.NDArray[Any]) -> tuple[str, Any]:
    """(type, sensor_msgs/Image): (h, w, 3) uint8 as rgb8, (h, w) uint16 as 16UC1, (h, w) uint8 as mono8."""
    if pixels.dtype == np.uint8 and pixels.ndim == 3:
        encoding, step = "rgb8", pixels.shape[1] * 3
    elif pixels.dtype == np.uint16 and pixels.ndim == 2:
        encoding, step = "16UC1", pixels.shape[1] * 2
    elif pixels.dtype == np.uint8 and pixels.ndim == 2:
        encoding, step = "mono8", pixels.shape[1]
    else:
        raise ValueError(f"no image encoding for {pixels.dtype} of shape {pixels.shape}")
    data = np.ascontiguousarray(pixels).view(np.uint8).ravel()
    return IMAGE, message_class(IMAGE)(header=header(stamp_ns, frame_id), height=pixels.shape[0],
                                       width=pixels.shape[1], encoding=encoding, is_bigendian=0, step=step,
                                       data=data)


def camera_info(stamp_ns: int, frame_id: str, *, width: int, height: int, k: npt.NDArray[np.float64],
                distortion_model: str = "plumb_bob", d: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0)
                ) -> tuple[str, Any]:
    """(type, sensor_msgs/CameraInfo) of a camera with intrinsics ``k`` (3, 3)."""
    p = np.zeros((3, 4))
    p[:, :3] = k
    return CAMERA_INFO, message_class(CAMERA_INFO)(
        header=header(stamp_ns, frame_id), height=height, width=width, distortion_model=distortion_model,
        d=np.array(d, np.float64), k=np.asarray(k, np.float64).ravel(), r=np.eye(3).ravel(), p=p.ravel(),
        binning_x=0, binning_y=0,
        roi=_RegionOfInterest(x_offset=0, y_offset=0, height=0, width=0, do_rectify=False))


"""ROS 2 messages of simulated sensor data, built with the shared typestore's classes."""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__Point as Point
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__Pose as Pose
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__PoseStamped as PoseStamped
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__PoseWithCovariance as PoseWithCovariance
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__Quaternion as Quaternion
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__Transform as Transform
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__TransformStamped as TransformStamped
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__Twist as Twist
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__TwistWithCovariance as TwistWithCovariance
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__Vector3 as Vector3
from rosbags.typesys.stores.ros2_jazzy import nav_msgs__msg__Odometry as Odometry
from rosbags.typesys.stores.ros2_jazzy import sensor_msgs__msg__CameraInfo as CameraInfo
from rosbags.typesys.stores.ros2_jazzy import sensor_msgs__msg__Image as Image
from rosbags.typesys.stores.ros2_jazzy import sensor_msgs__msg__LaserScan as LaserScan
from rosbags.typesys.stores.ros2_jazzy import sensor_msgs__msg__RegionOfInterest as RegionOfInterest
from rosbags.typesys.stores.ros2_jazzy import tf2_msgs__msg__TFMessage as TFMessage

from shared.messages import CAMERA_INFO, IMAGE, LASER_SCAN, ODOMETRY, POSE_STAMPED, TF_MESSAGE, header
from shared.transforms import quaternion_from_yaw


def _quaternion(q: npt.NDArray[np.float64]) -> Quaternion:
    return Quaternion(x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3]))


def transform_stamped(stamp_ns: int, parent: str, child: str, translation: tuple[float, float, float],
                      rotation_xyzw: npt.NDArray[np.float64]) -> TransformStamped:
    """geometry_msgs/TransformStamped of ``child`` in ``parent``."""
    return TransformStamped(
        header=header(stamp_ns, parent), child_frame_id=child,
        transform=Transform(translation=Vector3(x=float(translation[0]), y=float(translation[1]),
                                                  z=float(translation[2])),
                             rotation=_quaternion(rotation_xyzw)))


def planar_transform(stamp_ns: int, parent: str, child: str, pose: npt.NDArray[np.float64]) -> TransformStamped:
    """TransformStamped of a planar pose (x, y, yaw)."""
    return transform_stamped(stamp_ns, parent, child, (pose[0], pose[1], 0.0), quaternion_from_yaw(float(pose[2])))


def tf_message(transforms: list[TransformStamped]) -> tuple[str, TFMessage]:
    """(type, tf2_msgs/TFMessage) of ``transforms``."""
    return TF_MESSAGE, TFMessage(transforms=transforms)


def pose_stamped(stamp_ns: int, frame_id: str, pose: npt.NDArray[np.float64]) -> tuple[str, PoseStamped]:
    """(type, geometry_msgs/PoseStamped) of a planar pose."""
    return POSE_STAMPED, PoseStamped(
        header=header(stamp_ns, frame_id),
        pose=Pose(position=Point(x=float(pose[0]), y=float(pose[1]), z=0.0),
                   orientation=_quaternion(quaternion_from_yaw(float(pose[2])))))


def odometry(stamp_ns: int, frame_id: str, child_frame_id: str, pose: npt.NDArray[np.float64],
             twist: npt.NDArray[np.float64], *, position_var_m2: float, yaw_var_rad2: float) -> tuple[str, Odometry]:
    """(type, nav_msgs/Odometry) of a planar pose and (forward speed, turn rate) twist."""
    covariance = np.zeros(36)
    covariance[[0, 7]] = position_var_m2
    covariance[[14, 21, 28]] = 1e6  # z, roll, pitch are not estimated
    covariance[35] = yaw_var_rad2
    twist_cov = np.diag([1e-4, 1e-4, 1e6, 1e6, 1e6, 1e-4]).ravel()
    _, message = pose_stamped(stamp_ns, frame_id, pose)
    return ODOMETRY, Odometry(
        header=header(stamp_ns, frame_id), child_frame_id=child_frame_id,
        pose=PoseWithCovariance(pose=message.pose, covariance=covariance),
        twist=TwistWithCovariance(
            twist=Twist(linear=Vector3(x=float(twist[0]), y=0.0, z=0.0),
                         angular=Vector3(x=0.0, y=0.0, z=float(twist[1]))), covariance=twist_cov))


def laser_scan(stamp_ns: int, frame_id: str, *, angle_min_rad: float, angle_increment_rad: float,
               scan_time_s: float, range_min_m: float, range_max_m: float, ranges: npt.NDArray[np.float64],
               intensities: npt.NDArray[np.float64]) -> tuple[str, LaserScan]:
    """(type, sensor_msgs/LaserScan); beams without a return are +inf (REP 117)."""
    n = len(ranges)
    return LASER_SCAN, LaserScan(
        header=header(stamp_ns, frame_id), angle_min=angle_min_rad,
        angle_max=angle_min_rad + (n - 1) * angle_increment_rad, angle_increment=angle_increment_rad,
        time_increment=0.0, scan_time=scan_time_s, range_min=range_min_m, range_max=range_max_m,
        ranges=np.asarray(ranges, np.float32), intensities=np.asarray(intensities, np.float32))


def image(stamp_ns: int, frame_id: str, pixels: npt.NDArray[Any]) -> tuple[str, Image]:
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
    return IMAGE, Image(header=header(stamp_ns, frame_id), height=pixels.shape[0],
                                       width=pixels.shape[1], encoding=encoding, is_bigendian=0, step=step,
                                       data=data)


def camera_info(stamp_ns: int, frame_id: str, *, width: int, height: int, k: npt.NDArray[np.float64],
                distortion_model: str = "plumb_bob", d: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0)
                ) -> tuple[str, CameraInfo]:
    """(type, sensor_msgs/CameraInfo) of a camera with intrinsics ``k`` (3, 3)."""
    p = np.zeros((3, 4))
    p[:, :3] = k
    return CAMERA_INFO, CameraInfo(
        header=header(stamp_ns, frame_id), height=height, width=width, distortion_model=distortion_model,
        d=np.array(d, np.float64), k=np.asarray(k, np.float64).ravel(), r=np.eye(3).ravel(), p=p.ravel(),
        binning_x=0, binning_y=0,
        roi=RegionOfInterest(x_offset=0, y_offset=0, height=0, width=0, do_rectify=False))


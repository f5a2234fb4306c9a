"""Rigid-transform maths and the transform buffer."""

from __future__ import annotations

import math

import numpy as np
import pytest

from shared.messages import message_class
from shared.transforms import (
    Pose2D,
    Transform,
    TransformBuffer,
    add_odometry,
    add_tf_message,
    compose,
    from_matrix,
    interpolate,
    invert,
    quaternion_from_yaw,
    sensor_pose_2d,
    to_matrix,
    yaw_from_quaternion,
)

S = 1_000_000_000


def _tf(x: float, y: float, yaw: float, z: float = 0.0) -> Transform:
    return Transform(np.array([x, y, z]), quaternion_from_yaw(yaw))


@pytest.mark.parametrize("yaw", [0.0, 0.3, -2.5, math.pi - 1e-9])
def test_yaw_round_trips_through_quaternion(yaw: float) -> None:
    assert yaw_from_quaternion(quaternion_from_yaw(yaw)) == pytest.approx(yaw)


def test_compose_and_invert_match_matrices() -> None:
    rng = np.random.default_rng(3)
    for _ in range(20):
        q1, q2 = rng.normal(size=4), rng.normal(size=4)
        a = Transform(rng.normal(size=3), q1 / np.linalg.norm(q1))
        b = Transform(rng.normal(size=3), q2 / np.linalg.norm(q2))
        np.testing.assert_allclose(to_matrix(compose(a, b)), to_matrix(a) @ to_matrix(b), atol=1e-12)
        np.testing.assert_allclose(to_matrix(invert(a)), np.linalg.inv(to_matrix(a)), atol=1e-12)
        np.testing.assert_allclose(to_matrix(from_matrix(to_matrix(a))), to_matrix(a), atol=1e-12)


def test_interpolate_halfway_is_midpoint_and_half_angle() -> None:
    mid = interpolate(_tf(0, 0, 0), _tf(2, 4, 1.0), 0.5)
    np.testing.assert_allclose(mid.translation, [1, 2, 0])
    assert yaw_from_quaternion(mid.rotation) == pytest.approx(0.5)


def test_lookup_walks_tree_and_includes_static_mount() -> None:
    buf = TransformBuffer()
    buf.set_transform("base_link", "laser", 0, (0.1, 0, 0.2), quaternion_from_yaw(math.pi / 2), static=True)
    buf.set_transform("odom", "base_link", 1 * S, (1, 0, 0), quaternion_from_yaw(0))
    buf.set_transform("odom", "base_link", 3 * S, (3, 0, 0), quaternion_from_yaw(math.pi / 2))
    pose = sensor_pose_2d(buf.lookup("odom", "laser", 2 * S))
    # base at (2, 0) heading pi/4; mount 0.1 m forward, turned pi/2
    assert pose.x_m == pytest.approx(2 + 0.1 * math.cos(math.pi / 4))
    assert pose.y_m == pytest.approx(0.1 * math.sin(math.pi / 4))
    assert pose.yaw_rad == pytest.approx(3 * math.pi / 4)
    back = buf.lookup("laser", "odom", 2 * S)
    np.testing.assert_allclose(
        to_matrix(back) @ to_matrix(buf.lookup("odom", "laser", 2 * S)), np.eye(4), atol=1e-12
    )


def test_lookup_extrapolates_only_within_tolerance() -> None:
    buf = TransformBuffer(extrapolation_s=0.1)
    buf.set_transform("odom", "base_link", 10 * S, (1, 0, 0), (0, 0, 0, 1))
    buf.set_transform("odom", "base_link", 11 * S, (2, 0, 0), (0, 0, 0, 1))
    assert buf.lookup("odom", "base_link", 11 * S + S // 20).translation[0] == pytest.approx(2)
    assert buf.can_transform("odom", "base_link", 10 * S - S // 20)
    with pytest.raises(LookupError, match="after the last sample"):
        buf.lookup("odom", "base_link", 12 * S)
    assert not buf.can_transform("odom", "base_link", 9 * S)
    assert buf.lookup("odom", "base_link", None).translation[0] == pytest.approx(2)


def test_lookup_unknown_or_unconnected_frames_raise() -> None:
    buf = TransformBuffer()
    buf.set_transform("odom", "base_link", 0, (0, 0, 0), (0, 0, 0, 1))
    buf.set_transform("map", "other", 0, (0, 0, 0), (0, 0, 0, 1))
    with pytest.raises(LookupError, match="unknown frame 'nowhere'"):
        buf.lookup("odom", "nowhere", 0)
    with pytest.raises(LookupError, match="different trees"):
        buf.lookup("map", "base_link", 0)
    assert buf.newest_stamp_ns("map", "base_link") is None


def test_history_is_bounded_and_latest_parent_wins() -> None:
    buf = TransformBuffer(cache_s=2.0)
    for t in range(10):
        buf.set_transform("odom", "base_link", t * S, (t, 0, 0), (0, 0, 0, 1))
    with pytest.raises(LookupError, match="before the first"):
        buf.lookup("odom", "base_link", 5 * S)
    assert buf.newest_stamp_ns("odom", "base_link") == 9 * S
    buf.set_transform("map", "base_link", 10 * S, (0, 5, 0), (0, 0, 0, 1))
    assert buf.lookup("map", "base_link", 10 * S).translation[1] == pytest.approx(5)
    assert not buf.can_transform("odom", "base_link", 9 * S)


def test_set_transform_rejects_bad_input() -> None:
    buf = TransformBuffer()
    with pytest.raises(ValueError, match="quaternion"):
        buf.set_transform("a", "b", 0, (0, 0, 0), (0, 0, 0, 0))
    with pytest.raises(ValueError, match="invalid frames"):
        buf.set_transform("a", "a", 0, (0, 0, 0), (0, 0, 0, 1))


def test_messages_feed_the_buffer() -> None:
    time_cls = message_class("builtin_interfaces/msg/Time")
    header = message_class("std_msgs/msg/Header")(stamp=time_cls(sec=5, nanosec=0), frame_id="odom")
    q = quaternion_from_yaw(0.7)
    quat = message_class("geometry_msgs/msg/Quaternion")(x=q[0], y=q[1], z=q[2], w=q[3])
    tf = message_class("geometry_msgs/msg/TransformStamped")(
        header=header,
        child_frame_id="/base_link",
        transform=message_class("geometry_msgs/msg/Transform")(
            translation=message_class("geometry_msgs/msg/Vector3")(x=1.0, y=2.0, z=0.0), rotation=quat
        ),
    )
    buf = TransformBuffer()
    assert add_tf_message(buf, message_class("tf2_msgs/msg/TFMessage")(transforms=[tf])) == 1
    assert sensor_pose_2d(buf.lookup("odom", "base_link", 5 * S)) == pytest.approx(Pose2D(1.0, 2.0, 0.7))
    odom = message_class("nav_msgs/msg/Odometry")(
        header=header,
        child_frame_id="robot",
        pose=message_class("geometry_msgs/msg/PoseWithCovariance")(
            pose=message_class("geometry_msgs/msg/Pose")(
                position=message_class("geometry_msgs/msg/Point")(x=3.0, y=4.0, z=0.0), orientation=quat
            ),
            covariance=np.zeros(36),
        ),
        twist=message_class("geometry_msgs/msg/TwistWithCovariance")(
            twist=message_class("geometry_msgs/msg/Twist")(
                linear=message_class("geometry_msgs/msg/Vector3")(x=0.0, y=0.0, z=0.0),
                angular=message_class("geometry_msgs/msg/Vector3")(x=0.0, y=0.0, z=0.0),
            ),
            covariance=np.zeros(36),
        ),
    )
    add_odometry(buf, odom)
    assert sensor_pose_2d(buf.lookup("odom", "robot", 5 * S)) == pytest.approx(Pose2D(3.0, 4.0, 0.7))

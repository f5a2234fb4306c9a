"""shared.robots: the robot record as a map feature, and back."""

from __future__ import annotations

import pytest

from shared.robots import Robot, RobotError, TrackPoint
from shared.store import Feature

TRACK = (TrackPoint(0.0, 1.0, 0.0, 1_000), TrackPoint(0.5, 1.0, 0.1, 2_000))


def test_a_robot_round_trips_through_its_feature_at_its_current_position() -> None:
    robot = Robot("robot1", TRACK[-1], TRACK)

    feature = robot.feature()

    assert feature.kind == "robot" and feature.key == "robot1"
    assert feature.geometry == {"type": "Point", "coordinates": [0.5, 1.0]}
    assert Robot.from_feature(feature) == robot


def test_the_root_namespace_is_stored_under_a_slash() -> None:
    robot = Robot("", TRACK[-1], TRACK)

    assert robot.feature().key == "/" and Robot.from_feature(robot.feature()).robot == ""


def test_bad_track_points_are_left_out_and_a_bad_pose_is_refused() -> None:
    point = {"type": "Point", "coordinates": [0, 0]}
    lenient = Feature("robot", "r", point, {"pose": [0, 0, 0, 5], "track": [[0, 0, 0, 5], ["x", 0, 0, 1], [1, 2]]})
    assert Robot.from_feature(lenient).track == (TrackPoint(0.0, 0.0, 0.0, 5),)
    with pytest.raises(RobotError, match="pose"):
        Robot.from_feature(Feature("robot", "r", point, {"pose": [float("nan"), 0, 0, 5]}))
    with pytest.raises(RobotError, match="not a robot"):
        Robot.from_feature(Feature("dock", "r", point))

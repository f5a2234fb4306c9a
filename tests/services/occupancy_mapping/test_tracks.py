"""services.occupancy_mapping.tracks: each robot's recent poses, thinned and windowed."""

from __future__ import annotations

import itertools

import pytest

from services.occupancy_mapping.tracks import TrackRecorder
from shared.transforms import Pose2D

S = 1_000_000_000


def test_a_track_keeps_the_last_window_thinned_and_ends_at_the_newest_pose() -> None:
    tracks = TrackRecorder(window_s=10.0, spacing_s=1.0)
    for i in range(100):  # 20 s at 5 Hz
        tracks.add("/robot1", Pose2D(i * 0.1, 0.0, 0.0), stamp_ns=i * S // 5)

    (robot,) = tracks.robots()

    assert robot.robot == "robot1"
    assert robot.pose.x_m == pytest.approx(9.9) and robot.track[-1] == robot.pose
    stamps = [p.stamp_ns for p in robot.track]
    assert robot.pose.stamp_ns - stamps[0] <= 10 * S
    assert all(b - a >= S for a, b in itertools.pairwise(stamps[:-1]))
    assert 9 <= len(robot.track) <= 12


def test_robots_are_kept_apart_by_namespace() -> None:
    tracks = TrackRecorder()
    tracks.add("robot2", Pose2D(1.0, 1.0, 0.0), stamp_ns=S)
    tracks.add("robot1", Pose2D(2.0, 2.0, 0.0), stamp_ns=S)
    tracks.add("", Pose2D(3.0, 3.0, 0.0), stamp_ns=S)

    assert [(r.robot, r.pose.x_m) for r in tracks.robots()] == [("", 3.0), ("robot1", 2.0), ("robot2", 1.0)]


def test_a_window_that_is_not_positive_is_refused() -> None:
    with pytest.raises(ValueError, match="window_s"):
        TrackRecorder(window_s=0.0)

"""The robot record: where a robot the stages hear on the bus is, and where it was over the last minute.

The occupancy stage writes one ``robot`` feature per robot namespace with each revision it stores (the pose of
the robot's lidar in the map frame at its latest integrated scan, and the poses before it); the API and the
viewer read them back. The geometry is the current position (a GeoJSON Point), so area queries find robots where
they are now.

Examples
--------
>>> robot = Robot("robot1", TrackPoint(1.0, 2.0, 0.5, 3_000_000_000),
...               (TrackPoint(0.0, 2.0, 0.5, 2_000_000_000), TrackPoint(1.0, 2.0, 0.5, 3_000_000_000)))
>>> Robot.from_feature(robot.feature()) == robot
True
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

from shared.store import Feature
from shared.vocabulary import FeatureKind


class RobotError(ValueError):
    """A feature that is not a readable robot record."""


class TrackPoint(NamedTuple):
    """One pose of a robot: position in map metres, heading in radians from the map x axis, time of the scan."""

    x_m: float
    y_m: float
    yaw_rad: float
    stamp_ns: int


@dataclass(frozen=True, slots=True)
class Robot:
    """A robot's latest pose and its track (oldest first, ending at ``pose``).

    ``robot`` is the robot's ROS namespace without slashes (``""`` for the root namespace).
    """

    robot: str
    pose: TrackPoint
    track: tuple[TrackPoint, ...]

    def feature(self) -> Feature:
        """The ``robot`` map feature (key: the namespace, ``/`` for the root one)."""
        return Feature(FeatureKind.ROBOT, self.robot or "/",
                       {"type": "Point", "coordinates": [self.pose.x_m, self.pose.y_m]},
                       {"robot": self.robot, "pose": list(self.pose), "track": [list(p) for p in self.track]})

    @classmethod
    def from_feature(cls, feature: Feature) -> Robot:
        """The record of a stored ``robot`` feature; :class:`RobotError` if it is not one."""
        if feature.kind != FeatureKind.ROBOT:
            raise RobotError(f"feature {feature.kind}/{feature.key} is not a robot")
        properties = feature.properties
        pose = _point(properties.get("pose"))
        if pose is None:
            raise RobotError(f"robot feature {feature.key!r} has no valid pose [x, y, yaw, stamp_ns]")
        track = properties.get("track")
        points = [_point(p) for p in track] if isinstance(track, list) else []
        robot = properties.get("robot")
        return cls(robot if isinstance(robot, str) else feature.key, pose,
                   tuple(p for p in points if p is not None))


def _point(value: Any) -> TrackPoint | None:
    if not isinstance(value, Sequence) or len(value) != 4:
        return None
    x, y, yaw, stamp = value
    numbers = (x, y, yaw)
    if not all(isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) for v in numbers):
        return None
    if not isinstance(stamp, int) or isinstance(stamp, bool):
        return None
    return TrackPoint(float(x), float(y), float(yaw), stamp)

"""Robots on the map: each robot's latest pose and recent track, as the occupancy stage stored them."""

from __future__ import annotations

import logging
from typing import NamedTuple

from shared.robots import Robot, RobotError
from shared.store import MapInfo, MapStore
from shared.vocabulary import FeatureKind

log = logging.getLogger(__name__)


class StoredRobot(NamedTuple):
    """A robot record and the revision that wrote it."""

    robot: Robot
    revision_id: int


def robots(store: MapStore, map_info: MapInfo, *, revision: int | None = None) -> list[StoredRobot]:
    """The robots of the map as at ``revision`` (default: now), by name; unreadable records are logged and left out.

    Examples
    --------
    >>> from shared.robots import TrackPoint
    >>> from shared.store import RevisionWrite
    >>> store = MapStore("sqlite://"); store.upgrade()
    >>> info = store.ensure_map("site")
    >>> robot = Robot("r1", TrackPoint(1.0, 2.0, 0.0, 5), (TrackPoint(1.0, 2.0, 0.0, 5),))
    >>> _ = store.write_revision(info.id, RevisionWrite("occupancy_mapping", features={"robot": [robot.feature()]}))
    >>> [found.robot.pose.x_m for found in robots(store, info)]
    [1.0]
    """
    found = []
    for stored in store.features(map_info.id, kinds=[FeatureKind.ROBOT], revision=revision):
        try:
            found.append(StoredRobot(Robot.from_feature(stored.feature), stored.revision_id))
        except RobotError as err:
            log.warning("map %r: %s", map_info.name, err)
    return sorted(found, key=lambda item: item.robot.robot)

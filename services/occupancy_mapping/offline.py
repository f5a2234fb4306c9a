"""Build an occupancy grid from a recorded rosbag2 (sqlite3 or MCAP)."""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any, NamedTuple

from rosbags.highlevel import AnyReader
from rosbags.highlevel.anyreader import AnyReaderError

from services.occupancy_mapping.errors import OccupancyMappingError
from services.occupancy_mapping.grid import OccupancyGrid
from services.occupancy_mapping.mapper import AUTO_FRAME, ScanCorrector, ScanMapper
from shared.messages import LASER_SCAN, ODOMETRY, TF_MESSAGE, TYPESTORE

logger = logging.getLogger(__name__)


class BuildStats(NamedTuple):
    """What :func:`build_map_with_stats` did."""

    scans_integrated: int
    scans_dropped: int
    beams_used: int


def _namespace(topic: str, name: str) -> str | None:
    """``/robot1/scan`` with name ``/scan`` gives ``/robot1``; ``None`` if the topic is not ``name``."""
    suffix = "/" + name.strip("/")
    return topic[: -len(suffix)] if topic.endswith(suffix) else None


def _route(topic: str, msgtype: str, scan_topic: str) -> tuple[str, bool] | None:
    """(namespace, is_static) of a topic the mapper wants, else ``None``."""
    if msgtype == LASER_SCAN:
        ns = _namespace(topic, scan_topic)
        return None if ns is None else (ns, False)
    if msgtype == TF_MESSAGE:
        for name, static in (("tf", False), ("tf_static", True)):
            if (ns := _namespace(topic, name)) is not None:
                return ns, static
        return None
    if msgtype == ODOMETRY:
        return topic.rsplit("/", 1)[0], False
    return None


def build_map_with_stats(
    bag_path: Path,
    *,
    resolution_m: float = 0.05,
    scan_topic: str = "/scan",
    fixed_frame: str = AUTO_FRAME,
    max_range_m: float = 30.0,
    corrector: ScanCorrector | None = None,
) -> tuple[OccupancyGrid, BuildStats]:
    """:func:`build_map`, also returning counts of what was integrated and dropped."""
    bag_path = Path(bag_path)
    if not bag_path.exists():
        raise OccupancyMappingError(f"bag {bag_path} does not exist")
    mapper = ScanMapper(
        OccupancyGrid(resolution_m=resolution_m),
        fixed_frame=fixed_frame,
        max_range_m=max_range_m,
        corrector=corrector,
    )
    malformed = 0
    try:
        with AnyReader([bag_path], default_typestore=TYPESTORE) as reader:
            routes = {
                c.id: route for c in reader.connections if (route := _route(c.topic, c.msgtype, scan_topic))
            }
            connections = [c for c in reader.connections if c.id in routes]
            if not any(c.msgtype == LASER_SCAN for c in connections):
                raise OccupancyMappingError(f"bag {bag_path} has no LaserScan topic matching {scan_topic!r}")
            for connection, bag_ns, raw in reader.messages(connections=connections):
                message: Any = reader.deserialize(raw, connection.msgtype)
                namespace, static = routes[connection.id]
                if connection.msgtype == TF_MESSAGE:
                    mapper.add_tf(namespace, message, static=static)
                elif connection.msgtype == ODOMETRY:
                    mapper.add_odometry(namespace, message)
                else:
                    try:
                        mapper.add_scan(namespace, message, fallback_stamp_ns=bag_ns)
                    except OccupancyMappingError as err:
                        malformed += 1
                        logger.warning("scan on %s dropped: %s", connection.topic, err)
                mapper.drain()
            mapper.drain(final=True)
    except (AnyReaderError, OSError) as err:
        raise OccupancyMappingError(f"cannot read bag {bag_path}: {err}") from err
    counts = mapper.counts
    integrated = counts["scans_integrated"]
    dropped = malformed + sum(
        v for k, v in counts.items() if k.startswith("scans_") and k != "scans_integrated"
    )
    if integrated == 0:
        raise OccupancyMappingError(
            f"bag {bag_path}: none of its {dropped} scans could be placed in fixed frame {fixed_frame!r}"
        )
    stats = BuildStats(integrated, dropped, counts["beams_used"])
    logger.info("built map from %s: %s", bag_path, stats)
    return mapper.grid, stats


def build_map(
    bag_path: Path,
    *,
    resolution_m: float = 0.05,
    scan_topic: str = "/scan",
    fixed_frame: str = AUTO_FRAME,
    max_range_m: float = 30.0,
    corrector: ScanCorrector | None = None,
) -> OccupancyGrid:
    """Occupancy grid of every laser scan in a rosbag2, placed with the bag's transforms.

    ``/tf``, ``/tf_static`` and nav_msgs/Odometry (for frames the TF does not already carry), under
    any namespace prefix, feed one transform tree per namespace; each scan waits until its tree
    reaches its stamp and is integrated at its frame's pose in ``fixed_frame`` (``"auto"``: ``map``
    if the tree has it, else ``odom``), laser mounting included. See
    :class:`~services.occupancy_mapping.mapper.ScanMapper`.

    Parameters
    ----------
    bag_path : Path
        rosbag2 directory (or file) in sqlite3 or MCAP storage.
    resolution_m : float
        Grid cell size, metres.
    scan_topic : str
        LaserScan topic name, matched under any namespace prefix.
    fixed_frame : str
        Frame to map in, or ``"auto"``.
    max_range_m : float
        Returns at or beyond this are not marked occupied.
    corrector : callable, optional
        Pose correction applied per scan before integration (e.g. scan-to-map matching).
    """
    grid, _ = build_map_with_stats(
        bag_path,
        resolution_m=resolution_m,
        scan_topic=scan_topic,
        fixed_frame=fixed_frame,
        max_range_m=max_range_m,
        corrector=corrector,
    )
    return grid

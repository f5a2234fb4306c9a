"""Scans plus transforms in, occupancy grid out: the state machine shared by the live worker and
offline map building.

Each robot (ROS namespace) has its own transform tree. A scan waits until that tree has
transforms at or after its stamp, so it is placed by interpolation, never by stale poses; scans
that never get a pose within ``wait_s`` are dropped and counted.
"""

from __future__ import annotations

import logging
from collections import Counter, deque
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__PoseStamped as PoseStamped
from rosbags.typesys.stores.ros2_jazzy import nav_msgs__msg__Odometry as Odometry
from rosbags.typesys.stores.ros2_jazzy import sensor_msgs__msg__LaserScan as LaserScan
from rosbags.typesys.stores.ros2_jazzy import tf2_msgs__msg__TFMessage as TFMessage

from services.occupancy_mapping.errors import OccupancyMappingError
from services.occupancy_mapping.grid import OccupancyGrid
from services.occupancy_mapping.scan import ScanArrays, scan_arrays
from services.occupancy_mapping.tracks import TrackRecorder
from shared import messages
from shared.transforms import (
    Pose2D,
    Transform,
    TransformBuffer,
    add_odometry,
    add_tf_message,
    compose,
    invert,
    sensor_pose,
)

log = logging.getLogger(__name__)

AUTO_FRAME = "auto"

ScanCorrector = Callable[[OccupancyGrid, Pose2D, ScanArrays], Pose2D]
"""Optional pose correction: given the grid so far, a predicted sensor pose and the scan, a better pose."""


def _is_map_frame(frame: str) -> bool:
    return frame == "map" or frame.endswith("/map")


@dataclass
class _Robot:
    buffer: TransformBuffer
    pending: deque[ScanArrays] = field(default_factory=deque)
    tf_children: set[str] = field(default_factory=set)
    frame: str | None = None


class ScanMapper:
    """Integrates laser scans from one or more robots into one :class:`OccupancyGrid`.

    Parameters
    ----------
    grid : OccupancyGrid
        The grid to update (e.g. resumed from the store).
    fixed_frame : str
        Frame the grid lives in; ``"auto"`` takes ``map`` when a robot's tree has it, else ``odom``.
    max_range_m : float
        Returns at or beyond this are not marked occupied.
    wait_s : float
        How long (in scan time) a scan may wait for its transforms before it is dropped.
    corrector : callable, optional
        Pose correction per scan before integration (e.g. scan-to-map matching), applied to robots
        mapped in their odometry frame; robots that publish a ``map`` frame are localised already.
    """

    def __init__(self, grid: OccupancyGrid, *, fixed_frame: str = AUTO_FRAME, max_range_m: float = 30.0,
                 wait_s: float = 2.0, cache_s: float = 30.0, corrector: ScanCorrector | None = None) -> None:
        self.grid = grid
        self.fixed_frame = fixed_frame
        self.max_range_m = max_range_m
        self._wait_ns = round(wait_s * 1e9)
        self._cache_s = cache_s
        self._corrector = corrector
        self._robots: dict[str, _Robot] = {}
        self.counts: Counter[str] = Counter()
        self.first_stamp_ns: int | None = None
        self.last_stamp_ns: int | None = None
        self.tracks = TrackRecorder()
        """Where each robot's lidar was at its integrated scans, in the grid's frame (the last minute)."""

    def _robot(self, namespace: str) -> _Robot:
        if namespace not in self._robots:
            self._robots[namespace] = _Robot(TransformBuffer(cache_s=self._cache_s))
        return self._robots[namespace]

    def add_tf(self, namespace: str, message: TFMessage, *, static: bool = False) -> None:
        """Feed a tf2_msgs/TFMessage of robot ``namespace``."""
        robot = self._robot(namespace)
        robot.tf_children.update(t.child_frame_id.lstrip("/") for t in message.transforms)
        add_tf_message(robot.buffer, message, static=static)

    def add_odometry(self, namespace: str, message: Odometry) -> None:
        """Feed a nav_msgs/Odometry; ignored for frames the robot's TF already carries."""
        robot = self._robot(namespace)
        if message.child_frame_id.lstrip("/") not in robot.tf_children:
            add_odometry(robot.buffer, message)

    def add_map_pose(self, namespace: str, message: PoseStamped, *, base_frame: str) -> None:
        """Feed a geometry_msgs/PoseStamped: the robot's ``base_frame`` in a map frame (localisation).

        If the base hangs under an odometry frame, the pose becomes the map -> odom correction, as a
        localisation node would publish it; otherwise it links the map frame to the base directly.
        """
        robot = self._robot(namespace)
        stamp_ns = messages.stamp_ns(message.header)
        p, q = message.pose.position, message.pose.orientation
        pose = Transform(np.array([p.x, p.y, p.z]), np.array([q.x, q.y, q.z, q.w]))
        map_frame = message.header.frame_id.lstrip("/")
        base = next((f for f in sorted(robot.buffer.frames) if f == base_frame or f.endswith("/" + base_frame)),
                    base_frame)
        parent = robot.buffer.parent(base)
        if parent is None or parent == map_frame:
            robot.buffer.set_transform(map_frame, base, stamp_ns, pose.translation, pose.rotation)
            return
        try:
            odometry = robot.buffer.lookup(parent, base, stamp_ns)
        except LookupError:
            self.counts["poses_without_odometry"] += 1
            return
        correction = compose(pose, invert(odometry))
        robot.buffer.set_transform(map_frame, parent, stamp_ns, correction.translation, correction.rotation)

    def add_scan(self, namespace: str, message: LaserScan, *, fallback_stamp_ns: int = 0) -> None:
        """Queue a sensor_msgs/LaserScan; raises :class:`OccupancyMappingError` if it is malformed."""
        scan = scan_arrays(message)
        if scan.stamp_ns == 0:
            scan = scan._replace(stamp_ns=fallback_stamp_ns)
        self._robot(namespace).pending.append(scan)

    def drain(self, *, final: bool = False) -> int:
        """Integrate every queued scan whose transforms are known; return how many were integrated.

        With ``final`` every queued scan is decided now (integrated if possible, else dropped).
        """
        done = 0
        for namespace, robot in self._robots.items():
            while robot.pending:
                scan = robot.pending[0]
                robot.frame = robot.frame or self._choose_frame(namespace, robot.buffer)
                newest = robot.buffer.newest_stamp_ns(robot.frame, scan.frame_id) if robot.frame else None
                waiting = newest is None or newest < scan.stamp_ns
                if waiting and not final and robot.pending[-1].stamp_ns - scan.stamp_ns < self._wait_ns:
                    break
                robot.pending.popleft()
                done += self._integrate(namespace, robot, scan)
        return done

    def _choose_frame(self, namespace: str, buffer: TransformBuffer) -> str | None:
        if self.fixed_frame != AUTO_FRAME:
            return self.fixed_frame
        for wanted in ("map", "odom"):
            found = sorted(f for f in buffer.frames if f == wanted or f.endswith("/" + wanted))
            if found:
                if wanted == "odom":
                    log.warning("robot %r has no map frame; mapping in its odometry frame %r", namespace or "/",
                                found[0])
                return found[0]
        return None

    def _integrate(self, namespace: str, robot: _Robot, scan: ScanArrays) -> int:
        if robot.frame is None:
            self.counts["scans_without_frame"] += 1
            return 0
        try:
            transform = robot.buffer.lookup(robot.frame, scan.frame_id, scan.stamp_ns)
        except LookupError as err:
            self.counts["scans_without_pose"] += 1
            log.debug("scan at %d ns dropped: %s", scan.stamp_ns, err)
            return 0
        pose, angles = sensor_pose(transform, scan.angles)
        if self._corrector is not None and not _is_map_frame(robot.frame):
            # a localised robot (map frame) is trusted; odometry-only robots get drift-corrected.
            # Correctors track drift per sensor: the frame name is qualified by the robot's namespace
            frame = f"{namespace.strip('/')}/{scan.frame_id}" if namespace.strip("/") else scan.frame_id
            pose = self._corrector(self.grid, pose, scan._replace(angles=angles, frame_id=frame))
        try:
            beams = self.grid.integrate(pose, scan.ranges, angles, range_min_m=scan.range_min_m,
                                        range_max_m=scan.range_max_m, max_range_m=self.max_range_m)
        except OccupancyMappingError as err:
            self.counts["scans_rejected"] += 1
            log.warning("scan at %d ns rejected: %s", scan.stamp_ns, err)
            return 0
        self.counts["scans_integrated"] += 1
        self.tracks.add(namespace, pose, stamp_ns=scan.stamp_ns)
        self.counts["beams_used"] += beams
        self.counts["beams_skipped"] += scan.ranges.size - beams
        self.first_stamp_ns = scan.stamp_ns if self.first_stamp_ns is None else self.first_stamp_ns
        self.last_stamp_ns = scan.stamp_ns
        return 1

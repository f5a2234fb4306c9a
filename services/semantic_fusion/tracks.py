"""One robot's track in the semantic-fusion worker: its fusion, its recent poses, and what waits for them.

Each robot has its own :class:`~services.semantic_fusion.fusion.SemanticFusion` (keyframes, pose graph, loop
closures); the worker keeps beside it the camera poses of the robot's recent scans, to place what arrives
between them:

* a range scan (the robot's lidar) waits until an annotated scan is stamped at or after it, takes the robot's
  pose interpolated between the annotated scans around it (:meth:`RobotTrack.place`) and attaches to the
  current keyframe if none has yet (:func:`attach_range_scans`; range scans of keyframes already closed are
  not used). Range scans older than the kept poses are unplaced;
* a corrected pose at stamp ``t`` (already a camera pose, :meth:`SensorMounts.camera_pose`) is carried to the
  keyframe nearest ``t`` by the robot's own motion between the two (:meth:`RobotTrack.correction`) and enters
  the pose graph as a prior. Corrections wait until scans have passed their stamp and are applied at most once
  per correction period per robot, the newest waiting one (:meth:`RobotTrack.due_correction`), since each costs
  an optimisation.

The worker counts range scans as ``range_scans_attached``, ``range_scans_unplaced`` (older than the kept poses),
``range_scans_dropped`` (more than :data:`PENDING_RANGE_SCANS` waiting for a robot with a track),
``bad_range_scans`` and ``range_scans_mount_from_settings``; corrections as ``pose_corrections`` and
``pose_corrections_too_old``; bad poses as ``bad_poses``.
"""

from __future__ import annotations

import collections
import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt
from rosbags.typesys.stores.ros2_jazzy import sensor_msgs__msg__LaserScan as LaserScan

from services.semantic_fusion import se2
from services.semantic_fusion.fusion import FusionSettings, SemanticFusion
from services.semantic_fusion.grid import SemanticGrid
from services.semantic_fusion.scan import RangeScan, range_scan_from_arrays
from shared.messages import stamp_ns as header_stamp_ns

FloatArray = npt.NDArray[np.float64]

POSE_HISTORY = 1200
"""Recent scan poses kept per robot to place corrections and range scans (two minutes at 10 Hz)."""
PENDING_CORRECTIONS = 200
PENDING_RANGE_SCANS = 600
"""Range scans kept per robot while the annotated scans catch up (a minute of a 10 Hz lidar)."""

WaitingRangeScans = collections.deque[tuple[str, RangeScan]]
"""Range scans with their lidar frame, waiting for an annotated scan at or after their stamp; points in the
lidar's own frame."""


def range_scan(message: LaserScan) -> RangeScan:
    """A sensor_msgs/LaserScan's returns as a :class:`RangeScan` in the lidar's frame (pose zero, placed later).

    Raises
    ------
    SemanticFusionError
        Non-finite angles or a non-positive angle increment.
    """
    return range_scan_from_arrays(header_stamp_ns(message.header), np.zeros(3), float(message.angle_min),
                                  float(message.angle_increment), np.asarray(message.ranges),
                                  range_min_m=float(message.range_min), range_max_m=float(message.range_max))


@dataclass
class RobotTrack:
    """One robot's fusion and the camera poses of its recent scans (see the module docstring)."""

    fusion: SemanticFusion
    stamps_ns: collections.deque[int] = field(default_factory=lambda: collections.deque(maxlen=POSE_HISTORY))
    poses: collections.deque[FloatArray] = field(default_factory=lambda: collections.deque(maxlen=POSE_HISTORY))
    corrections: collections.deque[tuple[int, FloatArray]] = field(
        default_factory=lambda: collections.deque(maxlen=PENDING_CORRECTIONS))
    corrected_at: float = -math.inf
    out_of_order: int = 0

    def record(self, stamp_ns: int, camera_pose: FloatArray) -> None:
        """Keep the camera pose of a scan just added."""
        self.stamps_ns.append(stamp_ns)
        self.poses.append(camera_pose)

    def pose_at(self, stamp_ns: int) -> FloatArray | None:
        """The robot's own camera pose estimate at ``stamp_ns``, interpolated; None outside the history."""
        stamps = np.fromiter(self.stamps_ns, dtype=np.int64, count=len(self.stamps_ns))
        if not stamps.size or not stamps[0] <= stamp_ns <= stamps[-1]:
            return None
        i = int(np.searchsorted(stamps, stamp_ns))
        if stamps[i] == stamp_ns:
            return self.poses[i]
        a, b = self.poses[i - 1], self.poses[i]
        fraction = (stamp_ns - stamps[i - 1]) / (stamps[i] - stamps[i - 1])
        return se2.compose(a, fraction * se2.between(a, b))

    def place(self, scan_stamp_ns: int, stamp_ns: int, camera: FloatArray) -> FloatArray | None:
        """The camera pose at ``scan_stamp_ns`` before an annotated scan at ``stamp_ns`` with pose ``camera`` is
        recorded: interpolated from the newest kept pose to ``camera``, or from the history for an older stamp;
        None before the history."""
        if self.stamps_ns and scan_stamp_ns >= self.stamps_ns[-1]:
            before, t0 = self.poses[-1], self.stamps_ns[-1]
            fraction = (scan_stamp_ns - t0) / (stamp_ns - t0) if stamp_ns > t0 else 1.0
            return se2.compose(before, fraction * se2.between(before, camera))
        return self.pose_at(scan_stamp_ns)  # arrived after later annotated scans: placed from the pose history

    def due_correction(self, now_s: float, period_s: float) -> tuple[int, FloatArray] | None:
        """The newest waiting correction scans have passed, if ``period_s`` has passed since the last one
        (``now_s`` on the same monotonic clock); older ones are dropped, newer ones keep waiting."""
        newest = self.fusion.last_stamp_ns
        if newest is None or not self.corrections or now_s - self.corrected_at < period_s:
            return None
        ready = [c for c in self.corrections if c[0] <= newest]
        if not ready:
            return None
        waiting = [c for c in self.corrections if c[0] > newest]
        self.corrections.clear()
        self.corrections.extend(waiting)
        self.corrected_at = now_s
        return max(ready, key=lambda c: c[0])

    def correction(self, stamp_ns: int, camera: FloatArray) -> tuple[int, FloatArray] | None:
        """The keyframe nearest ``stamp_ns`` (its stamp) and its pose corrected so that the robot's pose at
        ``stamp_ns`` is ``camera``; None if ``stamp_ns`` is older than the kept poses."""
        estimate = self.pose_at(stamp_ns)
        if estimate is None:
            return None
        keyframe_stamps = self.fusion.keyframe_stamps_ns
        key = int(np.argmin(np.abs(keyframe_stamps - stamp_ns)))
        corrected = se2.compose(camera, se2.between(estimate, self.fusion.graph.odometry_pose(key)))
        return int(keyframe_stamps[key]), corrected


class Fleet:
    """Every robot's :class:`RobotTrack`, all fusing into one grid, and the range scans waiting for each robot
    (kept apart from the tracks: a robot's lidar may speak before its camera, and waiting scans are counted
    as dropped only for a robot with a track).

    Parameters
    ----------
    grid : SemanticGrid
        The grid every robot's fusion writes into.
    settings : FusionSettings
        Each robot's fusion tuning.
    detect_loops : bool
        Whether the robots' fusions close loops.
    """

    def __init__(self, grid: SemanticGrid, settings: FusionSettings, *, detect_loops: bool) -> None:
        self.grid = grid
        self.settings = settings
        self.detect_loops = detect_loops
        self.tracks: dict[str, RobotTrack] = {}
        self.range_scans: dict[str, WaitingRangeScans] = {}
        self.first_stamp_ns: int | None = None
        """Stamp of the oldest scan any robot added."""

    def track(self, namespace: str) -> RobotTrack:
        """The track of robot ``namespace``, started if it has none."""
        track = self.tracks.get(namespace)
        if track is None:
            fusion = SemanticFusion(self.settings, detect_loops=self.detect_loops, grid=self.grid)
            track = self.tracks[namespace] = RobotTrack(fusion)
        return track

    def restart(self, namespace: str) -> RobotTrack:
        """A fresh track for robot ``namespace`` (restarted, or a bag replayed); its waiting range scans are
        dropped, its evidence stays in the grid."""
        self.tracks.pop(namespace, None)
        self.range_scans.pop(namespace, None)
        return self.track(namespace)

    def queue_range_scan(self, namespace: str, frame_id: str, scan: RangeScan) -> bool:
        """Keep ``scan`` (lidar frame ``frame_id``) until robot ``namespace``'s annotated scans pass its stamp;
        whether that dropped the oldest waiting one of a robot with a track."""
        waiting = self.range_scans.setdefault(namespace, collections.deque(maxlen=PENDING_RANGE_SCANS))
        dropped = len(waiting) == waiting.maxlen and namespace in self.tracks
        waiting.append((frame_id, scan))
        return dropped

    def record(self, namespace: str, stamp_ns: int, camera_pose: FloatArray) -> None:
        """Keep the camera pose of a scan robot ``namespace`` just added."""
        self.tracks[namespace].record(stamp_ns, camera_pose)
        self.first_stamp_ns = stamp_ns if self.first_stamp_ns is None else min(self.first_stamp_ns, stamp_ns)

    def newest_stamp_ns(self) -> int | None:
        """Stamp of the newest scan any robot added."""
        return max((s for t in self.tracks.values() if (s := t.fusion.last_stamp_ns) is not None), default=None)

    def n_keyframes(self) -> int:
        return sum(t.fusion.graph.n_keyframes for t in self.tracks.values())

    def attach_range_scans(self, namespace: str, stamp_ns: int, camera: FloatArray,
                           lidar_in_camera: Callable[[str], tuple[FloatArray, float]]) -> tuple[int, int]:
        """Attach robot ``namespace``'s waiting range scans stamped up to ``stamp_ns`` (the annotated scan about to
        be added, camera pose ``camera``) to its fusion; (attached, unplaced) counts.

        A scan's map pose is the camera pose placed at its stamp (:meth:`RobotTrack.place`) composed with the
        lidar's mount in the camera frame, ``lidar_in_camera(frame_id)`` (pose and sweep direction).
        """
        track, waiting = self.tracks[namespace], self.range_scans.get(namespace)
        attached = unplaced = 0
        while waiting and waiting[0][1].stamp_ns <= stamp_ns:
            frame_id, scan = waiting.popleft()
            at = track.place(scan.stamp_ns, stamp_ns, camera)
            if at is None:
                unplaced += 1
                continue
            lidar, sweep = lidar_in_camera(frame_id)
            placed = scan._replace(pose=se2.compose(at, lidar), points_xy=scan.points_xy * (1.0, sweep))
            attached += track.fusion.add_range_scan(placed)
        return attached, unplaced

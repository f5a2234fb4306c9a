"""The semantic-fusion worker: annotated scans (and corrected poses) in, label and entropy layers out.

Under every robot namespace it takes ``annotated_scan`` (aisle_msgs/AnnotatedScan) and, when
``pose_topic`` is set, geometry_msgs/PoseStamped poses of the robot base in the map frame (a
localisation's corrected pose, e.g. ``localization_pose``). Each robot has its own
:class:`SemanticFusion` (keyframes, pose graph, loop closures); all of them write into one shared
:class:`SemanticGrid`, which the core allows because every update is a sum: a robot re-projecting
its own points after a loop closure leaves the others' evidence alone. Every ``store_period_s``
one revision stores the label layer (uint8 :class:`SemanticClass` codes, meta
``{"encoding": "semantic_labels", "classes": [...], "colours": [...]}``) and the entropy layer
(float32). Dynamic classes decay in the grid as of the newest scan stamp.

Zenoh callbacks only queue samples; all fusion work, loop closures and re-optimisation included,
runs in the stage thread between batches of at most ``_BATCH`` scans. Scans use the BLOCK policy, so
their queue is long (``scan_queue_size``) to ride out a slow optimisation without holding senders.

Bad annotated scans (arrays of different lengths, non-finite values, label ids outside
``class_names``, a bad pose) are counted as ``bad_scans`` and skipped; scans not newer than their
robot's newest as ``scans_out_of_order``. After ``restart_after_out_of_order_scans`` in a row the
robot is taken to have restarted (or a bag to be replayed): it gets a fresh fusion, and its earlier
evidence stays in the grid.

The robot's lidar (sensor_msgs/LaserScan on ``range_scan_topic``, ``scan`` by default, under the
same namespace; "" turns it off) feeds the scan matching behind loop closures and the sequential
keyframe alignment; a robot that publishes no range scans is fused from its annotated points alone.
Each range scan waits until an annotated scan is stamped at or after it, takes the robot's pose
interpolated between the annotated scans around it, and attaches to the current keyframe if none has
yet (range scans of keyframes already closed are not used). The lidar's mount is the robot's
``tf_static`` transform from ``base_frame`` (``<namespace>/base_frame`` where its tree is prefixed
so) to the scan's ``header.frame_id``, looked up when the scan is placed; without one,
``lidar_*_in_base`` is used and counted as ``range_scans_mount_from_settings``. Range scans older
than the robot's kept poses are counted as ``range_scans_unplaced``, unusable ones as
``bad_range_scans``, and the oldest waiting ones dropped when more than a minute's worth wait as
``range_scans_dropped`` (uncounted for a robot that has sent no annotated scan yet).

A corrected pose at stamp ``t`` becomes a camera pose through the fixed mount
(``camera_*_in_base``), is carried to the keyframe nearest ``t`` by the robot's own motion between
the two (interpolated from its recent scans' poses) and enters that robot's pose graph as a prior.
Corrections wait until scans have passed their stamp and are applied at most once per
``pose_correction_period_s`` per robot (the newest waiting one), since each costs an optimisation.

On start the grid is seeded from the stored layers (:func:`seed_grid`): the map survives a restart.
Pose graphs and attached observations are not stored, so evidence from before a restart no longer
moves with later loop closures; nothing else is resumed.
"""

from __future__ import annotations

import collections
import logging
import threading
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
from threadpoolctl import threadpool_limits

from services.semantic_fusion import se2
from services.semantic_fusion.errors import SemanticFusionError
from services.semantic_fusion.fusion import FusionSettings, SemanticFusion
from services.semantic_fusion.grid import SemanticGrid
from services.semantic_fusion.inference import infer_labels, rasterise
from services.semantic_fusion.resume import seed_grid
from services.semantic_fusion.scan import RangeScan, observation_from_message, range_scan_from_arrays
from shared import messages
from shared.bus import DropPolicy, Subscription
from shared.store import RevisionWrite, StoreUnavailableError
from shared.transforms import TransformBuffer, add_tf_message, sensor_pose, yaw_from_quaternion
from shared.worker import StageContext

log = logging.getLogger(__name__)

_BATCH = 50
_POSE_HISTORY = 1200
"""Recent scan poses kept per robot to place corrections (two minutes at 10 Hz)."""
_PENDING_CORRECTIONS = 200
_PENDING_RANGE_SCANS = 600
"""Range scans kept per robot while the annotated scans catch up (a minute of a 10 Hz lidar)."""


def _stamp_ns(header: Any) -> int:
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


@dataclass
class _Robot:
    fusion: SemanticFusion
    stamps_ns: collections.deque[int] = field(default_factory=lambda: collections.deque(maxlen=_POSE_HISTORY))
    poses: collections.deque[npt.NDArray[np.float64]] = field(
        default_factory=lambda: collections.deque(maxlen=_POSE_HISTORY))
    corrections: collections.deque[tuple[int, npt.NDArray[np.float64]]] = field(
        default_factory=lambda: collections.deque(maxlen=_PENDING_CORRECTIONS))
    corrected_at: float = -float("inf")
    out_of_order: int = 0

    def pose_at(self, stamp_ns: int) -> npt.NDArray[np.float64] | None:
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


class FusionStage:
    """Stage ``semantic_fusion``; see the module docstring.

    Parameters
    ----------
    context
        The stage context (only ``settings.robot_namespaces`` is read from its settings).
    scan_topic
        AnnotatedScan topic under each robot namespace.
    pose_topic
        PoseStamped topic of the robot base in the map frame taken as pose corrections; "" for none.
    range_scan_topic
        LaserScan topic of the robot's lidar under each robot namespace, for scan matching; "" for none.
    camera_x_in_base_m, camera_y_in_base_m, camera_yaw_in_base_rad
        The camera's floor frame (the frame of AnnotatedScan's camera pose) in the base frame.
    base_frame
        The robot frame the lidar's mount is looked up from in the robot's tf_static.
    lidar_x_in_base_m, lidar_y_in_base_m, lidar_yaw_in_base_rad
        The lidar's frame in the base frame, for robots whose tf_static does not have it.
    pose_correction_sigma_m, pose_correction_sigma_rad
        Standard deviations of a correction's prior, metres and radians.
    pose_correction_period_s
        Least time between two corrections applied to one robot, seconds.
    store_period_s
        How often a revision is committed when anything changed, seconds.
    resolution_m, dynamic_half_life_s, detect_loops
        Grid cell edge (metres), half-life of forklift and human evidence (seconds), loop closing.
    label_layer, entropy_layer
        Names of the stored layers.
    scan_queue_size
        Scans queued before the sender is held.
    restart_after_out_of_order_scans
        Out-of-order scans in a row after which a robot's trajectory starts afresh.
    """

    def __init__(
        self,
        context: StageContext,
        *,
        scan_topic: str = "annotated_scan",
        pose_topic: str = "",
        camera_x_in_base_m: float = 0.0,
        camera_y_in_base_m: float = 0.0,
        camera_yaw_in_base_rad: float = 0.0,
        range_scan_topic: str = "scan",
        base_frame: str = "base_link",
        lidar_x_in_base_m: float = 0.0,
        lidar_y_in_base_m: float = 0.0,
        lidar_yaw_in_base_rad: float = 0.0,
        pose_correction_sigma_m: float = 0.05,
        pose_correction_sigma_rad: float = 0.02,
        pose_correction_period_s: float = 5.0,
        store_period_s: float = 5.0,
        resolution_m: float = 0.05,
        dynamic_half_life_s: float = 20.0,
        detect_loops: bool = True,
        label_layer: str = "semantic_label",
        entropy_layer: str = "semantic_entropy",
        scan_queue_size: int = 2000,
        restart_after_out_of_order_scans: int = 50,
    ) -> None:
        if min(store_period_s, pose_correction_sigma_m, pose_correction_sigma_rad) <= 0 or pose_correction_period_s < 0:
            raise SemanticFusionError("store period and correction sigmas must be > 0, correction period >= 0")
        if scan_queue_size < 1 or restart_after_out_of_order_scans < 1:
            raise SemanticFusionError("scan_queue_size and restart_after_out_of_order_scans must be >= 1")
        self.context = context
        self.settings = FusionSettings(resolution_m=resolution_m, dynamic_half_life_s=dynamic_half_life_s)
        self.detect_loops = detect_loops
        self.mount = np.array([camera_x_in_base_m, camera_y_in_base_m, camera_yaw_in_base_rad], dtype=np.float64)
        self.base_frame = base_frame.strip("/")
        self.lidar_in_base = np.array([lidar_x_in_base_m, lidar_y_in_base_m, lidar_yaw_in_base_rad], dtype=np.float64)
        self.sigmas = (pose_correction_sigma_m, pose_correction_sigma_m, pose_correction_sigma_rad)
        self.pose_correction_period_s = pose_correction_period_s
        self.store_period_s = store_period_s
        self.layer_names = (label_layer, entropy_layer)
        self.restart_after = restart_after_out_of_order_scans
        self.grid = SemanticGrid(resolution_m=resolution_m, dynamic_half_life_s=dynamic_half_life_s)
        self._robots: dict[str, _Robot] = {}
        self._range_scans: dict[str, collections.deque[tuple[str, RangeScan]]] = {}
        """Range scans (with their header frame) waiting for an annotated scan at or after their stamp, by
        namespace; points in the lidar's own frame."""
        self._tf: dict[str, TransformBuffer] = {}
        """Each robot's static transforms, by namespace (kept across a robot's restarts)."""
        self._mount_sources: dict[tuple[str, str], str] = {}
        """Where each (namespace, lidar frame)'s mount came from last ("tf" or "settings"), to log changes."""
        self._first_stamp_ns: int | None = None
        self._since_store = collections.Counter[str]()
        self._resume()
        namespaces = context.settings.robot_namespaces

        def subscribe(topic: str, msgtype: str, maxsize: int) -> Subscription:
            return context.bus.subscribe(topic, msgtype, namespaces=namespaces, policy=DropPolicy.BLOCK,
                                         maxsize=maxsize, name=f"{context.name}.{topic}")

        self.scans = subscribe(scan_topic, messages.ANNOTATED_SCAN, scan_queue_size)
        self.poses = subscribe(pose_topic, messages.POSE_STAMPED, 2000) if pose_topic else None
        self.ranges = subscribe(range_scan_topic, messages.LASER_SCAN, 200) if range_scan_topic else None
        self.tf_static = subscribe("tf_static", messages.TF_MESSAGE, 100) if range_scan_topic else None

    def _resume(self) -> None:
        store, map_id = self.context.store, self.context.map.id
        try:
            labels, entropy = (store.layer(map_id, name) for name in self.layer_names)
        except StoreUnavailableError as err:
            log.warning("cannot read the stored semantic layers, starting empty: %s", err)
            return
        if labels is None or entropy is None:
            return
        lab, ent = labels.layer, entropy.layer
        if (labels.revision_id != entropy.revision_id or lab.data.shape != ent.data.shape
                or abs(lab.resolution_m - self.grid.resolution_m) > 1e-9):
            log.warning("stored semantic layers (revisions %d, %d; %s m) do not fit this grid (%s m): starting empty",
                        labels.revision_id, entropy.revision_id, lab.resolution_m, self.grid.resolution_m)
            return
        cells = seed_grid(self.grid, lab.data, ent.data, origin_x_m=lab.origin_x_m, origin_y_m=lab.origin_y_m)
        log.info("resumed %d labelled cells from revision %d", cells, labels.revision_id)

    # -- loop -----------------------------------------------------------------------------------

    def run(self, stop: threading.Event) -> None:
        last_store = time.monotonic()
        with threadpool_limits(limits=1, user_api="blas"):
            try:
                while not stop.is_set():
                    self._take_range_scans()
                    self._take_scans(timeout_s=0.05)
                    self._take_poses()
                    self._apply_corrections()
                    if time.monotonic() - last_store >= self.store_period_s:
                        last_store = time.monotonic()
                        self._store()
            finally:
                while self.scans.pending():
                    self._take_range_scans()
                    self._take_scans(timeout_s=0.0)
                self._store()
                for subscription in (self.scans, self.poses, self.ranges, self.tf_static):
                    if subscription is not None:
                        subscription.close()

    def _robot(self, namespace: str) -> _Robot:
        robot = self._robots.get(namespace)
        if robot is None:
            fusion = SemanticFusion(self.settings, detect_loops=self.detect_loops, grid=self.grid)
            robot = self._robots[namespace] = _Robot(fusion)
            self.context.counters.set(f"{self.context.name}.robots", len(self._robots))
        return robot

    def _take_scans(self, *, timeout_s: float) -> None:
        item = self.scans.receive(timeout_s)
        taken = 0
        while item is not None:
            self._add_scan(item.namespace, item.message)
            taken += 1
            item = self.scans.receive() if taken < _BATCH else None

    def _add_scan(self, namespace: str, message: Any) -> None:
        robot = self._robot(namespace)
        stamp_ns = _stamp_ns(message.header)
        newest = robot.fusion.last_stamp_ns
        if newest is not None and stamp_ns <= newest:
            robot.out_of_order += 1
            if robot.out_of_order < self.restart_after:
                self.context.count("scans_out_of_order")
                log.warning("scan from %r at %d ns skipped: not after its newest (%d ns)", namespace or "/",
                            stamp_ns, newest)
                return
            log.warning("robot %r: %d scans in a row before its newest: restarted or replayed; its trajectory "
                        "starts afresh (earlier evidence stays)", namespace or "/", robot.out_of_order)
            self.context.count("robot_restarts")
            del self._robots[namespace]
            self._range_scans.pop(namespace, None)
            robot = self._robot(namespace)
        try:
            observation = observation_from_message(message, previous_stamp_ns=robot.fusion.last_stamp_ns)
        except SemanticFusionError as err:
            self.context.count("bad_scans")
            log.warning("scan from %r skipped: %s", namespace or "/", err)
            return
        robot.out_of_order = 0
        self._take_range_scans()
        self._place_range_scans(namespace, robot, observation.stamp_ns, observation.camera_pose)
        closures = robot.fusion.add_scan(observation)
        robot.stamps_ns.append(observation.stamp_ns)
        robot.poses.append(observation.camera_pose)
        if self._first_stamp_ns is None or observation.stamp_ns < self._first_stamp_ns:
            self._first_stamp_ns = observation.stamp_ns
        self._since_store.update(scans=1, loop_closures=closures)
        self.context.count("scans_integrated")
        if closures:
            self.context.count("loop_closures", closures)

    def _take_range_scans(self) -> None:
        while self.tf_static is not None and (item := self.tf_static.receive()) is not None:
            try:
                add_tf_message(self._tf.setdefault(item.namespace, TransformBuffer()), item.message, static=True)
            except ValueError as err:
                self.context.count("bad_transforms")
                log.warning("tf_static from %r skipped: %s", item.namespace or "/", err)
        while self.ranges is not None and (item := self.ranges.receive()) is not None:
            msg = item.message
            try:
                scan = range_scan_from_arrays(_stamp_ns(msg.header), np.zeros(3), float(msg.angle_min),
                                              float(msg.angle_increment), np.asarray(msg.ranges),
                                              range_min_m=float(msg.range_min), range_max_m=float(msg.range_max))
            except SemanticFusionError as err:
                self.context.count("bad_range_scans")
                log.warning("range scan from %r skipped: %s", item.namespace or "/", err)
                continue
            waiting = self._range_scans.setdefault(item.namespace, collections.deque(maxlen=_PENDING_RANGE_SCANS))
            if len(waiting) == waiting.maxlen and item.namespace in self._robots:
                self.context.count("range_scans_dropped")  # uncounted for a robot without annotated scans
            waiting.append((str(msg.header.frame_id), scan))

    def _place_range_scans(self, namespace: str, robot: _Robot, stamp_ns: int,
                           camera: npt.NDArray[np.float64]) -> None:
        """Attach waiting range scans stamped up to ``stamp_ns`` (the annotated scan about to be added).

        A scan's map pose is the camera pose interpolated between the robot's previous annotated
        scan and this one, composed with the lidar's mount in the camera frame.
        """
        waiting = self._range_scans.get(namespace)
        while waiting and waiting[0][1].stamp_ns <= stamp_ns:
            frame_id, scan = waiting.popleft()
            if robot.stamps_ns and scan.stamp_ns >= robot.stamps_ns[-1]:
                before, t0 = robot.poses[-1], robot.stamps_ns[-1]
                fraction = (scan.stamp_ns - t0) / (stamp_ns - t0) if stamp_ns > t0 else 1.0
                at: npt.NDArray[np.float64] | None = se2.compose(before, fraction * se2.between(before, camera))
            else:  # arrived after later annotated scans: placed from the pose history
                at = robot.pose_at(scan.stamp_ns)
            if at is None:
                self.context.count("range_scans_unplaced")
                continue
            lidar, sweep = self._lidar_in_camera(namespace, frame_id)
            placed = scan._replace(pose=se2.compose(at, lidar), points_xy=scan.points_xy * (1.0, sweep))
            if robot.fusion.add_range_scan(placed):
                self.context.count("range_scans_attached")

    def _lidar_in_camera(self, namespace: str, frame_id: str) -> tuple[npt.NDArray[np.float64], float]:
        """The lidar frame ``frame_id`` in the camera's floor frame, and -1.0 if its bearings turn
        clockwise in the base frame (mounted upside down), else 1.0: from the robot's tf_static, or
        from the ``lidar_*_in_base`` settings when that has no transform from the base frame."""
        tf = self._tf.get(namespace)
        base = f"{namespace.strip('/')}/{self.base_frame}" if namespace.strip("/") else self.base_frame
        try:
            if tf is None:
                raise LookupError("no tf_static received")
            if base not in tf.frames:
                base = self.base_frame  # a tree with frames not prefixed by the namespace
            transform = tf.lookup(base, frame_id, None)
        except LookupError as err:
            self.context.count("range_scans_mount_from_settings")
            self._log_mount(namespace, frame_id, "settings", self.lidar_in_base, str(err))
            return se2.between(self.mount, self.lidar_in_base), 1.0
        pose, sweep = sensor_pose(transform, np.ones(1))
        mount = np.array(pose, dtype=np.float64)
        self._log_mount(namespace, frame_id, "tf", mount, f"from {base!r}")
        return se2.between(self.mount, mount), float(sweep[0])

    def _log_mount(self, namespace: str, frame_id: str, source: str, mount: npt.NDArray[np.float64],
                   detail: str) -> None:
        if self._mount_sources.get((namespace, frame_id)) == source:
            return
        self._mount_sources[namespace, frame_id] = source
        level = logging.INFO if source == "tf" else logging.WARNING
        log.log(level, "robot %r: lidar %r at (%.3f m, %.3f m, %.3f rad) in the base frame from %s (%s)",
                namespace or "/", frame_id, *mount, source, detail)

    def _take_poses(self) -> None:
        while self.poses is not None and (item := self.poses.receive()) is not None:
            pose = item.message.pose
            p, q = pose.position, pose.orientation
            try:
                yaw = yaw_from_quaternion((q.x, q.y, q.z, q.w))
            except ValueError as err:
                self.context.count("bad_poses")
                log.warning("pose from %r skipped: %s", item.namespace or "/", err)
                continue
            base = np.array([p.x, p.y, yaw], dtype=np.float64)
            if not np.all(np.isfinite(base)):
                self.context.count("bad_poses")
                log.warning("pose from %r skipped: not finite: %s", item.namespace or "/", base.tolist())
                continue
            camera = se2.compose(base, self.mount)
            self._robot(item.namespace).corrections.append((_stamp_ns(item.message.header), camera))

    def _apply_corrections(self) -> None:
        now = time.monotonic()
        for namespace, robot in self._robots.items():
            newest = robot.fusion.last_stamp_ns
            if newest is None or not robot.corrections or now - robot.corrected_at < self.pose_correction_period_s:
                continue
            ready = [c for c in robot.corrections if c[0] <= newest]
            if not ready:
                continue
            waiting = [c for c in robot.corrections if c[0] > newest]
            robot.corrections.clear()
            robot.corrections.extend(waiting)
            stamp_ns, camera = max(ready, key=lambda c: c[0])
            self._correct(namespace, robot, stamp_ns, camera)
            robot.corrected_at = now

    def _correct(self, namespace: str, robot: _Robot, stamp_ns: int, camera: npt.NDArray[np.float64]) -> None:
        estimate = robot.pose_at(stamp_ns)
        if estimate is None:
            self.context.count("pose_corrections_too_old")
            log.warning("pose of %r at %d ns is older than its kept scan poses; skipped", namespace or "/", stamp_ns)
            return
        fusion = robot.fusion
        keyframe_stamps = fusion.keyframe_stamps_ns
        key = int(np.argmin(np.abs(keyframe_stamps - stamp_ns)))
        corrected = se2.compose(camera, se2.between(estimate, fusion.graph.odometry_pose(key)))
        moved = fusion.add_pose_correction(int(keyframe_stamps[key]), corrected, sigmas=self.sigmas)
        self._since_store.update(pose_corrections=1)
        self.context.count("pose_corrections")
        log.debug("pose correction for %r keyframe %d re-projected %d keyframes", namespace or "/", key, moved)

    # -- store ------------------------------------------------------------------------------------

    def _store(self) -> None:
        if not self._since_store:
            return
        stamps = [r.fusion.last_stamp_ns for r in self._robots.values() if r.fusion.last_stamp_ns is not None]
        now_ns = max(stamps)
        cells = self.grid.cells(now_s=now_ns * 1e-9)
        layers = rasterise(cells, infer_labels(cells), resolution_m=self.grid.resolution_m)
        labels, entropy = layers.grid_layers(label_name=self.layer_names[0], entropy_name=self.layer_names[1])
        labelled = int(np.count_nonzero(labels.data))
        summary = {**self._since_store, "robots": sorted(self._robots), "labelled_cells": labelled}
        write = RevisionWrite(self.context.name, layers=[labels, entropy], input_start_ns=self._first_stamp_ns,
                              input_end_ns=now_ns, summary=summary)
        self.context.counters.set(f"{self.context.name}.grid_cells", self.grid.n_cells)
        self.context.counters.set(f"{self.context.name}.keyframes",
                                  sum(r.fusion.graph.n_keyframes for r in self._robots.values()))
        revision = self.context.commit(write)
        if revision is None:
            return  # store down: counted by commit; tried again next period
        log.info("revision %d: %d labelled cells (%d x %d), %s", revision.id, labelled, *labels.data.shape[::-1],
                 dict(self._since_store))
        self._since_store.clear()


def fusion_stage(context: StageContext) -> FusionStage:
    """The stage built from ``context.settings.fusion``."""
    return FusionStage(context, **context.settings.fusion.model_dump())

"""The semantic-fusion worker: annotated scans (and corrected poses) in, label and entropy layers out.

Under every robot namespace it takes ``scan_topic`` (aisle_msgs/AnnotatedScan), the robot's lidar (LaserScan on
``range_scan_topic``; "" turns it off) with its ``tf_static``, and, when ``pose_topic`` is set, PoseStamped poses
of the robot base in the map frame (a localisation's corrected pose). Each robot has its own track
(:mod:`~services.semantic_fusion.tracks`: fusion, pose graph, loop closures, range scans and corrections waiting to
be placed; sensor mounts from :mod:`~services.semantic_fusion.mounts`); all of them write into one shared
:class:`SemanticGrid` (every update is a sum). Every ``store_period_s`` one revision stores the label layer (uint8
:class:`SemanticClass` codes) and the entropy layer (float32); on start the grid is seeded from them.

All fusion work runs in the stage thread between batches of at most ``_BATCH`` scans; scans use the BLOCK policy
with a long queue (``scan_queue_size``) to ride out a slow optimisation. Scans not newer than their robot's newest
are counted as ``scans_out_of_order``; after ``restart_after_out_of_order_scans`` in a row the robot is taken to
have restarted (or a bag to be replayed) and gets a fresh track (its earlier evidence stays in the grid).
"""

from __future__ import annotations

import collections
import logging
import threading
import time
from typing import Any

import numpy as np
import numpy.typing as npt
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__PoseStamped as PoseStamped
from threadpoolctl import threadpool_limits

from services.semantic_fusion.errors import SemanticFusionError
from services.semantic_fusion.fusion import FusionSettings
from services.semantic_fusion.grid import SemanticGrid
from services.semantic_fusion.inference import infer_labels, rasterise
from services.semantic_fusion.mounts import SensorMounts
from services.semantic_fusion.resume import seed_from_stored
from services.semantic_fusion.scan import observation_from_message
from services.semantic_fusion.tracks import Fleet, RobotTrack, range_scan
from shared import messages
from shared.settings import SemanticFusionSettings
from shared.store import RevisionWrite, StoreUnavailableError
from shared.worker import IDLE_WAIT_S, StageContext, checked, drain, take_transforms

log = logging.getLogger(__name__)

_BATCH = 50


class FusionStage:
    """Stage ``semantic_fusion``, built from its settings section; see the module docstring."""

    def __init__(self, context: StageContext, settings: SemanticFusionSettings) -> None:
        self.context = context
        self.settings = settings = checked(settings, SemanticFusionError)
        self.mounts = SensorMounts.from_settings(settings)
        self.sigmas = (settings.pose_correction_sigma_m,) * 2 + (settings.pose_correction_sigma_rad,)
        self.layer_names = (settings.label_layer, settings.entropy_layer)
        fusion = FusionSettings(resolution_m=settings.resolution_m, dynamic_half_life_s=settings.dynamic_half_life_s)
        self.grid = SemanticGrid(resolution_m=fusion.resolution_m, dynamic_half_life_s=fusion.dynamic_half_life_s)
        self.fleet = Fleet(self.grid, fusion, detect_loops=settings.detect_loops)
        self._since_store = collections.Counter[str]()
        self._resume()
        self.scans = context.subscribe(settings.scan_topic, messages.ANNOTATED_SCAN, maxsize=settings.scan_queue_size)
        pose_topic, range_topic = settings.pose_topic, settings.range_scan_topic
        self.poses = context.subscribe(pose_topic, messages.POSE_STAMPED, maxsize=2000) if pose_topic else None
        self.ranges = context.subscribe(range_topic, messages.LASER_SCAN, maxsize=200) if range_topic else None
        self.tf_static = context.subscribe("tf_static", messages.TF_MESSAGE, maxsize=100) if range_topic else None

    def _resume(self) -> None:
        try:
            stored = [self.context.store.layer(self.context.map.id, name) for name in self.layer_names]
            cells = seed_from_stored(self.grid, *stored)
        except (StoreUnavailableError, SemanticFusionError) as err:
            log.warning("semantic layers not resumed, starting empty: %s", err)
            return
        if cells:
            log.info("resumed %d labelled cells from revision %d", cells, stored[0].revision_id if stored[0] else 0)

    def run(self, stop: threading.Event) -> None:
        last_store = time.monotonic()
        with threadpool_limits(limits=1, user_api="blas"):
            try:
                while not stop.is_set():
                    self._take_range_scans()
                    self._take_scans(timeout_s=IDLE_WAIT_S)
                    self._take_poses()
                    for namespace, robot in self.fleet.tracks.items():
                        if (due := robot.due_correction(time.monotonic(), self.settings.pose_correction_period_s)):
                            self._correct(namespace, robot, *due)
                    if time.monotonic() - last_store >= self.settings.store_period_s:
                        last_store = time.monotonic()
                        self._store()
            finally:
                while self.scans.pending():
                    self._take_range_scans()
                    self._take_scans(timeout_s=0.0)
                self._store()

    def _take_scans(self, *, timeout_s: float) -> None:
        item, taken = self.scans.receive(timeout_s), 0
        while item is not None:
            self._add_scan(item.namespace, item.message)
            taken += 1
            item = self.scans.receive() if taken < _BATCH else None

    def _add_scan(self, namespace: str, message: Any) -> None:  # aisle_msgs/AnnotatedScan (no static class)
        robot = self.fleet.track(namespace)
        self.context.counters.set(f"{self.context.name}.robots", len(self.fleet.tracks))
        stamp_ns, newest = messages.stamp_ns(message.header), robot.fusion.last_stamp_ns
        if newest is not None and stamp_ns <= newest:
            robot.out_of_order += 1
            if robot.out_of_order < self.settings.restart_after_out_of_order_scans:
                self.context.count("scans_out_of_order")
                log.warning("scan from %r at %d ns skipped: not after its newest (%d ns)", namespace or "/",
                            stamp_ns, newest)
                return
            log.warning("robot %r: %d scans in a row before its newest: restarted or replayed; its trajectory "
                        "starts afresh (earlier evidence stays)", namespace or "/", robot.out_of_order)
            self.context.count("robot_restarts")
            robot = self.fleet.restart(namespace)
        try:
            observation = observation_from_message(message, previous_stamp_ns=robot.fusion.last_stamp_ns)
        except SemanticFusionError as err:
            self.context.count("bad_scans")
            log.warning("scan from %r skipped: %s", namespace or "/", err)
            return
        robot.out_of_order = 0
        self._take_range_scans()
        attached, unplaced = self.fleet.attach_range_scans(namespace, observation.stamp_ns, observation.camera_pose,
                                                           lambda frame: self._lidar(namespace, frame))
        self.context.count("range_scans_attached", attached)
        self.context.count("range_scans_unplaced", unplaced)
        closures = robot.fusion.add_scan(observation)
        self.fleet.record(namespace, observation.stamp_ns, observation.camera_pose)
        self._since_store.update(scans=1, loop_closures=closures)
        self.context.count("scans_integrated")
        self.context.count("loop_closures", closures)

    def _lidar(self, namespace: str, frame_id: str) -> tuple[npt.NDArray[np.float64], float]:
        lidar, sweep, from_tf = self.mounts.lidar_in_camera(namespace, frame_id)
        self.context.count("range_scans_mount_from_settings", int(not from_tf))
        return lidar, sweep

    def _take_range_scans(self) -> None:
        take_transforms(self.context, self.mounts.static_tf, static=self.tf_static)
        for item in drain(self.ranges):
            try:
                scan = range_scan(item.message)
            except SemanticFusionError as err:
                self.context.count("bad_range_scans")
                log.warning("range scan from %r skipped: %s", item.namespace or "/", err)
                continue
            if self.fleet.queue_range_scan(item.namespace, str(item.message.header.frame_id), scan):
                self.context.count("range_scans_dropped")

    def _take_poses(self) -> None:
        for item in drain(self.poses):
            message: PoseStamped = item.message
            try:
                camera = self.mounts.camera_pose(message.pose)
            except SemanticFusionError as err:
                self.context.count("bad_poses")
                log.warning("pose from %r skipped: %s", item.namespace or "/", err)
                continue
            self.fleet.track(item.namespace).corrections.append((messages.stamp_ns(message.header), camera))

    def _correct(self, namespace: str, robot: RobotTrack, stamp_ns: int, camera: npt.NDArray[np.float64]) -> None:
        correction = robot.correction(stamp_ns, camera)
        if correction is None:
            self.context.count("pose_corrections_too_old")
            log.warning("pose of %r at %d ns is older than its kept scan poses; skipped", namespace or "/", stamp_ns)
            return
        moved = robot.fusion.add_pose_correction(*correction, sigmas=self.sigmas)
        self._since_store.update(pose_corrections=1)
        self.context.count("pose_corrections")
        log.debug("pose correction for %r at %d ns re-projected %d keyframes", namespace or "/", stamp_ns, moved)

    def _store(self) -> None:
        if not self._since_store:
            return
        now_ns = self.fleet.newest_stamp_ns() or 0
        cells = self.grid.cells(now_s=now_ns * 1e-9)
        layers = rasterise(cells, infer_labels(cells), resolution_m=self.grid.resolution_m)
        labels, entropy = layers.grid_layers(label_name=self.layer_names[0], entropy_name=self.layer_names[1])
        labelled = int(np.count_nonzero(labels.data))
        summary = {**self._since_store, "robots": sorted(self.fleet.tracks), "labelled_cells": labelled}
        write = RevisionWrite(self.context.name, layers=[labels, entropy], input_start_ns=self.fleet.first_stamp_ns,
                              input_end_ns=now_ns, summary=summary)
        self.context.counters.set(f"{self.context.name}.grid_cells", self.grid.n_cells)
        self.context.counters.set(f"{self.context.name}.keyframes", self.fleet.n_keyframes())
        revision = self.context.commit(write)
        if revision is None:
            return  # store down: counted by commit; tried again next period
        log.info("revision %d: %d labelled cells (%d x %d), %s", revision.id, labelled, *labels.data.shape[::-1],
                 dict(self._since_store))
        self._since_store.clear()


def fusion_stage(context: StageContext) -> FusionStage:
    """The stage built from its settings section, ``context.settings.fusion``."""
    return FusionStage(context, context.settings.fusion)

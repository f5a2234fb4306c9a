"""The pillar-mapping worker: fisheye frames and tf from the bus in, pillars, rack rows and bins out.

Every robot's downward fisheye frames are searched for uprights; each frame's bearings go into one bearing-only
map (the robots share the ``map`` frame), posed by the robot's tf at the image stamp (an image waits up to
``tf_wait_s`` for tf to reach it; :mod:`~services.pillar_mapping.posing`), with the localisation's stated
uncertainty (``localisation_sigma_m``/``_rad``) and, where tf has it, its pose in the robot's ``odom_frame``.
Every ``store_period_s``, when the localisation is uncertain, the window's poses and landmarks are smoothed with
the odometry's relative motion (:meth:`~services.pillar_mapping.mapper.BearingOnlyMapper.smooth`); then the
reliable landmarks precise to ``max_landmark_sigma_m`` are fitted with rack rows and bins
(:func:`~services.pillar_mapping.layout.fit_landmark_map`, bins on the levels of the site's ``rack_profiles``) and
stored as one revision of the ``pillar``, ``rack_row``, ``bin`` and ``corridor`` features. On start the stored
observed pillars seed the map, so a restart keeps what was committed.
"""

from __future__ import annotations

import logging
import threading
import time

import numpy as np

from services.pillar_mapping.camera import camera_from_info
from services.pillar_mapping.detection import detect_pillars
from services.pillar_mapping.errors import PillarMappingError
from services.pillar_mapping.layout import fit_landmark_map, layout_features
from services.pillar_mapping.levels import rack_profile
from services.pillar_mapping.mapper import BearingOnlyMapper
from services.pillar_mapping.mount import vehicle_bearings
from services.pillar_mapping.posing import (
    Frame,
    RobotView,
    decode_frame,
    frame_due,
    frame_pose,
    resumed_landmarks,
)
from shared import messages
from shared.settings import PillarSettings
from shared.store import RevisionWrite, StoreUnavailableError
from shared.vocabulary import FeatureKind
from shared.worker import IDLE_WAIT_S, PENDING_WAIT_S, StageContext, drain, take_transforms

log = logging.getLogger(__name__)


class PillarStage:
    """Stage ``pillar_mapping``; see the module docstring."""

    def __init__(self, context: StageContext, settings: PillarSettings) -> None:
        self.context = context
        self.settings = settings
        self.images = context.subscribe(settings.image_topic, messages.IMAGE, maxsize=4)
        self.infos = context.subscribe(settings.info_topic, messages.CAMERA_INFO, maxsize=4)
        self.tf, self.tf_static = context.subscribe_transforms()
        self.mapper = BearingOnlyMapper(max_range_m=settings.max_range_m)
        self.profiles = [rack_profile(p.levels_m, p.area) for p in settings.rack_profiles]
        sigma_m, sigma_rad = settings.localisation_sigma_m, settings.localisation_sigma_rad
        self.pose_cov = np.diag([sigma_m**2, sigma_m**2, sigma_rad**2]) if sigma_m > 0 or sigma_rad > 0 else None
        self.robots: dict[str, RobotView] = {}
        self.first_stamp_ns: int | None = None
        self.last_stamp_ns: int | None = None
        self._frames_since_store = 0
        self._resume()

    def _resume(self) -> None:
        try:
            stored = self.context.store.features(self.context.map.id, kinds=[FeatureKind.PILLAR])
        except StoreUnavailableError as err:
            log.warning("cannot read the stored pillars, starting empty: %s", err)
            return
        points = [s.feature.geometry["coordinates"] for s in stored
                  if s.stage == self.context.name and s.feature.properties.get("observed", True)
                  and s.feature.geometry.get("type") == "Point"]
        if points:
            self.mapper.seed(resumed_landmarks(points))
            log.info("resuming from %d stored pillars", len(points))

    def run(self, stop: threading.Event) -> None:
        last_store = time.monotonic()
        try:
            while not stop.is_set():
                waiting = any(robot.waiting is not None for robot in self.robots.values())
                self._take_inputs(timeout_s=PENDING_WAIT_S if waiting else IDLE_WAIT_S)
                self._process_waiting()
                if time.monotonic() - last_store >= self.settings.store_period_s:
                    self._store()
                    last_store = time.monotonic()
        finally:
            self._take_inputs(timeout_s=0.0)
            self._process_waiting(final=True)
            self._store()

    def _robot(self, namespace: str) -> RobotView:
        return self.robots.setdefault(namespace, RobotView())

    def _take_inputs(self, *, timeout_s: float) -> None:
        """tf, camera infos and images queued now (waiting up to ``timeout_s`` for an image)."""
        take_transforms(self.context, lambda namespace: self._robot(namespace).tf, static=self.tf_static,
                        dynamic=self.tf)
        for item in drain(self.infos):
            try:
                self._robot(item.namespace).camera = camera_from_info(item.message)
            except (PillarMappingError, ValueError, TypeError) as err:
                self.context.count("bad_camera_info")
                log.warning("camera info from %r skipped: %s", item.namespace or "/", err)
        image = self.images.receive(timeout_s)
        while image is not None:
            robot = self._robot(image.namespace)
            try:
                frame = decode_frame(image.message, image.received_ns, robot.camera)
            except PillarMappingError as err:
                self.context.count("bad_frames")
                log.warning("frame from %r skipped: %s", image.namespace or "/", err)
            else:
                if robot.waiting is not None:
                    self.context.count("frames_superseded")
                robot.waiting = frame
            image = self.images.receive()

    def _process_waiting(self, *, final: bool = False) -> None:
        now_ns, settings = time.time_ns(), self.settings
        for namespace, robot in self.robots.items():
            frame = robot.waiting
            if frame is not None and (final or frame_due(robot, frame, namespace=namespace, now_ns=now_ns,
                                                         map_frame=settings.map_frame, base_frame=settings.base_frame,
                                                         wait_s=settings.tf_wait_s)):
                robot.waiting = None
                self._map_frame(namespace, robot, frame)

    def _map_frame(self, namespace: str, robot: RobotView, frame: Frame) -> None:
        """Detect and map one image; bad or unposed frames are counted and skipped."""
        if robot.camera is None:
            self.context.count("frames_without_camera_info")
            return
        try:
            pose = frame_pose(robot.tf, frame, namespace=namespace, map_frame=self.settings.map_frame,
                              base_frame=self.settings.base_frame, odom_frame=self.settings.odom_frame)
        except (LookupError, ValueError) as err:
            self.context.count("frames_without_pose")
            log.debug("frame of %r at %d ns has no pose: %s", namespace or "/", frame.stamp_ns, err)
            return
        if pose.odometry is None:
            self.context.count("frames_without_odometry")
        start = time.perf_counter()
        try:
            seen = detect_pillars(frame.pixels, robot.camera)
            self.mapper.observe(tuple(pose.sensor), vehicle_bearings(pose.mount, seen.bearings_rad), seen.sigmas_rad,
                                pose_cov=self.pose_cov,
                                odometry_pose=None if pose.odometry is None else tuple(pose.odometry),
                                track=list(self.robots).index(namespace))
        except (PillarMappingError, ValueError) as err:
            self.context.count("bad_frames")
            log.warning("frame of %r at %d ns skipped: %s", namespace or "/", frame.stamp_ns, err)
            return
        self.context.count("frame_time_us", round(1e6 * (time.perf_counter() - start)))
        self.context.count("frames")
        self._frames_since_store += 1
        stamp = frame.stamp_ns
        self.first_stamp_ns = stamp if self.first_stamp_ns is None else min(self.first_stamp_ns, stamp)
        self.last_stamp_ns = stamp if self.last_stamp_ns is None else max(self.last_stamp_ns, stamp)

    def _store(self) -> None:
        if self._frames_since_store == 0:
            return
        if self.pose_cov is not None:
            start = time.process_time()
            try:
                self.mapper.smooth()
            except PillarMappingError as err:
                self.context.count("smoothing_failures")
                log.warning("landmarks not smoothed: %s", err)
            self.context.count("smooth_cpu_us", round(1e6 * (time.process_time() - start)))
        reliable = self.mapper.reliable_landmarks()
        try:
            layout = fit_landmark_map(reliable, max_sigma_m=self.settings.max_landmark_sigma_m,
                                      profiles=self.profiles, min_bay_pitch_m=self.settings.min_bay_pitch_m,
                                      max_bay_pitch_m=self.settings.max_bay_pitch_m)
        except (PillarMappingError, ValueError, np.linalg.LinAlgError) as err:
            self.context.count("fit_failures")
            log.warning("layout of %d landmarks not fitted: %s", len(reliable.means), err)
            return
        features = layout_features(layout)
        write = RevisionWrite(self.context.name, features=features, input_start_ns=self.first_stamp_ns,
                              input_end_ns=self.last_stamp_ns,
                              summary={"frames": self._frames_since_store, "landmarks": len(reliable.means)})
        revision = self.context.commit(write)
        if revision is not None:
            log.info("revision %d: %d pillars, %d rack rows, %d bins from %d landmarks (%d new frames)", revision.id,
                     *(len(features[kind]) for kind in (FeatureKind.PILLAR, FeatureKind.RACK_ROW, FeatureKind.BIN)),
                     len(reliable.means), self._frames_since_store)
            self._frames_since_store = 0


def pillar_stage(context: StageContext) -> PillarStage:
    """The stage built from its settings section, ``context.settings.pillars``."""
    return PillarStage(context, context.settings.pillars)

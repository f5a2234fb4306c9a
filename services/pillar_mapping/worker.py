"""The pillar-mapping worker: fisheye frames and tf from the bus in, pillars, rack rows and bins out.

Every robot's downward fisheye frames are searched for uprights; each frame's bearings go into
one bearing-only map (the robots share the ``map`` frame), posed by the robot's tf at the
image stamp (an image waits up to ``tf_wait_s`` for tf to reach it), with the localisation's
stated uncertainty (``localisation_sigma_m``/``_rad``) and, where tf has it, its pose in the
robot's ``odom_frame``. Every ``store_period_s``, when the localisation is uncertain, the window's
poses and landmarks are smoothed with the odometry's relative motion
(:meth:`~services.pillar_mapping.mapper.BearingOnlyMapper.smooth`); then the reliable
landmarks precise to ``max_landmark_sigma_m`` are fitted with rack rows and bins
(:func:`~services.pillar_mapping.layout.fit_landmark_map`, bins on the levels of the site's
``rack_profiles``) and stored as one revision of the ``pillar``, ``rack_row``, ``bin`` and
``corridor`` features. On start the stored observed pillars seed the
map, so a restart keeps what was committed.
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt

from services.pillar_mapping.bag import image_bgr
from services.pillar_mapping.camera import FisheyeCamera, camera_from_info
from services.pillar_mapping.detection import detect_pillars
from services.pillar_mapping.errors import PillarMappingError
from services.pillar_mapping.layout import fit_landmark_map, layout_features
from services.pillar_mapping.levels import rack_profile
from services.pillar_mapping.mapper import BearingOnlyMapper, LandmarkMap
from services.pillar_mapping.mount import mount_from_transform, sensor_pose, vehicle_bearings
from shared import messages
from shared.bus import DropPolicy, Received, Subscription
from shared.store import RevisionWrite, StoreUnavailableError
from shared.transforms import TransformBuffer, add_tf_message, sensor_pose_2d
from shared.worker import StageContext

log = logging.getLogger(__name__)

_RESUMED_SIGMA_M = 0.03
_RESUMED_OBSERVATIONS = 10


def _stamp_ns(message: Any) -> int:
    return int(message.header.stamp.sec) * 1_000_000_000 + int(message.header.stamp.nanosec)


def _frame(namespace: str, name: str) -> str:
    return f"{namespace}/{name}" if namespace else name


class _Frame(NamedTuple):
    """A decoded image waiting for tf: stamp and wall-clock arrival (ns), optical frame, BGR pixels."""

    stamp_ns: int
    received_ns: int
    frame_id: str
    pixels: npt.NDArray[np.uint8]


@dataclass
class _Robot:
    """What the worker knows of one robot: its tf, its camera, and the image waiting for tf."""

    tf: TransformBuffer = field(default_factory=lambda: TransformBuffer(cache_s=10.0))
    camera: FisheyeCamera | None = None
    waiting: _Frame | None = None


class PillarStage:
    """Stage ``pillar_mapping``; see the module docstring."""

    def __init__(self, context: StageContext) -> None:
        self.context = context
        self.settings = context.settings.pillars
        namespaces = context.settings.robot_namespaces
        bus = context.bus

        def subscribe(topic: str, msgtype: str, policy: DropPolicy, maxsize: int) -> Subscription:
            return bus.subscribe(topic, msgtype, namespaces=namespaces, policy=policy, maxsize=maxsize,
                                 name=f"{context.name}.{topic}")

        self.images = subscribe(self.settings.image_topic, messages.IMAGE, DropPolicy.KEEP_NEWEST, 4)
        self.infos = subscribe(self.settings.info_topic, messages.CAMERA_INFO, DropPolicy.KEEP_NEWEST, 4)
        self.tf = subscribe("tf", messages.TF_MESSAGE, DropPolicy.BLOCK, 2000)
        self.tf_static = subscribe("tf_static", messages.TF_MESSAGE, DropPolicy.BLOCK, 100)
        self._subscriptions = (self.images, self.infos, self.tf, self.tf_static)
        self.mapper = BearingOnlyMapper(max_range_m=self.settings.max_range_m)
        self.profiles = [rack_profile(p.levels_m, p.area) for p in self.settings.rack_profiles]
        sigma_m, sigma_rad = self.settings.localisation_sigma_m, self.settings.localisation_sigma_rad
        self.pose_cov = np.diag([sigma_m**2, sigma_m**2, sigma_rad**2]) if sigma_m > 0 or sigma_rad > 0 else None
        self.robots: dict[str, _Robot] = {}
        self.first_stamp_ns: int | None = None
        self.last_stamp_ns: int | None = None
        self._frames_since_store = 0
        self._resume()

    def _resume(self) -> None:
        try:
            stored = self.context.store.features(self.context.map.id, kinds=["pillar"])
        except StoreUnavailableError as err:
            log.warning("cannot read the stored pillars, starting empty: %s", err)
            return
        points = [
            s.feature.geometry["coordinates"]
            for s in stored
            if s.stage == self.context.name and s.feature.properties.get("observed", True)
            and s.feature.geometry.get("type") == "Point"
        ]
        if not points:
            return
        means = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        covs = np.tile(np.eye(2) * _RESUMED_SIGMA_M**2, (len(means), 1, 1))
        self.mapper.seed(LandmarkMap(means, covs, np.full(len(means), _RESUMED_OBSERVATIONS, dtype=np.int64)))
        log.info("resuming from %d stored pillars", len(means))

    def run(self, stop: threading.Event) -> None:
        last_store = time.monotonic()
        try:
            while not stop.is_set():
                self._take_transforms()
                self._take_infos()
                self._take_image(timeout_s=0.05)
                self._process_waiting()
                if time.monotonic() - last_store >= self.settings.store_period_s:
                    self._store()
                    last_store = time.monotonic()
        finally:
            self._take_transforms()
            self._take_infos()
            self._take_image(timeout_s=0.0)
            self._process_waiting(final=True)
            self._store()
            for subscription in self._subscriptions:
                subscription.close()

    def _robot(self, namespace: str) -> _Robot:
        return self.robots.setdefault(namespace, _Robot())

    def _take_transforms(self) -> None:
        for subscription, static in ((self.tf_static, True), (self.tf, False)):
            while (item := subscription.receive()) is not None:
                try:
                    add_tf_message(self._robot(item.namespace).tf, item.message, static=static)
                except ValueError as err:
                    self.context.count("bad_transforms")
                    log.warning("tf from %r skipped: %s", item.namespace or "/", err)

    def _take_infos(self) -> None:
        while (item := self.infos.receive()) is not None:
            namespace = item.namespace
            try:
                self._robot(namespace).camera = camera_from_info(item.message)
            except (PillarMappingError, ValueError, TypeError) as err:
                self.context.count("bad_camera_info")
                log.warning("camera info from %r skipped: %s", namespace or "/", err)

    def _take_image(self, *, timeout_s: float) -> None:
        item = self.images.receive(timeout_s)
        while item is not None:
            namespace = item.namespace
            frame = self._decode(namespace, item)
            if frame is not None:
                robot = self._robot(namespace)
                if robot.waiting is not None:
                    self.context.count("frames_superseded")
                robot.waiting = frame
            item = self.images.receive()

    def _decode(self, namespace: str, item: Received) -> _Frame | None:
        """The image's pixels, or None (counted) if its encoding or size is unusable."""
        robot = self._robot(namespace)
        try:
            pixels = image_bgr(item.message)
            if robot.camera is not None and pixels.shape[:2] != (robot.camera.height, robot.camera.width):
                raise PillarMappingError(f"image is {pixels.shape[1]}x{pixels.shape[0]} but the calibration is for "
                                         f"{robot.camera.width}x{robot.camera.height}")
        except (PillarMappingError, ValueError) as err:
            self.context.count("bad_frames")
            log.warning("frame from %r skipped: %s", namespace or "/", err)
            return None
        return _Frame(_stamp_ns(item.message), item.received_ns, str(item.message.header.frame_id), pixels)

    def _process_waiting(self, *, final: bool = False) -> None:
        now = time.time_ns()
        for namespace, robot in self.robots.items():
            frame = robot.waiting
            if frame is None:
                continue
            base = _frame(namespace, self.settings.base_frame)
            newest = robot.tf.newest_stamp_ns(self.settings.map_frame, base)
            waited_s = (now - frame.received_ns) / 1e9
            if not final and (newest is None or newest < frame.stamp_ns) and waited_s < self.settings.tf_wait_s:
                continue
            robot.waiting = None
            self._map_frame(namespace, robot, frame)

    def _map_frame(self, namespace: str, robot: _Robot, frame: _Frame) -> None:
        """Detect and map one image; bad or unposed frames are counted and skipped."""
        if robot.camera is None:
            self.context.count("frames_without_camera_info")
            return
        base = _frame(namespace, self.settings.base_frame)
        try:
            vehicle = sensor_pose_2d(robot.tf.lookup(self.settings.map_frame, base, frame.stamp_ns))
            mount = mount_from_transform(robot.tf.lookup(base, frame.frame_id, frame.stamp_ns))
        except (LookupError, ValueError) as err:
            self.context.count("frames_without_pose")
            log.debug("frame of %r at %d ns has no pose: %s", namespace or "/", frame.stamp_ns, err)
            return
        try:
            odometry = sensor_pose(mount, np.array(sensor_pose_2d(robot.tf.lookup(
                _frame(namespace, self.settings.odom_frame), base, frame.stamp_ns)), dtype=np.float64))
        except (LookupError, ValueError):
            self.context.count("frames_without_odometry")
            odometry = None
        start = time.perf_counter()
        try:
            seen = detect_pillars(frame.pixels, robot.camera)
            pose = sensor_pose(mount, np.array(vehicle, dtype=np.float64))
            self.mapper.observe(tuple(pose), vehicle_bearings(mount, seen.bearings_rad), seen.sigmas_rad,
                                pose_cov=self.pose_cov, odometry_pose=None if odometry is None else tuple(odometry),
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
                     len(features["pillar"]), len(features["rack_row"]), len(features["bin"]), len(reliable.means),
                     self._frames_since_store)
            self._frames_since_store = 0

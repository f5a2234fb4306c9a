"""The object-labelling worker: RGB-D frames from the bus in, annotated scans and dynamic objects out.

Per robot namespace it pairs ``rgbd/color/image_raw`` and ``rgbd/depth/image_raw`` by stamp,
teaches in the ground plane from the first usable frame (kept fixed; after
``reteach_after_frames`` consecutive frames failing the check it is taught in again), labels the
newest pair, publishes an ``aisle_msgs/AnnotatedScan`` on ``/<robot>/annotated_scan`` with the
camera's floor-frame pose in the map (TF at the frame stamp), and every ``commit_period_s``
commits the forklifts, people and pallets currently seen as ``object`` features.

Frames are only taken from the newest: camera queues drop the oldest, and a pair that a newer one
overtakes before it is labelled is skipped (counted).
"""

from __future__ import annotations

import collections
import hashlib
import logging
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
from threadpoolctl import threadpool_limits

from services.object_labelling.annotation import annotate_cones, camera_floor_pose, detections
from services.object_labelling.camera import (
    CameraIntrinsics,
    check_depth,
    depth_to_points,
    intrinsics_from_camera_info,
    subsample,
)
from services.object_labelling.classifier import UNKNOWN, LabelModel
from services.object_labelling.cnn import EfficientNetLite0, default_weights_path
from services.object_labelling.errors import ObjectLabellingError
from services.object_labelling.frames import decode_depth, decode_rgb
from services.object_labelling.ground_plane import GroundPlane, fit_ground_plane
from services.object_labelling.labeller import FrameLabels, ObjectLabeller
from services.object_labelling.objects import ObjectTracker
from services.object_labelling.pairing import FramePair, FramePairer, Stream
from services.object_labelling.retrieval import DEFAULT_PRIORS, PriorDatabase
from shared import messages
from shared.bus import DropPolicy, Publisher, Subscription
from shared.settings import Settings
from shared.store import RevisionWrite
from shared.transforms import Transform, TransformBuffer, add_tf_message
from shared.worker import StageContext

log = logging.getLogger(__name__)

ANNOTATED_SCAN_TOPIC = "annotated_scan"
DYNAMIC_CLASSES = frozenset({"forklift", "human", "pallet"})
TRAIN_HINT = (
    "train one with `aisle train-classifier --data ../shared/data/images` (real photos and simulator renders) "
    "or `aisle train-classifier` (simulator renders only); it writes labelling.model_path (see "
    "docs/object_labelling.md)"
)
_STEP_HISTORY = 500


def _stamp_ns(header: Any) -> int:
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def load_recogniser(model_path: Path, weights_path: Path | None) -> tuple[EfficientNetLite0, LabelModel]:
    """The CNN and the SVM model, checked to belong together; errors say how to get a model."""
    try:
        model = LabelModel.load(model_path)
    except ObjectLabellingError as err:
        raise ObjectLabellingError(f"{err}; {TRAIN_HINT}") from err
    weights = weights_path or default_weights_path()
    net = EfficientNetLite0.load(weights)
    if model.weights_sha256:
        digest = hashlib.sha256(weights.read_bytes()).hexdigest()
        if digest != model.weights_sha256:
            raise ObjectLabellingError(
                f"classifier model {model_path} was trained on CNN weights {model.weights_sha256[:12]}..., "
                f"but {weights} is {digest[:12]}...; {TRAIN_HINT}"
            )
    return net, model


@dataclass
class _Robot:
    """Per-robot state: camera model, taught-in plane, labeller, TF and the annotated-scan publisher."""

    publisher: Publisher
    transforms: TransformBuffer = field(default_factory=TransformBuffer)
    intrinsics: CameraIntrinsics | None = None
    plane: GroundPlane | None = None
    labeller: ObjectLabeller | None = None
    invalid_streak: int = 0
    last_stamp_ns: int = -1


class LabellingStage:
    """Stage ``object_labelling``; see the module docstring.

    Parameters
    ----------
    context
        The stage context (bus, store, settings: only ``robot_namespaces`` is read here).
    model_path, weights_path
        The SVM model file and the EfficientNet-Lite0 checkpoint (None: the pip package's file).
    colour_topic, depth_topic, camera_info_topic
        Topics under each robot namespace.
    map_frame
        The TF frame the camera pose and objects are expressed in.
    pair_tolerance_s
        Largest stamp difference between a colour and a depth frame of one pair.
    pose_wait_s
        How long a pair waits for TF to reach its stamp before it is dropped.
    max_rois
        Proposals per frame that go through the CNN.
    min_ground_inliers
        Points (on a 4-pixel grid) that must lie on the taught-in plane for a frame to be valid.
    reteach_after_frames
        Consecutive invalid frames after which the plane is taught in again.
    commit_period_s
        How often the currently seen objects are committed.
    forget_after_s, merge_distance_m
        Objects unseen for this long are dropped; detections this close to a known object of the
        same class update it.
    frame_queue_size
        Camera subscription queue length (newest frames kept).
    """

    def __init__(
        self,
        context: StageContext,
        *,
        model_path: Path = Path("var/object_labelling.npz"),
        weights_path: Path | None = None,
        colour_topic: str = "rgbd/color/image_raw",
        depth_topic: str = "rgbd/depth/image_raw",
        camera_info_topic: str = "rgbd/camera_info",
        map_frame: str = "map",
        pair_tolerance_s: float = 0.005,
        pose_wait_s: float = 0.5,
        max_rois: int = 3,
        min_ground_inliers: int = 300,
        reteach_after_frames: int = 30,
        commit_period_s: float = 5.0,
        forget_after_s: float = 10.0,
        merge_distance_m: float = 1.0,
        frame_queue_size: int = 4,
    ) -> None:
        self.context = context
        self.net, self.model = load_recogniser(model_path, weights_path)
        self.priors = PriorDatabase.read_csv(DEFAULT_PRIORS)
        self.class_names = (UNKNOWN, *self.model.roi.classes, *self.model.scene.classes)
        self.map_frame = map_frame
        self.max_rois = max_rois
        self.min_ground_inliers = min_ground_inliers
        self.reteach_after_frames = reteach_after_frames
        self.commit_period_s = commit_period_s
        self.pose_wait_s = pose_wait_s
        self.pairer: FramePairer[Any] = FramePairer(tolerance_ns=round(pair_tolerance_s * 1e9))
        self.tracker = ObjectTracker(merge_distance_m=merge_distance_m, forget_after_s=forget_after_s)
        self.step_times_s: dict[str, collections.deque[float]] = collections.defaultdict(
            lambda: collections.deque(maxlen=_STEP_HISTORY)
        )
        self._robots: dict[str, _Robot] = {}
        self._waiting: dict[str, tuple[FramePair[Any], float]] = {}
        self._clock: tuple[int, float] | None = None  # newest frame stamp and the wall time it came
        self._inputs: tuple[int, int, int] | None = None  # first and last stamp, frames since the last commit
        namespaces = context.settings.robot_namespaces
        bus = context.bus

        def subscribe(topic: str, msgtype: str, policy: DropPolicy, maxsize: int) -> Subscription:
            return bus.subscribe(topic, msgtype, namespaces=namespaces, policy=policy, maxsize=maxsize,
                                 name=f"{context.name}.{topic}")

        self.colour = subscribe(colour_topic, messages.IMAGE, DropPolicy.KEEP_NEWEST, frame_queue_size)
        self.depth = subscribe(depth_topic, messages.IMAGE, DropPolicy.KEEP_NEWEST, frame_queue_size)
        self.camera_info = subscribe(camera_info_topic, messages.CAMERA_INFO, DropPolicy.KEEP_NEWEST, 8)
        self.tf = subscribe("tf", messages.TF_MESSAGE, DropPolicy.BLOCK, 2000)
        self.tf_static = subscribe("tf_static", messages.TF_MESSAGE, DropPolicy.BLOCK, 100)
        self._subscriptions = (self.colour, self.depth, self.camera_info, self.tf, self.tf_static)

    # -- loop -----------------------------------------------------------------------------------

    def run(self, stop: threading.Event) -> None:
        last_commit = time.monotonic()
        with threadpool_limits(limits=1, user_api="blas"):
            try:
                while not stop.is_set():
                    self._take_frames(timeout_s=0.05)
                    self._take_transforms()
                    self._take_camera_info()
                    self._queue_pairs()
                    self._handle_waiting()
                    self.context.counters.set(f"{self.context.name}.pairs_skipped", self.pairer.skipped)
                    if time.monotonic() - last_commit >= self.commit_period_s:
                        last_commit = time.monotonic()
                        self._commit()
            finally:
                self._commit()
                for subscription in self._subscriptions:
                    subscription.close()

    def _robot(self, namespace: str) -> _Robot:
        robot = self._robots.get(namespace)
        if robot is None:
            publisher = self.context.bus.publisher(ANNOTATED_SCAN_TOPIC, messages.ANNOTATED_SCAN, namespace=namespace)
            robot = self._robots[namespace] = _Robot(publisher)
        return robot

    def _take_frames(self, *, timeout_s: float) -> None:
        start = time.perf_counter()
        item = self.colour.receive(timeout_s)
        while item is not None:
            self.pairer.add(item.namespace, Stream.COLOUR, _stamp_ns(item.message.header), item.message)
            item = self.colour.receive()
        while (item := self.depth.receive()) is not None:
            self.pairer.add(item.namespace, Stream.DEPTH, _stamp_ns(item.message.header), item.message)
        self._time("receive_pair", start)

    def _take_transforms(self) -> None:
        for subscription, static in ((self.tf_static, True), (self.tf, False)):
            while (item := subscription.receive()) is not None:
                try:
                    add_tf_message(self._robot(item.namespace).transforms, item.message, static=static)
                except ValueError as err:
                    self.context.count("malformed_tf")
                    log.warning("tf from %r skipped: %s", item.namespace or "/", err)

    def _take_camera_info(self) -> None:
        while (item := self.camera_info.receive()) is not None:
            robot = self._robot(item.namespace)
            try:
                intrinsics = intrinsics_from_camera_info(item.message)
            except ObjectLabellingError as err:
                self.context.count("malformed_camera_info")
                log.warning("camera info from %r skipped: %s", item.namespace or "/", err)
                continue
            if intrinsics != robot.intrinsics:
                robot.intrinsics, robot.labeller = intrinsics, None

    # -- one frame --------------------------------------------------------------------------------

    def _queue_pairs(self) -> None:
        """New pairs wait for their camera pose; one still waiting is overtaken (counted as skipped)."""
        for pair in self.pairer.take():
            if pair.namespace in self._waiting:
                self.pairer.skipped += 1
            self._waiting[pair.namespace] = (pair, time.monotonic())

    def _handle_waiting(self) -> None:
        for namespace, (pair, since) in list(self._waiting.items()):
            robot = self._robot(namespace)
            header = pair.colour.header
            try:
                optical_in_map = robot.transforms.lookup(self.map_frame, header.frame_id, pair.stamp_ns)
            except LookupError as err:
                if time.monotonic() - since < self.pose_wait_s:
                    log.debug("frame of %r waits for its pose: %s", namespace or "/", err)
                    continue  # TF may still be on its way
                del self._waiting[namespace]
                self.context.count("frames_without_pose")
                log.warning("frame of %r at %d ns dropped: no camera pose in %s: %s", namespace or "/",
                            pair.stamp_ns, self.map_frame, err)
                continue
            del self._waiting[namespace]
            if pair.stamp_ns <= robot.last_stamp_ns:
                self.context.count("frames_out_of_order")
                continue
            try:
                self._handle(robot, pair, optical_in_map)
            except ObjectLabellingError as err:
                self.context.count("corrupt_frames")
                log.warning("frame of %r at %d ns skipped: %s", namespace or "/", pair.stamp_ns, err)

    def _handle(self, robot: _Robot, pair: FramePair[Any], optical_in_map: Transform) -> None:
        start = time.perf_counter()
        if robot.intrinsics is None:
            self.context.count("frames_without_camera_info")
            return
        rgb, depth = decode_rgb(pair.colour), decode_depth(pair.depth)
        check_depth(depth, robot.intrinsics)
        if rgb.shape[:2] != depth.shape:
            raise ObjectLabellingError(
                f"colour image is {rgb.shape[1]}x{rgb.shape[0]} px but depth is {depth.shape[1]}x{depth.shape[0]} px"
            )
        self._time("decode", start)
        labeller = self._labeller(robot, depth)
        if labeller is None:
            return
        frame = labeller.label(rgb, depth)
        for name, seconds in frame.timings_s.items():
            self.step_times_s[name].append(seconds)
        if not self._ground_ok(robot, frame):
            return
        start = time.perf_counter()
        assert robot.plane is not None
        floor_in_map = camera_floor_pose(optical_in_map, robot.plane)
        robot.publisher.publish(self._message(pair, frame, floor_in_map))
        robot.last_stamp_ns = pair.stamp_ns
        self.context.count("frames_labelled")
        self._time("publish", start)
        found = detections(frame, floor_in_map, robot.plane, classes=DYNAMIC_CLASSES, stamp_ns=pair.stamp_ns,
                           namespace=pair.namespace)
        self.tracker.update(found)
        self._clock = (max(pair.stamp_ns, self._clock[0]) if self._clock else pair.stamp_ns, time.monotonic())
        first, _, frames = self._inputs or (pair.stamp_ns, 0, 0)
        self._inputs = (min(first, pair.stamp_ns), max(self._inputs[1] if self._inputs else 0, pair.stamp_ns),
                        frames + 1)

    def _labeller(self, robot: _Robot, depth: npt.NDArray[np.uint16]) -> ObjectLabeller | None:
        """The robot's labeller, teaching in the ground plane first if there is none."""
        assert robot.intrinsics is not None
        if robot.plane is None:
            start = time.perf_counter()
            sub, sub_intrinsics = subsample(depth, robot.intrinsics, step=4)
            try:
                points = depth_to_points(sub, sub_intrinsics)[0]
                robot.plane = fit_ground_plane(points, min_inliers=self.min_ground_inliers)
            except ObjectLabellingError as err:
                self.context.count("teach_in_failures")
                log.info("ground plane teach-in failed, trying the next frame: %s", err)
                return None
            self.context.count("teach_ins")
            log.info("ground plane taught in: camera %.2f m above the floor, normal %s", robot.plane.offset,
                     np.round(robot.plane.normal, 3).tolist())
            robot.labeller = None
            self._time("teach_in", start)
        if robot.labeller is None:
            robot.labeller = ObjectLabeller(self.net, self.model, self.priors, robot.intrinsics, robot.plane,
                                            max_rois=self.max_rois, min_ground_inliers=self.min_ground_inliers)
        return robot.labeller

    def _ground_ok(self, robot: _Robot, frame: FrameLabels) -> bool:
        if frame.ground.valid:
            robot.invalid_streak = 0
            if not frame.ground.verified:
                self.context.count("ground_unverified")  # no floor in view: nothing to check against
            return True
        robot.invalid_streak += 1
        self.context.count("ground_invalid")
        if robot.invalid_streak >= self.reteach_after_frames:
            log.error("ground plane invalid for %d frames in a row: the camera has moved; teaching it in again",
                      robot.invalid_streak)
            self.context.count("ground_reteach")
            robot.plane, robot.labeller, robot.invalid_streak = None, None, 0
        return False

    def _message(self, pair: FramePair[Any], frame: FrameLabels, floor_in_map: Transform) -> Any:
        cls = messages.message_class
        cones = annotate_cones(frame, self.class_names)
        t, q = floor_in_map
        scan = frame.scan
        return cls(messages.ANNOTATED_SCAN)(
            header=cls("std_msgs/msg/Header")(
                stamp=cls("builtin_interfaces/msg/Time")(sec=pair.stamp_ns // 10**9, nanosec=pair.stamp_ns % 10**9),
                frame_id=self.map_frame,
            ),
            camera_pose=cls("geometry_msgs/msg/Pose")(
                position=cls("geometry_msgs/msg/Point")(x=float(t[0]), y=float(t[1]), z=float(t[2])),
                orientation=cls("geometry_msgs/msg/Quaternion")(x=float(q[0]), y=float(q[1]), z=float(q[2]),
                                                                w=float(q[3])),
            ),
            bearings=scan.bearings_rad[cones.cones].astype(np.float32),
            ranges=scan.ranges_m[cones.cones].astype(np.float32),
            heights=scan.heights_m[cones.cones].astype(np.float32),
            labels=cones.labels,
            confidences=cones.confidences,
            class_names=list(self.class_names),
        )

    # -- store ------------------------------------------------------------------------------------

    def _commit(self) -> None:
        if self._clock is not None:
            stamp_ns, wall = self._clock
            self.tracker.forget(stamp_ns + round((time.monotonic() - wall) * 1e9))
        if not self.tracker.changed:
            return
        features = self.tracker.features()
        first, last, frames = self._inputs or (None, None, 0)
        write = RevisionWrite(self.context.name, features={"object": features}, input_start_ns=first,
                              input_end_ns=last, summary={"frames": frames})
        if self.context.commit(write) is None:
            self.tracker.changed = True  # store down: try again next period
            return
        self._inputs = None
        log.info("committed %d objects seen in %d frames", len(features), frames)

    def _time(self, step: str, start: float) -> None:
        self.step_times_s[step].append(time.perf_counter() - start)


def model_path_of(settings: Settings) -> Path:
    """The stage's model file: ``labelling.model_path``, relative paths under ``data_dir``."""
    path = Path(settings.labelling.model_path)
    return path if path.is_absolute() else settings.data_dir / path


def check_recogniser(settings: Settings) -> None:
    """Load the model and CNN weights the stage would use; raise :class:`ObjectLabellingError` saying what is wrong."""
    load_recogniser(model_path_of(settings), settings.labelling.weights_path)


def labelling_stage(context: StageContext) -> LabellingStage:
    """The stage built from ``context.settings.labelling`` (model at :func:`model_path_of`)."""
    params: dict[str, Any] = context.settings.labelling.model_dump()
    params["model_path"] = model_path_of(context.settings)
    return LabellingStage(context, **params)

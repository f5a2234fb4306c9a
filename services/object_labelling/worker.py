"""The object-labelling worker: RGB-D frames from the bus in, annotated scans and dynamic objects out.

Per robot namespace it pairs colour and depth frames by stamp, keeps a rig (camera model, ground plane taught in
from the first usable frame, labeller; :mod:`~services.object_labelling.rig`), labels the newest pair once tf has
its camera pose, publishes an ``aisle_msgs/AnnotatedScan`` on ``/<robot>/annotated_scan`` and every
``commit_period_s`` commits the forklifts, people and pallets currently seen as ``object`` features. Frames are
only taken from the newest: camera queues drop the oldest, and a pair a newer one overtakes is skipped (counted).
"""

from __future__ import annotations

import collections
import logging
import threading
import time

import numpy as np
import numpy.typing as npt
from rosbags.typesys.stores.ros2_jazzy import sensor_msgs__msg__Image as Image
from threadpoolctl import threadpool_limits

from services.object_labelling.annotation import camera_floor_pose, detections
from services.object_labelling.camera import intrinsics_from_camera_info
from services.object_labelling.classifier import UNKNOWN
from services.object_labelling.errors import ObjectLabellingError
from services.object_labelling.labeller import ObjectLabeller
from services.object_labelling.objects import ObjectTracker
from services.object_labelling.pairing import FramePair, FramePairer, Stream
from services.object_labelling.recogniser import load_recogniser, model_file
from services.object_labelling.retrieval import DEFAULT_PRIORS, PriorDatabase
from services.object_labelling.rig import DYNAMIC_CLASSES, AwaitingPose, Ground, Rig, annotated_scan, decode_pair
from shared import messages
from shared.settings import LabellingSettings
from shared.store import RevisionWrite
from shared.transforms import Transform
from shared.vocabulary import FeatureKind
from shared.worker import IDLE_WAIT_S, PENDING_WAIT_S, InputSpan, StageContext, drain, take_transforms

log = logging.getLogger(__name__)

_STEP_HISTORY = 500


class LabellingStage:
    """Stage ``object_labelling``, built from its settings section (``model_path`` relative to ``data_dir``)."""

    def __init__(self, context: StageContext, settings: LabellingSettings) -> None:
        self.context = context
        self.settings = settings
        model_path = model_file(settings.model_path, data_dir=context.settings.data_dir)
        self.net, self.model = load_recogniser(model_path, settings.weights_path)
        self.priors = PriorDatabase.read_csv(DEFAULT_PRIORS)
        self.class_names = (UNKNOWN, *self.model.roi.classes, *self.model.scene.classes)
        self.pairer: FramePairer[Image] = FramePairer(tolerance_ns=round(settings.pair_tolerance_s * 1e9))
        self.tracker = ObjectTracker(merge_distance_m=settings.merge_distance_m, forget_after_s=settings.forget_after_s)
        self.step_times_s: dict[str, collections.deque[float]] = collections.defaultdict(lambda: collections.deque(
            maxlen=_STEP_HISTORY))
        self._robots: dict[str, Rig] = {}
        self._awaiting = AwaitingPose(map_frame=settings.map_frame, wait_s=settings.pose_wait_s)
        self._clock: tuple[int, float] | None = None  # newest frame stamp and the wall time it came
        self._inputs = InputSpan()  # frames since the last commit
        self.colour = context.subscribe(settings.colour_topic, messages.IMAGE, maxsize=settings.frame_queue_size)
        self.depth = context.subscribe(settings.depth_topic, messages.IMAGE, maxsize=settings.frame_queue_size)
        self.camera_info = context.subscribe(settings.camera_info_topic, messages.CAMERA_INFO, maxsize=8)
        self.tf, self.tf_static = context.subscribe_transforms()

    def run(self, stop: threading.Event) -> None:
        last_commit = time.monotonic()
        with threadpool_limits(limits=1, user_api="blas"):
            try:
                while not stop.is_set():
                    self._take_inputs(timeout_s=PENDING_WAIT_S if self._awaiting else IDLE_WAIT_S)
                    self._handle_waiting()
                    self.context.counters.set(f"{self.context.name}.pairs_skipped", self.pairer.skipped)
                    if time.monotonic() - last_commit >= self.settings.commit_period_s:
                        last_commit = time.monotonic()
                        self._commit()
            finally:
                self._commit()

    def _robot(self, namespace: str) -> Rig:
        if namespace not in self._robots:
            self._robots[namespace] = Rig.publishing(self.context.bus, namespace)
        return self._robots[namespace]

    def _take_inputs(self, *, timeout_s: float) -> None:
        """Frames (waiting up to ``timeout_s`` for one), tf and camera info; new pairs wait for their pose, one
        still waiting is overtaken (counted as skipped)."""
        start = time.perf_counter()
        item = self.colour.receive(timeout_s)
        while item is not None:
            self.pairer.add(item.namespace, Stream.COLOUR, messages.stamp_ns(item.message.header), item.message)
            item = self.colour.receive()
        for item in drain(self.depth):
            self.pairer.add(item.namespace, Stream.DEPTH, messages.stamp_ns(item.message.header), item.message)
        self._time("receive_pair", start)
        take_transforms(self.context, lambda namespace: self._robot(namespace).transforms, static=self.tf_static,
                        dynamic=self.tf, counter="malformed_tf")
        for item in drain(self.camera_info):
            try:
                self._robot(item.namespace).set_intrinsics(intrinsics_from_camera_info(item.message))
            except ObjectLabellingError as err:
                self.context.count("malformed_camera_info")
                log.warning("camera info from %r skipped: %s", item.namespace or "/", err)
        for pair in self.pairer.take():
            self.pairer.skipped += self._awaiting.add(pair, time.monotonic())

    def _handle_waiting(self) -> None:
        for pair, pose in self._awaiting.due(self._robot, time.monotonic()):
            robot = self._robot(pair.namespace)
            if isinstance(pose, LookupError):
                self.context.count("frames_without_pose")
                log.warning("frame of %r at %d ns dropped: no camera pose in %s: %s", pair.namespace or "/",
                            pair.stamp_ns, self.settings.map_frame, pose)
            elif pair.stamp_ns <= robot.last_stamp_ns:
                self.context.count("frames_out_of_order")
            else:
                try:
                    self._handle(robot, pair, pose)
                except ObjectLabellingError as err:
                    self.context.count("corrupt_frames")
                    log.warning("frame of %r at %d ns skipped: %s", pair.namespace or "/", pair.stamp_ns, err)

    def _handle(self, robot: Rig, pair: FramePair[Image], optical_in_map: Transform) -> None:
        start = time.perf_counter()
        if robot.intrinsics is None:
            self.context.count("frames_without_camera_info")
            return
        rgb, depth = decode_pair(pair.colour, pair.depth, robot.intrinsics)
        self._time("decode", start)
        labeller = self._labeller(robot, depth)
        if labeller is None:
            return
        frame = labeller.label(rgb, depth)
        for name, seconds in frame.timings_s.items():
            self.step_times_s[name].append(seconds)
        ground = robot.check_ground(frame, reteach_after_frames=self.settings.reteach_after_frames)
        if ground is Ground.UNVERIFIED:
            self.context.count("ground_unverified")  # no floor in view: nothing to check against
        elif ground is not Ground.VALID:
            self.context.count("ground_invalid")
            if ground is Ground.RETEACH:
                log.error("ground plane invalid for %d frames in a row: the camera has moved; teaching it in again",
                          self.settings.reteach_after_frames)
                self.context.count("ground_reteach")
            return
        start = time.perf_counter()
        floor_in_map = camera_floor_pose(optical_in_map, labeller.plane)
        robot.publisher.publish(annotated_scan(pair.stamp_ns, frame, floor_in_map, class_names=self.class_names,
                                               map_frame=self.settings.map_frame))
        robot.last_stamp_ns = pair.stamp_ns
        self.context.count("frames_labelled")
        self._time("publish", start)
        self.tracker.update(detections(frame, floor_in_map, labeller.plane, classes=DYNAMIC_CLASSES,
                                       stamp_ns=pair.stamp_ns, namespace=pair.namespace))
        self._clock = (max(pair.stamp_ns, self._clock[0]) if self._clock else pair.stamp_ns, time.monotonic())
        self._inputs.add(pair.stamp_ns)

    def _labeller(self, robot: Rig, depth: npt.NDArray[np.uint16]) -> ObjectLabeller | None:
        """The robot's labeller, teaching in the ground plane first if there is none."""
        if robot.plane is None:
            start = time.perf_counter()
            try:
                plane = robot.teach_in(depth, min_inliers=self.settings.min_ground_inliers)
            except ObjectLabellingError as err:
                self.context.count("teach_in_failures")
                log.info("ground plane teach-in failed, trying the next frame: %s", err)
                return None
            self.context.count("teach_ins")
            log.info("ground plane taught in: camera %.2f m above the floor, normal %s", plane.offset,
                     np.round(plane.normal, 3).tolist())
            self._time("teach_in", start)
        return robot.ensure_labeller(self.net, self.model, self.priors, max_rois=self.settings.max_rois,
                                     min_ground_inliers=self.settings.min_ground_inliers)

    def _commit(self) -> None:
        if self._clock is not None:
            stamp_ns, wall = self._clock
            self.tracker.forget(stamp_ns + round((time.monotonic() - wall) * 1e9))
        if not self.tracker.changed:
            return
        features = self.tracker.features()
        inputs = self._inputs
        write = RevisionWrite(self.context.name, features={FeatureKind.OBJECT: features},
                              input_start_ns=inputs.first_ns, input_end_ns=inputs.last_ns,
                              summary={"frames": inputs.count})
        if self.context.commit(write) is None:
            self.tracker.changed = True  # store down: try again next period
            return
        self._inputs = InputSpan()
        log.info("committed %d objects seen in %d frames", len(features), inputs.count)

    def _time(self, step: str, start: float) -> None:
        self.step_times_s[step].append(time.perf_counter() - start)


def labelling_stage(context: StageContext) -> LabellingStage:
    """The stage built from its settings section, ``context.settings.labelling``."""
    return LabellingStage(context, context.settings.labelling)

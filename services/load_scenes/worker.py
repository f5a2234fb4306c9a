"""The load-scene worker: RGB-D depth frames in, bay scene graphs and bin occupancy out.

Per robot namespace it keeps the camera model (from camera info) and tf. Each depth frame waits (at most
``pose_wait_s``) for its camera pose in the map; a frame taken where the robot's last estimated one was (camera
moved less than ``min_move_m``, turned less than ``min_turn_rad``, within ``still_period_s``) is skipped, as it
shows the same; then :func:`~services.load_scenes.estimation.estimate_boxes`
gives the pallets, loads and beams of the bays in view and their depth evidence; a bay keeps its newest
``views_per_bay`` views. Every ``commit_period_s`` each bay seen since is explained: its views' estimates merged
(:func:`~services.load_scenes.estimation.merge_views`), the scene graph inferred
(:func:`~services.load_scenes.inference.infer_scene`), the bins' occupancy read off it
(:func:`~services.load_scenes.occupancy.bin_occupancy`) and fused with what the bins showed before
(:func:`~services.load_scenes.occupancy.fuse_occupancy`); the changed states and scenes go into ONE revision
(:class:`shared.loads.SceneWriter`). The rack model (bays) is rebuilt from the map's ``bin`` features and the
site's rack profiles at each commit. At its first commit the stage reads the bin states stored before (by an
earlier run), so fusion continues across restarts. Frames that cannot be used are counted and skipped with the
reason.
"""

from __future__ import annotations

import collections
import logging
import threading
import time
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt
from rosbags.typesys.stores.ros2_jazzy import sensor_msgs__msg__Image as Image
from threadpoolctl import threadpool_limits

from services.load_scenes.errors import LoadScenesError
from services.load_scenes.estimation import RackView, bays_from_bins, camera_moved, estimate_boxes, merge_views
from services.load_scenes.frames import Intrinsics, decode_depth, intrinsics_from_camera_info
from services.load_scenes.inference import infer_scene
from services.load_scenes.model import Bay, BinOccupancy, SceneGraph
from services.load_scenes.occupancy import bin_evidence, bin_occupancy, fuse_occupancy
from shared import messages
from shared.bins import Bin
from shared.loads import SceneWriter, occupancy_from_feature
from shared.settings import LoadScenesStageSettings
from shared.store import StoreUnavailableError
from shared.transforms import TransformBuffer, to_matrix
from shared.vocabulary import FeatureKind
from shared.worker import IDLE_WAIT_S, PENDING_WAIT_S, InputSpan, StageContext, checked, drain, take_transforms

log = logging.getLogger(__name__)


@dataclass
class _Robot:
    transforms: TransformBuffer = field(default_factory=TransformBuffer)
    intrinsics: Intrinsics | None = None
    last_stamp_ns: int = -1
    last_pose: npt.NDArray[np.float64] | None = None
    """Camera pose of the last frame estimated."""


class LoadScenesStage:
    """Stage ``load_scenes``, built from its settings section; see the module docstring."""

    def __init__(self, context: StageContext, settings: LoadScenesStageSettings) -> None:
        self.context = context
        self.settings = settings = checked(settings, LoadScenesError)
        self.profiles = context.settings.pillars.rack_profiles
        self.writer = SceneWriter(context.store, context.map.id)
        self.bays: dict[str, Bay] = {}
        self.views: dict[str, collections.deque[RackView]] = {}
        self.states: dict[str, BinOccupancy] | None = None
        """Fused state per bin id; None until read back from the store (first commit)."""
        self._robots: dict[str, _Robot] = {}
        self._waiting: dict[str, tuple[Image, float]] = {}
        self._seen: set[str] = set()
        self._inputs = InputSpan()
        self.depth = context.subscribe(settings.depth_topic, messages.IMAGE, maxsize=settings.frame_queue_size)
        self.camera_info = context.subscribe(settings.camera_info_topic, messages.CAMERA_INFO, maxsize=8)
        self.tf, self.tf_static = context.subscribe_transforms()

    def run(self, stop: threading.Event) -> None:
        last_commit = time.monotonic()
        with threadpool_limits(limits=1, user_api="blas"):
            try:
                while not stop.is_set():
                    self._take_inputs(timeout_s=PENDING_WAIT_S if self._waiting else IDLE_WAIT_S)
                    self._handle_waiting()
                    if time.monotonic() - last_commit >= self.settings.commit_period_s:
                        last_commit = time.monotonic()
                        self._commit()
            finally:
                self._commit()

    def _robot(self, namespace: str) -> _Robot:
        return self._robots.setdefault(namespace, _Robot())

    def _take_inputs(self, *, timeout_s: float) -> None:
        item = self.depth.receive(timeout_s)
        while item is not None:
            if item.namespace in self._waiting:
                self.context.count("frames_overtaken")
            self._waiting[item.namespace] = (item.message, time.monotonic())
            item = self.depth.receive()
        take_transforms(self.context, lambda namespace: self._robot(namespace).transforms, static=self.tf_static,
                        dynamic=self.tf, counter="malformed_tf")
        for item in drain(self.camera_info):
            try:
                self._robot(item.namespace).intrinsics = intrinsics_from_camera_info(item.message)
            except LoadScenesError as err:
                self.context.count("malformed_camera_info")
                log.warning("camera info from %r skipped: %s", item.namespace or "/", err)

    def _handle_waiting(self) -> None:
        now = time.monotonic()
        for namespace, (image, since) in list(self._waiting.items()):
            robot = self._robot(namespace)
            stamp_ns = messages.stamp_ns(image.header)
            try:
                pose = robot.transforms.lookup(self.settings.map_frame, image.header.frame_id, stamp_ns)
            except LookupError as err:
                if now - since < self.settings.pose_wait_s:
                    continue  # tf may still be on its way
                del self._waiting[namespace]
                self.context.count("frames_without_pose")
                log.warning("depth frame of %r at %d ns dropped: no camera pose in %s: %s", namespace or "/",
                            stamp_ns, self.settings.map_frame, err)
                continue
            del self._waiting[namespace]
            if stamp_ns <= robot.last_stamp_ns:
                self.context.count("frames_out_of_order")
            elif robot.intrinsics is None:
                self.context.count("frames_without_camera_info")
            elif not self.bays:
                self.context.count("frames_without_bays")
            else:
                try:
                    self._handle(robot, image, to_matrix(pose), stamp_ns)
                except LoadScenesError as err:
                    self.context.count("corrupt_frames")
                    log.warning("depth frame of %r at %d ns skipped: %s", namespace or "/", stamp_ns, err)

    def _handle(self, robot: _Robot, image: Image, pose: npt.NDArray[np.float64], stamp_ns: int) -> None:
        assert robot.intrinsics is not None
        s = self.settings
        if (robot.last_pose is not None and stamp_ns - robot.last_stamp_ns < s.still_period_s * 1e9
                and not camera_moved(robot.last_pose, pose, min_move_m=s.min_move_m, min_turn_rad=s.min_turn_rad)):
            self.context.count("frames_still")  # the same view again: nothing new to estimate
            return
        depth = decode_depth(image)
        view = estimate_boxes(depth, robot.intrinsics, pose, list(self.bays.values()), stamp_ns=stamp_ns,
                              stride=self.settings.stride, max_range_m=self.settings.max_range_m)
        robot.last_stamp_ns, robot.last_pose = stamp_ns, pose
        self.context.count("frames_estimated")
        self.context.count("boxes_estimated", len(view.boxes))
        for key in view.evidence:
            queue = self.views.setdefault(key, collections.deque(maxlen=self.settings.views_per_bay))
            queue.append(view)
            self._seen.add(key)
        self._inputs.add(stamp_ns)

    def _load_bays(self) -> None:
        """The rack model from the map's bins (and the site's rack profiles)."""
        store, map_id = self.context.store, self.context.map.id
        records = [Bin.from_feature(item.feature) for item in store.features(map_id, kinds=[FeatureKind.BIN])]
        try:
            bays = bays_from_bins(records, profiles=self.profiles, beam_height_m=self.settings.beam_height_m)
        except LoadScenesError as err:
            self.context.count("bad_rack_model")
            log.warning("rack model not rebuilt from %d bins: %s", len(records), err)
            return
        self.bays = {bay.key: bay for bay in bays}

    def _load_states(self) -> dict[str, BinOccupancy]:
        """The bin states stored before, read once: fusion goes on from them after a restart."""
        if self.states is None:
            stored = self.context.store.features(self.context.map.id, kinds=[FeatureKind.BIN_STATE])
            self.states = {s.bin_id: s for s in (occupancy_from_feature(item.feature) for item in stored)}
            log.info("%d stored bin states read back", len(self.states))
        return self.states

    def _commit(self) -> None:
        try:
            self._load_bays()
            known = self._load_states()
        except StoreUnavailableError as err:
            self.context.count("store_unavailable")
            log.warning("bins or bin states not read, will retry: %s", err)
            return
        scenes: list[SceneGraph] = []
        states: dict[str, BinOccupancy] = {}  # fused onto ``known`` only once stored: a retry must not fuse twice
        for key in sorted(self._seen):
            bay = self.bays.get(key)
            if bay is None:
                self.context.count("bays_gone")  # the rack model changed under the views
                continue
            views = list(self.views.get(key, ()))
            estimates = merge_views([b for view in views for b in view.boxes if b.bay == key],
                                    distance_m=self.settings.merge_distance_m)
            evidence = [view.evidence[key] for view in views]
            try:
                graph = infer_scene(bay, estimates, evidence)
                occupancy = bin_occupancy(bay, graph, bin_evidence(bay, graph, evidence))
            except LoadScenesError as err:
                self.context.count("scene_errors")
                log.warning("bay %s not explained: %s", key, err)
                continue
            scenes.append(graph)
            for state in occupancy:
                states[state.bin_id] = fuse_occupancy(known.get(state.bin_id), state)
        if not scenes:
            return
        inputs = self._inputs
        try:
            written = self.writer.write(scenes, list(states.values()), commit=self.context.commit,
                                        input_start_ns=inputs.first_ns, input_end_ns=inputs.last_ns)
        except StoreUnavailableError as err:
            self.context.count("store_unavailable")
            log.warning("scenes not stored, will retry: %s", err)
            return
        known.update(states)
        self._seen.clear()
        for key in [g.bay for g in scenes]:
            self.views.pop(key, None)
        self._inputs = InputSpan()
        self.context.count("scenes", len(scenes))
        log.info("%d bay scenes from %d frames; %d bin states changed", len(scenes), inputs.count,
                 len(written.bins_written))


def load_scenes_stage(context: StageContext) -> LoadScenesStage:
    """The stage built from its settings section, ``context.settings.load_scenes``."""
    return LoadScenesStage(context, context.settings.load_scenes)

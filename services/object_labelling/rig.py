"""One robot's RGB-D rig as the object-labelling worker knows it, and the AnnotatedScan it publishes.

Per robot the worker keeps the camera model (from camera info), the ground plane taught in from the first usable
depth frame (kept fixed; taught in again after ``reteach_after_frames`` consecutive frames failing the check),
the labeller built on both, and the robot's tf. The scan goes out with the camera's floor-frame pose in the map
(:func:`~services.object_labelling.annotation.camera_floor_pose`).
"""

from __future__ import annotations

import enum
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__Point as Point
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__Pose as Pose
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__Quaternion as Quaternion
from rosbags.typesys.stores.ros2_jazzy import sensor_msgs__msg__Image as Image

from services.object_labelling.annotation import annotate_cones
from services.object_labelling.camera import CameraIntrinsics, check_depth, depth_to_points, subsample
from services.object_labelling.classifier import LabelModel
from services.object_labelling.cnn import EfficientNetLite0
from services.object_labelling.errors import ObjectLabellingError
from services.object_labelling.frames import decode_depth, decode_rgb
from services.object_labelling.ground_plane import GroundPlane, fit_ground_plane
from services.object_labelling.labeller import FrameLabels, ObjectLabeller
from services.object_labelling.pairing import FramePair
from services.object_labelling.retrieval import PriorDatabase
from shared import messages
from shared.bus import Bus, Publisher
from shared.transforms import Transform, TransformBuffer

ANNOTATED_SCAN_TOPIC = "annotated_scan"
"""Where a robot's annotated scans go: ``/<robot>/annotated_scan``."""
DYNAMIC_CLASSES = frozenset({"forklift", "human", "pallet"})
"""Classes of the objects the worker tracks and commits as ``object`` features."""


class Ground(enum.Enum):
    """What a labelled frame says of the taught-in ground plane."""

    VALID = "valid"
    UNVERIFIED = "unverified"
    """Valid, but no floor in view to check it against."""
    INVALID = "invalid"
    RETEACH = "reteach"
    """Invalid once too often in a row: the camera has moved; the plane is dropped to be taught in again."""


@dataclass
class Rig:
    """One robot's camera model, taught-in ground plane, labeller, tf and annotated-scan publisher."""

    publisher: Publisher
    transforms: TransformBuffer = field(default_factory=TransformBuffer)
    intrinsics: CameraIntrinsics | None = None
    plane: GroundPlane | None = None
    labeller: ObjectLabeller | None = None
    invalid_streak: int = 0
    last_stamp_ns: int = -1

    @classmethod
    def publishing(cls, bus: Bus, namespace: str) -> Rig:
        """A rig of the robot under ``namespace``, its annotated scans published on ``/<namespace>/annotated_scan``."""
        return cls(bus.publisher(ANNOTATED_SCAN_TOPIC, messages.ANNOTATED_SCAN, namespace=namespace))

    def set_intrinsics(self, intrinsics: CameraIntrinsics) -> None:
        """Take the camera model from camera info; a changed one needs a new labeller."""
        if intrinsics != self.intrinsics:
            self.intrinsics, self.labeller = intrinsics, None

    def teach_in(self, depth: npt.NDArray[np.uint16], *, min_inliers: int) -> GroundPlane:
        """Fit the ground plane to a depth frame (on a 4-pixel grid); :class:`ObjectLabellingError` if none fits."""
        assert self.intrinsics is not None
        sub, sub_intrinsics = subsample(depth, self.intrinsics, step=4)
        self.plane = fit_ground_plane(depth_to_points(sub, sub_intrinsics)[0], min_inliers=min_inliers)
        self.labeller = None
        return self.plane

    def ensure_labeller(self, net: EfficientNetLite0, model: LabelModel, priors: PriorDatabase, *, max_rois: int,
                        min_ground_inliers: int) -> ObjectLabeller:
        """The labeller on the current camera model and ground plane (both must be known), built if there is none."""
        assert self.intrinsics is not None and self.plane is not None
        if self.labeller is None:
            self.labeller = ObjectLabeller(net, model, priors, self.intrinsics, self.plane, max_rois=max_rois,
                                           min_ground_inliers=min_ground_inliers)
        return self.labeller

    def check_ground(self, frame: FrameLabels, *, reteach_after_frames: int) -> Ground:
        """Follow the ground check of a labelled frame; after ``reteach_after_frames`` invalid ones in a row the
        plane and labeller are dropped (:attr:`Ground.RETEACH`)."""
        if frame.ground.valid:
            self.invalid_streak = 0
            return Ground.VALID if frame.ground.verified else Ground.UNVERIFIED
        self.invalid_streak += 1
        if self.invalid_streak < reteach_after_frames:
            return Ground.INVALID
        self.plane, self.labeller, self.invalid_streak = None, None, 0
        return Ground.RETEACH


class AwaitingPose:
    """Frame pairs waiting for their camera pose in tf, the newest of each robot (a newer pair overtakes one still
    waiting); a pair waits at most ``wait_s`` seconds for tf to reach its stamp in ``map_frame``."""

    def __init__(self, *, map_frame: str, wait_s: float) -> None:
        self.map_frame = map_frame
        self.wait_s = wait_s
        self._pairs: dict[str, tuple[FramePair[Image], float]] = {}

    def __bool__(self) -> bool:
        """Whether a frame waits for its pose."""
        return bool(self._pairs)

    def add(self, pair: FramePair[Image], now_s: float) -> bool:
        """Let ``pair`` wait from ``now_s`` (monotonic seconds); whether it overtook one still waiting."""
        overtook = pair.namespace in self._pairs
        self._pairs[pair.namespace] = (pair, now_s)
        return overtook

    def due(self, rig_of: Callable[[str], Rig], now_s: float
            ) -> Iterator[tuple[FramePair[Image], Transform | LookupError]]:
        """The pairs done waiting, each with its optical frame in the map from ``rig_of(namespace).transforms``, or
        the look-up's error once it has waited ``wait_s``. A pair waits (up to ``wait_s``) until tf has reached
        its stamp, so its pose is interpolated, not the last one held beyond it."""
        for namespace, (pair, since) in list(self._pairs.items()):
            transforms, frame_id = rig_of(namespace).transforms, pair.colour.header.frame_id
            waiting = now_s - since < self.wait_s
            newest = transforms.newest_stamp_ns(self.map_frame, frame_id)
            if waiting and (newest is None or newest < pair.stamp_ns):
                continue  # tf may still be on its way: interpolate the pose rather than hold the last one
            try:
                pose: Transform | LookupError = transforms.lookup(self.map_frame, frame_id, pair.stamp_ns)
            except LookupError as err:
                if waiting:
                    continue
                pose = err
            del self._pairs[namespace]
            yield pair, pose


def decode_pair(colour: Image, depth: Image, intrinsics: CameraIntrinsics
                ) -> tuple[npt.NDArray[np.uint8], npt.NDArray[np.uint16]]:
    """RGB (h, w, 3) uint8 and depth (h, w) uint16 millimetres of one frame pair, checked against the camera
    model and each other; :class:`ObjectLabellingError` otherwise."""
    rgb, depth_mm = decode_rgb(colour), decode_depth(depth)
    check_depth(depth_mm, intrinsics)
    if rgb.shape[:2] != depth_mm.shape:
        raise ObjectLabellingError(f"colour image is {rgb.shape[1]}x{rgb.shape[0]} px but depth is "
                                   f"{depth_mm.shape[1]}x{depth_mm.shape[0]} px")
    return rgb, depth_mm


def annotated_scan(stamp_ns: int, frame: FrameLabels, floor_in_map: Transform, *, class_names: tuple[str, ...],
                   map_frame: str) -> Any:  # aisle_msgs/AnnotatedScan has no static class
    """The aisle_msgs/AnnotatedScan of a labelled frame: its annotated cones in the camera's floor frame, whose
    pose in ``map_frame`` is ``floor_in_map``."""
    cones = annotate_cones(frame, class_names)
    t, q = floor_in_map
    scan = frame.scan
    return messages.message_class(messages.ANNOTATED_SCAN)(
        header=messages.header(stamp_ns, map_frame),
        camera_pose=Pose(position=Point(x=float(t[0]), y=float(t[1]), z=float(t[2])),
                         orientation=Quaternion(x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3]))),
        bearings=scan.bearings_rad[cones.cones].astype(np.float32),
        ranges=scan.ranges_m[cones.cones].astype(np.float32),
        heights=scan.heights_m[cones.cones].astype(np.float32),
        labels=cones.labels,
        confidences=cones.confidences,
        class_names=list(class_names),
    )

"""The whole recognition chain for one RGB-D frame, as the worker runs it.

depth -> ground check -> range/height scan -> segments -> retrieval (class by size, ROI) ->
CNN features on up to ``max_rois`` ROIs (one batch) -> ROI SVMs, restricted to the classes the
size prior allows.

Nothing is recomputed that has not changed: the whole image goes through the CNN and the scene
SVMs only when it differs noticeably from the last time (a small thumbnail difference), and at
most every ``scene_period_frames`` frames (racks and gates come and go slowly); a ROI
keeps the class probabilities of the previous frame's ROI it continues (box IoU >= 0.5, range
within 0.5 m, a small thumbnail difference of the crop) for up to ``roi_reuse_frames`` frames, so
at 30 frames/s an object is still re-classified several times a second.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from typing import NamedTuple

import cv2
import numpy as np
import numpy.typing as npt

from services.object_labelling.camera import CameraIntrinsics, check_depth, depth_to_points, subsample
from services.object_labelling.classifier import UNKNOWN, LabelModel
from services.object_labelling.cnn import EfficientNetLite0, resize_for_cnn
from services.object_labelling.crops import ROI_PAD_FRACTION, box_iou, crop_box
from services.object_labelling.errors import ObjectLabellingError
from services.object_labelling.ground_plane import GroundCheck, GroundPlane, check_ground_plane
from services.object_labelling.range_scan import RangeHeightScan, range_height_scan
from services.object_labelling.retrieval import PriorDatabase, Proposal, retrieve
from services.object_labelling.segments import segments

log = logging.getLogger(__name__)


class LabelledObject(NamedTuple):
    """A classified ROI: final label (``"unknown"`` if rejected), the calibrated probability of the
    best class the size prior allows, and the size proposal."""

    label: str
    probability: float
    proposal: Proposal


class FrameLabels(NamedTuple):
    """Everything :meth:`ObjectLabeller.label` found in one frame, with per-step times in seconds."""

    ground: GroundCheck
    scan: RangeHeightScan
    proposals: list[Proposal]
    objects: list[LabelledObject]
    scene: dict[str, float]
    """Calibrated probability of each whole-image class."""
    scene_present: tuple[str, ...]
    """The whole-image classes at least ``min_probability`` likely."""
    timings_s: dict[str, float]
    cnn_rois: int
    """ROIs that went through the CNN in this frame (the others continued a ROI of the frame before)."""


class _Roi(NamedTuple):
    """A classified ROI remembered for the next frame: where it was, how it looked when the CNN saw
    it (a 12 x 12 thumbnail), its ROI-class probabilities and the frames since."""

    box: tuple[int, int, int, int]
    range_m: float
    thumbnail: npt.NDArray[np.float32]
    probabilities: npt.NDArray[np.float32]
    age: int


@dataclass
class ObjectLabeller:
    """Stateful per-camera labeller (it caches the whole-image result and the last ROIs); not thread-safe.

    ``change_threshold`` is the mean absolute thumbnail difference (grey levels) above which the
    whole image or a ROI counts as changed; ``scene_period_frames`` the fewest frames between two
    whole-image classifications; ``roi_reuse_frames`` how many frames in a row a ROI may reuse
    earlier probabilities (0: every ROI goes through the CNN every frame).
    """

    net: EfficientNetLite0
    model: LabelModel
    priors: PriorDatabase
    intrinsics: CameraIntrinsics
    plane: GroundPlane
    max_rois: int = 3
    min_ground_inliers: int = 300
    ground_check_step: int = 4
    change_threshold: float = 12.0
    scene_period_frames: int = 5
    roi_reuse_frames: int = 10
    _scene_age: int = field(default=0, repr=False)
    _scene_thumbnail: npt.NDArray[np.float32] | None = field(default=None, repr=False)
    _scene: dict[str, float] = field(default_factory=dict, repr=False)
    _rois: list[_Roi] = field(default_factory=list, repr=False)

    def _check_rgb(self, rgb: npt.NDArray[np.uint8], depth_mm: npt.NDArray[np.uint16]) -> None:
        check_depth(depth_mm, self.intrinsics)
        if rgb.dtype != np.uint8 or rgb.ndim != 3 or rgb.shape[2] != 3:
            raise ObjectLabellingError(f"colour image must be (h, w, 3) uint8 RGB, got {rgb.dtype} {rgb.shape}")
        if rgb.shape[:2] != depth_mm.shape:
            raise ObjectLabellingError(
                f"colour image is {rgb.shape[1]}x{rgb.shape[0]} px but depth is "
                f"{depth_mm.shape[1]}x{depth_mm.shape[0]} px"
            )

    def _scene_labels(self, rgb: npt.NDArray[np.uint8]) -> dict[str, float]:
        self._scene_age += 1
        if self._scene_thumbnail is not None and self._scene_age < self.scene_period_frames:
            return self._scene
        thumbnail = cv2.resize(rgb, (32, 24), interpolation=cv2.INTER_AREA).astype(np.float32)
        if (
            self._scene_thumbnail is None
            or np.abs(thumbnail - self._scene_thumbnail).mean() > self.change_threshold
        ):
            self._scene_age = 0
            bank = self.model.scene
            features = self.net.features(resize_for_cnn(rgb, size_px=self.model.scene_input_size_px)[None])
            probabilities = bank.probabilities(bank.scores(features))[0]
            self._scene = {name: float(p) for name, p in zip(bank.classes, probabilities, strict=True)}
            self._scene_thumbnail = thumbnail
        return self._scene

    def label(self, rgb: npt.NDArray[np.uint8], depth_mm: npt.NDArray[np.uint16]) -> FrameLabels:
        """Label one registered RGB-D frame (same size, depth in millimetres)."""
        self._check_rgb(rgb, depth_mm)
        times: dict[str, float] = {}
        start = time.perf_counter()
        sub, sub_intrinsics = subsample(depth_mm, self.intrinsics, step=self.ground_check_step)
        points = depth_to_points(sub, sub_intrinsics)[0] if sub.any() else np.zeros((0, 3))
        ground = check_ground_plane(points, self.plane, min_inliers=self.min_ground_inliers)
        if not ground.valid:
            log.warning("frame contradicts the ground plane (%d points on it): has the camera moved?", ground.inliers)
        times["ground_check"] = time.perf_counter() - start
        start = time.perf_counter()
        scan = range_height_scan(depth_mm, self.intrinsics, self.plane)
        times["range_scan"] = time.perf_counter() - start
        start = time.perf_counter()
        proposals = retrieve(segments(scan), self.priors, self.intrinsics)
        times["segments_retrieval"] = time.perf_counter() - start
        start = time.perf_counter()
        classes = self.model.roi.classes
        candidates = sorted(
            (p for p in proposals if any(name in classes for name in p.distances)), key=lambda p: p.segment.range_m
        )[: self.max_rois]
        objects, cnn_rois = [], 0
        if candidates:
            bank = self.model.roi
            crops = [crop_box(rgb, p.box, pad_fraction=ROI_PAD_FRACTION) for p in candidates]
            thumbnails = [cv2.resize(c, (12, 12), interpolation=cv2.INTER_AREA).astype(np.float32) for c in crops]
            taken: set[int] = set()
            rois = [self._continued(p, t, taken) for p, t in zip(candidates, thumbnails, strict=True)]
            new = [i for i, roi in enumerate(rois) if roi is None]
            if new:
                size = self.model.input_size_px
                features = self.net.features(np.stack([resize_for_cnn(crops[i], size_px=size) for i in new]))
                for i, row in zip(new, bank.probabilities(bank.scores(features)), strict=True):
                    rois[i] = _Roi(candidates[i].box, candidates[i].segment.range_m, thumbnails[i], row, 0)
            cnn_rois = len(new)
            self._rois = [roi for roi in rois if roi is not None]
            for proposal, roi in zip(candidates, self._rois, strict=True):
                allowed = [i for i, name in enumerate(bank.classes) if name in proposal.distances]
                best = max(allowed, key=lambda i: roi.probabilities[i])
                p = float(roi.probabilities[best])
                objects.append(LabelledObject(bank.classes[best] if p >= self.model.min_probability else UNKNOWN, p,
                                              proposal))
        else:
            self._rois = []
        times["roi_cnn_svm"] = time.perf_counter() - start
        start = time.perf_counter()
        scene = self._scene_labels(rgb)
        present = tuple(name for name, p in scene.items() if p >= self.model.min_probability)
        times["scene_cnn_svm"] = time.perf_counter() - start
        return FrameLabels(ground, scan, proposals, objects, scene, present, times, cnn_rois)

    def _continued(self, proposal: Proposal, thumbnail: npt.NDArray[np.float32], taken: set[int]) -> _Roi | None:
        """The previous frame's ROI this proposal continues (not in ``taken``, then added), aged by one frame."""
        candidates = [
            k for k, roi in enumerate(self._rois)
            if k not in taken and roi.age < self.roi_reuse_frames
            and abs(roi.range_m - proposal.segment.range_m) <= 0.5
            and np.abs(thumbnail - roi.thumbnail).mean() <= self.change_threshold
        ]
        if not candidates:
            return None
        iou = box_iou(np.array([proposal.box]), np.array([self._rois[k].box for k in candidates]))[0]
        if iou.max() < 0.5:
            return None
        k = candidates[int(np.argmax(iou))]
        taken.add(k)
        return self._rois[k]._replace(box=proposal.box, range_m=proposal.segment.range_m, age=self._rois[k].age + 1)

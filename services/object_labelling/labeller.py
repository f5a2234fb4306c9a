"""The whole recognition chain for one RGB-D frame, as the worker runs it.

depth -> ground check -> range/height scan -> segments -> retrieval (class by size, ROI) ->
CNN features on up to ``max_rois`` ROIs -> ROI SVMs, restricted to the classes the size prior
allows; the whole image goes through the CNN and the scene SVMs only when it has changed
noticeably since the last time (a small thumbnail difference), otherwise the cached result is
reused.
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
from services.object_labelling.errors import ObjectLabellingError
from services.object_labelling.ground_plane import GroundCheck, GroundPlane, check_ground_plane
from services.object_labelling.range_scan import RangeHeightScan, range_height_scan
from services.object_labelling.retrieval import PriorDatabase, Proposal, retrieve
from services.object_labelling.segments import segments

log = logging.getLogger(__name__)


class LabelledObject(NamedTuple):
    """A classified ROI: final label (``"unknown"`` if rejected), its SVM score and the size proposal."""

    label: str
    score: float
    proposal: Proposal


class FrameLabels(NamedTuple):
    """Everything :meth:`ObjectLabeller.label` found in one frame, with per-step times in seconds."""

    ground: GroundCheck
    scan: RangeHeightScan
    proposals: list[Proposal]
    objects: list[LabelledObject]
    scene: dict[str, bool]
    timings_s: dict[str, float]


@dataclass
class ObjectLabeller:
    """Stateful per-camera labeller (it caches the whole-image result); not thread-safe."""

    net: EfficientNetLite0
    model: LabelModel
    priors: PriorDatabase
    intrinsics: CameraIntrinsics
    plane: GroundPlane
    max_rois: int = 3
    min_ground_inliers: int = 300
    ground_check_step: int = 4
    scene_change_threshold: float = 12.0
    _scene_thumbnail: npt.NDArray[np.float32] | None = field(default=None, repr=False)
    _scene: dict[str, bool] = field(default_factory=dict, repr=False)

    def _check_rgb(self, rgb: npt.NDArray[np.uint8], depth_mm: npt.NDArray[np.uint16]) -> None:
        check_depth(depth_mm, self.intrinsics)
        if rgb.dtype != np.uint8 or rgb.ndim != 3 or rgb.shape[2] != 3:
            raise ObjectLabellingError(f"colour image must be (h, w, 3) uint8 RGB, got {rgb.dtype} {rgb.shape}")
        if rgb.shape[:2] != depth_mm.shape:
            raise ObjectLabellingError(
                f"colour image is {rgb.shape[1]}x{rgb.shape[0]} px but depth is "
                f"{depth_mm.shape[1]}x{depth_mm.shape[0]} px"
            )

    def _scene_labels(self, rgb: npt.NDArray[np.uint8]) -> dict[str, bool]:
        thumbnail = cv2.resize(rgb, (32, 24), interpolation=cv2.INTER_AREA).astype(np.float32)
        if (
            self._scene_thumbnail is None
            or np.abs(thumbnail - self._scene_thumbnail).mean() > self.scene_change_threshold
        ):
            size = self.model.input_size_px
            scores = self.model.scene.scores(self.net.features(resize_for_cnn(rgb, size_px=size)[None]))[0]
            self._scene = {name: bool(s >= 0.0) for name, s in zip(self.model.scene.classes, scores, strict=True)}
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
            log.warning("ground plane check failed (%d inliers): has the camera moved?", ground.inliers)
        times["ground_check"] = time.perf_counter() - start
        start = time.perf_counter()
        scan = range_height_scan(depth_mm, self.intrinsics, self.plane)
        times["range_scan"] = time.perf_counter() - start
        start = time.perf_counter()
        proposals = retrieve(segments(scan), self.priors, self.intrinsics)
        times["segments_retrieval"] = time.perf_counter() - start
        start = time.perf_counter()
        candidates = sorted((p for p in proposals if p.label is not None), key=lambda p: p.segment.range_m)
        candidates = candidates[: self.max_rois]
        objects = []
        if candidates:
            size = self.model.input_size_px
            crops = np.stack(
                [
                    resize_for_cnn(rgb[r0 : r1 + 1, c0 : c1 + 1], size_px=size)
                    for r0, c0, r1, c1 in (p.box for p in candidates)
                ]
            )
            scores = self.model.roi.scores(self.net.features(crops))
            classes = self.model.roi.classes
            for proposal, row in zip(candidates, scores, strict=True):
                allowed = [i for i, name in enumerate(classes) if name in proposal.distances]
                best = max(allowed, key=lambda i: row[i]) if allowed else int(np.argmax(row))
                ok = allowed and row[best] >= self.model.min_score
                objects.append(LabelledObject(classes[best] if ok else UNKNOWN, float(row[best]), proposal))
        times["roi_cnn_svm"] = time.perf_counter() - start
        start = time.perf_counter()
        scene = self._scene_labels(rgb)
        times["scene_cnn_svm"] = time.perf_counter() - start
        return FrameLabels(ground, scan, proposals, objects, scene, times)

"""Matching object proposals with ground truth, and the segmentation score on simulated views.

An object counts as *found* when a segment's ROI box overlaps the box of the object's visible
pixels with an intersection over union of at least 0.5 (the PASCAL VOC criterion), each segment
matched to at most one object and each object to at most one segment (greedy, highest IoU first).
Class labels play no part: this is the article's "detection rate irrespective of the class".
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import NamedTuple

import numpy as np

from services.labelling_training.sim_views import Box, SimView
from services.object_labelling.crops import box_iou
from services.object_labelling.range_scan import range_height_scan
from services.object_labelling.retrieval import PriorDatabase, retrieve
from services.object_labelling.segments import segments


def match_boxes(truth: list[Box], found: list[Box], *, min_iou: float = 0.5) -> list[tuple[int, int, float]]:
    """One-to-one (truth index, found index, IoU) pairs with IoU >= ``min_iou``, greedily by IoU."""
    if not truth or not found:
        return []
    iou = box_iou(np.array(truth, dtype=np.int64), np.array(found, dtype=np.int64))
    pairs = []
    used_truth: set[int] = set()
    used_found: set[int] = set()
    for flat in np.argsort(-iou, axis=None):
        i, j = divmod(int(flat), iou.shape[1])
        if iou[i, j] < min_iou:
            break
        if i not in used_truth and j not in used_found:
            used_truth.add(i)
            used_found.add(j)
            pairs.append((i, j, float(iou[i, j])))
    return pairs


class SegmentationScore(NamedTuple):
    """Counts over a set of views: objects in view and found, per class; segments and proposals.

    ``false_proposals`` are segments that match no object yet pass the size prior (they would
    reach the CNN); ``ious`` the IoU of every match.
    """

    objects: dict[str, int]
    found: dict[str, int]
    views: int
    segments: int
    proposals: int
    false_proposals: int
    ious: list[float]

    @property
    def recall(self) -> float:
        """Share of the objects in view that a segment found (1.0 when there were none)."""
        total = sum(self.objects.values())
        return sum(self.found.values()) / total if total else 1.0


def score_segmentation(views: Iterable[SimView], priors: PriorDatabase, *, min_iou: float = 0.5
                       ) -> SegmentationScore:
    """Run the range/height scan, segmentation and retrieval on each view and match with its ground truth."""
    objects: dict[str, int] = {}
    found: dict[str, int] = {}
    n_views = n_segments = n_proposals = n_false = 0
    ious: list[float] = []
    for view in views:
        proposals = retrieve(segments(range_height_scan(view.depth_mm, view.intrinsics, view.plane)), priors,
                             view.intrinsics)
        matches = match_boxes([o.box for o in view.objects], [p.box for p in proposals], min_iou=min_iou)
        for obj in view.objects:
            objects[obj.label] = objects.get(obj.label, 0) + 1
        for i, _, iou in matches:
            label = view.objects[i].label
            found[label] = found.get(label, 0) + 1
            ious.append(iou)
        matched = {j for _, j, _ in matches}
        n_views += 1
        n_segments += len(proposals)
        n_proposals += sum(p.label is not None for p in proposals)
        n_false += sum(p.label is not None and j not in matched for j, p in enumerate(proposals))
    return SegmentationScore(objects, found, n_views, n_segments, n_proposals, n_false, ious)

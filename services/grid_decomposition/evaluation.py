"""The ipa room-segmentation protocol: per-room recall, per-segment precision and best IoU."""

from __future__ import annotations

from typing import NamedTuple

import cv2
import numpy as np
import numpy.typing as npt

from services.grid_decomposition.errors import DecompositionError

FREE_GREY = 250
MIN_AREA_PX = 100


class IpaScores(NamedTuple):
    """Scores of one segmentation against one ground truth (fractions in [0, 1]).

    ``recall``/``precision`` are means over rooms/segments; the ``_weighted`` forms weight each
    room/segment by its pixel count; ``mean_iou`` is, per room, the best IoU with any segment,
    averaged over rooms.
    """

    recall: float
    precision: float
    recall_weighted: float
    precision_weighted: float
    mean_iou: float
    n_rooms: int
    n_segments: int


def ground_truth_rooms(gt_grey: npt.NDArray[np.uint8]) -> npt.NDArray[np.int32]:
    """Rooms of an ipa ``_gt_segmentation.png`` (grey levels): 8-connected white regions > 100 px.

    Returns
    -------
    (H, W) int32
        Room id per pixel, 0 outside rooms.
    """
    grey = np.asarray(gt_grey)
    if grey.ndim != 2 or grey.size == 0:
        raise DecompositionError(f"ground truth must be a non-empty 2-D grey image, got shape {grey.shape}")
    n, labels = cv2.connectedComponents((grey >= FREE_GREY).astype(np.uint8), connectivity=8, ltype=cv2.CV_32S)
    return _drop_small(np.asarray(labels, dtype=np.int32), int(n))


def _drop_small(labels: npt.NDArray[np.int32], n: int) -> npt.NDArray[np.int32]:
    sizes = np.bincount(labels.ravel(), minlength=n)
    keep = sizes > MIN_AREA_PX
    keep[0] = False
    remap = np.where(keep, np.cumsum(keep), 0).astype(np.int32)
    return remap[labels]


def ipa_scores(segments: npt.NDArray[np.integer], rooms: npt.NDArray[np.int32]) -> IpaScores:
    """Score a segmentation against ground-truth rooms with the ipa protocol.

    Parameters
    ----------
    segments : (H, W) integer
        Segment id per pixel, 0 ignored; segments of at most 100 px are dropped.
    rooms : (H, W) int32
        From :func:`ground_truth_rooms`.
    """
    seg = np.asarray(segments)
    if seg.shape != rooms.shape:
        raise DecompositionError(f"segmentation shape {seg.shape} differs from ground truth {rooms.shape}")
    values, inverse = np.unique(seg, return_inverse=True)
    dense = inverse.reshape(seg.shape).astype(np.int32) + np.int32(0 if values[0] == 0 else 1)
    seg_ids = _drop_small(dense, int(dense.max()) + 1)
    n_seg, n_room = int(seg_ids.max()), int(rooms.max())
    if n_room == 0:
        raise DecompositionError("ground truth has no room larger than 100 px")
    both = (seg_ids > 0) & (rooms > 0)
    overlap = np.zeros((n_seg + 1, n_room + 1), dtype=np.int64)
    np.add.at(overlap, (seg_ids[both], rooms[both]), 1)
    seg_size = np.bincount(seg_ids.ravel(), minlength=n_seg + 1)[1:].astype(np.float64)
    room_size = np.bincount(rooms.ravel(), minlength=n_room + 1)[1:].astype(np.float64)
    o = overlap[1:, 1:].astype(np.float64)
    if n_seg == 0:
        return IpaScores(0.0, 0.0, 0.0, 0.0, 0.0, n_room, 0)
    precision = o.max(axis=1) / seg_size
    recall = o.max(axis=0) / room_size
    iou = (o / (seg_size[:, None] + room_size[None, :] - o)).max(axis=0)
    return IpaScores(
        recall=float(recall.mean()),
        precision=float(precision.mean()),
        recall_weighted=float(np.average(recall, weights=room_size)),
        precision_weighted=float(np.average(precision, weights=seg_size)),
        mean_iou=float(iou.mean()),
        n_rooms=n_room,
        n_segments=n_seg,
    )

"""The ipa room-segmentation protocol: per-room recall, per-segment precision and best IoU.

Also the ROSE\u00b2 form of it (colour ground truth, scored on the map's free pixels only) and the
stability of region ids over the steps of a growing map.
"""

from __future__ import annotations

from typing import NamedTuple

import cv2
import numpy as np
import numpy.typing as npt

from services.grid_decomposition.errors import DecompositionError

FREE_GREY = 250
GT_ROOM_GREY = 250  # ipa: cv::threshold(gt, 250, THRESH_BINARY), rooms are the pixels above it
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
    """Rooms of an ipa ``_gt_segmentation.png`` (grey levels): 8-connected regions above grey 250, > 100 px.

    Returns
    -------
    (H, W) int32
        Room id per pixel, 0 outside rooms.
    """
    grey = np.asarray(gt_grey)
    if grey.ndim != 2 or grey.size == 0:
        raise DecompositionError(f"ground truth must be a non-empty 2-D grey image, got shape {grey.shape}")
    n, labels = cv2.connectedComponents((grey > GT_ROOM_GREY).astype(np.uint8), connectivity=8, ltype=cv2.CV_32S)
    return _drop_small(np.asarray(labels, dtype=np.int32), int(n))


def _drop_small(labels: npt.NDArray[np.int32], n: int) -> npt.NDArray[np.int32]:
    sizes = np.bincount(labels.ravel(), minlength=n)
    keep = sizes > MIN_AREA_PX
    keep[0] = False
    remap = np.where(keep, np.cumsum(keep), 0).astype(np.int32)
    return remap[labels]


class _Overlap(NamedTuple):
    segment_ids: npt.NDArray[np.int64]  # (S,) the segmentation's own id of each scored segment
    room_ids: npt.NDArray[np.int64]  # (R,) the ground truth's id of each scored room
    pixels: npt.NDArray[np.int64]  # (S, R) pixels of segment i in room j
    segment_px: npt.NDArray[np.float64]  # (S,)
    room_px: npt.NDArray[np.float64]  # (R,)


def _overlap(segments: npt.NDArray[np.integer], rooms: npt.NDArray[np.int32]) -> _Overlap:
    seg = np.asarray(segments)
    if seg.shape != rooms.shape:
        raise DecompositionError(f"segmentation shape {seg.shape} differs from ground truth {rooms.shape}")
    values, inverse = np.unique(seg, return_inverse=True)
    shift = 0 if values[0] == 0 else 1
    dense = inverse.reshape(seg.shape).astype(np.int32) + np.int32(shift)
    seg_ids = _drop_small(dense, int(dense.max()) + 1)
    n_seg, n_room = int(seg_ids.max()), int(max(rooms.max(), 0))
    # rooms of at most 100 scored pixels are dropped as segments are (ids kept): a ROSE2 room with a
    # single free pixel is no room on the free pixels the scores count
    room_size = np.bincount(np.maximum(rooms, 0).ravel(), minlength=n_room + 1)[1:].astype(np.float64)
    scored = room_size > MIN_AREA_PX
    if not scored.any():
        raise DecompositionError("ground truth has no room larger than 100 px")
    both = (seg_ids > 0) & (rooms > 0)
    overlap = np.zeros((n_seg + 1, n_room + 1), dtype=np.int64)
    np.add.at(overlap, (seg_ids[both], rooms[both]), 1)
    seg_size = np.bincount(seg_ids.ravel(), minlength=n_seg + 1)[1:].astype(np.float64)
    # the dense id each scored segment had before the small ones were dropped, and its own id
    first = np.zeros(n_seg + 1, dtype=np.int64)
    first[seg_ids.ravel()] = dense.ravel()
    own = values[np.maximum(first[1:] - shift, 0)].astype(np.int64)
    room_ids = np.flatnonzero(scored).astype(np.int64) + 1
    return _Overlap(own, room_ids, overlap[1:, 1:][:, scored], seg_size, room_size[scored])


def ipa_scores(segments: npt.NDArray[np.integer], rooms: npt.NDArray[np.int32]) -> IpaScores:
    """Score a segmentation against ground-truth rooms with the ipa protocol.

    Parameters
    ----------
    segments : (H, W) integer
        Segment id per pixel, 0 ignored; segments of at most 100 px are dropped.
    rooms : (H, W) int32
        From :func:`ground_truth_rooms` (or :func:`colour_rooms` kept on the free pixels, :func:`on_free`);
        rooms of at most 100 px are dropped, as the segments are: on the free pixels a ROSE² room may
        keep only a few.
    """
    ov = _overlap(segments, rooms)
    seg_size, room_size = ov.segment_px, ov.room_px
    n_room = room_size.size
    if seg_size.size == 0:
        return IpaScores(0.0, 0.0, 0.0, 0.0, 0.0, n_room, 0)
    o = ov.pixels.astype(np.float64)
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
        n_segments=int(seg_size.size),
    )


class RoomMatch(NamedTuple):
    """One ground-truth room's terms of :func:`ipa_scores`: its recall (share of it in the segment holding
    most of it) and its best IoU with any segment."""

    room: int
    pixels: int
    segment: int  # the segment holding most of the room (its own id), 0 if none
    recall: float
    iou: float


class SegmentMatch(NamedTuple):
    """One segment's term of :func:`ipa_scores`: its precision (purity: the share of it in its best room)."""

    segment: int
    pixels: int
    room: int  # the room holding most of it, 0 if none
    purity: float


def matches(
    segments: npt.NDArray[np.integer], rooms: npt.NDArray[np.int32]
) -> tuple[list[RoomMatch], list[SegmentMatch]]:
    """Per room and per segment, the terms :func:`ipa_scores` averages: what a low score is made of.

    Segments keep their own ids; segments and rooms of at most 100 px are left out, as in the scores.
    """
    ov = _overlap(segments, rooms)
    o = ov.pixels.astype(np.float64)
    if ov.segment_px.size == 0:
        return [RoomMatch(int(r), int(p), 0, 0.0, 0.0) for r, p in zip(ov.room_ids, ov.room_px, strict=True)], []
    iou = o / (ov.segment_px[:, None] + ov.room_px[None, :] - o)
    best_segment = o.argmax(axis=0)
    best_room = o.argmax(axis=1)
    room_rows = [
        RoomMatch(
            int(ov.room_ids[j]), int(ov.room_px[j]),
            int(ov.segment_ids[best_segment[j]]) if o[best_segment[j], j] > 0 else 0,
            float(o[best_segment[j], j] / ov.room_px[j]), float(iou[:, j].max()),
        )
        for j in range(ov.room_px.size)
    ]
    segment_rows = [
        SegmentMatch(
            int(ov.segment_ids[i]), int(ov.segment_px[i]),
            int(ov.room_ids[best_room[i]]) if o[i, best_room[i]] > 0 else 0,
            float(o[i, best_room[i]] / ov.segment_px[i]),
        )
        for i in range(ov.segment_px.size)
    ]
    return room_rows, segment_rows


def colour_rooms(
    gt_rgb: npt.NDArray[np.uint8], *, background: tuple[tuple[int, int, int], ...] = ((0, 0, 0),)
) -> npt.NDArray[np.int32]:
    """Rooms of a colour ground truth (ROSE\u00b2 ``gt.png``): each colour is one room.

    Parameters
    ----------
    gt_rgb : (H, W, 3 or 4) uint8
        One colour per room; an alpha channel is ignored.
    background : tuple of (r, g, b)
        Colours that are no room (black in ``gt.png``; ROSE\u00b2's ``rose2_rooms.png`` leaves
        white where it found no room).

    Returns
    -------
    (H, W) int32
        Room id per pixel (colours numbered in sorted order), 0 outside rooms; rooms of at most
        100 px dropped.
    """
    rgb = np.asarray(gt_rgb)
    if rgb.ndim != 3 or rgb.shape[2] < 3 or rgb.size == 0:
        raise DecompositionError(f"colour ground truth must be an (H, W, 3|4) image, got shape {rgb.shape}")
    key = (rgb[..., 0].astype(np.int64) << 16) | (rgb[..., 1].astype(np.int64) << 8) | rgb[..., 2]
    for r, g, b in background:
        key[key == (r << 16) | (g << 8) | b] = -1
    key += 1
    values, inverse = np.unique(key, return_inverse=True)
    dense = inverse.reshape(key.shape).astype(np.int32) + np.int32(0 if values[0] == 0 else 1)
    return _drop_small(dense, int(dense.max()) + 1)


def on_free(labels: npt.NDArray[np.integer], free: npt.NDArray[np.bool_]) -> npt.NDArray[np.int32]:
    """``labels`` kept on ``free`` pixels only (the ROSE\u00b2 scoring: free in the map on both sides)."""
    lab = np.asarray(labels)
    if lab.shape != free.shape:
        raise DecompositionError(f"labels shape {lab.shape} differs from the free mask {free.shape}")
    return np.where(free, lab, 0).astype(np.int32)


def align_offset(
    before: npt.NDArray[np.bool_], after: npt.NDArray[np.bool_], *, max_shift_px: int = 400
) -> tuple[int, int]:
    """(row, col) offset of ``before`` inside ``after`` that best overlaps their free pixels.

    A growing map keeps its resolution but may grow on any side: the offset of the older map's
    origin in the newer one, searched within ``max_shift_px`` (and the size difference) by the
    overlap of the two free masks (FFT correlation).
    """
    a = np.asarray(before, dtype=np.float32)
    b = np.asarray(after, dtype=np.float32)
    if a.ndim != 2 or b.ndim != 2:
        raise DecompositionError(f"free masks must be 2-D, got {a.shape} and {b.shape}")
    h, w = b.shape[0] + a.shape[0], b.shape[1] + a.shape[1]
    corr = np.fft.irfft2(np.fft.rfft2(b, (h, w)) * np.conj(np.fft.rfft2(a, (h, w))), (h, w))
    rows = np.fft.fftfreq(h, 1.0 / h).astype(np.int64)  # offsets -h/2 .. h/2
    cols = np.fft.fftfreq(w, 1.0 / w).astype(np.int64)
    ok_r = np.abs(rows) <= max_shift_px + abs(b.shape[0] - a.shape[0])
    ok_c = np.abs(cols) <= max_shift_px + abs(b.shape[1] - a.shape[1])
    corr = np.where(ok_r[:, None] & ok_c[None, :], corr, -np.inf)
    r, c = np.unravel_index(int(np.argmax(corr)), corr.shape)
    return int(rows[r]), int(cols[c])


def shift_into(
    image: npt.NDArray[np.integer], offset: tuple[int, int], shape: tuple[int, int]
) -> npt.NDArray[np.int32]:
    """``image`` placed at ``offset`` (row, col) in a zero image of ``shape`` (parts outside cut off)."""
    out = np.zeros(shape, dtype=np.int32)
    dr, dc = offset
    h, w = image.shape
    r0, c0 = max(dr, 0), max(dc, 0)
    r1, c1 = min(dr + h, shape[0]), min(dc + w, shape[1])
    if r1 > r0 and c1 > c0:
        out[r0:r1, c0:c1] = image[r0 - dr : r1 - dr, c0 - dc : c1 - dc]
    return out


class IdStability(NamedTuple):
    """Region ids of one step kept in the next: ``kept`` of ``matched`` regions (``share`` = kept / matched)."""

    kept: int
    matched: int
    share: float


def id_stability(
    before: npt.NDArray[np.integer],
    after: npt.NDArray[np.integer],
    rooms_after: npt.NDArray[np.int32],
    *,
    min_overlap: float = 0.5,
) -> IdStability:
    """How many regions of a step keep their id in the next step, where their room still exists.

    Regions are matched by overlap (both images in the newer map's frame, 0 = none): a region of
    ``before`` whose pixels lie mostly (> ``min_overlap``) in rooms of ``rooms_after`` is counted;
    it is kept when the region of ``after`` it overlaps most carries the same id and holds more
    than ``min_overlap`` of it. Region ids of a decomposition are its own: give ``after`` with ids
    carried over by :func:`~services.grid_decomposition.keys.stable_ids` to score what a live map shows.
    """
    b, a = np.asarray(before), np.asarray(after)
    if b.shape != a.shape or rooms_after.shape != a.shape:
        raise DecompositionError(f"shapes differ: {b.shape}, {a.shape}, {rooms_after.shape}")
    kept = matched = 0
    for rid in np.unique(b[b > 0]):
        mask = b == rid
        size = int(mask.sum())
        if size <= MIN_AREA_PX or (rooms_after[mask] > 0).mean() <= min_overlap:
            continue
        matched += 1
        ids, counts = np.unique(a[mask], return_counts=True)
        best = int(np.argmax(np.where(ids > 0, counts, -1)))
        if ids[best] == rid and counts[best] > min_overlap * size:
            kept += 1
    return IdStability(kept, matched, kept / matched if matched else 1.0)

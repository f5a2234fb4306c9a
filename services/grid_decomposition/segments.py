"""From per-face segment ids to a clean per-pixel segmentation of free space."""

from __future__ import annotations

import cv2
import numpy as np
import numpy.typing as npt
from scipy import ndimage


def fill_from_neighbours(
    segments: npt.NDArray[np.int32], target: npt.NDArray[np.bool_], *, max_iterations: int = 200
) -> npt.NDArray[np.int32]:
    """Give unlabelled (0) ``target`` pixels the id of a labelled 8-neighbour, growing outwards."""
    out = segments.copy()
    kernel = np.ones((3, 3), np.uint8)
    for _ in range(max_iterations):
        hole = target & (out == 0)
        if not hole.any():
            break
        rows, cols = np.nonzero(hole)
        r0, r1 = max(rows.min() - 1, 0), rows.max() + 2
        c0, c1 = max(cols.min() - 1, 0), cols.max() + 2
        crop = out[r0:r1, c0:c1]
        grown = cv2.dilate(crop.astype(np.float32), kernel).astype(np.int32)
        h = hole[r0:r1, c0:c1]
        fill = h & (grown > 0)
        if not fill.any():
            break
        crop[fill] = grown[fill]
    return out


def segment_image(
    face_image: npt.NDArray[np.int32],
    face_segment: npt.NDArray[np.int64],
    free: npt.NDArray[np.bool_],
    *,
    min_area_px: int,
) -> npt.NDArray[np.int32]:
    """Per-pixel segments of free space from a segment id per face.

    Line pixels take a neighbouring face's segment; every segment is split into its 4-connected
    pieces; pieces smaller than ``min_area_px`` are absorbed by their neighbours.

    Parameters
    ----------
    face_image : (H, W) int32
        Face id per pixel, 0 on lines.
    face_segment : (F + 1,) int64
        Segment id per face (0 = none).
    free : (H, W) bool
    min_area_px : int

    Returns
    -------
    (H, W) int32
        Segment ids 1..N (consecutive), 0 off free space.
    """
    seg = np.where(free, face_segment[face_image], 0).astype(np.int32)
    seg = fill_from_neighbours(seg, free & (face_image == 0), max_iterations=3)
    out = np.zeros_like(seg)
    next_id = 1
    small = np.zeros(seg.shape, dtype=bool)
    for sid, box in enumerate(ndimage.find_objects(seg), start=1):
        if box is None:
            continue
        mask = seg[box] == sid
        n, pieces, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=4)
        view = out[box]
        for k in range(1, n):
            piece = pieces == k
            if stats[k, cv2.CC_STAT_AREA] < min_area_px:
                small[box] |= piece
                continue
            view[piece] = next_id
            next_id += 1
    if small.any():
        out = fill_from_neighbours(out, small)
    return out

"""Joining pieces of one furnished room: no neck between them, and together they are as convex as a room."""

from __future__ import annotations

import cv2
import numpy as np
import numpy.typing as npt
from scipy import ndimage

from services.grid_decomposition.segments import renumber


def join_room_pieces(
    segments: npt.NDArray[np.int32],
    furniture: npt.NDArray[np.bool_],
    *,
    resolution_m: float,
    furniture_reach_m: float = 1.0,
    fixed: npt.NDArray[np.bool_] | None = None,
    min_saddle_ratio: float = 0.8,
    min_solidity: float = 0.8,
) -> npt.NDArray[np.int32]:
    """Join touching segments that are pieces of one furnished room rather than rooms joined by a doorway.

    On the clearance map of the floor (free space with ``furniture`` standing on it; distance to
    the nearest wall) a room is a basin whose peak is the middle of its floor. Two rooms joined by
    a doorway meet at a saddle (the middle of the doorway) much lower than the smaller room's
    peak; two pieces of one furnished room, cut apart along a gap between desks, meet at a saddle
    almost as high as the smaller piece's peak (``saddle >= min_saddle_ratio * min(peaks)``: the
    smaller piece has no room of its own behind the border). A wide opening between a small room
    and a corridor is no neck either: there the union has the shape of a T or an L, while two
    pieces of one room fill their convex hull (furniture holes counted in), so the union's
    solidity must reach ``min_solidity``. Only borders with furniture within
    ``furniture_reach_m`` are joined: the pieces of a bare room were not cut by furniture (a row
    of bare cubicles, each as wide as its opening onto the corridor, stays apart).

    Pairs are joined best solidity first, one join per segment per round, until none is left;
    a joined segment's peak is the higher of its pieces'.

    Parameters
    ----------
    segments : (H, W) int32
        Segment ids 1..N per pixel, 0 = none.
    furniture : (H, W) bool
        Obstacles standing on the floor of the rooms (floor for the clearance).
    resolution_m : float
        Metres per pixel.
    fixed : (N + 1,) bool, optional
        Per segment id: never joined (warehouse floors, road networks).

    Returns
    -------
    (H, W) int32
        Segment ids 1..M (consecutive), 0 where ``segments`` is 0.
    """
    seg = np.asarray(segments, dtype=np.int32)
    n = int(seg.max()) + 1
    if n <= 2:
        return renumber(seg)
    floor = ((seg > 0) | furniture).astype(np.uint8)
    clearance = np.asarray(cv2.distanceTransform(floor, cv2.DIST_L2, 5), dtype=np.float32)
    reach = max(1, round(furniture_reach_m / resolution_m))
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * reach + 1, 2 * reach + 1))
    near = cv2.dilate(furniture.astype(np.uint8), disc) > 0
    peak = np.zeros(n, dtype=np.float32)
    np.maximum.at(peak, seg.ravel(), clearance.ravel())
    frozen = np.zeros(n, dtype=bool) if fixed is None else np.asarray(fixed[:n], dtype=bool).copy()
    frozen[0] = True
    parent = np.arange(n)
    while True:
        pairs, saddle, furnished = _saddles(seg, clearance, near)
        keep = furnished & ~frozen[pairs[:, 0]] & ~frozen[pairs[:, 1]]
        keep &= saddle >= min_saddle_ratio * np.minimum(peak[pairs[:, 0]], peak[pairs[:, 1]])
        pairs = pairs[keep]
        if pairs.size == 0:
            break
        boxes = ndimage.find_objects(seg)
        solid = np.array([_solidity(seg, boxes, int(a), int(b)) for a, b in pairs])
        order = np.argsort(-solid, kind="stable")
        used = np.zeros(n, dtype=bool)
        joined = False
        for k in order[solid[order] >= min_solidity]:
            a, b = (int(v) for v in pairs[k])
            if used[a] or used[b]:
                continue
            used[a] = used[b] = True
            parent[b] = a
            peak[a] = max(peak[a], peak[b])
            joined = True
        if not joined:
            break
        lut = np.arange(n, dtype=np.int32)
        lut[used] = parent[used].astype(np.int32)
        seg = lut[seg]
    return renumber(seg)


def _saddles(
    seg: npt.NDArray[np.int32],
    clearance: npt.NDArray[np.float32],
    near: npt.NDArray[np.bool_],
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.float32], npt.NDArray[np.bool_]]:
    """Touching segment pairs (a < b), the highest clearance along their border, and whether furniture is near it."""
    n = int(seg.max()) + 1
    keys: list[npt.NDArray[np.int64]] = []
    heights: list[npt.NDArray[np.float32]] = []
    nears: list[npt.NDArray[np.bool_]] = []
    for dy, dx in ((0, 1), (1, 0)):
        h, w = seg.shape
        a, b = seg[: h - dy, : w - dx], seg[dy:, dx:]
        rows, cols = np.nonzero((a != b) & (a > 0) & (b > 0))
        p, q = a[rows, cols].astype(np.int64), b[rows, cols].astype(np.int64)
        keys.append(np.minimum(p, q) * n + np.maximum(p, q))
        heights.append(np.minimum(clearance[rows, cols], clearance[rows + dy, cols + dx]))
        nears.append(near[rows, cols] | near[rows + dy, cols + dx])
    key, height = np.concatenate(keys), np.concatenate(heights)
    codes, inverse = np.unique(key, return_inverse=True)
    top = np.zeros(codes.size, dtype=np.float32)
    np.maximum.at(top, inverse, height)
    furnished = np.bincount(inverse, weights=np.concatenate(nears), minlength=codes.size) > 0
    return np.stack([codes // n, codes % n], axis=1), top, furnished


def _solidity(seg: npt.NDArray[np.int32], boxes: list[tuple[slice, slice] | None], a: int, b: int) -> float:
    """Area of segments ``a`` and ``b`` together, holes filled, over the area of their convex hull."""
    box_a, box_b = boxes[a - 1], boxes[b - 1]
    assert box_a is not None and box_b is not None
    r0, r1 = min(box_a[0].start, box_b[0].start), max(box_a[0].stop, box_b[0].stop)
    c0, c1 = min(box_a[1].start, box_b[1].start), max(box_a[1].stop, box_b[1].stop)
    crop = seg[r0:r1, c0:c1]
    union = ((crop == a) | (crop == b)).astype(np.uint8)
    outlines, _ = cv2.findContours(union, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    filled = cv2.drawContours(np.zeros_like(union), outlines, -1, 1, thickness=cv2.FILLED)  # holes filled
    hull = cv2.convexHull(np.concatenate(outlines))  # the outlines' hull is the pixels' hull
    # pixel centres span the hull: half a pixel all round is still the union's area
    hull_area = cv2.contourArea(hull) + 0.5 * cv2.arcLength(hull, True) + 1.0
    return float(np.count_nonzero(filled) / hull_area)

"""Rooms seen from outside: fans of laser rays (or floor) through a doorway, split off the region they enter from."""

from __future__ import annotations

import cv2
import numpy as np
import numpy.typing as npt

from services.grid_decomposition.arrays import components_stats, label_boxes, near, nonzero_rc
from services.grid_decomposition.rooms import open_share


def split_fans(
    segments: npt.NDArray[np.int32],
    occupied: npt.NDArray[np.bool_],
    fixed: npt.NDArray[np.bool_],
    *,
    resolution_m: float,
    max_neck_m: float = 1.2,
    min_area_m2: float = 0.75,
    min_depth_m: float = 2.0,
    min_segment_area_m2: float = 50.0,
    outside_reach_m: float = 6.0,
    max_open_share: float = 0.4,
    thin: npt.NDArray[np.bool_] | None = None,
    min_room_area_m2: float = 15.0,
    min_thin_share: float = 0.2,
) -> npt.NDArray[np.int32]:
    """Give every room that leaves a segment through a doorway-wide neck a segment of its own.

    A robot passing a door sees the room behind it as a fan of rays bounded by unknown space and
    walls, or as floor where the rays are dense. It is free space, so the region it grows from (a
    corridor) takes it; the room then lies whole inside the corridor's segment. A segment's *core*
    is its largest part that survives an opening with a disc ``max_neck_m`` wide (no such disc
    passes the door, so the floor just behind it is no part of the core); a part of the rest is a
    room when it is at least ``min_area_m2``, touches the core along at most ``max_neck_m``, reaches
    at least ``min_depth_m`` beyond it and has walls round it: less than ``max_open_share`` of 32
    beams from its middle meet no ``occupied`` cell within ``outside_reach_m``
    (:func:`~services.grid_decomposition.rooms.open_share`; rays through a gap in an outer wall
    have none beyond them). Only segments of at least ``min_segment_area_m2`` (halls, corridors)
    lose rooms so, and, when ``thin`` is given, smaller ones of at least ``min_room_area_m2`` (a room
    or a corridor's piece) lose such parts of which at least ``min_thin_share`` is ``thin``: a room
    seen from inside another only through its door is a fan of rays, while a part of a room's own
    floor beyond a neck (an alcove, a bay between cupboards) is dense floor.

    Parameters
    ----------
    segments : (H, W) int32
        Segment id per pixel, 0 off free space.
    occupied : (H, W) bool
        Walls and obstacles as mapped.
    fixed : (N + 1,) bool
        Segments left alone (warehouse floors, roads).
    resolution_m : float
        Metres per pixel.
    thin : (H, W) bool, optional
        Free space too thin to be floor (the cleaning's rays and streaks); without it only segments of
        at least ``min_segment_area_m2`` lose rooms.

    Returns
    -------
    (H, W) int32
        ``segments`` with each such room under a new id (above the largest one).
    """
    out = segments.copy()
    radius = max(1, round(max_neck_m / 2 / resolution_m))
    ring = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))
    next_id = int(segments.max()) + 1
    min_area_px = min_area_m2 / resolution_m**2
    for k, found in enumerate(label_boxes(segments), start=1):
        if found is None or fixed[k]:
            continue
        box = tuple(slice(max(0, s.start - radius), s.stop + radius) for s in found)
        mine = segments[box] == k
        area = mine.sum() * resolution_m**2
        if area < (min_segment_area_m2 if thin is None else min(min_segment_area_m2, min_room_area_m2)):
            continue
        # the opening by distances (a disc's erosion and dilation are thresholds of the distance transform,
        # each one dilation by the transform's own ball: ``near``)
        inner = ~near(~mine, radius, 5)
        n, parts, stats = components_stats(inner.astype(np.uint8), 8)
        if n < 2:
            continue
        core = mine & near(parts == 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA])), radius, 5)
        n, parts, stats = components_stats((mine & ~core).astype(np.uint8), 8)
        big = np.flatnonzero(stats[:, cv2.CC_STAT_AREA] >= min_area_px)
        big = big[big > 0]
        if big.size == 0:
            continue
        neck = np.bincount(parts[cv2.dilate(core.astype(np.uint8), ring).astype(bool)], minlength=n)
        fans = [c for c in big if 0 < neck[c] * resolution_m <= max_neck_m]
        if fans and thin is not None and area < min_segment_area_m2:  # a room's own floor stays: only rays leave
            thin_share = np.bincount(parts[thin[box]], minlength=n) / np.maximum(stats[:, cv2.CC_STAT_AREA], 1)
            fans = [c for c in fans if thin_share[c] >= min_thin_share]
        if fans:
            depth = cv2.distanceTransform((~core).astype(np.uint8), cv2.DIST_L2, 5)
            fans = [c for c in fans if depth[parts == c].max() * resolution_m >= min_depth_m]
        if fans:
            fans = [c for c, share in zip(fans, open_share(
                occupied, np.array([_middle(parts == c) for c in fans]) + np.array([box[0].start, box[1].start]),
                reach_px=round(outside_reach_m / resolution_m)), strict=True) if share < max_open_share]
        if not fans:
            continue
        lut = np.zeros(n, dtype=np.int32)
        lut[fans] = np.arange(next_id, next_id + len(fans))
        next_id += len(fans)
        out[box] = np.where(lut[parts] > 0, lut[parts], out[box])
    return out


def _middle(mask: npt.NDArray[np.bool_]) -> tuple[int, int]:
    """(row, col) of the pixel of ``mask`` nearest its centroid."""
    rows, cols = nonzero_rc(mask)
    j = int(np.argmin((rows - rows.mean()) ** 2 + (cols - cols.mean()) ** 2))
    return int(rows[j]), int(cols[j])

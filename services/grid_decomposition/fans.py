"""Rooms seen from outside: fans of laser rays (or floor) through a doorway, split off the region they enter from."""

from __future__ import annotations

import math
from typing import NamedTuple

import cv2
import numpy as np
import numpy.typing as npt

from services.grid_decomposition.arrays import components_stats, label_boxes, nonzero_rc
from services.grid_decomposition.rooms import open_share

_RING = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))


class _FanTests(NamedTuple):
    """What a part beyond a core must pass to be a room (see :func:`split_fans`)."""

    occupied: npt.NDArray[np.bool_]
    resolution_m: float
    min_area_m2: float
    min_depth_m: float
    outside_reach_m: float
    max_open_share: float
    min_thin_share: float


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
    wide_neck_m: float = 0.0,
    lobe_max_area_m2: float = 0.0,
    lobe_min_border_m: float = 0.25,
) -> npt.NDArray[np.int32]:
    """Give every room that leaves a segment through a doorway-wide neck a segment of its own.

    A robot passing a door sees the room behind it as a fan of rays bounded by unknown space and
    walls, or as floor where the rays are dense. It is free space, so the region it grows from (a
    corridor) takes it; the room then lies whole inside the corridor's segment. A segment's *core*
    is its largest part that survives an opening with a disc ``max_neck_m`` wide (no such disc
    passes the door, so the floor just behind it is no part of the core); a part of the rest is a
    room when it is at least ``min_area_m2``, touches the core along at most ``max_neck_m``, reaches
    at least ``min_depth_m`` beyond it and has walls round it: less than ``max_open_share`` of 32
    beams from its middle meet no ``occupied`` cell nor the core within ``outside_reach_m``
    (:func:`~services.grid_decomposition.rooms.open_share`; rays through a gap in an outer wall
    have none beyond them, while a beam from a room back through its door, or through a wall the
    laser never hit, into the segment it leaves is inside the building: a room seen only through
    its door has walls the laser never hit). Only segments of at least ``min_segment_area_m2`` (halls, corridors)
    lose rooms so, and, when ``thin`` is given, smaller ones of at least ``min_room_area_m2`` (a room
    or a corridor's piece) lose such parts of which at least ``min_thin_share`` is ``thin``: a room
    seen from inside another only through its door is a fan of rays, while a part of a room's own
    floor beyond a neck (an alcove, a bay between cupboards) is dense floor.

    A door wider than ``max_neck_m`` lets that disc through, so the room behind it stays in the core. With
    ``thin``, a segment of at least ``min_segment_area_m2`` is also opened with a disc ``wide_neck_m`` wide (the
    widest door): such a disc stops at the door's line, bulging through it, and a part beyond it that passes the
    same tests with ``wide_neck_m`` for the neck, and of which at least ``min_thin_share`` is ``thin``, is a room,
    with the core's floor between its border and that border's chord (the bulge through the door). Only rays
    leave so: a corridor or a bay narrower than that disc is dense floor. A room found by the narrow disc inside
    such a room is a room of its own.

    A part smaller than ``lobe_max_area_m2`` (a room's least area) that also touches a segment other than the one
    it leaves, along at least ``lobe_min_border_m`` (a corner or the end of a ray is no border), is a beam of a fan
    that segment holds (a room seen through its door in several beams): it joins the segment it touches along most
    pixels rather than standing as a room too small to be one. With ``thin``, such a part beyond a door-wide neck
    that fails the fan tests (too shallow, dense floor) joins the segment it so touches when at least
    ``min_thin_share`` of that segment is ``thin``: a room seen only through its door is rays beyond the floor just
    inside the door, which the laser saw densely from the corridor (a closet as wide as its door, whose door line the
    room stage found no doorway: the cut lies where the rays widen, inside).

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
    wide_neck_m : float
        The widest door, for rooms of rays behind doors wider than ``max_neck_m``; 0 (or without ``thin``): none.
    lobe_max_area_m2, lobe_min_border_m : float
        Parts smaller than ``lobe_max_area_m2`` join another segment they touch along ``lobe_min_border_m``; 0: none
        do.

    Returns
    -------
    (H, W) int32
        ``segments`` with each such room under a new id (above the largest one).
    """
    out = segments.copy()
    radius = max(1, round(max_neck_m / 2 / resolution_m))
    wide_radius = round(wide_neck_m / 2 / resolution_m)
    next_id = int(segments.max()) + 1
    lobe_max_px = lobe_max_area_m2 / resolution_m**2
    lobe_border_px = max(1, round(lobe_min_border_m / resolution_m))
    floor_m2 = min_segment_area_m2 if thin is None else min(min_segment_area_m2, min_room_area_m2)
    tests = _FanTests(occupied, resolution_m, min_area_m2, min_depth_m, outside_reach_m, max_open_share, min_thin_share)
    for k, found in enumerate(label_boxes(segments), start=1):
        if found is None or fixed[k]:
            continue
        pad = max(radius, wide_radius)
        box = tuple(slice(max(0, s.start - pad), s.stop + pad) for s in found)
        mine = segments[box] == k
        area = np.count_nonzero(mine) * resolution_m**2
        if area < floor_m2:
            continue
        thin_here = None if thin is None else thin[box]
        offset = (box[0].start, box[1].start)
        inside = cv2.distanceTransform(mine.view(np.uint8), cv2.DIST_L2, 5)
        rooms: list[npt.NDArray[np.bool_]] = []
        if thin_here is not None and wide_radius > radius and area >= min_segment_area_m2:
            # a door wider than the disc: a disc wider than the door stops at its line and bulges through it
            # (the room takes the floor between that bulge and its chord); only rays leave so, since a corridor
            # narrower than that disc is dense floor
            parts, core, fans, _ = _beyond_core(mine, inside, wide_radius, wide_neck_m, offset, tests, thin_here)
            rooms = [(parts == c) | _door_lens(parts == c, core) for c in fans]
        # a room's own floor beyond a neck stays in a small segment: only rays leave it
        small = thin_here if area < min_segment_area_m2 else None
        parts, _, fans, necked = _beyond_core(mine, inside, radius, max_neck_m, offset, tests, small)
        rooms += [parts == c for c in fans]  # a room behind a narrow door inside one behind a wide door: its own
        for room in rooms:
            lobe_of = _lobe_of(out[box], room, k, fixed, lobe_border_px) if np.count_nonzero(room) < lobe_max_px else 0
            out[box][room] = lobe_of or next_id
            next_id += 0 if lobe_of else 1
        if thin is None:
            continue
        for c in necked:  # the floor just inside the door of a room seen only as rays: that room's
            pocket = parts == c
            if c in fans or np.count_nonzero(pocket) >= lobe_max_px:
                continue
            lobe_of = _lobe_of(out[box], pocket, k, fixed, lobe_border_px)
            if lobe_of and _thin_share(out, lobe_of, thin) >= min_thin_share:
                out[box][pocket] = lobe_of
    return out


def _thin_share(labels: npt.NDArray[np.int32], label: int, thin: npt.NDArray[np.bool_]) -> float:
    """The share of the pixels of ``label`` in ``labels`` that are ``thin``."""
    mine = labels == label
    return int(np.count_nonzero(thin & mine)) / max(1, int(np.count_nonzero(mine)))


def _lobe_of(
    labels: npt.NDArray[np.int32], part: npt.NDArray[np.bool_], host: int, fixed: npt.NDArray[np.bool_], min_border: int
) -> int:
    """The segment of ``labels`` other than ``host`` (and not ``fixed``) that ``part`` touches along most pixels
    (4-connected), when along at least ``min_border`` of them; else 0."""
    ring = cv2.dilate(part.view(np.uint8), _RING).view(bool) & ~part
    touched = labels[ring]
    touched = touched[(touched > 0) & (touched != host)]
    touched = touched[(touched >= fixed.size) | ~fixed[np.minimum(touched, fixed.size - 1)]]
    if touched.size < min_border:
        return 0
    counts = np.bincount(touched)
    return int(np.argmax(counts)) if counts.max() >= min_border else 0


def _beyond_core(
    mine: npt.NDArray[np.bool_],
    inside: npt.NDArray[np.float32],
    radius: int,
    max_neck_m: float,
    offset: tuple[int, int],
    tests: _FanTests,
    thin: npt.NDArray[np.bool_] | None,
) -> tuple[npt.NDArray[np.int32], npt.NDArray[np.bool_], list[int], list[int]]:
    """The parts of ``mine`` beyond its core (what a disc of ``radius`` sweeps), the core, the parts that pass
    the fan tests of :func:`split_fans` and those of at least its least area beyond a neck no wider than
    ``max_neck_m`` (``inside``: the distance transform of ``mine``; ``offset``: its top-left corner in
    ``tests.occupied``)."""
    occupied, resolution_m, min_area_m2, min_depth_m, outside_reach_m, max_open_share, min_thin_share = tests
    # the opening by distances: a disc's erosion and dilation are thresholds of the distance transform (``near``
    # by one transform each: a dilation by a ball as wide as a door is slower)
    inner = inside > radius
    n, parts, stats = components_stats(inner.view(np.uint8), 8)
    if n < 2:
        return parts, mine, [], []
    largest = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    # the transform's distances are chamfer sums, each step at least a pixel in row or column: only within ``radius``
    # rows and columns of the largest part's box are they within ``radius`` of it, and there they are the same
    # measured in that box widened by ``radius`` (the part lies in it whole)
    box = _widened(stats[largest], radius + 1, mine.shape)
    core = np.zeros(mine.shape, dtype=bool)
    core[box] = mine[box] & (cv2.distanceTransform((parts[box] != largest).view(np.uint8), cv2.DIST_L2, 5) <= radius)
    n, parts, stats = components_stats((mine & ~core).view(np.uint8), 8)  # 0/1 bytes as they are
    big = np.flatnonzero(stats[:, cv2.CC_STAT_AREA] >= min_area_m2 / resolution_m**2)
    big = big[big > 0]
    if big.size == 0:
        return parts, core, [], []
    neck = np.bincount(parts[cv2.dilate(core.view(np.uint8), _RING).view(bool)], minlength=n)
    necked = [int(c) for c in big if 0 < neck[c] * resolution_m <= max_neck_m]
    fans = necked
    if fans and thin is not None:
        thin_share = np.bincount(parts[thin], minlength=n) / np.maximum(stats[:, cv2.CC_STAT_AREA], 1)
        fans = [c for c in fans if thin_share[c] >= min_thin_share]
    if fans:
        # a pixel of a part less than ``reach`` from the core has its nearest core pixel within ``reach`` rows and
        # columns (as above), so in the part's box widened by ``reach`` its depth is the same; a deeper one is at least
        # ``reach`` deep there too, deep enough either way
        reach = math.ceil(min_depth_m / resolution_m) + 1
        fans = [c for c in fans if _depth(core, parts, c, _widened(stats[c], reach, mine.shape)) * resolution_m
                >= min_depth_m]
    if fans:
        # a beam back through the door, or through an unseen wall into the segment, crosses the building: the core
        # the part leaves walls it as the map's walls do
        reach = round(outside_reach_m / resolution_m)
        top, left = (max(0, o - reach) for o in offset)
        walled = occupied[top : offset[0] + mine.shape[0] + reach, left : offset[1] + mine.shape[1] + reach].copy()
        y0, x0 = offset[0] - top, offset[1] - left
        walled[y0 : y0 + mine.shape[0], x0 : x0 + mine.shape[1]] |= core
        middles = np.array([_middle(parts == c) for c in fans]) + np.array([y0, x0])
        fans = [c for c, share in zip(fans, open_share(walled, middles, reach_px=reach), strict=True)
                if share < max_open_share]
    return parts, core, fans, necked


def _widened(stat: npt.NDArray[np.int32], margin: int, shape: tuple[int, ...]) -> tuple[slice, slice]:
    """The box of a component's ``cv2.CC_STAT_*`` row widened by ``margin`` pixels on each side, within ``shape``."""
    left, top = int(stat[cv2.CC_STAT_LEFT]), int(stat[cv2.CC_STAT_TOP])
    right, bottom = left + int(stat[cv2.CC_STAT_WIDTH]), top + int(stat[cv2.CC_STAT_HEIGHT])
    return (slice(max(top - margin, 0), min(bottom + margin, shape[0])),
            slice(max(left - margin, 0), min(right + margin, shape[1])))


def _depth(core: npt.NDArray[np.bool_], parts: npt.NDArray[np.int32], c: int, box: tuple[slice, slice]) -> float:
    """The greatest distance (``cv2.DIST_L2``, mask 5) from ``core`` of a pixel of part ``c`` of ``parts``, the
    distances measured within ``box`` (round the part)."""
    depth = cv2.distanceTransform((~core[box]).view(np.uint8), cv2.DIST_L2, 5)
    return float(depth[parts[box] == c].max())


def _door_lens(room: npt.NDArray[np.bool_], core: npt.NDArray[np.bool_]) -> npt.NDArray[np.bool_]:
    """The core's pixels inside the convex hull of its border with ``room``: where a disc wider than the door bulged
    through it, between that border and its chord (the door's line)."""
    rows, cols = nonzero_rc(core & cv2.dilate(room.astype(np.uint8), _RING).astype(bool))
    hull = np.zeros(room.shape, dtype=np.uint8)
    cv2.fillConvexPoly(hull, cv2.convexHull(np.stack([cols, rows], axis=1).astype(np.int32)), 1)
    lens: npt.NDArray[np.bool_] = core & hull.astype(bool)
    return lens


def _middle(mask: npt.NDArray[np.bool_]) -> tuple[int, int]:
    """(row, col) of the pixel of ``mask`` nearest its centroid."""
    rows, cols = nonzero_rc(mask)
    j = int(np.argmin((rows - rows.mean()) ** 2 + (cols - cols.mean()) ** 2))
    return int(rows[j]), int(cols[j])

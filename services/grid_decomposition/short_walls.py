"""A wall that stops short of a region's edge: the room behind it parts along the wall's own line."""

from __future__ import annotations

import cv2
import numpy as np
import numpy.typing as npt

from services.grid_decomposition.corridors import _coordinates, _runs
from services.grid_decomposition.radiogram import Line


def split_at_short_walls(
    segments: npt.NDArray[np.int32],
    occupied: npt.NDArray[np.bool_],
    lines: list[Line],
    candidates: npt.NDArray[np.bool_],
    *,
    resolution_m: float,
    wall_min_m: float = 3.0,
    gap_max_m: float = 3.0,
    gap_max_ratio: float = 0.5,
    wall_gap_m: float = 1.0,
    tolerance_px: int = 5,
    room_min_area_m2: float = 8.0,
    room_min_radius_m: float = 1.5,
    room_min_solidity: float = 0.6,
    flank_m: float = 1.5,
    min_flank_share: float = 0.3,
    margin_px: int = 4,
) -> npt.NDArray[np.int32]:
    """Part a region where a wall between two rooms stops short of the region's edge.

    A partition wall the map draws only partly (the laser never saw its last metres) leaves two rooms
    one region, open onto each other between the wall's end and the region's edge (where it borders a
    corridor parted before). Along every decomposition line, in every region ``k`` with
    ``candidates[k]``: a wall run (occupied cells within ``tolerance_px`` of the line, gaps up to
    ``wall_gap_m`` bridged) at least ``wall_min_m`` long, whose line goes on from the run's end
    through the region's free space and leaves the region into another region (not a wall: a gap
    between two walls is a doorway, judged by the room stage) after at most ``gap_max_m`` and at
    most ``gap_max_ratio`` of the run's length. The region is cut along that stretch, and parts when
    it falls into two pieces that are both room-like (as :func:`~services.grid_decomposition.corridors.
    part_rooms_from_corridors` asks: ``room_min_area_m2``, a disc of ``room_min_radius_m``, area at
    least ``room_min_solidity`` of the convex hull's) and that the wall parts: each lies along the wall run
    on its own side (within ``flank_m`` of the line over at least ``min_flank_share`` of the run). A line
    from the wall between two rooms across the corridor in front of them is no such cut: the corridor's
    pieces do not flank that wall. The cut pixels stay with the larger piece.

    Returns
    -------
    (H, W) int32
        The segments with the parted rooms numbered after the existing ones.
    """
    out = segments.copy()
    next_id = int(segments.max()) + 1
    wall_min, gap_max, bridge = wall_min_m / resolution_m, gap_max_m / resolution_m, wall_gap_m / resolution_m
    flank_px = flank_m / resolution_m
    for k in np.flatnonzero(candidates).tolist():
        rows, cols = np.nonzero(out == k)
        if rows.size == 0:
            continue
        top, left = max(0, int(rows.min()) - margin_px), max(0, int(cols.min()) - margin_px)
        bottom, right = int(rows.max()) + 1 + margin_px, int(cols.max()) + 1 + margin_px
        window = out[top:bottom, left:right]
        walls = occupied[top:bottom, left:right]
        for angle in sorted({ln.angle_rad for ln in lines}):
            u, t = _coordinates(window.shape, top, left, angle)
            t0 = int(t.min())
            span = int(t.max()) - t0 + 1
            for line in (ln for ln in lines if ln.angle_rad == angle):
                offset = round(line.offset_px)
                near = np.abs(u - offset) <= tolerance_px
                wall_t = np.bincount(t[near & walls] - t0, minlength=span) > 0
                if not wall_t.any():
                    continue
                on = u == offset
                starts, ends = _runs(wall_t)
                keep = np.r_[True, starts[1:] - ends[:-1] > bridge]  # bridge short gaps in the wall
                run_starts = starts[keep]
                run_ends = np.r_[ends[np.flatnonzero(keep)[1:] - 1], ends[-1]]
                for s, e in zip(run_starts.tolist(), run_ends.tolist(), strict=True):
                    if e - s < wall_min:
                        continue
                    for end, step in ((e - 1, 1), (s, -1)):
                        stretch = _stretch(window, on, t - t0, k, end, step, min(gap_max, gap_max_ratio * (e - s)))
                        if stretch is None:
                            continue
                        lo, hi = stretch
                        cut = (window == k) & (np.abs(u - offset) <= 1) & (t - t0 >= lo) & (t - t0 <= hi)
                        part = _two_rooms(window == k, cut, resolution_m, room_min_area_m2, room_min_radius_m,
                                          room_min_solidity)
                        if part is not None and _flank(part, (window == k) & ~cut & ~part, u - offset, t - t0, s, e,
                                                       flank_px, min_flank_share):
                            window[part] = next_id
                            next_id += 1
    return out


def _stretch(
    window: npt.NDArray[np.int32],
    on: npt.NDArray[np.bool_],
    t: npt.NDArray[np.int32],
    k: int,
    end: int,
    step: int,
    longest: float,
) -> tuple[int, int] | None:
    """Along-line range (inclusive) of the region ``k``'s free stretch beyond a wall's ``end`` (going ``step``),
    when it leaves the region into another region within ``longest`` pixels; else None."""
    span = int(t.max()) + 1
    mine = np.bincount(t[on & (window == k)], minlength=span) > 0
    other = np.bincount(t[on & (window > 0) & (window != k)], minlength=span) > 0
    reach = int(np.ceil(longest))
    at = end + step
    while 0 <= at < span and not mine[at] and abs(at - end) <= 3:  # the wall's last pixels, its thickness
        at += step
    if not (0 <= at < span) or not mine[at]:
        return None
    first = at
    while 0 <= at < span and mine[at]:
        at += step
        if abs(at - first) > reach:
            return None
    if not (0 <= at < span) or not other[at]:
        return None
    last = at - step
    return (min(first, last), max(first, last))


def _flank(
    a: npt.NDArray[np.bool_],
    b: npt.NDArray[np.bool_],
    u: npt.NDArray[np.int32],
    t: npt.NDArray[np.int32],
    start: int,
    end: int,
    reach_px: float,
    min_share: float,
) -> bool:
    """Whether pieces ``a`` and ``b`` lie along the wall run ``start..end`` (along-line ``t``) on opposite sides
    of its line (across offset ``u`` from it), each within ``reach_px`` over at least ``min_share`` of the run."""
    sides = []
    for piece in (a, b):
        beside = piece & (np.abs(u) <= reach_px) & (t >= start) & (t < end)
        if np.unique(t[beside]).size < min_share * (end - start):
            return False
        if beside.any():  # (none beside when no share is asked: the test is off)
            sides.append(np.sign(np.mean(u[beside])))
    return len(sides) < 2 or bool(sides[0] != sides[1])


def _two_rooms(
    region: npt.NDArray[np.bool_],
    cut: npt.NDArray[np.bool_],
    resolution_m: float,
    min_area_m2: float,
    min_radius_m: float,
    min_solidity: float,
) -> npt.NDArray[np.bool_] | None:
    """The smaller of two room-like 4-connected pieces ``region`` falls into without ``cut``, or None."""
    _, labels, stats, _ = cv2.connectedComponentsWithStats((region & ~cut).astype(np.uint8), connectivity=4)
    big = np.flatnonzero(stats[1:, cv2.CC_STAT_AREA] >= min_area_m2 / resolution_m**2) + 1
    if big.size != 2:
        return None
    for p in big.tolist():
        piece = labels == p
        clearance = cv2.distanceTransform(np.pad(piece, 1).astype(np.uint8), cv2.DIST_L2, 5)
        if clearance.max() < min_radius_m / resolution_m:
            return None
        outline, _ = cv2.findContours(piece.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        if stats[p, cv2.CC_STAT_AREA] < min_solidity * cv2.contourArea(cv2.convexHull(np.concatenate(outline))):
            return None
    small = int(big[np.argmin(stats[big, cv2.CC_STAT_AREA])])
    return np.asarray(labels == small, dtype=bool)

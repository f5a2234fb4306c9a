"""A wall that stops short of a region's edge: the room behind it parts along the wall's own line."""

from __future__ import annotations

import cv2
import numpy as np
import numpy.typing as npt

from services.grid_decomposition.arrays import components_stats, label_boxes, nonzero_rc
from services.grid_decomposition.corridors import _coordinates, _row_runs
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
    flank_px = round(flank_m / resolution_m)
    boxes = label_boxes(segments)
    for k in np.flatnonzero(candidates[: len(boxes) + 1]).tolist():
        box = boxes[k - 1]
        if box is None:
            continue
        top, left = max(0, box[0].start - margin_px), max(0, box[1].start - margin_px)
        bottom, right = box[0].stop + margin_px, box[1].stop + margin_px
        window = out[top:bottom, left:right]
        wall_rows, wall_cols = nonzero_rc(occupied[top:bottom, left:right])
        free_rows, free_cols = nonzero_rc(window == k)
        for angle in sorted({ln.angle_rad for ln in lines}):
            wall_u, wall_t = _project(wall_rows, wall_cols, top, left, angle)
            free_u, free_t = _project(free_rows, free_cols, top, left, angle)
            every_u, every_t = np.r_[wall_u, free_u], np.r_[wall_t, free_t]
            u0, t0 = int(every_u.min()), int(every_t.min())
            shape = (int(every_u.max()) - u0 + 1, int(every_t.max()) - t0 + 1)
            wall_u, wall_t, free_u, free_t = wall_u - u0, wall_t - t0, free_u - u0, free_t - t0
            wall_at = _raster(wall_u, wall_t, shape)  # (across, along): a pixel of it at each place
            mine_at = _raster(free_u, free_t, shape)
            for offset, runs in _wall_runs(
                wall_at, [round(ln.offset_px) - u0 for ln in lines if ln.angle_rad == angle],
                tolerance_px=tolerance_px, bridge_px=bridge, min_length_px=wall_min,
            ):
                bands = (slice(max(offset - flank_px, 0), offset), slice(offset + 1, offset + 1 + flank_px))
                sides = [np.asarray(mine_at[band].any(axis=0), dtype=bool) for band in bands]
                for a, b in runs:
                    if any(side[a:b].sum() < min_flank_share * (b - a) for side in sides):
                        continue  # the region lies along one side of the wall only
                    for end_t, step in ((b - 1, 1), (a, -1)):
                        stretch = _stretch(mine_at[offset], end_t, step, min(gap_max, gap_max_ratio * (b - a)))
                        if stretch is None or not _another_region(window, k, angle, offset + u0, stretch[2] + t0,
                                                                  top, left):
                            continue
                        region = window == k
                        u, t = _coordinates(window.shape, top, left, angle)
                        u, t = u - u0, t - t0
                        cut = region & (np.abs(u - offset) <= 1) & (t >= stretch[0]) & (t <= stretch[1])
                        part = _two_rooms(region, cut, resolution_m, room_min_area_m2, room_min_radius_m,
                                          room_min_solidity)
                        if part is not None and _flank(part, region & ~cut & ~part, u - offset, t, a, b,
                                                       flank_px, min_flank_share):
                            window[part] = next_id
                            next_id += 1
                            still = window[free_rows, free_cols] == k
                            mine_at = _raster(free_u[still], free_t[still], shape)
    return out


def _wall_runs(
    wall_at: npt.NDArray[np.bool_],
    offsets: list[int],
    *,
    tolerance_px: int,
    bridge_px: float,
    min_length_px: float,
) -> list[tuple[int, list[tuple[int, int]]]]:
    """Per line (across ``offsets`` into the (across, along) raster ``wall_at``, in their order), the wall runs
    along it at least ``min_length_px`` long: along-line starts and ends (exclusive) of the places with a wall
    pixel within ``tolerance_px`` across, gaps up to ``bridge_px`` bridged. Lines off the raster or without such
    a run are left out."""
    inside = [offset for offset in offsets if 0 <= offset < wall_at.shape[0]]
    # a wall within the tolerance across, for every line at once
    near = cv2.dilate(wall_at.view(np.uint8), np.ones((2 * tolerance_px + 1, 1), np.uint8)).view(bool)
    line, starts, ends = _row_runs(near[inside])
    if starts.size == 0:
        return []
    keep = np.ones(starts.size, dtype=bool)  # a line's first run, and a run after a gap too wide to bridge
    keep[1:] = (line[1:] != line[:-1]) | (starts[1:] - ends[:-1] > bridge_px)
    first = np.flatnonzero(keep)
    last = np.append(first[1:] - 1, starts.size - 1)  # the bridged run ends where the next begins
    line, starts, ends = line[first], starts[first], ends[last]
    long = ends - starts >= min_length_px
    runs: dict[int, list[tuple[int, int]]] = {}
    for i, a, b in zip(line[long].tolist(), starts[long].tolist(), ends[long].tolist(), strict=True):
        runs.setdefault(i, []).append((a, b))
    return [(inside[i], found) for i, found in sorted(runs.items())]


def _project(
    rows: npt.NDArray[np.intp], cols: npt.NDArray[np.intp], top: int, left: int, angle_rad: float
) -> tuple[npt.NDArray[np.int32], npt.NDArray[np.int32]]:
    """Across and along coordinates of window pixels, as :func:`~services.grid_decomposition.corridors.
    _coordinates` gives them for the whole window."""
    x, y = (cols + left).astype(np.float32), (rows + top).astype(np.float32)
    s, c = np.float32(np.sin(angle_rad)), np.float32(np.cos(angle_rad))
    return np.rint(-s * x + c * y).astype(np.int32), np.rint(c * x + s * y).astype(np.int32)


def _raster(u: npt.NDArray[np.int32], t: npt.NDArray[np.int32], shape: tuple[int, int]) -> npt.NDArray[np.bool_]:
    """Where pixels at across ``u``, along ``t`` lie, as an (across, along) raster."""
    out = np.zeros(shape, dtype=bool)
    out[u, t] = True
    return out


def _stretch(mine: npt.NDArray[np.bool_], end: int, step: int, longest: float) -> tuple[int, int, int] | None:
    """The region's free stretch (``mine``, per along-line pixel of the line) beyond a wall's ``end`` (going
    ``step``) when it ends within ``longest`` pixels: its along-line range (inclusive) and the pixel beyond it;
    else None."""
    span = mine.size
    at = end + step
    while 0 <= at < span and not mine[at] and abs(at - end) <= 3:  # the wall's last pixels, its thickness
        at += step
    if not (0 <= at < span) or not mine[at]:
        return None
    first = at
    while 0 <= at < span and mine[at]:
        at += step
        if abs(at - first) > longest:
            return None
    last = at - step
    return min(first, last), max(first, last), at


def _another_region(
    window: npt.NDArray[np.int32], k: int, angle_rad: float, u: int, t: int, top: int, left: int
) -> bool:
    """Whether the pixel at across ``u``, along ``t`` lies in a region other than ``k`` (not on a wall)."""
    s, c = np.sin(angle_rad), np.cos(angle_rad)
    col, row = round(c * t - s * u) - left, round(s * t + c * u) - top
    if not (0 <= row < window.shape[0] and 0 <= col < window.shape[1]):
        return False
    return bool(window[row, col] > 0 and window[row, col] != k)


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
    _, labels, stats = components_stats((region & ~cut).astype(np.uint8), 4)
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

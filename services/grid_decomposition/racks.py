"""Rack rows however the map draws them, and the aisles, cross aisles and junctions between them.

Maps of the same hall draw a rack in many ways: a solid occupied rectangle (a lidar at beam
height, Gazebo / nav2 maps), a row of upright dots with some missing (a low lidar), pallet faces
with unknown space behind them and empty bays open through to the flue (a lidar at pallet
height), beams as lines. Seen along the rows, all of them are bands of obstacles (occupied or
unknown) broken by gaps no longer than a bay, and 1-3 m deep; aisles are free strips between them.

For each dominant direction the map is turned so that the direction is a grid axis, and for
both axes: obstacles are closed along the rows over gaps up to ``max_bay_gap_m`` (joining the
uprights and pallet faces of a row, but not across a cross aisle), then across over up to
``max_depth_gap_m`` (joining the front and back of a rack and the flue, but not across an
aisle). Closed components shaped like a rack (``min_length_m`` long, a single or back-to-back row
deep, filling their rectangle) are rack rows; their front edges are the median over their
columns (a pallet overhanging the aisle does not narrow it). Rows and sections (the runs of
racks between cross aisles) form a grid: a strip between two racks of a section is an aisle
(corridor), a gap between two sections of a row a cross aisle (corridor), an aisle end or a
crossing meeting three or four such pieces a junction; the perimeter aisles and end cross aisles
reach to the next obstacle (at most ``max_aisle_m``).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import cv2
import numpy as np
import numpy.typing as npt

from services.grid_decomposition.semantics import Label

_UNKNOWN = 2
_OCCUPIED = 1


class RackLayout(NamedTuple):
    """Racks found in an occupancy grid and the grid of places between them.

    Attributes
    ----------
    cells : (H, W) int32
        Place id (1..N) of every pixel of a rack row, aisle piece, cross-aisle piece or junction
        (free and obstacle pixels alike), 0 elsewhere.
    cell_labels : (N + 1,) int64
        :class:`Label` value of each place (index 0 unused).
    outline : (H, W) bool
        Borders of the places, 1 px wide: cuts for the planar subdivision.
    rows_px : (R, 4, 2) float64
        Corners (x = column, y = row) of every rack row facing an aisle (one side of a back-to-back
        row), pixels.
    """

    cells: npt.NDArray[np.int32]
    cell_labels: npt.NDArray[np.int64]
    outline: npt.NDArray[np.bool_]
    rows_px: npt.NDArray[np.float64]

    @property
    def storage(self) -> npt.NDArray[np.bool_]:
        """(H, W) bool: rack footprints."""
        out: npt.NDArray[np.bool_] = self.cell_labels[self.cells] == Label.STORAGE.value
        return out


def _empty(shape: tuple[int, int]) -> RackLayout:
    return RackLayout(
        np.zeros(shape, np.int32), np.zeros(1, np.int64), np.zeros(shape, bool), np.zeros((0, 4, 2), np.float64)
    )


class _Band(NamedTuple):
    lo: float
    hi: float


def _merge(intervals: list[tuple[float, float]], tolerance: float) -> list[_Band]:
    """Overlapping intervals (within ``tolerance``) merged; each band the median of its members' ends."""
    out: list[list[tuple[float, float]]] = []
    for lo, hi in sorted(intervals):
        if out and lo <= max(h for _, h in out[-1]) - tolerance:
            out[-1].append((lo, hi))
        else:
            out.append([(lo, hi)])
    return [_Band(float(np.median([a for a, _ in g])), float(np.median([b for _, b in g]))) for g in out]


class _Rack(NamedTuple):
    x0: int
    x1: int  # exclusive
    y0: float
    y1: float


def _edge(depths: npt.NDArray[np.int64], size: int, share: float = 0.2) -> float:
    """The outermost depth that at least ``share`` of the columns reach within 1 px.

    A rack's front is where the uprights stand: columns notched by a missing upright reach deeper,
    pallets overhanging the aisle less deep and scattered; the median would follow the notches when
    a row misses several uprights.
    """
    counts = np.bincount(depths, minlength=size + 2).astype(np.float64)
    near = counts + np.r_[counts[1:], 0.0] + np.r_[0.0, counts[:-1]]
    hits = np.flatnonzero(near >= share * depths.size)
    if not hits.size:
        return float(np.median(depths))
    first = int(hits[0])
    return float(first + int(np.argmax(counts[first : first + 3])))


def _racks(
    code: npt.NDArray[np.uint8],
    *,
    gap_px: int,
    depth_gap_px: int,
    min_length_px: float,
    min_depth_px: float,
    max_depth_px: float,
    min_fill: float,
) -> list[_Rack]:
    """Rack rows running along x in a turned code image (0 free, 1 occupied, 2 unknown).

    Kernel lengths are odd: an even one shifts OpenCV's closing by a pixel.
    """
    obstacle = (code != 0).astype(np.uint8)
    # a free pixel stays free only inside a free bay-by-depth rectangle: every such rectangle over a
    # bay holds an upright, an aisle or a cross aisle is wider
    body = cv2.morphologyEx(obstacle, cv2.MORPH_CLOSE, np.ones((depth_gap_px, gap_px), np.uint8))
    n, parts, stats, _ = cv2.connectedComponentsWithStats(body, connectivity=4)
    w, h, area = stats[:, cv2.CC_STAT_WIDTH], stats[:, cv2.CC_STAT_HEIGHT], stats[:, cv2.CC_STAT_AREA]
    keep = np.flatnonzero((w >= min_length_px) & (h >= min_depth_px) & (area >= 0.3 * w * h))
    keep = keep[keep > 0]
    out: list[_Rack] = []
    for k in keep:
        x, y, ww, hh = (int(v) for v in stats[k, :4])
        mask = parts[y : y + hh, x : x + ww] == k
        cols = mask.any(axis=0)
        top = np.argmax(mask, axis=0)[cols]
        bottom = hh - np.argmax(mask[::-1], axis=0)[cols]
        y0, y1 = _edge(top, hh), hh - _edge(hh - bottom, hh)
        if not min_depth_px <= y1 - y0 <= max_depth_px:
            continue
        # a rack fills its band in most columns (a missing upright leaves a notch, not a hole through)
        inside = mask[int(y0) : int(math.ceil(y1))].mean(axis=0)
        band = inside.sum() * (int(math.ceil(y1)) - int(y0))
        if cols.mean() >= 0.95 and (inside >= 0.3).mean() >= min_fill and mask.sum() <= 1.5 * band:
            out.append(_Rack(x, x + ww, y + y0, y + y1))
    return out


def _free_reach(free: npt.NDArray[np.bool_], start: int, step: int, span: tuple[int, int], cap: int) -> float:
    """Median free run (px) from row ``start`` in direction ``step`` over columns ``span``, at most ``cap``."""
    h = free.shape[0]
    stop = start + step * cap
    lo, hi = (start, min(stop, h - 1)) if step > 0 else (max(stop, 0), start)
    if hi < lo or span[1] <= span[0]:
        return 0.0
    window = free[lo : hi + 1, span[0] : span[1]]
    if step < 0:
        window = window[::-1]
    blocked = ~window
    first = np.where(blocked.any(axis=0), np.argmax(blocked, axis=0), window.shape[0])
    return float(np.median(first))


class _Grid(NamedTuple):
    cells: list[tuple[float, float, float, float, int]]  # x0, x1, y0, y1, label (turned frame)
    rows: list[tuple[float, float, float, float]]  # rack rows facing an aisle


def _grid(
    racks: list[_Rack], free: npt.NDArray[np.bool_], *, double_px: float, max_aisle_px: int, min_free: float
) -> _Grid:
    """Storage, aisle, cross-aisle and junction rectangles of racks standing in rows and sections."""
    bands = _merge([(r.y0, r.y1) for r in racks], 0.0)
    sections = _merge([(float(r.x0), float(r.x1)) for r in racks], 0.0)
    n_r, n_s = len(bands), len(sections)
    have = np.zeros((n_r, n_s), dtype=bool)
    for r in racks:
        i = next(k for k, b in enumerate(bands) if b.lo - 1 <= (r.y0 + r.y1) / 2 <= b.hi + 1)
        for j, s in enumerate(sections):
            if min(r.x1, s.hi) - max(r.x0, s.lo) > 0.5 * (s.hi - s.lo):
                have[i, j] = True
    # aisle bands: below the first row, between rows, above the last; gaps likewise along x
    h, w = free.shape

    def reach_y(i: int, up: bool) -> float:
        spans = [(int(s.lo), int(s.hi)) for j, s in enumerate(sections) if have[i, j]]
        vals = [
            _free_reach(free, int(round(bands[i].hi)) + 1 if up else int(round(bands[i].lo)) - 1, 1 if up else -1, sp,
                        max_aisle_px)
            for sp in spans
        ]
        return float(np.median(vals)) if vals else 0.0

    def reach_x(j: int, right: bool) -> float:
        spans = [(int(b.lo), int(b.hi)) for i, b in enumerate(bands) if have[i, j]]
        vals = [
            _free_reach(free.T, int(round(sections[j].hi)) + 1 if right else int(round(sections[j].lo)) - 1,
                        1 if right else -1, sp, max_aisle_px)
            for sp in spans
        ]
        return float(np.median(vals)) if vals else 0.0

    ys = [(bands[0].lo - reach_y(0, False), bands[0].lo)]
    ys += [(bands[i].hi, bands[i + 1].lo) for i in range(n_r - 1)]
    ys.append((bands[-1].hi, bands[-1].hi + reach_y(n_r - 1, True)))
    xs = [(sections[0].lo - reach_x(0, False), sections[0].lo)]
    xs += [(sections[j].hi, sections[j + 1].lo) for j in range(n_s - 1)]
    xs.append((sections[-1].hi, sections[-1].hi + reach_x(n_s - 1, True)))

    def open_rect(x0: float, x1: float, y0: float, y1: float) -> bool:
        a, b, c, d = max(int(x0), 0), min(int(math.ceil(x1)), w), max(int(y0), 0), min(int(math.ceil(y1)), h)
        if b - a < 2 or d - c < 2 or x1 - x0 > max_aisle_px + 2 and y1 - y0 > max_aisle_px + 2:
            return False
        return bool(free[c:d, a:b].mean() >= min_free)

    cells: list[tuple[float, float, float, float, int]] = []
    rows: list[tuple[float, float, float, float]] = []
    # aisle pieces (k = aisle band, j = section): racks on both sides, or one side at the perimeter
    aisle = np.zeros((n_r + 1, n_s), dtype=bool)
    for k in range(n_r + 1):
        for j in range(n_s):
            below = have[k - 1, j] if k > 0 else False
            above = have[k, j] if k < n_r else False
            edge = k in (0, n_r)
            if (below and above) or (edge and (below or above)):
                y0, y1 = ys[k]
                if y1 - y0 >= 2 and open_rect(sections[j].lo, sections[j].hi, y0, y1):
                    aisle[k, j] = True
                    cells.append((sections[j].lo, sections[j].hi, y0, y1, Label.CORRIDOR.value))
    cross = np.zeros((n_r, n_s + 1), dtype=bool)
    for i in range(n_r):
        for g in range(n_s + 1):
            left = have[i, g - 1] if g > 0 else False
            right = have[i, g] if g < n_s else False
            edge = g in (0, n_s)
            if (left and right) or (edge and (left or right)):
                x0, x1 = xs[g]
                if x1 - x0 >= 2 and open_rect(x0, x1, bands[i].lo, bands[i].hi):
                    cross[i, g] = True
                    cells.append((x0, x1, bands[i].lo, bands[i].hi, Label.CORRIDOR.value))
    for k in range(n_r + 1):
        for g in range(n_s + 1):
            arms = [
                aisle[k, g - 1] if g > 0 else False,
                aisle[k, g] if g < n_s else False,
                cross[k - 1, g] if k > 0 else False,
                cross[k, g] if k < n_r else False,
            ]
            if sum(arms) < 2:
                continue
            (x0, x1), (y0, y1) = xs[g], ys[k]
            if x1 - x0 >= 2 and y1 - y0 >= 2 and open_rect(x0, x1, y0, y1):
                cells.append((x0, x1, y0, y1, Label.JUNCTION.value if sum(arms) >= 3 else Label.CORRIDOR.value))
    for i, band in enumerate(bands):
        for j, s in enumerate(sections):
            if not have[i, j]:
                continue
            halves = [(band.lo, band.hi)]
            if band.hi - band.lo >= double_px:  # back to back: a row facing each aisle
                mid = (band.lo + band.hi) / 2
                halves = [(band.lo, mid), (mid, band.hi)]
            for y0, y1 in halves:
                cells.append((s.lo, s.hi, y0, y1, Label.STORAGE.value))
                rows.append((s.lo, s.hi, y0, y1))
    return _Grid(cells, rows)


def _turn(shape: tuple[int, int], angle_rad: float) -> tuple[npt.NDArray[np.float64], tuple[int, int]]:
    """Affine map (2, 3) turning direction ``angle_rad`` onto +x, and the turned canvas size (w, h)."""
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    rot = np.array([[c, s], [-s, c]])
    h, w = shape
    corners = np.array([[0, 0], [w, 0], [w, h], [0, h]], dtype=np.float64) @ rot.T
    lo, hi = corners.min(axis=0), corners.max(axis=0)
    matrix = np.hstack([rot, -lo[:, None]])
    return matrix, (int(math.ceil(hi[0] - lo[0])) + 1, int(math.ceil(hi[1] - lo[1])) + 1)


def find_racks(
    occupied: npt.NDArray[np.bool_],
    known: npt.NDArray[np.bool_],
    *,
    resolution_m: float,
    angles_rad: list[float],
    max_bay_gap_m: float = 2.95,
    max_depth_gap_m: float = 1.3,
    min_length_m: float = 6.0,
    min_depth_m: float = 0.6,
    max_depth_m: float = 3.0,
    double_m: float = 1.8,
    max_aisle_m: float = 6.0,
    min_fill: float = 0.7,
    min_free: float = 0.85,
) -> RackLayout:
    """Rack rows (any drawing: solid, uprights, pallet faces, beams) and the places between them.

    Parameters
    ----------
    occupied, known : (H, W) bool
        Occupied and known cells; free = known and not occupied (uncertain cells count as occupied).
    resolution_m : float
        Metres per cell.
    angles_rad : list of float
        Directions to look along (x = column, y = row); each is tried with its normal too.
    max_bay_gap_m, max_depth_gap_m : float
        Gaps closed along a row (a bay, not a cross aisle) and across it (a rack's depth or the
        flue, not an aisle).
    min_length_m, min_depth_m, max_depth_m, double_m, min_fill : float
        A rack row is at least ``min_length_m`` long, ``min_depth_m`` to ``max_depth_m`` deep
        (from ``double_m`` on: back to back, two rows), and in ``min_fill`` of its columns it fills
        at least 30 % of its depth (a missing upright leaves a notch).
    max_aisle_m, min_free : float
        Perimeter aisles and end cross aisles reach at most this far; an aisle, cross aisle or
        junction must be at least ``min_free`` free.

    Returns
    -------
    RackLayout
        Empty (no places) where no rack is found.
    """
    shape = occupied.shape
    code = np.where(known, np.where(occupied, _OCCUPIED, 0), _UNKNOWN).astype(np.uint8)
    families: list[float] = []
    for a in angles_rad:
        a = math.remainder(a, math.pi / 2)
        if all(abs(math.remainder(a - b, math.pi / 2)) > math.radians(2.0) for b in families):
            families.append(a)
    px = 1.0 / resolution_m
    cells = np.zeros(shape, np.int32)
    labels: list[int] = [0]
    rows: list[npt.NDArray[np.float64]] = []
    for angle in families:
        matrix, size = _turn(shape, angle)
        flags = cv2.INTER_NEAREST
        turned = cv2.warpAffine(code, matrix, size, flags=flags, borderMode=cv2.BORDER_CONSTANT, borderValue=_UNKNOWN)
        turned_cells = np.zeros((size[1], size[0]), np.int32)
        inverse = cv2.invertAffineTransform(matrix)
        for transpose in (False, True):
            image = turned.T if transpose else turned
            racks = _racks(
                np.ascontiguousarray(image),
                gap_px=2 * round(max_bay_gap_m * px / 2) + 1,
                depth_gap_px=2 * round(max_depth_gap_m * px / 2) + 1,
                min_length_px=min_length_m * px,
                min_depth_px=min_depth_m * px,
                max_depth_px=max_depth_m * px,
                min_fill=min_fill,
            )
            if not racks:
                continue
            grid = _grid(
                racks, image == 0, double_px=double_m * px, max_aisle_px=round(max_aisle_m * px), min_free=min_free
            )
            target = turned_cells.T if transpose else turned_cells
            for x0, x1, y0, y1, label in grid.cells:
                labels.append(label)
                target[int(round(y0)) : int(round(y1)), int(round(x0)) : int(round(x1))] = len(labels) - 1
            for x0, x1, y0, y1 in grid.rows:
                corners = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], dtype=np.float64)
                if transpose:
                    corners = corners[:, ::-1]
                rows.append(corners @ inverse[:, :2].T + inverse[:, 2])
        if turned_cells.any():
            back = cv2.warpAffine(
                turned_cells.astype(np.float32), matrix, (shape[1], shape[0]),
                flags=flags | cv2.WARP_INVERSE_MAP, borderValue=0,
            ).astype(np.int32)
            cells = np.where(cells == 0, back, cells)
    if len(labels) == 1:
        return _empty(shape)
    outline = np.zeros(shape, dtype=bool)
    outline[:, 1:] |= cells[:, 1:] != cells[:, :-1]
    outline[1:, :] |= cells[1:, :] != cells[:-1, :]
    return RackLayout(cells, np.array(labels, dtype=np.int64), outline, np.array(rows).reshape(-1, 4, 2))

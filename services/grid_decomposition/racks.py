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

import functools
import math
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import NamedTuple, TypeVar

import cv2
import numpy as np
import numpy.typing as npt
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components

from services.grid_decomposition.arrays import (
    Components,
    components,
    components_stats,
    label_boxes,
    label_counts,
    nonzero_rc,
    unique_inverse,
)
from shared.vocabulary import PlaceLabel

_UNKNOWN = 2
_OCCUPIED = 1
_UNCERTAIN = 3  # an obstacle not surely occupied
# what components_stats returns: count, labels, stats
_Labelled = tuple[int, npt.NDArray[np.int32], npt.NDArray[np.int32]]
_Byte = TypeVar("_Byte", np.bool_, np.uint8)


class RackLayout(NamedTuple):
    """Racks found in an occupancy grid and the grid of places between them.

    Attributes
    ----------
    cells : (H, W) int32
        Place id (1..N) of every pixel of a rack row, aisle piece, cross-aisle piece or junction
        (free and obstacle pixels alike), 0 elsewhere.
    cell_labels : (N + 1,) int64
        :class:`PlaceLabel` value of each place (index 0 unused).
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
        out: npt.NDArray[np.bool_] = self.cell_labels[self.cells] == PlaceLabel.STORAGE.value
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


def _inner_obstacles(code: npt.NDArray[np.uint8]) -> npt.NDArray[np.uint8]:
    """Obstacles of a code image (0 free, 1 occupied, 2 unknown, 3 uncertain) but unknown space reaching its border.

    Unknown space reaching the image border is the unexplored outside, not a rack: closed with the
    obstacles it would join every rack row ending within a bay of it (a map explored only up to the
    racks' ends) into one body with it, too large to be a rack. The same of the transposed image is
    this transposed. The unknown space reaching the border is one 4-connected fill from a frame of
    unknown cells around the image, not a labelling of all of it.
    """
    framed = cv2.copyMakeBorder((code == _UNKNOWN).astype(np.uint8), 1, 1, 1, 1, cv2.BORDER_CONSTANT, value=1)
    cv2.floodFill(framed, None, (0, 0), 2, flags=4)
    obstacle: npt.NDArray[np.uint8] = ((code != 0) & (framed[1:-1, 1:-1] != 2)).astype(np.uint8)
    return obstacle


def _reopen_cross_aisles(
    body: npt.NDArray[np.uint8], labelled: _Labelled, solid: npt.NDArray[np.bool_], *, gap_px: int,
    min_length_px: float, off_pitch: float,
) -> npt.NDArray[np.uint8]:
    """``body`` (obstacles closed along x) with its gaps that are off the hall's bay pitch opened again.

    A gap of a body is a run of its columns holding no ``solid`` cell of it (surely occupied: uprights and
    pallets; an uncertain trace a person left across a cross aisle is not). One the closing bridged (half
    ``gap_px`` to ``gap_px`` long) is an empty bay between uprights, or a cross aisle about one bay wide (the
    simulator's halls: 2.7 m bays, 3.0 m cross aisles). Bays share a pitch: a bridged gap more than ``off_pitch``
    times the median bridged gap of the image's bodies ``min_length_px`` long or longer is a cross aisle, and the
    body is cut there through its whole depth. Where every bay is loaded (only cross aisles bridged) nothing is
    cut. ``labelled`` is ``components_stats(body, 4)``; ``body`` itself is returned
    when nothing is cut.
    """
    n, parts, stats = labelled
    chosen = np.flatnonzero(stats[:, cv2.CC_STAT_WIDTH] >= min_length_px)
    chosen = chosen[chosen > 0]
    if chosen.size == 0:
        return body
    long = np.zeros(n, dtype=np.int64)
    long[chosen] = np.arange(1, chosen.size + 1)
    width = body.shape[1]
    hit = np.zeros((chosen.size + 1, width), dtype=bool)  # (body, column): a solid cell of the body there
    rows, cols = nonzero_rc(solid)
    hit[long[parts[rows, cols]], cols] = True
    at = np.flatnonzero(hit[1:])
    which, col = at // width, at % width
    gap = np.diff(col) - 1
    bridged = (which[1:] == which[:-1]) & (gap >= (gap_px + 1) // 2) & (gap <= gap_px)
    if not bridged.any():
        return body
    cuts = np.flatnonzero(bridged & (gap > off_pitch * float(np.median(gap[bridged]))))
    if cuts.size == 0:  # every bridged gap on the pitch: bays
        return body
    out = body.copy()
    for i in cuts:
        k = int(chosen[which[i]])
        y, h = int(stats[k, cv2.CC_STAT_TOP]), int(stats[k, cv2.CC_STAT_HEIGHT])
        span = out[y : y + h, col[i] + 1 : col[i + 1]]
        span[parts[y : y + h, col[i] + 1 : col[i + 1]] == k] = 0
    return out


def _racks(
    obstacle: npt.NDArray[np.uint8],
    solid: npt.NDArray[np.bool_],
    *,
    gap_px: int,
    depth_gap_px: int,
    min_length_px: float,
    min_depth_px: float,
    max_depth_px: float,
    min_fill: float,
    off_pitch: float,
) -> list[_Rack]:
    """Rack rows running along x in a turned obstacle image (:func:`_inner_obstacles`); ``solid`` its cells
    surely occupied (:func:`_reopen_cross_aisles`).

    Kernel lengths are odd: an even one shifts OpenCV's closing by a pixel.
    """
    # a free pixel stays free only inside a free bay-by-depth rectangle: every such rectangle over a
    # bay holds an upright, an aisle or a cross aisle is wider
    closed = np.asarray(cv2.morphologyEx(obstacle, cv2.MORPH_CLOSE, np.ones((depth_gap_px, gap_px), np.uint8)),
                        dtype=np.uint8)
    labelled = components_stats(closed, 4)
    body = _reopen_cross_aisles(closed, labelled, solid, gap_px=gap_px, min_length_px=min_length_px,
                                off_pitch=off_pitch)
    _, parts, stats = labelled if body is closed else components_stats(body, 4)
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
        inside = mask[int(y0) : math.ceil(y1)].mean(axis=0)
        band = inside.sum() * (math.ceil(y1) - int(y0))
        if cols.mean() >= 0.95 and (inside >= 0.3).mean() >= min_fill and mask.sum() <= 1.5 * band:
            rows = mask[int(y0) : math.ceil(y1)]
            rows = rows[rows.any(axis=1)]
            x0 = _edge(np.argmax(rows, axis=1), ww)
            x1 = ww - _edge(np.argmax(rows[:, ::-1], axis=1), ww)
            out.append(_Rack(x + int(x0), x + int(x1), y + y0, y + y1))
    return out


def _free_reach(free: npt.NDArray[np.bool_], start: int, step: int, span: tuple[int, int], cap: int) -> float:
    """Upper-quartile free run (px) from row ``start`` in direction ``step`` over columns ``span``, at most ``cap``."""
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
    return float(np.quantile(first, 0.75))


def _dots(
    free: npt.NDArray[np.bool_], row: int, step: int, spans: list[_Band], use: npt.NDArray[np.bool_], max_px: int
) -> float:
    """Half the thickness of the obstacles on ``row`` when they are sparse dots (uprights), else 0.

    ``row`` is the first obstacle row of an edge, ``step`` points into the rack. Uprights cover
    under 30 % of the edge; a solid rack, a beam or a row of pallet faces covers more.
    """
    h = free.shape[0]
    if not 0 <= row < h:
        return 0.0
    parts = [np.arange(int(b.lo), int(b.hi), dtype=np.int64) for b, ok in zip(spans, use, strict=True) if ok]
    cols = np.concatenate(parts) if parts else np.zeros(0, dtype=np.int64)
    if cols.size == 0:
        return 0.0
    hit = cols[~free[row, cols]]
    nxt = row + step
    covered = ~free[row, cols] | (~free[nxt, cols] if 0 <= nxt < h else False)
    if hit.size == 0 or covered.mean() >= 0.3:  # a turned edge steps between two rows
        return 0.0
    depth = np.zeros(hit.size)
    solid = np.ones(hit.size, dtype=bool)
    for k in range(max_px + 1):
        r = row + step * k
        if not 0 <= r < h:
            break
        solid &= ~free[r, hit]
        depth += solid
    thin = depth[depth <= max_px]  # an upright, not a pallet face with unknown space behind it
    return float(np.median(thin)) / 2.0 if thin.size else 0.0


def _blocks(racks: list[_Rack], *, max_aisle_px: float) -> list[list[_Rack]]:
    """Racks grouped into blocks of at least two: neighbours across an aisle or a cross aisle (``max_aisle_px``)."""
    n = len(racks)
    x0 = np.array([r.x0 for r in racks], dtype=np.float64)
    x1 = np.array([r.x1 for r in racks], dtype=np.float64)
    y0 = np.array([r.y0 for r in racks])
    y1 = np.array([r.y1 for r in racks])
    gap_x = np.maximum(x0[:, None], x0[None, :]) - np.minimum(x1[:, None], x1[None, :])
    gap_y = np.maximum(y0[:, None], y0[None, :]) - np.minimum(y1[:, None], y1[None, :])
    overlap_x = -gap_x > 0.5 * np.minimum((x1 - x0)[:, None], (x1 - x0)[None, :])
    overlap_y = -gap_y > 0.5 * np.minimum((y1 - y0)[:, None], (y1 - y0)[None, :])
    linked = (overlap_x & (gap_y <= max_aisle_px)) | (overlap_y & (gap_x <= max_aisle_px))
    _, group = connected_components(csr_matrix(linked), directed=False)
    blocks = [[racks[k] for k in np.flatnonzero(group == g)] for g in range(int(group.max()) + 1 if n else 0)]
    # racks stand in rows: a lone long obstacle (a block of pallets on the floor, a wall) is none
    return [b for b in blocks if len(b) >= 2]


class _Grid(NamedTuple):
    """A rack grid in turned pixel-centre coordinates: cell (k, g) spans ys[k]..ys[k+1] x xs[g]..xs[g+1]."""

    xs: npt.NDArray[np.float64]  # (2 S + 2,) the end cross aisles' outer edges, then every section's ends
    ys: npt.NDArray[np.float64]  # (2 R + 2 + D,) likewise for rows, a back-to-back row split in two
    labels: npt.NDArray[np.int64]  # (len(ys) - 1, len(xs) - 1) PlaceLabel value, 0 = no place
    rack: npt.NDArray[np.bool_]  # same shape: a rack row facing an aisle
    twin: npt.NDArray[np.bool_]  # (len(ys) - 1,) the second half of a back-to-back row


def _grid(
    racks: list[_Rack],
    free: npt.NDArray[np.bool_],
    refine: _Refine,
    *,
    double_px: float,
    max_aisle_px: int,
    min_free: float,
    dot_px: int,
) -> _Grid:
    """Storage, aisle, cross-aisle and junction places of racks standing in rows and sections.

    Uprights (obstacles at most ``dot_px`` thick along the normal) put an edge on their centres.
    """
    bands = _merge([(r.y0, r.y1) for r in racks], 0.0)
    sections = _merge([(float(r.x0), float(r.x1)) for r in racks], 0.0)
    n_r, n_s = len(bands), len(sections)
    have = np.zeros((n_r, n_s), dtype=bool)
    for r in racks:
        i = next(k for k, b in enumerate(bands) if b.lo - 1 <= (r.y0 + r.y1) / 2 <= b.hi + 1)
        for j, sec in enumerate(sections):
            if min(r.x1, sec.hi) - max(r.x0, sec.lo) > 0.5 * (sec.hi - sec.lo):
                have[i, j] = True
    h, w = free.shape

    def density(i: int, j: int) -> float:
        a, b = int(sections[j].lo), math.ceil(sections[j].hi)
        c, d = max(int(bands[i].lo), 0), min(math.ceil(bands[i].hi), h)
        return float((~free[c:d, a:b]).mean()) if b > a and d > c else 0.0

    # a place of the grid whose rack was missed (many uprights missing) holds obstacles as densely
    typical = float(np.median([density(i, j) for i, j in zip(*np.nonzero(have), strict=True)]))
    for i, j in zip(*np.nonzero(~have), strict=True):
        have[i, j] = density(i, j) >= 0.4 * typical

    def reach(i: int, up: bool, transpose: bool) -> float:
        lines, across = (sections, bands) if transpose else (bands, sections)
        spans = [(int(c.lo), int(c.hi)) for j, c in enumerate(across) if (have[j, i] if transpose else have[i, j])]
        start = round(lines[i].hi) if up else round(lines[i].lo) - 1
        image = free.T if transpose else free
        vals = [_free_reach(image, start, 1 if up else -1, sp, max_aisle_px) for sp in spans]
        return float(np.quantile(vals, 0.75)) if vals else 0.0

    # edges in pixel-centre coordinates: a band of rows lo..hi - 1 spans lo - 0.5 .. hi - 0.5; an
    # edge drawn only by uprights lies on their centres
    y_in = [
        refine.edge(False, b.lo - 0.5, sections, have[i], low=True)
        + _dots(free, int(b.lo), 1, sections, have[i], dot_px)
        for i, b in enumerate(bands)
    ]
    y_out = [
        refine.edge(False, b.hi - 0.5, sections, have[i], low=False)
        - _dots(free, round(b.hi) - 1, -1, sections, have[i], dot_px)
        for i, b in enumerate(bands)
    ]
    x_in = [
        refine.edge(True, sec.lo - 0.5, bands, have[:, j], low=True)
        + _dots(free.T, int(sec.lo), 1, bands, have[:, j], dot_px)
        for j, sec in enumerate(sections)
    ]
    x_out = [
        refine.edge(True, sec.hi - 0.5, bands, have[:, j], low=False)
        - _dots(free.T, round(sec.hi) - 1, -1, bands, have[:, j], dot_px)
        for j, sec in enumerate(sections)
    ]
    ys = [y_in[0] - reach(0, False, False) - 2.0]
    for i in range(n_r):
        ys.append(y_in[i])
        if bands[i].hi - bands[i].lo >= double_px:  # back to back: a row facing each aisle
            ys.append((y_in[i] + y_out[i]) / 2)
        ys.append(y_out[i])
    ys.append(y_out[-1] + reach(n_r - 1, True, False) + 2.0)
    xs = [x_in[0] - reach(0, False, True) - 2.0]
    for j in range(n_s):
        xs += [x_in[j], x_out[j]]
    xs.append(x_out[-1] + reach(n_s - 1, True, True) + 2.0)
    # which y interval is which: ("aisle", k) for k = 0..n_r, ("rack", i)
    y_kind: list[tuple[str, int]] = [("aisle", 0)]
    for i in range(n_r):
        y_kind.append(("rack", i))
        if bands[i].hi - bands[i].lo >= double_px:
            y_kind.append(("rack", i))
        y_kind.append(("aisle", i + 1))
    x_kind: list[tuple[str, int]] = [("gap", 0)]
    for j in range(n_s):
        x_kind += [("section", j), ("gap", j + 1)]

    def open_rect(x0: float, x1: float, y0: float, y1: float) -> bool:
        a, b = max(int(x0 + 2.5), 0), min(int(x1 - 1.5), w)
        c, d = max(int(y0 + 2.5), 0), min(int(y1 - 1.5), h)
        if b - a < 2 or d - c < 2:
            return False
        return bool(free[c:d, a:b].mean() >= min_free)

    aisle = np.zeros((n_r + 1, n_s), dtype=bool)
    cross = np.zeros((n_r, n_s + 1), dtype=bool)
    for ky, (yk, a_i) in enumerate(y_kind):
        for kx, (xk, b_j) in enumerate(x_kind):
            box = (xs[kx], xs[kx + 1], ys[ky], ys[ky + 1])
            if yk == "aisle" and xk == "section":
                below = have[a_i - 1, b_j] if a_i > 0 else False
                above = have[a_i, b_j] if a_i < n_r else False
                edge = a_i in (0, n_r)
                aisle[a_i, b_j] = ((below and above) or (edge and (below or above))) and open_rect(*box)
            elif yk == "rack" and xk == "gap":
                left = have[a_i, b_j - 1] if b_j > 0 else False
                right = have[a_i, b_j] if b_j < n_s else False
                edge = b_j in (0, n_s)
                cross[a_i, b_j] = ((left and right) or (edge and (left or right))) and open_rect(*box)
    labels = np.zeros((len(y_kind), len(x_kind)), dtype=np.int64)
    rack = np.zeros(labels.shape, dtype=bool)
    for ky, (yk, a_i) in enumerate(y_kind):
        for kx, (xk, b_j) in enumerate(x_kind):
            if yk == "rack" and xk == "section":
                rack[ky, kx] = have[a_i, b_j]
                labels[ky, kx] = PlaceLabel.STORAGE.value if have[a_i, b_j] else 0
            elif yk == "aisle" and xk == "section":
                labels[ky, kx] = PlaceLabel.CORRIDOR.value if aisle[a_i, b_j] else 0
            elif yk == "rack" and xk == "gap":
                labels[ky, kx] = PlaceLabel.CORRIDOR.value if cross[a_i, b_j] else 0
            else:
                arms = [
                    aisle[a_i, b_j - 1] if b_j > 0 else False,
                    aisle[a_i, b_j] if b_j < n_s else False,
                    cross[a_i - 1, b_j] if a_i > 0 else False,
                    cross[a_i, b_j] if a_i < n_r else False,
                ]
                box = (xs[kx], xs[kx + 1], ys[ky], ys[ky + 1])
                if sum(arms) >= 2 and open_rect(*box):
                    labels[ky, kx] = PlaceLabel.JUNCTION.value if sum(arms) >= 3 else PlaceLabel.CORRIDOR.value
    twin = np.array([k > 0 and y_kind[k] == y_kind[k - 1] for k in range(len(y_kind))])
    return _Grid(np.array(xs), np.array(ys), labels, rack, twin)


class _Refine:
    """Sub-pixel rack edges from the obstacle pixels of the original map (turned exactly, not resampled).

    The turned image is resampled to the nearest pixel, so an edge found there is up to a pixel off
    along a turned wall; the obstacle pixels bordering free space, turned exactly, give the edge
    between the last free and the first obstacle pixel centre.
    """

    def __init__(self, border_uv: npt.NDArray[np.float64]) -> None:
        self.uv = border_uv  # (N, 2) turned coordinates of obstacle pixels next to free space

    def transposed(self) -> _Refine:
        return _Refine(self.uv[:, ::-1])

    def edge(self, along_x: bool, guess: float, spans: list[_Band], use: npt.NDArray[np.bool_], *, low: bool) -> float:
        """The edge near ``guess`` (pixel-centre coordinate across ``spans``): just outside the obstacles there."""
        coord = self.uv[:, 0] if along_x else self.uv[:, 1]
        other = self.uv[:, 1] if along_x else self.uv[:, 0]
        near = np.flatnonzero(np.abs(coord - guess) <= 1.0)  # the spans are tested at these few points only
        across = other[near]
        inside = np.zeros(near.shape, dtype=bool)
        for span, ok in zip(spans, use, strict=True):
            if ok:
                inside |= (across >= span.lo) & (across <= span.hi - 1)
        values = coord[near[inside]]
        if values.size < 4:
            return guess
        # a straight edge turned spreads its first obstacle centres evenly over one pixel: the
        # 30th percentile less 0.3 px finds its start and shrugs off a stray or overhanging pixel
        return float(np.quantile(values, 0.3) - 0.3) if low else float(np.quantile(values, 0.7) + 0.3)


def _turn(shape: tuple[int, int], angle_rad: float) -> tuple[npt.NDArray[np.float64], tuple[int, int]]:
    """Affine map (2, 3) turning direction ``angle_rad`` onto +x, and the turned canvas size (w, h)."""
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    rot = np.array([[c, s], [-s, c]])
    h, w = shape
    corners = np.array([[0, 0], [w, 0], [w, h], [0, h]], dtype=np.float64) @ rot.T
    lo, hi = corners.min(axis=0), corners.max(axis=0)
    matrix = np.hstack([rot, -lo[:, None]])
    return matrix, (math.ceil(hi[0] - lo[0]) + 1, math.ceil(hi[1] - lo[1]) + 1)


def _below(edges: npt.NDArray[np.float64], along: npt.NDArray[np.float64], base: npt.NDArray[np.float64]) -> (
    npt.NDArray[np.int64] | None
):
    """(R, E) number of columns ``j`` with ``along[j] + base[r] < edges[i]``, for ``along`` rising.

    Rounding keeps the order of a sum, so these columns are the first ones of the row: a binary
    search of ``edges - base`` in ``along`` lands on or next to the count, and comparing the exact
    sums on either side settles it. ``None`` when that does not settle within a few steps
    (``along`` nearly flat).
    """
    target = edges[None, :] - base[:, None]
    count = np.searchsorted(along, target.ravel(), side="left").reshape(target.shape)
    last = along.size
    for _ in range(8):
        lower = (count > 0) & (along[np.maximum(count - 1, 0)] + base[:, None] >= edges[None, :])
        higher = (count < last) & (along[np.minimum(count, last - 1)] + base[:, None] < edges[None, :])
        if not (lower.any() or higher.any()):
            return count
        count = count - lower + higher
    return None


def _interval_image(
    xs: npt.NDArray[np.float64],
    ys: npt.NDArray[np.float64],
    u: tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]],
    v: tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]],
    ids: npt.NDArray[np.int32],
) -> npt.NDArray[np.int32]:
    """``ids[kv, ku]`` per pixel, ``ku = np.searchsorted(xs, u, side="right")`` and ``kv`` likewise.

    ``u = (along, base)`` gives ``u[r, j] = along[j] + base[r]`` (an affine function of the
    column, so it rises or falls along every row; ``v`` the same). Along a row ``ku`` and ``kv``
    step at a few columns: the row is a few runs of one id, found from a search per row and edge
    instead of one per pixel.
    """
    (along_u, base_u), (along_v, base_v) = u, v
    h, w = base_u.size, along_u.size
    steps: list[npt.NDArray[np.int64]] = []
    rises: list[bool] = []
    for edges, along, base in ((xs, along_u, base_u), (ys, along_v, base_v)):
        rising = bool(along[-1] >= along[0])
        rises.append(rising)
        below = None
        if np.all(np.isfinite(edges)) and not np.any(edges[1:] < edges[:-1]):
            below = _below(edges, along if rising else along[::-1], base)
        if below is None:  # a search per pixel
            ku = np.searchsorted(xs, along_u[None, :] + base_u[:, None], side="right")
            kv = np.searchsorted(ys, along_v[None, :] + base_v[:, None], side="right")
            out: npt.NDArray[np.int32] = ids[kv, ku]
            return out
        steps.append(below if rising else w - below)
    # runs start at column 0 and at every step; a value is past edge i from its step on (rising)
    # or before it (falling)
    starts = np.sort(np.concatenate([np.zeros((h, 1), np.int64), *steps], axis=1), axis=1)
    length = np.diff(np.concatenate([starts, np.full((h, 1), w)], axis=1), axis=1)
    k = []
    for step, rising in zip(steps, rises, strict=True):
        past = starts[:, :, None] >= step[:, None, :] if rising else starts[:, :, None] < step[:, None, :]
        k.append(past.sum(axis=2))
    run_ids = ids[k[1], k[0]]
    return np.repeat(run_ids.ravel(), length.ravel()).reshape(h, w)


def _rasterise(
    grid: _Grid, matrix: npt.NDArray[np.float64], transpose: bool, shape: tuple[int, int], first_id: int
) -> tuple[npt.NDArray[np.int32], npt.NDArray[np.int64], list[npt.NDArray[np.float64]]]:
    """Place ids (from ``first_id``) of the original pixels, their labels, and the rack rows' corners."""
    inverse = cv2.invertAffineTransform(matrix)
    xs, ys = (grid.ys, grid.xs) if transpose else (grid.xs, grid.ys)
    corners = np.array([[xs[0], ys[0]], [xs[-1], ys[0]], [xs[-1], ys[-1]], [xs[0], ys[-1]]])
    back = corners @ inverse[:, :2].T + inverse[:, 2]
    h, w = shape
    c0, r0 = np.maximum(np.floor(back.min(axis=0)).astype(int), 0)
    c1, r1 = np.minimum(np.ceil(back.max(axis=0)).astype(int) + 1, [w, h])
    out = np.zeros(shape, dtype=np.int32)
    rows_px: list[npt.NDArray[np.float64]] = []
    ids = np.zeros(grid.labels.shape, dtype=np.int64)
    ids[grid.labels > 0] = first_id + np.arange(int((grid.labels > 0).sum()))
    # a cross-aisle piece beside a back-to-back row is one place, not one per rack
    for ky in np.flatnonzero(grid.twin):
        same = (grid.labels[ky] > 0) & ~grid.rack[ky] & (grid.labels[ky - 1] == grid.labels[ky])
        ids[ky, same] = ids[ky - 1, same]
    used = np.unique(ids[ids > 0])
    renumber = np.zeros(int(ids.max()) + 1, dtype=np.int64)
    renumber[used] = first_id + np.arange(used.size)
    ids = renumber[ids]
    if c1 <= c0 or r1 <= r0:
        return out, np.zeros(0, np.int64), rows_px
    cols = np.arange(c0, c1, dtype=np.float64)
    rows = np.arange(r0, r1, dtype=np.float64)
    # turned coordinates: u[r, j] = along[j] + base[r]
    u = (matrix[0, 0] * cols, matrix[0, 1] * rows + matrix[0, 2])
    v = (matrix[1, 0] * cols, matrix[1, 1] * rows + matrix[1, 2])
    if transpose:
        u, v = v, u
    # interval k of each pixel along both axes; 0 and the last are outside the grid
    n_y, n_x = grid.labels.shape
    padded = np.zeros((n_y + 2, n_x + 2), dtype=np.int32)
    padded[1:-1, 1:-1] = ids
    out[r0:r1, c0:c1] = _interval_image(grid.xs, grid.ys, u, v, padded)
    for ky, kx in zip(*np.nonzero(grid.rack), strict=True):
        box = np.array(
            [[grid.xs[kx], grid.ys[ky]], [grid.xs[kx + 1], grid.ys[ky]], [grid.xs[kx + 1], grid.ys[ky + 1]],
             [grid.xs[kx], grid.ys[ky + 1]]]
        )
        if transpose:
            box = box[:, ::-1]
        rows_px.append(np.asarray(box @ inverse[:, :2].T + inverse[:, 2], dtype=np.float64))
    place_labels = np.zeros(used.size, dtype=np.int64)
    place_labels[ids[ids > 0] - first_id] = grid.labels[ids > 0]
    return out, place_labels, rows_px


def _transposed(image: npt.NDArray[_Byte]) -> npt.NDArray[_Byte]:
    """``np.ascontiguousarray(image.T)`` of a bool or uint8 image: OpenCV's transpose of its bytes, several times
    faster on an image than numpy's strided copy."""
    out: npt.NDArray[_Byte] = np.asarray(cv2.transpose(image.view(np.uint8)), dtype=np.uint8).view(image.dtype)
    return out


def _search_transposed(
    search: Callable[[npt.NDArray[np.uint8], npt.NDArray[np.bool_]], list[_Rack]],
    obstacle: npt.NDArray[np.uint8],
    solid: npt.NDArray[np.bool_],
) -> list[_Rack]:
    """``search`` across: on the transposed images (transposed on the thread that searches them)."""
    return search(_transposed(obstacle), _transposed(solid))


def find_racks(
    occupied: npt.NDArray[np.bool_],
    known: npt.NDArray[np.bool_],
    *,
    resolution_m: float,
    angles_rad: list[float],
    domain: npt.NDArray[np.bool_] | None = None,
    max_bay_gap_m: float = 2.95,
    max_depth_gap_m: float = 1.3,
    min_length_m: float = 6.0,
    min_depth_m: float = 0.6,
    max_depth_m: float = 3.0,
    double_m: float = 1.8,
    max_aisle_m: float = 6.0,
    min_fill: float = 0.7,
    min_free: float = 0.85,
    max_upright_m: float = 0.25,
    off_pitch: float = 1.08,
    solid: npt.NDArray[np.bool_] | None = None,
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
    domain : (H, W) bool, optional
        Look only here (a texture region with its own directions); outside counts as unknown.
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
    max_upright_m : float
        An edge drawn by obstacles at most this thick, covering under 30 % of it, is a row of
        uprights: the rack's edge runs through their centres.
    off_pitch : float
        A gap along a row that the closing bridged and that is this many times the median bridged gap (the
        bays' pitch) or more is a cross aisle about one bay wide: the row is cut there.
    solid : (H, W) bool, optional
        Cells surely occupied (default: every occupied cell): only these bound a gap along a row (a person's
        faint trace across a cross aisle does not).

    Returns
    -------
    RackLayout
        Empty (no places) where no rack is found.
    """
    shape = occupied.shape
    sure = np.where(occupied if solid is None else solid, np.uint8(_OCCUPIED), np.uint8(_UNCERTAIN))
    code = np.where(known, np.where(occupied, sure, np.uint8(0)), np.uint8(_UNKNOWN))
    if domain is not None:
        code[~domain] = _UNKNOWN
    border_rc: npt.NDArray[np.float64] | None = None  # the free space's border, once a rack row is found
    families: list[float] = []
    for angle in angles_rad:
        a = math.remainder(angle, math.pi / 2)
        if all(abs(math.remainder(a - b, math.pi / 2)) > math.radians(2.0) for b in families):
            families.append(a)
    px = 1.0 / resolution_m
    cells = np.zeros(shape, np.int32)
    labels: list[npt.NDArray[np.int64]] = [np.zeros(1, np.int64)]
    rows: list[npt.NDArray[np.float64]] = []
    n_ids = 1
    for angle in families:
        matrix, size = _turn(shape, angle)
        turned = np.asarray(
            cv2.warpAffine(
                code, matrix, size, flags=cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT, borderValue=_UNKNOWN
            ),
            dtype=np.uint8,
        )
        obstacle = _inner_obstacles(turned)
        solid_turned = turned == _OCCUPIED
        search = functools.partial(
            _racks,
            gap_px=2 * round(max_bay_gap_m * px / 2) + 1,
            depth_gap_px=2 * round(max_depth_gap_m * px / 2) + 1,
            min_length_px=min_length_m * px,
            min_depth_px=min_depth_m * px,
            max_depth_px=max_depth_m * px,
            min_fill=min_fill,
            off_pitch=off_pitch,
        )
        with ThreadPoolExecutor(max_workers=1, thread_name_prefix="racks") as beside:  # the second core
            across = beside.submit(_search_transposed, search, obstacle, solid_turned)
            along = search(obstacle, solid_turned)
            found = ((False, along), (True, across.result()))
        if along or found[1][1]:
            if border_rc is None:
                border = (code != 0) & (cv2.dilate((code == 0).astype(np.uint8), np.ones((3, 3), np.uint8)) > 0)
                border_rc = np.argwhere(border).astype(np.float64)
            refine = _Refine(border_rc[:, ::-1] @ matrix[:, :2].T + matrix[:, 2])
        for transpose, racks in found:
            free = turned == 0  # once for all blocks
            if transpose:
                free = _transposed(free)
            for block in _blocks(racks, max_aisle_px=max_aisle_m * px):
                grid = _grid(
                    block,
                    free,
                    refine.transposed() if transpose else refine,
                    double_px=double_m * px,
                    max_aisle_px=round(max_aisle_m * px),
                    min_free=min_free,
                    dot_px=max(1, round(max_upright_m * px)),
                )
                placed, placed_labels, placed_rows = _rasterise(grid, matrix, transpose, shape, n_ids)
                cells = placed if n_ids == 1 else np.where(cells == 0, placed, cells)  # no place yet: all 0 so far
                labels.append(placed_labels)
                rows += placed_rows
                n_ids += placed_labels.size
    if domain is not None:
        cells[~domain] = 0
    if n_ids == 1:
        return _empty(shape)
    outline = np.zeros(shape, dtype=bool)
    outline[:, 1:] |= cells[:, 1:] != cells[:, :-1]
    outline[1:, :] |= cells[1:, :] != cells[:-1, :]
    return RackLayout(cells, np.concatenate(labels), outline, np.array(rows).reshape(-1, 4, 2))


def structure_angles(
    occupied: npt.NDArray[np.bool_],
    *,
    resolution_m: float,
    min_length_m: float = 6.0,
    share: float = 0.2,
    labelled: Components | None = None,
) -> list[float]:
    """Directions (radians, x = column, y = row) of long obstacle components: solid racks and walls.

    Each component at least ``min_length_m`` long votes for the direction of its minimum-area
    rectangle's long side with that length (mod 90 degrees); directions with at
    least ``share`` of the top vote are returned, each the weighted mean of its cluster (within 2
    degrees). Rasterised edges at a shallow angle can mislead gradient histograms; the rectangle of
    a 20 m rack cannot. ``labelled`` is ``components(occupied)``, when already labelled.
    """
    labelled = components(occupied) if labelled is None else labelled
    parts, stats = labelled.labels, labelled.stats
    extent = np.maximum(stats[:, cv2.CC_STAT_WIDTH], stats[:, cv2.CC_STAT_HEIGHT])
    long = np.flatnonzero(extent >= min_length_m / resolution_m)
    found: list[tuple[float, float]] = []  # (angle mod 90 degrees in radians, length)
    for k in long[long > 0]:
        x, y, w, h = stats[k, :4]
        rows, cols = nonzero_rc(parts[y : y + h, x : x + w] == k)
        (_, _), (rw, rh), angle = cv2.minAreaRect(np.column_stack([cols + x, rows + y]).astype(np.float32))
        theta = math.radians(angle) + (0.0 if rw >= rh else math.pi / 2)
        found.append((theta % (math.pi / 2), max(rw, rh)))
    # clusters within 2 degrees (mod 90), each the length-weighted mean of its members
    clusters: list[list[tuple[float, float]]] = []
    for theta, length in sorted(found, key=lambda t: -t[1]):
        for c in clusters:
            if abs(math.remainder(theta - c[0][0], math.pi / 2)) <= math.radians(2.0):
                c.append((c[0][0] + math.remainder(theta - c[0][0], math.pi / 2), length))
                break
        else:
            clusters.append([(theta, length)])
    if not clusters:
        return []
    weight = [sum(w for _, w in c) for c in clusters]
    return [
        sum(a * w for a, w in c) / wc for c, wc in zip(clusters, weight, strict=True) if wc >= share * max(weight)
    ]


def find_racks_by_region(
    occupied: npt.NDArray[np.bool_],
    known: npt.NDArray[np.bool_],
    regions: list[tuple[npt.NDArray[np.bool_] | None, list[float]]],
    *,
    resolution_m: float,
    solid: npt.NDArray[np.bool_] | None = None,
    labelled: Components | None = None,
) -> RackLayout:
    """:func:`find_racks` in each texture region (mask, its line directions), regions of one direction as one.

    A region's directions are its lines' and those of its long obstacle components
    (:func:`structure_angles`); regions whose strongest direction agrees within 2 degrees are
    searched together, so a texture border through a hall does not cut its racks. ``labelled`` is
    ``components(occupied)``, when already labelled.
    """
    shape = occupied.shape
    merged: list[tuple[npt.NDArray[np.bool_] | None, list[float], float]] = []
    for mask, angles in regions:
        inside = occupied if mask is None else occupied & mask
        own = structure_angles(inside, resolution_m=resolution_m, labelled=labelled if mask is None else None)
        # a line direction near a long component's is that direction, less precisely
        tol = math.radians(10.0)
        every = own + [a for a in angles if all(abs(math.remainder(a - b, math.pi / 2)) > tol for b in own)]
        key = every[0] if every else 0.0
        for k, (m, a, ky) in enumerate(merged):
            if abs(math.remainder(key - ky, math.pi / 2)) <= math.radians(2.0):
                union = None if m is None or mask is None else m | mask
                merged[k] = (union, a + every, ky)
                break
        else:
            merged.append((mask, every, key))
    layouts = [
        find_racks(occupied, known, resolution_m=resolution_m, angles_rad=a, domain=m, solid=solid)
        for m, a, _ in merged if a
    ]
    return combine(layouts, shape)


def combine(layouts: list[RackLayout], shape: tuple[int, int]) -> RackLayout:
    """One layout of several (of disjoint texture regions); place ids renumbered."""
    if len(layouts) == 1:  # as it is (one search, most maps): the same arrays, no pass over the map
        return layouts[0]
    cells = np.zeros(shape, dtype=np.int32)
    labels = [np.zeros(1, dtype=np.int64)]
    rows = [np.zeros((0, 4, 2))]
    offset = 0
    for lay in layouts:
        n = lay.cell_labels.size - 1
        if n == 0:
            continue
        cells = np.where((cells == 0) & (lay.cells > 0), lay.cells + offset, cells)
        labels.append(lay.cell_labels[1:])
        rows.append(lay.rows_px)
        offset += n
    outline = np.zeros(shape, dtype=bool)
    outline[:, 1:] |= cells[:, 1:] != cells[:, :-1]
    outline[1:, :] |= cells[1:, :] != cells[:-1, :]
    return RackLayout(cells, np.concatenate(labels), outline, np.concatenate(rows))


def face_places(
    face_image: npt.NDArray[np.int32], n_faces: int, layout: RackLayout, free: npt.NDArray[np.bool_]
) -> npt.NDArray[np.int64]:
    """(F + 1,) :class:`PlaceLabel` value of the place holding most of each face's free pixels; 0 off the racks."""
    out = np.zeros(n_faces + 1, dtype=np.int64)
    if layout.cell_labels.size <= 1:
        return out
    n_lab = len(PlaceLabel)
    # free pixels per (face, place label), counted from the runs of equal face, place and freedom in raster order
    # (whole numbers summed: the counts of the (face, label) key image's runs, without drawing that image)
    face, cell, on = (np.ascontiguousarray(a).ravel() for a in (face_image, layout.cells, free))
    start = np.empty(face.size, dtype=bool)
    start[0] = True
    np.not_equal(face[1:], face[:-1], out=start[1:])
    changed = np.empty(face.size - 1, dtype=bool)
    for image in (cell, on):
        np.not_equal(image[1:], image[:-1], out=changed)
        start[1:] |= changed
    first = np.flatnonzero(start)
    length = np.diff(np.append(first, face.size))
    first, length = first[on[first]], length[on[first]]
    key = face[first].astype(np.int64) * n_lab + layout.cell_labels[cell[first]]
    votes = (
        np.bincount(key, weights=length, minlength=(n_faces + 1) * n_lab).astype(np.int64).reshape(n_faces + 1, n_lab)
    )
    best = votes[:, 1:].argmax(axis=1) + 1
    majority = votes[np.arange(n_faces + 1), best] > 0.5 * votes.sum(axis=1)
    out[majority] = best[majority]
    out[0] = 0
    return out


def place_segments(
    segments: npt.NDArray[np.int32],
    layout: RackLayout,
    free: npt.NDArray[np.bool_],
    *,
    min_area_px: int,
    n_known: int = 0,
) -> tuple[npt.NDArray[np.int32], npt.NDArray[np.int32]]:
    """``segments`` with every rack place its own segment, ids renumbered 1..N without gaps.

    A rack place keeps the pieces ``segments`` cut it into (the pallet cells of a warehouse floor).

    What the places leave of a segment joins the nearest place that is no rack (floor is never
    storage) when it is under ``min_area_px`` or under half of the segment (the slivers of a hall
    the places cover). Places ``1..n_known`` are
    known (another stage's bins and aisles, first in ``layout``): a region however little free
    space they hold (a loaded bay), and what they leave of a segment stays a segment unless a crumb.
    Also returns the place of every free pixel now in one (0 elsewhere).
    """
    if layout.cell_labels.size <= 1:
        return segments, np.zeros(segments.shape, dtype=np.int32)
    region = free | (segments > 0)  # furniture inside a room is part of its segment
    in_cells = layout.cells > 0
    # a place with a crumb of free space (a solid rack's edge pixel) is no region of its own
    n_free = label_counts(layout.cells, layout.cell_labels.size, free)[1]
    crumb = (n_free > 0) & (n_free < min_area_px)
    crumb[: n_known + 1] = False
    cells = np.where(crumb[layout.cells], 0, layout.cells) if crumb.any() else layout.cells
    inside = (cells > 0) & free
    n_old = int(segments.max()) + 1
    # known places are no reason to give up what is left of a segment (a hall's floor round its racks)
    known = in_cells & (layout.cells <= n_known) if n_known else None
    count, after = label_counts(segments, n_old, ~in_cells)
    before = count if known is None else label_counts(segments, n_old, ~known)[1]
    left = (after > 0) & ((after < min_area_px) | (after < 0.5 * before))
    left[0] = False
    floor = np.take(left, segments) & ~in_cells & region if left.any() else np.zeros(free.shape, dtype=bool)
    crumbs = crumb[layout.cells] & free if crumb.any() else np.zeros(free.shape, dtype=bool)
    place = cells.astype(np.int32)  # a copy (ids stay far below 2**31)
    # a crumb joins the nearest place; a sliver of floor the nearest place that is no rack (floor is no storage)
    rack = layout.cell_labels == PlaceLabel.STORAGE.value
    for joining, off_racks in ((crumbs, False), (floor, True)):
        if not joining.any():
            continue
        seeds = (cells > 0) & ~rack[cells] if off_racks else cells > 0
        if seeds.any():
            _, nearest = cv2.distanceTransformWithLabels(
                (~seeds).astype(np.uint8), cv2.DIST_L2, 5, labelType=cv2.DIST_LABEL_PIXEL
            )
            lut = np.zeros(int(nearest.max()) + 1, dtype=np.int32)
            lut[nearest[seeds]] = cells[seeds]
            place[joining] = lut[nearest[joining]]
            inside |= joining & (place > 0)
    # each run of equal segment, place, membership and dropped pixel along the rows takes one id, renumbered and
    # spread once: no whole-image copy of the segments written over, gathered from and renumbered (raster order, so
    # the pallet cells' keys and their order are those of the pixels)
    dropped = in_cells & ~free  # uprights and pallets in a rack place belong to no region
    run_at, run_length = _joint_runs(segments, place, inside, dropped)
    seg_run = np.ascontiguousarray(segments).ravel()[run_at].astype(np.int64)
    place_run, inside_run = place.ravel()[run_at], inside.ravel()[run_at]  # (arrays of this function's own)
    value = np.where(dropped.ravel()[run_at], 0, seg_run)
    np.copyto(value, place_run + np.int64(n_old), where=inside_run)
    # a rack keeps the pallet cells the warehouse floor cut it into (a region per bay and side)
    cell = inside_run & rack[place_run] & (seg_run > 0)
    if cell.any():
        keys, pieces = unique_inverse(place_run[cell].astype(np.int64) * n_old + seg_run[cell])
        size = np.bincount(pieces, weights=run_length[cell]).astype(np.int64)
        # a crumb joins the largest piece of its rack
        owner = keys // n_old
        order = np.lexsort((-size, owner))
        first = np.r_[True, owner[order][1:] != owner[order][:-1]]
        largest = np.zeros(int(owner.max()) + 1, dtype=np.int64)
        largest[owner[order][first]] = order[first]
        target = np.where(size >= min_area_px, np.arange(size.size), largest[owner])
        value[cell] = n_old + layout.cell_labels.size + target[pieces]
    present = np.bincount(value) > 0
    present[0] = True
    lut = (np.cumsum(present) - 1).astype(np.int32)
    np.multiply(place, inside, out=place)  # its own copy (int32): 0 off the free pixels in a place
    return np.repeat(lut[value], run_length).reshape(segments.shape), place


def _joint_runs(
    *images: npt.NDArray[np.generic],
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Flat index of the first pixel and length of each run along the rows over which every image is constant."""
    w = images[0].shape[1]
    start = np.zeros(images[0].size, dtype=bool)
    start[::w] = True
    for image in images:
        flat = np.ascontiguousarray(image).ravel()
        start[1:] |= flat[1:] != flat[:-1]
    first = np.flatnonzero(start)
    return first, np.diff(np.append(first, start.size))


def floor_objects(
    occupied: npt.NDArray[np.bool_],
    known: npt.NDArray[np.bool_],
    *,
    resolution_m: float,
    max_area_m2: float = 12.0,
    max_length_m: float = 6.0,
    min_thickness_m: float = 0.4,
    min_fill: float = 0.75,
    labelled: Components | None = None,
) -> npt.NDArray[np.bool_]:
    """(H, W) bool: things standing on the floor (pallets, box stacks, blocks of pallets).

    Occupied components of at most ``max_area_m2`` and ``max_length_m`` that touch neither unknown
    space nor the map border (walls and racks seen from one side do), blocks at least
    ``min_thickness_m`` thick filling ``min_fill`` of their rectangle (not a piece of wall).
    ``labelled`` is ``components(occupied)``, when already labelled.
    """
    labelled = components(occupied) if labelled is None else labelled
    parts, stats = labelled.labels, labelled.stats
    n = len(stats)
    if n <= 1:
        return np.zeros(occupied.shape, dtype=bool)
    near_unknown = cv2.dilate((~known).astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    walled = np.zeros(n, dtype=bool)
    walled[np.unique(parts[near_unknown & occupied])] = True
    edge = np.r_[parts[0], parts[-1], parts[:, 0], parts[:, -1]]
    walled[np.unique(edge)] = True
    size = np.maximum(stats[:, cv2.CC_STAT_WIDTH], stats[:, cv2.CC_STAT_HEIGHT]) * resolution_m
    small = (stats[:, cv2.CC_STAT_AREA] * resolution_m**2 <= max_area_m2) & (size <= max_length_m)
    keep = small & ~walled
    keep[0] = False
    for k in np.flatnonzero(keep):  # a block (a pallet, a box stack), not a piece of wall
        x, y, w, h = stats[k, :4]
        rows, cols = nonzero_rc(parts[y : y + h, x : x + w] == k)
        (_, _), (rw, rh), _ = cv2.minAreaRect(np.column_stack([cols, rows]).astype(np.float32))
        thick = (min(rw, rh) + 1) * resolution_m
        keep[k] = thick >= min_thickness_m and rows.size >= min_fill * (rw + 1) * (rh + 1)
    out: npt.NDArray[np.bool_] = labelled.spread(keep)
    return out


def pocket_merges(
    segments: npt.NDArray[np.int32],
    rooms: list[int],
    open_areas: set[int],
    objects: npt.NDArray[np.bool_],
    free: npt.NDArray[np.bool_],
    *,
    min_object_share: float = 0.3,
    max_area_px: int | None = None,
) -> dict[int, int]:
    """Rooms that are pockets of open floor between pallets: room segment -> the open area it joins.

    A room among ``rooms`` whose bordering obstacle pixels are at least ``min_object_share`` floor
    objects (:func:`floor_objects`) and whose longest free border is with an open area (a segment
    of ``open_areas``) is floor around pallets, not a room: it joins that open area. Rooms over
    ``max_area_px``, and rooms off rooms and corridors (an office, a lab with cupboards), stay.
    """
    merges: dict[int, int] = {}
    kernel = np.ones((3, 3), np.uint8)
    h, w = segments.shape
    if not rooms:
        return merges
    area = label_counts(segments, max(int(segments.max()), *rooms) + 1)[0]
    boxes = label_boxes(segments, max(rooms))
    for sid in rooms:
        found = boxes[sid - 1]  # None without a pixel
        if found is None or (max_area_px is not None and area[sid] > max_area_px):
            continue
        rows, cols = found
        r0, r1 = max(rows.start - 2, 0), min(rows.stop + 2, h)
        c0, c1 = max(cols.start - 2, 0), min(cols.stop + 2, w)
        mask = segments[r0:r1, c0:c1] == sid
        ring = (cv2.dilate(mask.astype(np.uint8), kernel) > 0) & ~mask
        wall = ring & ~free[r0:r1, c0:c1]
        if not wall.any() or objects[r0:r1, c0:c1][wall].mean() < min_object_share:
            continue
        others = segments[r0:r1, c0:c1][ring & free[r0:r1, c0:c1]]
        others = others[(others > 0) & (others != sid)]
        if others.size and int(np.bincount(others).argmax()) in open_areas:
            merges[sid] = int(np.bincount(others).argmax())
    return merges

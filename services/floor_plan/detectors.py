"""Data-driven proposals: wall weights, Hough wall lines, WBU/FSU unit candidates and door candidates.

Eqs. 3.10-3.17 (unit weights from wall weights), 3.18 (split lines weighted by length) and 3.23-3.25
(door weights). All sums over rectangles come from integral images, so weighting a candidate costs O(1).
"""

from __future__ import annotations

from typing import NamedTuple

import cv2
import numpy as np
import numpy.typing as npt

from services.floor_plan.likelihood import CellClass
from services.floor_plan.world import Rect, Side, World, shared_band, sharing, wall_band


class Evidence:
    """Integral images of wall and free cells of C_M, for O(1) rectangle counts."""

    def __init__(self, classes_map: npt.NDArray[np.uint8]) -> None:
        self.shape = (int(classes_map.shape[0]), int(classes_map.shape[1]))
        self._wall = _integral(classes_map == CellClass.WALL)
        self._free = _integral(classes_map == CellClass.FREE)

    def walls(self, r: Rect) -> int:
        return _box(self._wall, r)

    def free(self, r: Rect) -> int:
        return _box(self._free, r)

    def wall_weight(self, rect: Rect, side: Side, wall_cells: int) -> float:
        """omega_w (eq. 3.11): the share of a wall's cells that are walls in the map."""
        band = wall_band(rect, side, wall_cells)
        return self.walls(band) / ((band.rows) * (band.cols))

    def unit_weight(self, rect: Rect, wall_cells: int) -> float:
        """omega_r (eq. 3.10): the weight of the unit's worst wall."""
        return min(self.wall_weight(rect, s, wall_cells) for s in Side)


def _integral(mask: npt.NDArray[np.bool_]) -> npt.NDArray[np.int64]:
    out = np.zeros((mask.shape[0] + 1, mask.shape[1] + 1), np.int64)
    out[1:, 1:] = mask.cumsum(0, dtype=np.int64).cumsum(1)
    return out


def _box(ii: npt.NDArray[np.int64], r: Rect) -> int:
    return int(ii[r.r1 + 1, r.c1 + 1] - ii[r.r0, r.c1 + 1] - ii[r.r1 + 1, r.c0] + ii[r.r0, r.c0])


def _boxes(ii: npt.NDArray[np.int64], r0: npt.NDArray[np.int64], r1: npt.NDArray[np.int64],
           c0: npt.NDArray[np.int64], c1: npt.NDArray[np.int64]) -> npt.NDArray[np.int64]:
    out: npt.NDArray[np.int64] = ii[r1 + 1, c1 + 1] - ii[r0, c1 + 1] - ii[r1 + 1, c0] + ii[r0, c0]
    return out


class WallLines(NamedTuple):
    """Axis-parallel wall lines from the Hough detector: position (row of a horizontal line or column
    of a vertical one, the first cell of a wall band centred on the line), span [lo, hi] along it."""

    horizontal: npt.NDArray[np.int64]  # (n, 3): row, col_lo, col_hi
    vertical: npt.NDArray[np.int64]  # (m, 3): col, row_lo, row_hi


def wall_lines(
    classes_map: npt.NDArray[np.uint8], *, wall_cells: int, min_length_cells: int = 10, max_gap_cells: int = 3,
    tolerance_rad: float = 0.06,
) -> WallLines:
    """Hough line segments (OpenCV probabilistic Hough) on the wall cells, kept when near-axis-parallel."""
    walls = (classes_map == CellClass.WALL).astype(np.uint8) * 255
    segs = cv2.HoughLinesP(walls, 1, np.pi / 180, threshold=max(min_length_cells // 2, 3),
                           minLineLength=min_length_cells, maxLineGap=max_gap_cells)
    horizontal: list[tuple[int, int, int]] = []
    vertical: list[tuple[int, int, int]] = []
    half = wall_cells // 2
    for x0, y0, x1, y1 in (segs.reshape(-1, 4) if segs is not None else np.zeros((0, 4), np.int64)):
        angle = np.arctan2(float(y1 - y0), float(x1 - x0))
        if abs(np.sin(angle)) < np.sin(tolerance_rad):
            horizontal.append((round((y0 + y1) / 2) - half, min(x0, x1), max(x0, x1)))
        elif abs(np.cos(angle)) < np.sin(tolerance_rad):
            vertical.append((round((x0 + x1) / 2) - half, min(y0, y1), max(y0, y1)))
    return WallLines(np.array(horizontal, np.int64).reshape(-1, 3), np.array(vertical, np.int64).reshape(-1, 3))


def wall_line_segments(
    classes_map: npt.NDArray[np.uint8], *, min_length_cells: int, max_gap_cells: int, wall_share: float = 0.5,
    min_angle_rad: float | None = None,
) -> npt.NDArray[np.float64]:
    """The map's straight wall lines, in every direction or at an angle to the grid (one detector for every step
    that needs wall lines that are not the units' own: the slanted walls of :mod:`services.floor_plan.walls`, the
    room re-cut of :mod:`services.floor_plan.slanted`).

    The outline of the free space (cells that are not free beside a free cell, so walls drawn occupied or unknown
    count and the unknown outside does not; where laser beams' traces through windows read as unknown,
    :func:`~services.floor_plan.likelihood.beam_traces`, their edges do not either), OpenCV probabilistic Hough
    segments on it (one-degree steps) at least ``min_length_cells`` long with gaps up to ``max_gap_cells`` bridged
    (dashed walls, doorways), kept where at least ``wall_share`` of their cells lie on or beside the outline and (with
    ``min_angle_rad``) at least that far from both axes, each refitted (``cv2.fitLine``, least squares) to the
    outline cells within 1.5 cells of it that share a side with free space (a wall's face, not the unknown cells
    diagonally past a one-cell wall's steps). Returns (N, 4) ``x0, y0, x1, y1`` (x = column, y = row, cell centres):
    the refitted line between the segment's ends projected onto it.

    >>> cm = np.full((40, 40), CellClass.FREE, np.uint8); rr = np.arange(5, 35)
    >>> cm[rr, rr // 2 + 5] = CellClass.WALL  # a wall leaning about 27 degrees off the columns
    >>> lines = wall_line_segments(cm, min_length_cells=20, max_gap_cells=3, min_angle_rad=0.09)
    >>> len(lines) >= 1, bool(np.all(np.abs(np.diff(lines[:, 1::2], axis=1)) > 20))
    (True, True)
    """
    free = (classes_map == CellClass.FREE).astype(np.uint8)
    box = np.ones((3, 3), np.uint8)
    outline = ((classes_map != CellClass.FREE) & (cv2.dilate(free, box) > 0)).astype(np.uint8)
    segs = cv2.HoughLinesP(outline * 255, 1, np.pi / 180, round(0.75 * min_length_cells),
                           minLineLength=min_length_cells, maxLineGap=max_gap_cells)
    if segs is None:
        return np.zeros((0, 4))
    segs = segs.reshape(-1, 4).astype(np.float64)
    if min_angle_rad is not None:
        angle = np.arctan2(segs[:, 3] - segs[:, 1], segs[:, 2] - segs[:, 0])
        segs = segs[np.abs((angle + np.pi / 4) % (np.pi / 2) - np.pi / 4) >= min_angle_rad]
    near = cv2.dilate(outline, box) > 0
    face = (outline > 0) & (cv2.dilate(free, cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))) > 0)
    out = []
    for x0, y0, x1, y1 in segs:
        d = np.array([x1 - x0, y1 - y0])
        length = float(np.hypot(*d))
        n = round(max(abs(d[0]), abs(d[1]))) + 1
        if near[np.rint(np.linspace(y0, y1, n)).astype(np.int64), np.rint(np.linspace(x0, x1, n)).astype(np.int64)
                ].mean() < wall_share:
            continue
        u = d / length
        left, top = max(int(min(x0, x1)) - 2, 0), max(int(min(y0, y1)) - 2, 0)
        ys, xs = np.nonzero(face[top : int(max(y0, y1)) + 3, left : int(max(x0, x1)) + 3])
        points = np.stack([xs + left, ys + top], axis=1).astype(np.float64)
        rel = points - (x0, y0)
        along = rel @ u
        fit = points[(np.abs(rel @ np.array([-u[1], u[0]])) <= 1.5) & (along >= 0) & (along <= length)]
        if len(fit) < 2:
            continue
        vx, vy, cx, cy = cv2.fitLine(fit.astype(np.float32), cv2.DIST_L2, 0, 0.01, 0.01).ravel()
        v, c = np.array([vx, vy], np.float64), np.array([cx, cy], np.float64)
        a, b = (np.array([x0, y0]) - c) @ v, (np.array([x1, y1]) - c) @ v
        out.append((*(c + a * v), *(c + b * v)))
    return np.array(out, np.float64).reshape(-1, 4)


def _positions(lines: npt.NDArray[np.int64], merge_cells: int) -> npt.NDArray[np.int64]:
    """Line positions with neighbours closer than ``merge_cells`` merged (weighted by length)."""
    if len(lines) == 0:
        return np.zeros(0, np.int64)
    order = np.argsort(lines[:, 0])
    pos, length = lines[order, 0], lines[order, 2] - lines[order, 1] + 1
    groups = np.r_[0, np.cumsum(np.diff(pos) > merge_cells)]
    sums = np.bincount(groups, pos * length)
    return np.rint(sums / np.bincount(groups, length)).astype(np.int64)


class Candidate(NamedTuple):
    rect: Rect
    weight: float


def wbu_candidates(
    lines: WallLines, evidence: Evidence, *, wall_cells: int, min_inner_cells: int, max_span: int = 4,
    min_weight: float = 0.3, min_free_share: float = 0.3, max_candidates: int = 4000,
) -> list[Candidate]:
    """Wall-based unit candidates (fig. 3.12): rectangles between extended wall lines, weighted by eq. 3.10.

    Extending the lines splits the map into sub-areas; any block of up to ``max_span`` x ``max_span``
    sub-areas is a candidate. Candidates whose worst wall is below ``min_weight`` or whose free space is
    mostly not free in the map are dropped; the best ``max_candidates`` are kept.
    """
    h, w = evidence.shape
    t = wall_cells
    rows = np.unique(np.clip(_positions(lines.horizontal, t), 0, h - t))
    cols = np.unique(np.clip(_positions(lines.vertical, t), 0, w - t))
    if len(rows) < 2 or len(cols) < 2:
        return []
    i, j = np.triu_indices(len(rows), 1)
    keep = j - i <= max_span
    i, j = i[keep], j[keep]
    k, m = np.triu_indices(len(cols), 1)
    keep = m - k <= max_span
    k, m = k[keep], m[keep]
    r0 = np.repeat(rows[i], len(k))
    r1 = np.repeat(rows[j] + t - 1, len(k))
    c0 = np.tile(cols[k], len(i))
    c1 = np.tile(cols[m] + t - 1, len(i))
    ok = (r1 - r0 + 1 >= 2 * t + min_inner_cells) & (c1 - c0 + 1 >= 2 * t + min_inner_cells)
    r0, r1, c0, c1 = r0[ok], r1[ok], c0[ok], c1[ok]
    if len(r0) == 0:
        return []
    ww = evidence._wall
    weights = np.min(np.stack([
        _boxes(ww, r0, r0 + t - 1, c0, c1) / (t * (c1 - c0 + 1)),
        _boxes(ww, r1 - t + 1, r1, c0, c1) / (t * (c1 - c0 + 1)),
        _boxes(ww, r0, r1, c0, c0 + t - 1) / (t * (r1 - r0 + 1)),
        _boxes(ww, r0, r1, c1 - t + 1, c1) / (t * (r1 - r0 + 1)),
    ]), axis=0)
    inner = _boxes(evidence._free, r0 + t, r1 - t, c0 + t, c1 - t) / ((r1 - r0 + 1 - 2 * t) * (c1 - c0 + 1 - 2 * t))
    good = np.flatnonzero((weights >= min_weight) & (inner >= min_free_share))
    good = good[np.argsort(-weights[good], kind="stable")[:max_candidates]]
    return [Candidate(Rect(int(r0[g]), int(r1[g]), int(c0[g]), int(c1[g])), float(weights[g])) for g in good]


def fsu_candidates(
    classes_map: npt.NDArray[np.uint8], classes_world: npt.NDArray[np.uint8], evidence: Evidence, *,
    wall_cells: int, min_inner_cells: int, max_candidates: int = 24, min_free_share: float = 0.3,
    max_wall_share: float = 0.15, floor_weight: float = 0.05, positions_rc: npt.NDArray[np.int64] | None = None,
) -> list[Candidate]:
    """Free-space unit candidates (fig. 3.13): rectangles grown over free map cells the world leaves unexplained.

    The unexplained free cells are cleaned by an opening of ``min_inner_cells``; seeds are the cells
    deepest inside them (distance transform), each grown side by side while the next row or column of the
    map holds at least ``min_free_share`` free and at most ``max_wall_share`` wall cells; the grown free
    space gets a wall around it. Each seed gives two candidates: one grown over the map alone (it may
    replace units that explain the place badly) and one that also stops at the cells the world's units
    already claim, so that it fills a gap between them and its walls fall on theirs (shared walls, where
    doors can open). Weights follow eq. 3.10, floored at ``floor_weight`` (such units often lack a seen wall).

    ``positions_rc`` ((N, 2) cells, row and column), where a robot is known to have been (its trajectory),
    are seeds too, ahead of the deepest cells (the robot-position detector): a robot stood in a unit, so
    every place it passed that the world leaves unexplained gets up to ``max_candidates`` more candidates.
    """
    t = wall_cells
    h, w = classes_map.shape
    loose = ((classes_map == CellClass.FREE) & (classes_world != CellClass.FREE)).astype(np.uint8)
    opened = cv2.morphologyEx(loose, cv2.MORPH_OPEN, np.ones((min_inner_cells, min_inner_cells), np.uint8))
    depth = cv2.distanceTransform(opened, cv2.DIST_L1, 3)
    deep = np.flatnonzero(depth.ravel() * 2 >= min_inner_cells)
    order = deep[np.argsort(-depth.ravel()[deep], kind="stable")]
    robot: npt.NDArray[np.int64] = np.zeros(0, np.int64)
    if positions_rc is not None and len(positions_rc):
        rc = np.asarray(positions_rc, np.int64).reshape(-1, 2)
        inside = (rc[:, 0] >= t) & (rc[:, 0] < h - t) & (rc[:, 1] >= t) & (rc[:, 1] < w - t)
        flat = rc[inside, 0] * w + rc[inside, 1]
        robot = flat[loose.ravel()[flat] > 0]
    if not len(order) and not len(robot):
        return []
    claimed = _integral(classes_world != CellClass.UNKNOWN)
    bounds = (t, h - 1 - t, t, w - 1 - t)
    out: list[Candidate] = []
    taken = np.zeros(opened.shape, bool)
    seeds = 0
    limit = max_candidates + min(len(robot), max_candidates)
    for flat in np.r_[robot, order[: 50 * max_candidates]]:
        r, c = divmod(int(flat), w)
        if seeds >= limit:
            break
        if taken[r, c]:
            continue
        seeds += 1
        seed = Rect(r, r, c, c)
        plain = _grow(evidence, seed, bounds, min_free_share, max_wall_share)
        gap = _grow(evidence, seed, bounds, min_free_share, max_wall_share, claimed=claimed)
        taken[plain.r0 : plain.r1 + 1, plain.c0 : plain.c1 + 1] = True
        for inner in {plain, gap}:
            if inner.rows < min_inner_cells or inner.cols < min_inner_cells:
                continue
            rect = Rect(inner.r0 - t, inner.r1 + t, inner.c0 - t, inner.c1 + t)
            out.append(Candidate(rect, max(evidence.unit_weight(rect, t), floor_weight)))
    return out


def _grow(evidence: Evidence, rect: Rect, bounds: tuple[int, int, int, int], min_free: float,
          max_wall: float, step: int = 8, claimed: npt.NDArray[np.int64] | None = None) -> Rect:
    """Grow ``rect`` side by side, up to ``step`` lines a round, while each new line is open enough
    (and, with ``claimed``, an integral image of the cells units claim, holds none of them)."""
    r0, r1, c0, c1 = rect
    lo_r, hi_r, lo_c, hi_c = bounds
    active = [True, True, True, True]
    while any(active):
        for side in range(4):
            if not active[side]:
                continue
            if side == 0:
                idx = np.arange(r0 - 1, max(r0 - 1 - step, lo_r - 1), -1)
                box = (idx, idx, np.full(len(idx), c0), np.full(len(idx), c1))
                n = c1 - c0 + 1
            elif side == 1:
                idx = np.arange(r1 + 1, min(r1 + 1 + step, hi_r + 1))
                box = (idx, idx, np.full(len(idx), c0), np.full(len(idx), c1))
                n = c1 - c0 + 1
            elif side == 2:
                idx = np.arange(c0 - 1, max(c0 - 1 - step, lo_c - 1), -1)
                box = (np.full(len(idx), r0), np.full(len(idx), r1), idx, idx)
                n = r1 - r0 + 1
            else:
                idx = np.arange(c1 + 1, min(c1 + 1 + step, hi_c + 1))
                box = (np.full(len(idx), r0), np.full(len(idx), r1), idx, idx)
                n = r1 - r0 + 1
            ok = (_boxes(evidence._free, *box) >= min_free * n) & (_boxes(evidence._wall, *box) <= max_wall * n)
            if claimed is not None:
                ok &= _boxes(claimed, *box) == 0
            k = len(ok) if ok.all() else int(np.argmin(ok))
            if k < len(ok) or k == 0:
                active[side] = False
            if k == 0:
                continue
            far = int(idx[k - 1])
            if side == 0:
                r0 = far
            elif side == 1:
                r1 = far
            elif side == 2:
                c0 = far
            else:
                c1 = far
    return Rect(r0, r1, c0, c1)


def split_options(
    rect: Rect, lines: WallLines, *, wall_cells: int, min_inner_cells: int
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], npt.NDArray[np.float64]]:
    """Ways to split ``rect`` along detected wall lines (eq. 3.18): axis (0 = at a row, 1 = at a column),
    position (first cell of the new shared wall) and weight (the line's length inside the unit)."""
    t, m = wall_cells, min_inner_cells
    axes, pos, weight = [], [], []
    for axis, arr, lo, hi, a0, a1 in ((0, lines.horizontal, rect.r0, rect.r1, rect.c0, rect.c1),
                                      (1, lines.vertical, rect.c0, rect.c1, rect.r0, rect.r1)):
        if len(arr) == 0:
            continue
        p = arr[:, 0]
        inside = (p >= lo + t + m) & (p + t - 1 <= hi - t - m)
        overlap = np.minimum(arr[:, 2], a1 - t) - np.maximum(arr[:, 1], a0 + t) + 1
        ok = inside & (overlap > 0)
        if not ok.any():
            continue
        # one option per position: the summed length of the lines there
        uniq, inv = np.unique(p[ok], return_inverse=True)
        axes.append(np.full(len(uniq), axis, np.int64))
        pos.append(uniq)
        weight.append(np.bincount(inv, overlap[ok].astype(np.float64)))
    if not axes:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.float64)
    return np.concatenate(axes), np.concatenate(pos), np.concatenate(weight)


def split_rect(rect: Rect, axis: int, position: int, wall_cells: int) -> tuple[Rect, Rect]:
    """The two units of a split: they share the wall band starting at ``position``."""
    t = wall_cells
    if axis == 0:
        return rect._replace(r1=position + t - 1), rect._replace(r0=position)
    return rect._replace(c1=position + t - 1), rect._replace(c0=position)


def _sharing(rects: list[Rect], wall_cells: int) -> npt.NDArray[np.int64]:
    """The pairs ``(a, b)``, ``a < b`` in row-major order, of ``rects`` that share a wall
    (:func:`~services.floor_plan.world.sharing`), all pairs tested at once."""
    boxes = np.array(rects, np.int64).reshape(-1, 4)
    column = Rect(*(boxes[:, None, k] for k in range(4)))  # type: ignore[arg-type]  # Rect of arrays: broadcasts
    out: npt.NDArray[np.int64] = np.argwhere(np.triu(sharing(column, boxes[None], wall_cells), 1))
    return out


def door_candidates(
    world: World, evidence: Evidence, *, wall_cells: int, min_door_cells: int, min_free_share: float = 0.5
) -> list[Candidate]:
    """Door candidates (fig. 3.18): runs of open cells along the walls adjacent units share, weighted by eq. 3.23."""
    t = wall_cells
    rects = list(world.units.values())
    out: list[Candidate] = []
    for a, b in _sharing(rects, t):
        band = shared_band(rects[a], rects[b], t)
        assert band is not None  # _sharing's pairs share a wall
        along_rows = band.rows > band.cols  # a vertical wall: the door runs along rows
        n = band.rows if along_rows else band.cols
        idx = np.arange(n)
        if along_rows:
            free = _boxes(evidence._free, band.r0 + idx, band.r0 + idx, np.full(n, band.c0), np.full(n, band.c1))
        else:
            free = _boxes(evidence._free, np.full(n, band.r0), np.full(n, band.r1), band.c0 + idx, band.c0 + idx)
        open_ = np.r_[False, free >= min_free_share * t, False]
        edges = np.flatnonzero(np.diff(open_.astype(np.int8)))
        for s, e in zip(edges[::2], edges[1::2], strict=True):
            if e - s < min_door_cells:
                continue
            lo, hi = int(s), int(e) - 1
            door = (Rect(band.r0 + lo, band.r0 + hi, band.c0, band.c1) if along_rows
                    else Rect(band.r0, band.r1, band.c0 + lo, band.c0 + hi))
            out.append(Candidate(door, evidence.free(door) / (door.rows * door.cols)))
    return out

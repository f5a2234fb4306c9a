"""Storage bins between consecutive uprights of rack rows, with stable WMS-style ids."""

from __future__ import annotations

import itertools
import logging
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from services.pillar_mapping.rows import RackRow

logger = logging.getLogger(__name__)

FloatArray = npt.NDArray[np.float64]


class StorageBin(NamedTuple):
    """One pallet cell at floor level.

    ``id`` is ``"AA-BBB"`` (aisle, bay; odd bays on the aisle's left looking along the row
    direction, even on its right); ``footprint`` (4, 2) metres, front edge first;
    ``centre`` (2,) metres; ``access_pose`` (x, y, yaw) in the aisle facing the opening; ``row``
    the index of the aisle-facing row in the row list; ``back_row`` the row behind.
    """

    id: str
    aisle: int
    bay: int
    footprint: FloatArray
    centre: FloatArray
    access_pose: tuple[float, float, float]
    row: int
    back_row: int


def _frame(row: RackRow) -> tuple[FloatArray, FloatArray]:
    u = np.array([np.cos(row.theta_rad), np.sin(row.theta_rad)])
    return u, np.array([-u[1], u[0]])


def _overlap(span: dict[int, tuple[float, float]], a: int, b: int) -> float:
    """Length (metres) over which rows ``a`` and ``b`` overlap along the region, given each row's (lo, hi)."""
    return min(span[a][1], span[b][1]) - max(span[a][0], span[b][0])


def _gap(w: dict[int, float], span: dict[int, tuple[float, float]], i: int, side: float) -> float:
    """Distance from row ``i`` to the nearest overlapping row on ``side`` (+1 or -1 across), or inf."""
    gaps = [(w[j] - w[i]) * side for j in w if j != i and (w[j] - w[i]) * side > 0.05 and _overlap(span, i, j) > 0]
    return min(gaps) if gaps else float("inf")


def storage_bins(
    rows: list[RackRow],
    *,
    min_rack_depth_m: float = 0.6,
    max_rack_depth_m: float = 1.6,
    min_aisle_width_m: float = 2.0,
    default_aisle_width_m: float = 3.0,
    access_standoff_m: float = 1.2,
) -> list[StorageBin]:
    """Pallet cells of every rack: a pair of parallel rows ``min_rack_depth_m``..``max_rack_depth_m`` apart.

    Of a rack's two rows, the one with an open gap of at least ``min_aisle_width_m`` to the
    next row beyond it faces an aisle (if both or neither do, the one with the narrower such
    gap, else the first). Each pair of consecutive uprights of that row, with the back row
    behind, bounds a cell. Aisles are numbered per region (regions in the row list's order)
    by increasing offset along the region's normal, bays from the row direction's low end
    (the region's initialisation line), so ids survive a rebuild of the map. Rows in no rack
    get no bins.
    """
    bins: list[StorageBin] = []
    aisle_base = 0
    for region in sorted({r.region for r in rows}):
        index = [i for i, r in enumerate(rows) if r.region == region]
        u, v = _frame(rows[index[0]])
        w = {i: float(rows[i].uprights.mean(axis=0) @ v) for i in index}
        along = {i: rows[i].uprights @ u for i in index}
        span = {i: (float(s.min()), float(s.max())) for i, s in along.items()}
        order = sorted(index, key=lambda i: w[i])

        racks: list[tuple[int, int, float]] = []  # (front, back, side of the aisle from the front row)
        used: set[int] = set()
        for a, b in itertools.pairwise(order):
            depth = w[b] - w[a]
            if a in used or b in used or not min_rack_depth_m <= depth <= max_rack_depth_m:
                continue
            if _overlap(span, a, b) <= 0:
                continue
            used |= {a, b}
            gap_a, gap_b = _gap(w, span, a, -1.0), _gap(w, span, b, 1.0)
            open_a = np.isfinite(gap_a) and gap_a >= min_aisle_width_m
            open_b = np.isfinite(gap_b) and gap_b >= min_aisle_width_m
            front_is_b = (open_b and not open_a) or (open_a and open_b and gap_b < gap_a)
            racks.append((b, a, 1.0) if front_is_b else (a, b, -1.0))
        aisle_centres: list[float] = []
        assignments = []
        for front, back, side in racks:
            gap = _gap(w, span, front, side)
            width = gap if np.isfinite(gap) and gap >= min_aisle_width_m else default_aisle_width_m
            centre = w[front] + side * 0.5 * width
            match = [k for k, c in enumerate(aisle_centres) if abs(c - centre) < 0.5 * min_aisle_width_m]
            if match:
                k = match[0]
            else:
                aisle_centres.append(centre)
                k = len(aisle_centres) - 1
            assignments.append((front, back, side, k, width))
        numbering = {k: aisle_base + 1 + rank for rank, k in enumerate(np.argsort(aisle_centres))}
        aisle_base += len(aisle_centres)
        if not rows or not index:
            continue
        origin = min(float((rows[i].uprights @ u).min()) for i in index)
        for front, back, side, k, width in assignments:
            row = rows[front]
            back_offset = w[back] - w[front]
            back_dir = np.sign(back_offset) * v
            depth = abs(back_offset)
            lo, hi = (rows[back].uprights @ u).min(), (rows[back].uprights @ u).max()
            left = side > 0
            for j in range(row.n - 1):
                p, q = row.uprights[j], row.uprights[j + 1]
                mid_along = 0.5 * float((p + q) @ u)
                if not lo - 0.25 * row.d_m <= mid_along <= hi + 0.25 * row.d_m:
                    continue
                footprint = np.array([p, q, q + depth * back_dir, p + depth * back_dir])
                centre = footprint.mean(axis=0)
                slot = int(np.floor((mid_along - origin) / row.d_m)) + 1
                bay = 2 * slot - 1 if left else 2 * slot
                standoff = min(access_standoff_m, 0.5 * width)
                access = 0.5 * (p + q) - back_dir * standoff
                yaw = float(np.arctan2(back_dir[1], back_dir[0]))
                aisle = numbering[k]
                bins.append(
                    StorageBin(
                        f"{aisle:02d}-{bay:03d}",
                        aisle,
                        bay,
                        footprint,
                        centre,
                        (float(access[0]), float(access[1]), yaw),
                        front,
                        back,
                    )
                )
    unpaired = len(rows) - 2 * sum(1 for _ in {(b.row, b.back_row) for b in bins})
    logger.debug("%d bins; %d rows in no rack", len(bins), max(unpaired, 0))
    return bins

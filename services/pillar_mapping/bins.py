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
IntArray = npt.NDArray[np.int64]

_CANONICAL_FROM_RAD = -0.25 * np.pi - 0.1
"""Bays count along a region's rows in the direction whose angle lies in [this, this + pi): along +x
for rows along x, along +y for rows along y. The one angle where the choice flips (about -51 deg or
129 deg) is far from the axis-aligned and 45 deg layouts halls are built in, so a rebuild with other
noise counts the same way."""


UPRIGHT_TOLERANCE_M = 0.1
"""How close a mapped upright must be to its true place for a bin it bounds to be where the map says (bins
must come out within 10 cm), metres; :func:`bin_confidence` is the chance of that."""


class StorageBin(NamedTuple):
    """One pallet cell.

    ``id`` is ``"AA-BBB"`` (aisle, bay; odd bays on the aisle's left looking along the row
    direction, even on its right), with ``"-LL"`` appended (``LL`` = ``level`` + 1) when the rack's
    levels are known (:data:`shared.bins.ID_FORMAT`); ``footprint`` (4, 2) metres, front edge
    first; ``centre`` (2,) metres; ``access_pose`` (x, y, yaw) in the aisle facing the opening; ``row`` the index of the
    aisle-facing row in the row list; ``back_row`` the row behind; ``confidence`` in [0, 1]
    (:func:`bin_confidence` of its four uprights); ``level`` 0 for the floor, None when unknown;
    ``z_m`` the height of the cell's floor (beam top), metres, None when unknown.
    """

    id: str
    aisle: int
    bay: int
    footprint: FloatArray
    centre: FloatArray
    access_pose: tuple[float, float, float]
    row: int
    back_row: int
    confidence: float
    level: int | None = None
    z_m: float | None = None


class _Rack(NamedTuple):
    """Two rows of a block forming one rack: the aisle-facing ``front``, the ``back``, the ``side`` (+1 or
    -1 across) the aisle lies on from the front row, the aisle's centre offset ``centre`` and ``width``."""

    front: int
    back: int
    side: float
    centre: float
    width: float


def _frame(theta_rad: float) -> tuple[FloatArray, FloatArray]:
    """The canonical (along, across) unit vectors of rows at ``theta_rad``."""
    theta = (theta_rad - _CANONICAL_FROM_RAD) % np.pi + _CANONICAL_FROM_RAD
    u = np.array([np.cos(theta), np.sin(theta)])
    return u, np.array([-u[1], u[0]])


def _overlap(span: dict[int, tuple[float, float]], a: int, b: int) -> float:
    """Length (metres) over which rows ``a`` and ``b`` overlap along the region, given each row's (lo, hi)."""
    return min(span[a][1], span[b][1]) - max(span[a][0], span[b][0])


def _gap(w: dict[int, float], span: dict[int, tuple[float, float]], i: int, side: float) -> float:
    """Distance from row ``i`` to the nearest overlapping row on ``side`` (+1 or -1 across), or inf."""
    gaps = [(w[j] - w[i]) * side for j in w if j != i and (w[j] - w[i]) * side > 0.05 and _overlap(span, i, j) > 0]
    return min(gaps) if gaps else float("inf")


def _candidates(
    w: dict[int, float], span: dict[int, tuple[float, float]], depth_m: tuple[float, float]
) -> list[tuple[int, int]]:
    """Neighbouring rows (by offset ``w``) overlapping along and ``depth_m`` (least, most) apart."""
    return [
        (a, b)
        for a, b in itertools.pairwise(sorted(w, key=lambda i: w[i]))
        if depth_m[0] <= w[b] - w[a] <= depth_m[1] and _overlap(span, a, b) > 0
    ]


def _typical_depth(depths: list[float], tolerance_m: float) -> float:
    """The depth most others agree with (within ``tolerance_m``); of equals the smallest (a pair over a flue
    is a rack depth plus the flue)."""
    values = np.sort(np.asarray(depths))
    votes = (np.abs(values[:, None] - values[None, :]) <= tolerance_m).sum(axis=1)
    return float(values[int(np.argmax(votes))])


def _racks(
    w: dict[int, float],
    span: dict[int, tuple[float, float]],
    *,
    typical_depth_m: float,
    min_rack_depth_m: float,
    max_rack_depth_m: float,
    rack_depth_tolerance_m: float,
    min_aisle_width_m: float,
    default_aisle_width_m: float,
) -> list[_Rack]:
    """Pairs of parallel rows of one block ``min..max_rack_depth_m`` apart, each facing its aisle.

    Candidate pairs (:func:`_candidates`) nearest ``typical_depth_m`` are taken first, each row in
    one rack, none further than ``rack_depth_tolerance_m`` from it (so while a rack's back row is
    unmapped, its front row is not paired with the back row of the rack behind, over the flue). Of
    a rack's two rows, the one with an open gap of at least ``min_aisle_width_m`` to the next row
    beyond it faces an aisle (if both or neither do, the one with the narrower such gap, else the
    first).
    """
    candidates = _candidates(w, span, (min_rack_depth_m, max_rack_depth_m))
    typical = typical_depth_m
    racks = []
    used: set[int] = set()
    for a, b in sorted(candidates, key=lambda pair: abs(w[pair[1]] - w[pair[0]] - typical)):
        if a in used or b in used or abs(w[b] - w[a] - typical) > rack_depth_tolerance_m:
            continue
        used |= {a, b}
        gap_a, gap_b = _gap(w, span, a, -1.0), _gap(w, span, b, 1.0)
        open_a = np.isfinite(gap_a) and gap_a >= min_aisle_width_m
        open_b = np.isfinite(gap_b) and gap_b >= min_aisle_width_m
        front, back, side = (b, a, 1.0) if (open_b and not open_a) or (open_a and open_b and gap_b < gap_a) else (
            a, b, -1.0)
        gap = _gap(w, span, front, side)
        width = gap if np.isfinite(gap) and gap >= min_aisle_width_m else default_aisle_width_m
        racks.append(_Rack(front, back, side, w[front] + side * 0.5 * width, width))
    return racks


def bin_confidence(sigma_m: npt.ArrayLike, *, tolerance_m: float = UPRIGHT_TOLERANCE_M) -> float:
    """Confidence in [0, 1] of a bin bounded by uprights whose landmarks have largest standard deviations
    ``sigma_m`` (4,) metres (inf for an upright no landmark supports, restored from its row's lattice).

    The expected fraction of the bin's uprights that lie within ``tolerance_m`` of where the map puts them:
    each mapped upright counts the chance a 2-D Gaussian error of its landmark's largest standard deviation
    stays within the tolerance, ``1 - exp(-t^2 / (2 sigma^2))`` (0.86 at sigma = 5 cm, 1.00 at 2 cm), an
    unsupported upright 0.

    >>> round(bin_confidence([0.02, 0.02, 0.05, float("inf")]), 2)
    0.72
    """
    sigma = np.asarray(sigma_m, dtype=np.float64)
    with np.errstate(divide="ignore"):
        chance = -np.expm1(-0.5 * (tolerance_m / sigma) ** 2)
    return float(np.clip(np.mean(chance), 0.0, 1.0))


def _back_uprights(back: RackRow, corners: FloatArray) -> IntArray:
    """Indices of the back row's uprights nearest ``corners`` (2, 2) metres."""
    return np.asarray(np.argmin(np.hypot(*(back.uprights[None] - corners[:, None]).transpose(2, 0, 1)), axis=1))


def _supported(row: RackRow, j: int, back: RackRow, behind: IntArray) -> bool:
    """Whether the cell between front uprights ``j`` and ``j + 1`` lies between seen uprights of its row, or
    a landmark supports one of its four corner uprights (the back ones ``behind``)."""
    seen = np.flatnonzero(row.observed)
    if row.observed[j] or row.observed[j + 1] or (seen.size and seen.min() <= j and seen.max() >= j + 1):
        return True
    return bool(back.observed[behind].any())


def storage_bins(
    rows: list[RackRow],
    *,
    min_rack_depth_m: float = 0.6,
    max_rack_depth_m: float = 1.6,
    rack_depth_tolerance_m: float = 0.1,
    min_aisle_width_m: float = 2.0,
    default_aisle_width_m: float = 3.0,
    access_standoff_m: float = 1.2,
) -> list[StorageBin]:
    """Floor-level pallet cells of every rack: a pair of parallel rows ``min_rack_depth_m``..``max_rack_depth_m`` apart.

    Racks are paired within each block (:class:`~services.pillar_mapping.rows.RackRow`), from rows whose
    distance is within ``rack_depth_tolerance_m`` of the depth most neighbouring rows of the region
    agree on (racks of one region are one depth: a region of mixed depths gets bins for the
    common one only); each pair of
    consecutive uprights of the aisle-facing row, with the back row behind, bounds a cell, made
    only where it lies between seen uprights of its row or a landmark supports one of its four
    corner uprights (a cell beyond a row's seen end whose uprights were all restored from the
    region's lines is not one anybody saw). Aisles are numbered per region
    (regions in the row list's order) by increasing offset across, one number for the aisle on
    both sides of a cross aisle; bays are counted along the rows (:data:`_CANONICAL_FROM_RAD`) from
    the region's first block, on across cross aisles as the bays of the blocks before, so ids
    survive a rebuild of the map. Rows in no rack get no bins; levels are added by
    :func:`~services.pillar_mapping.levels.bins_on_levels`.
    """
    bins: list[StorageBin] = []
    aisle_base = 0
    for region in sorted({r.region for r in rows}):
        index = [i for i, r in enumerate(rows) if r.region == region]
        u, v = _frame(rows[index[0]].theta_rad)
        w = {i: float(rows[i].uprights.mean(axis=0) @ v) for i in index}
        span = {i: (float((rows[i].uprights @ u).min()), float((rows[i].uprights @ u).max())) for i in index}
        blocks: list[tuple[float, float, float, list[_Rack]]] = []  # (start, bays, spacing, racks) along u
        groups = [[i for i in index if rows[i].block == b] for b in sorted({rows[i].block for i in index})]
        depths = [
            w[b] - w[a]
            for members in groups
            for a, b in _candidates({i: w[i] for i in members}, span, (min_rack_depth_m, max_rack_depth_m))
        ]
        for members in groups:
            start, end = min(span[i][0] for i in members), max(span[i][1] for i in members)
            d = float(np.median([rows[i].d_m for i in members]))
            racks = _racks(
                {i: w[i] for i in members},
                {i: span[i] for i in members},
                typical_depth_m=_typical_depth(depths, 0.5 * rack_depth_tolerance_m) if depths else 0.0,
                min_rack_depth_m=min_rack_depth_m,
                max_rack_depth_m=max_rack_depth_m,
                rack_depth_tolerance_m=rack_depth_tolerance_m,
                min_aisle_width_m=min_aisle_width_m,
                default_aisle_width_m=default_aisle_width_m,
            )
            blocks.append((start, float(np.rint((end - start) / d)), d, racks))
        blocks.sort(key=lambda block: block[0])
        aisle_centres: list[float] = []
        for rack in (rack for block in blocks for rack in block[3]):
            if not any(abs(c - rack.centre) < 0.5 * min_aisle_width_m for c in aisle_centres):
                aisle_centres.append(rack.centre)
        aisle_centres.sort()
        offset = 0.0
        for start, bays, d, racks in blocks:
            for rack in racks:
                aisle = aisle_base + 1 + int(np.argmin([abs(c - rack.centre) for c in aisle_centres]))
                bins += _rack_bins(rows, rack, u, v, aisle=aisle, start=start, first_slot=int(offset),
                                   spacing=d, standoff=min(access_standoff_m, 0.5 * rack.width))
            offset += bays
        aisle_base += len(aisle_centres)
    logger.debug("%d floor bins in %d regions", len(bins), len({r.region for r in rows}))
    return bins


def _rack_bins(
    rows: list[RackRow],
    rack: _Rack,
    u: FloatArray,
    v: FloatArray,
    *,
    aisle: int,
    start: float,
    first_slot: int,
    spacing: float,
    standoff: float,
) -> list[StorageBin]:
    """The cells of one rack; bays counted from along position ``start`` (metres), the first being slot
    ``first_slot`` + 1 (odd bays on the aisle's left, ``rack.side`` > 0)."""
    row, back = rows[rack.front], rows[rack.back]
    back_offset = float(back.uprights.mean(axis=0) @ v - row.uprights.mean(axis=0) @ v)
    back_dir = np.sign(back_offset) * v
    depth = abs(back_offset)
    lo, hi = float((back.uprights @ u).min()), float((back.uprights @ u).max())
    out = []
    for j in range(row.n - 1):
        p, q = row.uprights[j], row.uprights[j + 1]
        mid_along = 0.5 * float((p + q) @ u)
        if not lo - 0.25 * row.d_m <= mid_along <= hi + 0.25 * row.d_m:
            continue
        behind = _back_uprights(back, np.array([p, q]) + depth * back_dir)
        if not _supported(row, j, back, behind):
            continue
        if (q - p) @ u < 0:
            p, q = q, p
        footprint = np.array([p, q, q + depth * back_dir, p + depth * back_dir])
        slot = first_slot + int(np.floor((mid_along - start) / spacing)) + 1
        bay = 2 * slot - 1 if rack.side > 0 else 2 * slot
        access = 0.5 * (p + q) - back_dir * standoff
        yaw = float(np.arctan2(back_dir[1], back_dir[0]))
        out.append(
            StorageBin(
                f"{aisle:02d}-{bay:03d}",
                aisle,
                bay,
                footprint,
                footprint.mean(axis=0),
                (float(access[0]), float(access[1]), yaw),
                rack.front,
                rack.back,
                bin_confidence(np.concatenate([row.sigma_m[j : j + 2], back.sigma_m[behind]])),
            )
        )
    return out

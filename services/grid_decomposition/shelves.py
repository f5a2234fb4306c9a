"""Shelves a lidar sees only as rows of short dashes (the upright frames of a rack).

A low 2-D lidar sees a pallet rack as its upright frames: each frame (two uprights and the
bottom cross beam, as deep as the rack) is a short thin dash, the racks of a bank stand side by
side so their frames form rows of evenly spaced, equally long dashes, and a rack 4 m long shows
one such row at each of its frames (AWS small warehouse: six racks 0.9 m deep at a 1.8 m pitch,
frames 2 m apart). No decomposition line lies on the 2-3 px dash ends, so no face has a rack's
shape; this module finds the banks from the dashes themselves: rows of at least
``min_dashes`` collinear dashes of regular pitch, rows paired when parallel, ``min_row_gap_m`` to
``max_row_gap_m`` apart and with their dashes aligned, a rack per column of aligned dashes and
an aisle between neighbouring racks. Chairs and table legs of furnished offices are neither thin
dashes nor in long regular rows, so offices give nothing.
"""

from __future__ import annotations

import itertools
import math
from typing import NamedTuple

import cv2
import numpy as np
import numpy.typing as npt
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from services.grid_decomposition.arrays import Components, components, nonzero_rc


class ShelfBanks(NamedTuple):
    """Racks and the aisles between them, found from rows of dashes.

    Attributes
    ----------
    storage : (H, W) bool
        Footprints of the racks (a column of aligned dashes over the paired rows).
    aisle : (H, W) bool
        Free strips between neighbouring racks of a bank.
    outline : (H, W) bool
        Borders of racks and aisles, 1 px wide: cuts for the planar subdivision.
    """

    storage: npt.NDArray[np.bool_]
    aisle: npt.NDArray[np.bool_]
    outline: npt.NDArray[np.bool_]


class _Dashes(NamedTuple):
    center: npt.NDArray[np.float64]  # (D, 2) x, y px
    direction: npt.NDArray[np.float64]  # (D, 2) unit, x >= 0 half-plane
    length: npt.NDArray[np.float64]  # (D,) px
    corners: npt.NDArray[np.float32]  # (D, 4, 2) rectangle corners


def _dashes(
    occupied: Components, min_length_px: float, max_length_px: float, max_thickness_px: float
) -> _Dashes:
    """Thin straight obstacle components between ``min_length_px`` and ``max_length_px`` long."""
    parts, stats = occupied.labels, occupied.stats
    big = np.maximum(stats[:, cv2.CC_STAT_WIDTH], stats[:, cv2.CC_STAT_HEIGHT])
    candidates = np.flatnonzero(
        (big >= min_length_px * math.sqrt(0.5))
        & (big <= max_length_px + 2)
        & (stats[:, cv2.CC_STAT_AREA] <= (max_length_px + 2) * (max_thickness_px + 1))
    )
    centers, directions, lengths, corners = [], [], [], []
    for i in candidates[candidates > 0]:
        x, y, w, h = stats[i, :4]
        rows, cols = nonzero_rc(parts[y : y + h, x : x + w] == i)
        rect = cv2.minAreaRect(np.column_stack([cols + x, rows + y]).astype(np.float32))
        (cx, cy), (rw, rh), angle = rect
        length, thick = max(rw, rh) + 1.0, min(rw, rh) + 1.0
        if not (min_length_px <= length <= max_length_px and thick <= max_thickness_px):
            continue
        theta = math.radians(angle) + (0.0 if rw >= rh else math.pi / 2)
        d = np.array([math.cos(theta), math.sin(theta)])
        centers.append((cx, cy))
        directions.append(d if d[0] > 0 or (d[0] == 0 and d[1] > 0) else -d)
        lengths.append(length)
        corners.append(cv2.boxPoints(rect))
    if not centers:
        return _Dashes(np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0), np.zeros((0, 4, 2), np.float32))
    return _Dashes(np.array(centers), np.array(directions), np.array(lengths), np.array(corners, np.float32))


def _groups(n: int, pairs: npt.NDArray[np.int64]) -> npt.NDArray[np.int32]:
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n)) if len(pairs) else None
    if graph is None:
        return np.arange(n, dtype=np.int32)
    _, group = connected_components(graph, directed=False)
    return np.asarray(group, dtype=np.int32)


def find_shelf_banks(
    occupied: npt.NDArray[np.bool_],
    free: npt.NDArray[np.bool_],
    *,
    resolution_m: float,
    min_dash_m: float = 0.5,
    max_dash_m: float = 1.2,
    max_thickness_m: float = 0.2,
    min_dashes: int = 4,
    max_pitch_deviation: float = 0.2,
    min_row_gap_m: float = 0.8,
    max_row_gap_m: float = 2.5,
    max_angle_deg: float = 5.0,
    collinear_m: float = 0.15,
    labelled: Components | None = None,
) -> ShelfBanks:
    """Racks seen as rows of short dashes, and the aisles between them.

    Parameters
    ----------
    occupied, free : (H, W) bool
        Occupied and free cells (unknown cells are neither: a dash may stand before unknown space).
    min_dash_m, max_dash_m, max_thickness_m : float
        A dash is an occupied component this long and at most this thick.
    min_dashes, max_pitch_deviation : int, float
        A row has at least ``min_dashes`` collinear dashes of similar length (within
        ``max_pitch_deviation`` of their median) whose centre spacings are all within
        ``max_pitch_deviation`` of their median, which leaves a gap between dashes.
    min_row_gap_m, max_row_gap_m : float
        Rows are paired when parallel, this far apart and with at least ``min_dashes`` of their
        dashes aligned (centres within a quarter pitch along the row).
    max_angle_deg, collinear_m : float
        Tolerances for parallel and collinear.
    labelled : Components, optional
        ``components(occupied)``, when already labelled.

    Returns
    -------
    ShelfBanks
        Empty masks where no bank is found.
    """
    shape = occupied.shape
    empty = np.zeros(shape, dtype=bool)
    labelled = components(occupied) if labelled is None else labelled
    d = _dashes(labelled, min_dash_m / resolution_m, max_dash_m / resolution_m, max_thickness_m / resolution_m)
    n = d.length.size
    if n < 2 * min_dashes:
        return ShelfBanks(empty, empty.copy(), empty.copy())
    cos_tol = math.cos(math.radians(max_angle_deg))
    parallel = np.abs(d.direction @ d.direction.T) >= cos_tol
    delta = d.center[None, :, :] - d.center[:, None, :]  # j - i
    along = np.einsum("ijk,ik->ij", delta, d.direction)
    across = np.abs(np.einsum("ijk,ik->ij", delta, d.direction[:, ::-1] * np.array([-1.0, 1.0])))
    collinear = parallel & (across <= collinear_m / resolution_m) & (np.abs(along) <= 3.0 * max_dash_m / resolution_m)
    i, j = np.nonzero(np.triu(collinear, 1))
    row_of = _groups(n, np.column_stack([i, j]))
    rows: list[npt.NDArray[np.int64]] = []
    pitches: list[float] = []
    for r in np.unique(row_of):
        members = np.flatnonzero(row_of == r)
        if members.size < min_dashes:
            continue
        axis = d.direction[members[0]]
        members = members[np.argsort(d.center[members] @ axis)]
        spacing = np.diff(d.center[members] @ axis)
        pitch, length = float(np.median(spacing)), float(np.median(d.length[members]))
        regular = np.all(np.abs(spacing - pitch) <= max_pitch_deviation * pitch)
        even = np.all(np.abs(d.length[members] - length) <= max_pitch_deviation * length)
        if regular and even and pitch >= 1.2 * length:
            rows.append(members)
            pitches.append(pitch)
    if len(rows) < 2:
        return ShelfBanks(empty, empty.copy(), empty.copy())
    # columns: dashes aligned across paired rows
    links: list[tuple[int, int]] = []
    for a in range(len(rows)):
        for b in range(a + 1, len(rows)):
            axis = d.direction[rows[a][0]]
            if abs(float(axis @ d.direction[rows[b][0]])) < cos_tol:
                continue
            normal = np.array([-axis[1], axis[0]])
            gap = abs(float((d.center[rows[b]].mean(axis=0) - d.center[rows[a]].mean(axis=0)) @ normal))
            if not (min_row_gap_m / resolution_m <= gap <= max_row_gap_m / resolution_m):
                continue
            pa, pb = d.center[rows[a]] @ axis, d.center[rows[b]] @ axis
            offset = np.abs(pa[:, None] - pb[None, :])
            best = np.argmin(offset, axis=1)
            aligned = offset[np.arange(pa.size), best] <= 0.25 * min(pitches[a], pitches[b])
            if aligned.sum() >= min_dashes:
                links.extend(zip(rows[a][aligned].tolist(), rows[b][best[aligned]].tolist(), strict=True))
    if not links:
        return ShelfBanks(empty, empty.copy(), empty.copy())
    in_bank = np.unique(np.array(links))
    column_of = _groups(n, np.array(links, dtype=np.int64))
    storage = np.zeros(shape, dtype=np.uint8)
    aisle = np.zeros(shape, dtype=np.uint8)
    outline = np.zeros(shape, dtype=np.uint8)
    bank_of = _groups(n, np.array([(r[0], k) for r in rows for k in r] + links, dtype=np.int64))
    for bank in np.unique(bank_of[in_bank]):
        # every dash of a bank is linked to an aligned one: each column holds two or more
        columns = [np.flatnonzero(column_of == c) for c in np.unique(column_of[in_bank[bank_of[in_bank] == bank]])]
        axis = d.direction[columns[0][0]]
        columns.sort(key=lambda c: float(d.center[c].mean(axis=0) @ axis))
        hulls = [cv2.convexHull(d.corners[c].reshape(-1, 2)).astype(np.int32) for c in columns]
        for hull in hulls:
            cv2.fillConvexPoly(storage, hull, 1)
            cv2.polylines(outline, [hull], True, 1, 1, cv2.LINE_8)
        for left, right in itertools.pairwise(columns):
            both = cv2.convexHull(d.corners[np.r_[left, right]].reshape(-1, 2)).astype(np.int32)
            cv2.fillConvexPoly(aisle, both, 1)
            cv2.polylines(outline, [both], True, 1, 1, cv2.LINE_8)
    rack = storage.astype(bool)
    return ShelfBanks(rack & free, aisle.astype(bool) & ~rack & free, outline.astype(bool))


def majority_faces(
    face_image: npt.NDArray[np.int32], n_faces: int, mask: npt.NDArray[np.bool_], free: npt.NDArray[np.bool_]
) -> npt.NDArray[np.bool_]:
    """(F + 1,) faces with more than half of their free pixels in ``mask`` (index 0 False)."""
    if not mask.any():
        return np.zeros(n_faces + 1, dtype=bool)
    faces = face_image[free]
    total = np.bincount(faces, minlength=n_faces + 1)
    inside = np.bincount(faces, weights=mask[free], minlength=n_faces + 1)
    out: npt.NDArray[np.bool_] = inside > 0.5 * total
    out[0] = False
    return out

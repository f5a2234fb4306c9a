"""Rack-row models fitted to a landmark map (paper A, sections 2 and 3.1).

Each row is the model ``M(n, d, x, y, theta)``: ``n`` uprights ``d`` apart from ``(x, y)``
along ``theta``. Rows are segmented by the closed-form Hough transform with DBSCAN around the
dominant orientations of every neighbourhood, their spacing found by Fourier analysis, pieces
of one row joined and leftover landmarks on a row's lattice pulled in
(:mod:`services.pillar_mapping.join`). Regions (rows of one orientation close together) are cut
into blocks where a cross aisle runs through them (:mod:`services.pillar_mapping.blocks`), and
the global constraints are applied per block: the dominant orientation, the modal spacing
(refined by least squares over all its rows), landmarks off their row's lattice dropped, pieces
on one line joined and free landmarks on the lattice pulled in or made into rows, and the
initialisation (and end) lines through the rows' first (and last) uprights, which restore end
uprights that were never seen. A last optimisation places each model on its landmarks.
"""

from __future__ import annotations

import logging
from typing import NamedTuple

import numpy as np
import numpy.typing as npt
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from services.pillar_mapping.blocks import block_cuts, lattice_breaks, split_rows, step_spacing
from services.pillar_mapping.errors import PillarMappingError
from services.pillar_mapping.hough import (
    hough_pairs,
    local_orientations,
    refine_orientation,
    segment_aligned,
    wrap_half,
)
from services.pillar_mapping.join import complete_block, join_rows
from services.pillar_mapping.rowmodel import (
    RowModel,
    along_line,
    fit_model,
    lattice_inliers,
    lattice_phase,
    validated_landmarks,
)

logger = logging.getLogger(__name__)

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]


class RackRow(NamedTuple):
    """One fitted row.

    ``n`` uprights ``d_m`` apart from ``(x_m, y_m)`` along ``theta_rad`` in [-pi/2, pi/2);
    ``uprights`` (n, 2) metres; ``observed`` (n,) whether a landmark supports each;
    ``members`` indices of the input landmarks in the row; ``region`` its region number (rows of
    one orientation close together) and ``block`` the block of the region it lies in (0, 1, ...
    along the rows, between cross aisles); ``sigma_m`` (n,) the largest standard deviation of the
    landmark supporting each upright, metres, inf where none does.
    """

    n: int
    d_m: float
    theta_rad: float
    x_m: float
    y_m: float
    region: int
    block: int
    uprights: FloatArray
    observed: npt.NDArray[np.bool_]
    members: IntArray
    sigma_m: FloatArray


def _split(table: FloatArray, members: IntArray, u: FloatArray, max_gap_m: float) -> list[IntArray]:
    s = table[members, :2] @ u
    order = np.argsort(s)
    cuts = np.flatnonzero(np.diff(s[order]) > max_gap_m) + 1
    return [members[part] for part in np.split(order, cuts)]


def _line_rms(pts: FloatArray) -> float:
    """RMS distance of points from their total-least-squares line, metres."""
    centred = pts - pts.mean(axis=0)
    return float(np.sqrt(np.linalg.eigvalsh(centred.T @ centred / len(pts))[0]))


def _merge_collinear(
    pts: FloatArray, labels: IntArray, u: FloatArray, *, window_m: float = 0.6, max_rms_m: float = 0.06
) -> IntArray:
    """Join sets lying on one line (DBSCAN splits a row where several uprights are missing).

    Sets whose offsets across ``u`` differ by less than ``window_m`` are joined when the union
    still fits one line to ``max_rms_m``.
    """
    found = np.unique(labels[labels >= 0])
    if found.size < 2:
        return labels
    normal = np.array([-u[1], u[0]])
    offset = np.array([np.median(pts[labels == lab] @ normal) for lab in found])
    order = np.argsort(offset)
    groups = {int(lab): np.flatnonzero(labels == lab) for lab in found}
    owner = {int(lab): int(lab) for lab in found}
    for a_pos, a in enumerate(order):
        for b in order[a_pos + 1 :]:
            if offset[b] - offset[a] > window_m:
                break
            ra, rb = owner[int(found[a])], owner[int(found[b])]
            if ra == rb:
                continue
            union = np.concatenate([groups[ra], groups[rb]])
            if _line_rms(pts[union]) <= max_rms_m:
                groups[ra] = union
                for lab, o in owner.items():
                    if o == rb:
                        owner[lab] = ra
                del groups[rb]
    out = np.full(len(labels), -1, dtype=np.int64)
    for root, members in groups.items():
        out[members] = root
    return out


def _segment(
    table: FloatArray,
    pitch: tuple[float, float],
    *,
    min_uprights: int,
    min_coherence: float,
    max_missing_run: int,
    min_fill: float,
) -> list[RowModel]:
    """Regular aligned sets along every dominant orientation; each landmark kept in the longest."""
    pts = table[:, :2]
    pairs = hough_pairs(pts, min_length_m=0.9 * pitch[0], max_length_m=2.2 * pitch[1])
    candidates: list[RowModel] = []
    for k, peak in enumerate(local_orientations(pts, pairs)):
        alpha = refine_orientation(pts, pairs, float(peak))
        u0 = np.array([np.cos(alpha), np.sin(alpha)])
        labels = _merge_collinear(pts, segment_aligned(pts, pairs, float(alpha)), u0)
        found: list[RowModel] = []
        for label in np.unique(labels[labels >= 0]):
            for piece in _split(table, np.flatnonzero(labels == label), u0, (max_missing_run + 1.5) * pitch[1]):
                if piece.size < min_uprights:
                    continue
                row = fit_model(table, piece, u0, k, pitch)
                # a set broken by a cross aisle half a bay off its lattice is irregular as a whole, regular in parts
                parts = [row] if row.coherence >= min_coherence else [
                    fit_model(table, part, u0, k, pitch)
                    for part in lattice_breaks(table, piece, u0, pitch)
                    if part.size >= min_uprights
                ]
                found += [r for r in parts if r.coherence >= min_coherence and r.members.size >= min_fill * r.n]
        inside = sum(r.members.size for r in found)
        if inside < 0.5 * int((labels >= 0).sum()):
            logger.debug(
                "orientation %.2f deg: %d of %d aligned landmarks in regular rows; not a row orientation",
                np.rad2deg(alpha),
                inside,
                int((labels >= 0).sum()),
            )
            continue
        candidates.extend(found)
    return _claim(table, candidates, pitch, min_uprights=min_uprights, min_coherence=min_coherence)


def _claim(
    table: FloatArray,
    candidates: list[RowModel],
    pitch: tuple[float, float],
    *,
    min_uprights: int,
    min_coherence: float,
) -> list[RowModel]:
    """Give each landmark to one row: orientations in turn, the one whose regular sets of still-free
    landmarks are longest (sum of squared sizes) first, so a region's rows come before the
    diagonals of its lattice; within an orientation the longest sets first."""
    claimed = np.zeros(len(table), dtype=bool)
    rows: list[RowModel] = []
    pending = {o: [r for r in candidates if r.orientation == o] for o in {r.orientation for r in candidates}}

    def usable(row: RowModel) -> npt.NDArray[np.int64]:
        free = row.members[~claimed[row.members]]
        return free if free.size >= max(min_uprights, 0.8 * row.members.size) else free[:0]

    while pending:
        score = {o: sum(usable(r).size ** 2 for r in group) for o, group in pending.items()}
        best = max(score, key=lambda o: score[o])
        if score[best] == 0:
            break
        for row in sorted(pending.pop(best), key=lambda r: -r.members.size):
            free = usable(row)
            if free.size == 0:
                continue
            kept = (
                row if free.size == row.members.size else fit_model(table, free, row.direction, row.orientation, pitch)
            )
            if kept.coherence < min_coherence:
                continue
            claimed[kept.members] = True
            rows.append(kept)
    return rows


def _extent(row: RowModel, u: FloatArray) -> tuple[float, float]:
    a = float(row.centre @ u + row.first * (row.direction @ u))
    b = a + (row.n - 1) * row.d * float(row.direction @ u)
    return min(a, b), max(a, b)


def _regions(rows: list[RowModel], gap_m: float) -> IntArray:
    """Region label per row: rows of one orientation within ``gap_m`` of each other, overlapping along."""
    count = len(rows)
    src, dst = [], []
    for i in range(count):
        for j in range(i + 1, count):
            a, b = rows[i], rows[j]
            if a.orientation != b.orientation:
                continue
            u = a.direction
            v = np.array([-u[1], u[0]])
            (lo_a, hi_a), (lo_b, hi_b) = _extent(a, u), _extent(b, u)
            if abs((b.centre - a.centre) @ v) <= gap_m and min(hi_a, hi_b) - max(lo_a, lo_b) > -gap_m:
                src.append(i)
                dst.append(j)
    graph = coo_matrix((np.ones(len(src)), (src, dst)), shape=(count, count))
    _, labels = connected_components(graph, directed=False)
    out: IntArray = np.asarray(labels, dtype=np.int64)
    return out


def _direction(rows: list[RowModel]) -> FloatArray:
    """Unit vector (2,) of the median direction of ``rows`` (all found along one orientation)."""
    theta = float(np.median([np.arctan2(r.direction[1], r.direction[0]) for r in rows]))
    return np.array([np.cos(theta), np.sin(theta)])


def _lattice(
    table: FloatArray,
    rows: list[RowModel],
    free: npt.NDArray[np.bool_],
    *,
    spacing_tolerance: float,
    angle_tolerance_rad: float,
) -> tuple[list[RowModel], FloatArray, float]:
    """Rows on their block's dominant orientation and spacing, with their phase and count on that lattice.

    The spacing is the mode of the rows' spacings, refined by least squares over the landmarks of
    every row that takes it (each row its own offset, one spacing for all); rows whose spacing or
    angle is off by more than the tolerances keep their own. Landmarks off their row's line or
    lattice (:func:`~services.pillar_mapping.rowmodel.lattice_inliers`) leave it and are marked
    ``free``; rows left with fewer than two landmarks are dropped. Returns the rows, the block's
    direction (2,) and spacing, metres.
    """
    thetas = np.array([np.arctan2(r.direction[1], r.direction[0]) for r in rows])
    u0 = _direction(rows)
    theta0 = float(np.arctan2(u0[1], u0[0]))
    ds = np.array([r.d for r in rows])
    hist, edges = np.histogram(ds, bins=np.arange(ds.min() - 0.005, ds.max() + 0.015, 0.01))
    mode = 0.5 * (edges[np.argmax(hist)] + edges[np.argmax(hist) + 1])
    d0 = float(np.median(ds[np.abs(ds - mode) <= spacing_tolerance * mode]))
    aligned = [abs(float(wrap_half(t - theta0))) <= angle_tolerance_rad for t in thetas]
    regular = [bool(abs(r.d - d0) <= spacing_tolerance * d0) for r in rows]
    placed = []
    for r, ok_angle, ok_d in zip(rows, aligned, regular, strict=True):
        row = r._replace(direction=u0 if ok_angle else r.direction, d=d0 if ok_d else r.d)
        inliers = lattice_inliers(table, row)
        free[row.members[~inliers]] = True
        if inliers.sum() >= 2:
            placed.append((row._replace(members=row.members[inliers]), ok_angle and ok_d))
    num = den = 0.0
    for row, on in placed:
        if on:
            s, _ = along_line(table, row.members, row.centre, u0)
            _, slots = lattice_phase(s, d0)
            k = slots - slots.mean()
            num, den = num + float(k @ (s - s.mean())), den + float(k @ k)
    d_fit = num / den if den > 0 else d0
    out = []
    for row, on in placed:
        d = d_fit if on or row.d == d0 else row.d
        s, _ = along_line(table, row.members, row.centre, row.direction)
        first, slots = lattice_phase(s, d)
        out.append(row._replace(d=d, first=first, n=int(slots.max()) + 1))
    return out, u0, d_fit


def _end_line(w: FloatArray, line: FloatArray, tolerance_m: float) -> FloatArray:
    """Where the line most rows' ends ``line`` (R,) lie on (within ``tolerance_m``, metres along) puts each
    row's end, given the rows' offsets across ``w`` (R,).

    Candidates are the lines through every two rows' ends and the lines square to the rows through
    each one; the one with most ends on it wins (of equals the squarest), refined by least squares
    over those ends. A few rows short of the line cannot tilt it, as they tilt a regression.
    """
    i, j = np.triu_indices(w.size, k=1)
    apart = np.abs(w[j] - w[i]) > 0.1
    i, j = i[apart], j[apart]
    slope = np.concatenate([np.zeros(w.size), (line[j] - line[i]) / (w[j] - w[i])])
    intercept = np.concatenate([line, line[i] - slope[w.size :] * w[i]])
    inliers = np.abs(intercept[:, None] + slope[:, None] * w[None, :] - line[None, :]) <= tolerance_m
    best = int(np.lexsort((np.abs(slope), -inliers.sum(axis=1)))[0])
    on = inliers[best]
    if np.ptp(w[on]) > 0.1:
        fitted_slope, fitted_intercept = np.polyfit(w[on], line[on], 1)
    else:
        fitted_slope, fitted_intercept = 0.0, float(line[on].mean())
    return np.asarray(fitted_intercept + fitted_slope * w)


def _restore_ends(rows: list[RowModel], u0: FloatArray, d0: float, *, max_restored: int) -> list[RowModel]:
    """Unseen uprights restored at rows' ends from the block's initialisation (and end) line.

    The lines are robust fits (:func:`_end_line`) of the rows' first (last) upright positions against
    their offsets across; a row short of a line by a whole number of spacings, at most ``max_restored``,
    is extended to it, but never beyond the block's seen extent (the first and last seen upright of
    any of its rows): in a partly surveyed block the lines' slopes come from ends not seen yet.
    Needs three rows on the block's lattice (direction ``u0``, spacing ``d0``).
    """
    on = [i for i, r in enumerate(rows) if r.d == d0 and np.array_equal(r.direction, u0)]
    if len(on) < 3:
        return rows
    out = list(rows)
    v0 = np.array([-u0[1], u0[0]])
    w = np.array([rows[i].centre @ v0 for i in on])
    starts = np.array([rows[i].centre @ u0 + rows[i].first for i in on])
    ends = starts + np.array([(rows[i].n - 1) * d0 for i in on])
    seen = (starts.min() - 0.25 * d0, ends.max() + 0.25 * d0)
    for line, sign in ((starts, -1), (ends, 1)):
        predicted = _end_line(w, line, min(0.15, 0.25 * d0))
        for k, i in enumerate(on):
            r = out[i]
            missing = sign * (predicted[k] - line[k]) / d0
            m = int(np.rint(missing))
            inside = seen[0] <= line[k] + sign * m * d0 <= seen[1]
            if 1 <= m <= max_restored and abs(missing - m) <= 0.25 and inside:
                out[i] = r._replace(first=r.first - m * d0 if sign < 0 else r.first, n=r.n + m)
    return out


def _fit_block(
    table: FloatArray,
    rows: list[RowModel],
    free: npt.NDArray[np.bool_],
    *,
    spacing_tolerance: float,
    angle_tolerance_rad: float,
    max_restored: int,
) -> list[RowModel]:
    """A block's rows on its lattice, completed (:func:`~services.pillar_mapping.join.complete_block`), their
    ends restored, sorted by offset across."""
    options = {"spacing_tolerance": spacing_tolerance, "angle_tolerance_rad": angle_tolerance_rad}
    first, _, _ = _lattice(table, rows, free, **options)
    if not first:
        return []
    completed, u0, d0 = _lattice(table, complete_block(table, first, free), free, **options)
    if not completed:
        return []
    restored = _restore_ends(completed, u0, d0, max_restored=max_restored)
    v = np.array([-u0[1], u0[0]])
    return sorted(restored, key=lambda r: float(r.centre @ v))


def _place(table: FloatArray, row: RowModel, sigma_floor_m: float) -> FloatArray:
    """Translate the model to maximise the landmark densities at its uprights (eq. 7).

    With each landmark's density dominated by its nearest model upright, the objective's
    maximum is the weighted least-squares shift of the uprights onto their landmarks.
    """
    base = row.centre + (row.first + np.arange(row.n)[:, None] * row.d) * row.direction
    mu = table[row.members, :2]
    slots = np.clip(np.rint(((mu - row.centre) @ row.direction - row.first) / row.d).astype(np.int64), 0, row.n - 1)
    inv = np.linalg.inv(table[row.members][:, [2, 3, 3, 4]].reshape(-1, 2, 2) + sigma_floor_m**2 * np.eye(2))
    shift = np.linalg.solve(inv.sum(axis=0), np.einsum("kij,kj->i", inv, mu - base[slots]))
    return np.asarray(base + shift)


def fit_rack_rows(
    landmarks: npt.ArrayLike,
    *,
    min_bay_pitch_m: float = 1.5,
    max_bay_pitch_m: float = 4.5,
    min_row_uprights: int = 4,
    min_coherence: float = 0.8,
    max_missing_run: int = 2,
    min_fill: float = 0.6,
    max_restored_uprights: int = 5,
    region_gap_m: float = 8.0,
    spacing_tolerance: float = 0.05,
    angle_tolerance_rad: float = float(np.deg2rad(1.0)),
    sigma_floor_m: float = 0.03,
) -> list[RackRow]:
    """Rack-row models of a landmark map.

    Parameters
    ----------
    landmarks : array_like, shape (N, 5) or (N, 2)
        ``x, y, sxx, sxy, syy`` per upright, metres and m^2 (or just ``x, y``).
    min_bay_pitch_m, max_bay_pitch_m : float
        Range of upright spacings along a row.
    min_row_uprights : int
        Fewest landmarks of a row.
    min_coherence : float
        Least regularity (Fourier coherence, 0..1) of a row's landmarks at its spacing.
    max_missing_run : int
        Most consecutive unseen uprights inside a row.
    min_fill : float
        Least fraction of a row's uprights that must have been seen.
    max_restored_uprights : int
        Most unseen uprights restored at a row's end from its region's initialisation or end line.
    region_gap_m : float
        Rows of one orientation closer than this (across) belong to one region.
    spacing_tolerance : float
        Relative spacing difference within which a row takes its region's modal spacing.
    angle_tolerance_rad : float
        Angle within which a row takes its region's dominant orientation.
    sigma_floor_m : float
        Added to landmark standard deviations when placing the models.

    Returns
    -------
    list of RackRow
        Sorted by region, block, then offset across the rows. Empty when there are no rows.

    Raises
    ------
    PillarMappingError
        On a malformed table, non-finite values or a bad pitch range.
    """
    if not 0 < min_bay_pitch_m < max_bay_pitch_m:
        raise PillarMappingError(f"bay pitch range [{min_bay_pitch_m}, {max_bay_pitch_m}] m is empty")
    table = validated_landmarks(landmarks)
    if len(table) < min_row_uprights:
        return []
    pitch = (min_bay_pitch_m, max_bay_pitch_m)
    rows = _segment(
        table,
        pitch,
        min_uprights=min_row_uprights,
        min_coherence=min_coherence,
        max_missing_run=max_missing_run,
        min_fill=min_fill,
    )
    if not rows:
        return []
    rows = join_rows(
        table,
        rows,
        pitch,
        spacing_tolerance=spacing_tolerance,
        max_gap_m=(max_missing_run + 1.5) * max_bay_pitch_m,
        min_coherence=min_coherence,
    )
    regions = _regions(rows, region_gap_m)
    order = sorted(
        range(int(regions.max()) + 1),
        key=lambda g: tuple(np.mean([rows[i].centre for i in np.flatnonzero(regions == g)], axis=0).round(1)),
    )
    blocks: list[tuple[int, int, list[RowModel]]] = []  # (region, block, rows)
    for number, g in enumerate(order):
        group = [rows[i] for i in np.flatnonzero(regions == g)]
        u0 = _direction(group)
        d_step = step_spacing(table, group, u0, pitch)
        cuts = block_cuts(table, group, u0, d_step)
        if cuts.size:
            logger.debug("region %d cut at %s m along", number, np.round(cuts, 2).tolist())
        cut = split_rows(table, group, cuts, u0, d_step) if cuts.size else [(0, r) for r in group]
        for b, k in enumerate(sorted({k for k, _ in cut})):
            blocks.append((number, b, [r for j, r in cut if j == k]))
    sxx, sxy, syy = table[:, 2], table[:, 3], table[:, 4]
    largest_sigma = np.sqrt(np.maximum(0.5 * (sxx + syy) + np.hypot(0.5 * (sxx - syy), sxy), 0.0))
    free = np.ones(len(table), dtype=bool)
    for _, _, block_rows in blocks:
        for row in block_rows:
            free[row.members] = False
    out: list[RackRow] = []
    for number, b, block_rows in blocks:
        group = _fit_block(
            table,
            block_rows,
            free,
            spacing_tolerance=spacing_tolerance,
            angle_tolerance_rad=angle_tolerance_rad,
            max_restored=max_restored_uprights,
        )
        for row in group:
            uprights = _place(table, row, sigma_floor_m)
            mu = table[row.members, :2]
            distance = np.hypot(*(uprights[:, None, :] - mu[None]).transpose(2, 0, 1))
            nearest = np.argmin(distance, axis=1)
            observed = distance[np.arange(row.n), nearest] <= min(0.25 * row.d, 0.3)
            theta = float(np.arctan2(row.direction[1], row.direction[0]))
            out.append(
                RackRow(
                    row.n,
                    row.d,
                    theta,
                    float(uprights[0, 0]),
                    float(uprights[0, 1]),
                    number,
                    b,
                    uprights,
                    observed,
                    row.members,
                    np.where(observed, largest_sigma[row.members[nearest]], np.inf),
                )
            )
    return out

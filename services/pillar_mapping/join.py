"""The join pass over segmented rows: pieces of one row merged, leftover landmarks pulled into rows.

Segmentation can cut a long row in two where several uprights in a row are missing or where a
stretch of it was voted into no aligned set, and it leaves landmarks near a row's ends in no
row at all. Both show up as rows with the wrong ``n`` and bins never made. This pass joins
collinear pieces whose spacing agrees and whose uprights fall on one lattice (the same phase
along the line), pulls every leftover landmark lying on a row's line at one of its lattice
slots into it, and re-estimates the row's spacing, phase and count from the enlarged set.
"""

from __future__ import annotations

import logging

import numpy as np
import numpy.typing as npt

from services.pillar_mapping.rowmodel import RowModel, along_line, fit_model, lattice_inliers, lattice_phase

logger = logging.getLogger(__name__)

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]


def _normal(u: FloatArray) -> FloatArray:
    return np.array([-u[1], u[0]])


def _lattice(table: FloatArray, members: IntArray, row: RowModel) -> tuple[IntArray, FloatArray]:
    """Slot (K,) of each landmark on ``row``'s lattice and its along-line residual (K,), metres."""
    s, _ = along_line(table, members, row.centre, row.direction)
    slots = np.rint((s - row.first) / row.d).astype(np.int64)
    return slots, s - row.first - slots * row.d


def _pull(
    table: FloatArray,
    row: RowModel,
    free: BoolArray,
    pitch: tuple[float, float],
    *,
    max_offset_m: float,
    phase_tolerance_m: float,
    max_gap_m: float,
) -> IntArray:
    """Free landmarks on ``row``'s line at an empty slot: inside the row, or beyond an end by a chain of
    steps no longer than ``max_gap_m``."""
    index = np.flatnonzero(free)
    across = (table[index, :2] - row.centre) @ _normal(row.direction)
    index = index[np.abs(across) <= max_offset_m]
    if index.size == 0:
        return index
    slots, residual = _lattice(table, index, row)
    taken, _ = _lattice(table, row.members, row)
    fits = (np.abs(residual) <= phase_tolerance_m) & ~np.isin(slots, taken)
    index, slots = index[fits], slots[fits]
    order = np.argsort(slots)
    index, slots = index[order], slots[order]
    _, first = np.unique(slots, return_index=True)  # one landmark per slot
    index, slots = index[first], slots[first]
    lo, hi = int(taken.min()), int(taken.max())
    keep = (slots >= lo) & (slots <= hi)
    reach = max(1, int(np.floor(max_gap_m / row.d)))
    end = hi
    for k in np.flatnonzero(slots > hi):
        if slots[k] - end > reach:
            break
        keep[k], end = True, int(slots[k])
    end = lo
    for k in np.flatnonzero(slots < lo)[::-1]:
        if end - slots[k] > reach:
            break
        keep[k], end = True, int(slots[k])
    return index[keep]


def _pull_leftovers(
    table: FloatArray,
    rows: list[RowModel],
    pitch: tuple[float, float],
    *,
    max_offset_m: float,
    phase_tolerance_m: float,
    spacing_tolerance: float,
    max_gap_m: float,
    min_coherence: float,
) -> list[RowModel]:
    free = np.ones(len(table), dtype=bool)
    for row in rows:
        free[row.members] = False
    out = []
    for original in sorted(rows, key=lambda r: -r.members.size):
        row = original
        for _ in range(3):
            found = _pull(
                table,
                row,
                free,
                pitch,
                max_offset_m=max_offset_m,
                phase_tolerance_m=phase_tolerance_m,
                max_gap_m=max_gap_m,
            )
            if found.size == 0:
                break
            refit = fit_model(table, np.concatenate([row.members, found]), row.direction, row.orientation, pitch)
            if refit.coherence < min_coherence or abs(refit.d - row.d) > spacing_tolerance * row.d:
                break
            free[found] = False
            row = refit
        out.append(row)
    return out


def _mergeable(
    table: FloatArray,
    a: RowModel,
    b: RowModel,
    pitch: tuple[float, float],
    *,
    max_offset_m: float,
    phase_tolerance_m: float,
    spacing_tolerance: float,
    max_gap_m: float,
    min_coherence: float,
) -> RowModel | None:
    """The row of ``a`` and ``b`` together if they are pieces of one row, else None."""
    if a.orientation != b.orientation or abs(a.d - b.d) > spacing_tolerance * min(a.d, b.d):
        return None
    for one, other in ((a, b), (b, a)):
        across = (table[other.members, :2] - one.centre) @ _normal(one.direction)
        if np.median(np.abs(across)) > max_offset_m:
            return None
    union = np.concatenate([a.members, b.members])
    joined = fit_model(table, union, a.direction, a.orientation, pitch)
    if joined.coherence < min_coherence or abs(joined.d - 0.5 * (a.d + b.d)) > spacing_tolerance * joined.d:
        return None
    slots, _ = _lattice(table, union, joined)
    if np.unique(slots).size < union.size or np.max(np.diff(np.sort(slots))) * joined.d > max_gap_m:
        return None
    # Each piece's phase at the pieces' common spacing: a joint fit would absorb a phase jump
    # into a slightly wrong spacing, the pieces' own spacings do not.
    d = (a.d * a.n + b.d * b.n) / (a.n + b.n)
    s, _ = along_line(table, union, joined.centre, joined.direction)
    turns = np.exp(2j * np.pi * s / d)
    jump = np.angle(np.mean(turns[: a.members.size]) * np.conj(np.mean(turns[a.members.size :])))
    return joined if abs(float(jump)) / (2 * np.pi) * d <= phase_tolerance_m else None


def _merge_pieces(
    table: FloatArray,
    rows: list[RowModel],
    pitch: tuple[float, float],
    *,
    max_offset_m: float,
    phase_tolerance_m: float,
    spacing_tolerance: float,
    max_gap_m: float,
    min_coherence: float,
) -> list[RowModel]:
    rows = list(rows)
    merged = True
    while merged:
        merged = False
        offsets = [float(r.centre @ _normal(r.direction)) for r in rows]
        order = np.argsort(offsets)
        for pos, i in enumerate(order):
            for j in order[pos + 1 :]:
                if offsets[j] - offsets[i] > 4 * max_offset_m:
                    break
                joined = _mergeable(
                    table,
                    rows[i],
                    rows[j],
                    pitch,
                    max_offset_m=max_offset_m,
                    phase_tolerance_m=phase_tolerance_m,
                    spacing_tolerance=spacing_tolerance,
                    max_gap_m=max_gap_m,
                    min_coherence=min_coherence,
                )
                if joined is not None:
                    logger.debug("joined row pieces of %d and %d landmarks", rows[i].members.size, rows[j].members.size)
                    rows = [r for k, r in enumerate(rows) if k not in (i, j)] + [joined]
                    merged = True
                    break
            if merged:
                break
    return rows


def join_rows(
    table: FloatArray,
    rows: list[RowModel],
    pitch: tuple[float, float],
    *,
    max_offset_m: float = 0.1,
    phase_tolerance_m: float = 0.1,
    spacing_tolerance: float = 0.05,
    max_gap_m: float = 15.0,
    min_coherence: float = 0.8,
) -> list[RowModel]:
    """Rows with their pieces merged and leftover landmarks on their lattices pulled in.

    Parameters
    ----------
    table : ndarray of float64, shape (N, 5)
        Landmarks ``x, y, sxx, sxy, syy``, metres and m^2.
    rows : list of RowModel
        Rows from segmentation, each landmark in at most one.
    pitch : (float, float)
        Least and most upright spacing, metres.
    max_offset_m : float
        Largest distance across a row's line of a landmark (median of a piece's) that joins it.
    phase_tolerance_m : float
        Largest along-line distance of a pulled landmark from its lattice slot, and largest
        difference of two pieces' mean lattice residuals: pieces of parallel rows broken by a
        cross aisle sit off each other's lattice unless the aisle is a multiple of the pitch.
    spacing_tolerance : float
        Relative spacing difference within which pieces may be one row.
    max_gap_m : float
        Longest stretch without a landmark inside a joined row, metres.
    min_coherence : float
        Least Fourier coherence of a joined or enlarged row.

    Returns
    -------
    list of RowModel
        Each landmark still in at most one row; spacing, phase and count re-estimated.
    """
    options = {
        "max_offset_m": max_offset_m,
        "phase_tolerance_m": phase_tolerance_m,
        "spacing_tolerance": spacing_tolerance,
        "max_gap_m": max_gap_m,
        "min_coherence": min_coherence,
    }
    rows = _pull_leftovers(table, rows, pitch, **options)
    rows = _merge_pieces(table, rows, pitch, **options)
    return _pull_leftovers(table, rows, pitch, **options)


def _on_lattice(table: FloatArray, members: IntArray, row: RowModel) -> RowModel:
    """``row`` with ``members`` as its landmarks, its line through their mean, phase and count on its lattice."""
    centre = table[members, :2].mean(axis=0)
    centre = row.centre + ((centre - row.centre) @ _normal(row.direction)) * _normal(row.direction)
    s, _ = along_line(table, members, centre, row.direction)
    first, slots = lattice_phase(s, row.d)
    return row._replace(members=members, centre=centre, first=first, n=int(slots.max()) + 1)


def _same_line(table: FloatArray, a: RowModel, b: RowModel, max_offset_m: float, phase_tolerance_m: float) -> bool:
    """Whether ``b`` continues ``a``: same lattice, on ``a``'s line and phase, in slots ``a`` leaves empty."""
    if a.d != b.d or not np.array_equal(a.direction, b.direction):
        return False
    if abs(float((b.centre - a.centre) @ _normal(a.direction))) > max_offset_m:
        return False
    slots_b, residual = _lattice(table, b.members, a)
    if np.abs(np.median(residual)) > phase_tolerance_m:
        return False
    slots_a, _ = _lattice(table, a.members, a)
    return not np.isin(slots_b, slots_a).any()


def complete_block(
    table: FloatArray,
    rows: list[RowModel],
    free: BoolArray,
    *,
    max_offset_m: float = 0.1,
    phase_tolerance_m: float = 0.1,
    min_landmarks: int = 3,
    max_rack_depth_m: float = 1.6,
) -> list[RowModel]:
    """A block's rows with pieces of one line merged and free landmarks on their lattices pulled in.

    Run once the block's spacing and orientation are known (every row on one lattice), which is
    far more precise than one piece's own: pieces that segmentation or the first join pass could
    not join (few landmarks, a noisy spacing) are joined when they lie on one line at one phase,
    and every free landmark on a row's line, at an empty slot of its lattice and within the
    block's extent along the rows (never across a cross aisle), is pulled into it. At least
    ``min_landmarks`` free landmarks on one line parallel to the rows, within ``max_rack_depth_m``
    of the block across and on one lattice of its spacing, make a new row.

    Parameters
    ----------
    table : ndarray of float64, shape (N, 5)
        Landmarks ``x, y, sxx, sxy, syy``, metres and m^2.
    rows : list of RowModel
        The rows of one block, on its lattice.
    free : ndarray of bool, shape (N,)
        Landmarks in no row; those pulled in are cleared.
    max_offset_m, phase_tolerance_m : float
        Largest distance of a landmark (or a piece's line) across a row's line and along it from
        its lattice slot (a piece's median), metres.

    Returns
    -------
    list of RowModel
        The block's rows, fewer when pieces were joined.
    """
    rows = sorted(rows, key=lambda r: -r.members.size)
    merged = True
    while merged:
        merged = False
        for i, j in ((i, j) for i in range(len(rows)) for j in range(len(rows)) if i != j):
            if _same_line(table, rows[i], rows[j], max_offset_m, phase_tolerance_m):
                joined = _on_lattice(table, np.concatenate([rows[i].members, rows[j].members]), rows[i])
                rows = [r for k, r in enumerate(rows) if k not in (i, j)] + [joined]
                merged = True
                break
    if not rows:
        return rows
    u = rows[0].direction
    starts = np.array([r.centre @ u + r.first * (r.direction @ u) for r in rows])
    ends = starts + np.array([(r.n - 1) * r.d * (r.direction @ u) for r in rows])
    lo, hi = float(np.minimum(starts, ends).min()), float(np.maximum(starts, ends).max())
    rows = rows + _new_rows(table, rows, free, (lo, hi), max_offset_m, min_landmarks, max_rack_depth_m)
    return [_pull_on_lattice(table, row, free, (lo, hi), max_offset_m, phase_tolerance_m) for row in rows]


def _new_rows(
    table: FloatArray,
    rows: list[RowModel],
    free: BoolArray,
    extent: tuple[float, float],
    max_offset_m: float,
    min_landmarks: int,
    max_rack_depth_m: float,
) -> list[RowModel]:
    """Rows of free landmarks on a line parallel to the block's (but on none of its rows' lines), at most a
    rack depth beyond its rows and within ``extent`` along, on one lattice of the block's spacing (a row
    segmentation could not see: too few landmarks close enough together to form an aligned set)."""
    model = max(rows, key=lambda r: r.members.size)
    u, v = model.direction, _normal(model.direction)
    offsets = np.array([r.centre @ v for r in rows])
    index = np.flatnonzero(free)
    along, across = table[index, :2] @ u, table[index, :2] @ v
    inside = (along >= extent[0] - 0.25 * model.d) & (along <= extent[1] + 0.25 * model.d)
    inside &= (across >= offsets.min() - max_rack_depth_m) & (across <= offsets.max() + max_rack_depth_m)
    inside &= np.min(np.abs(across[:, None] - offsets[None, :]), axis=1) > max_offset_m  # those are pulled
    index, across = index[inside], across[inside]
    order = np.argsort(across)
    out = []
    for group in np.split(index[order], np.flatnonzero(np.diff(across[order]) > max_offset_m) + 1):
        if group.size < min_landmarks:
            continue
        centre = table[group, :2].mean(axis=0)
        candidate = _on_lattice(table, group, model._replace(centre=centre, members=group))
        members = candidate.members[lattice_inliers(table, candidate)]
        if members.size >= min_landmarks:
            free[members] = False
            out.append(_on_lattice(table, members, candidate))
    return out


def _pull_on_lattice(
    table: FloatArray,
    row: RowModel,
    free: BoolArray,
    extent: tuple[float, float],
    max_offset_m: float,
    phase_tolerance_m: float,
) -> RowModel:
    """``row`` with the free landmarks on its line at empty slots within ``extent`` (along its block) pulled in."""
    lo, hi = extent
    u = row.direction
    index = np.flatnonzero(free)
    along = table[index, :2] @ u
    near = (np.abs((table[index, :2] - row.centre) @ _normal(u)) <= max_offset_m) & (
        along >= lo - 0.25 * row.d
    ) & (along <= hi + 0.25 * row.d)
    index = index[near]
    slots, residual = _lattice(table, index, row)
    taken, _ = _lattice(table, row.members, row)
    fits = (np.abs(residual) <= phase_tolerance_m) & ~np.isin(slots, taken)
    index, slots, residual = index[fits], slots[fits], residual[fits]
    order = np.lexsort((np.abs(residual), slots))
    _, first = np.unique(slots[order], return_index=True)  # the closest landmark per slot
    found = index[order][first]
    if found.size == 0:
        return row
    free[found] = False
    return _on_lattice(table, np.concatenate([row.members, found]), row)

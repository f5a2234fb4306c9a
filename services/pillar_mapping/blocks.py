"""Rack blocks: rows cut where a cross aisle runs through their region.

A cross aisle cuts every row of a region at one place along it. Where the aisle is not a whole
number of bays wide, the uprights beyond it sit off the lattice of those before it: in every row
that spans the aisle, the step between the landmarks either side of it is not a multiple of the
spacing. Where it is a whole number of bays wide, every row has an empty lattice slot there. Both
are judged over all rows of the region at once, so one noisy landmark or one unseen upright in
one row cuts nothing, and a cross aisle about one bay wide is never fitted as one more bay. Rows
are cut there into pieces, one per block, and each block gets its own constraints (start and end
lines, spacing), as the region would without the cross aisle.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from services.pillar_mapping.rowmodel import RowModel, along_line, lattice_phase

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]


class _Steps(NamedTuple):
    """Consecutive-landmark steps of a region's lines of rows, along ``u``: line index, interval ``lo``..``hi``
    (metres), whole spacings ``k`` in it, its off-lattice residual ``e`` (metres) and its std ``sigma``."""

    row: IntArray
    lo: FloatArray
    hi: FloatArray
    k: IntArray
    e: FloatArray
    sigma: FloatArray


def step_spacing(table: FloatArray, rows: list[RowModel], u: FloatArray, pitch: tuple[float, float]) -> float:
    """Median single step (metres) between consecutive landmarks of ``rows`` along unit ``u``.

    Unlike a row's Fourier spacing it is not pulled off by a cross aisle the row was fitted across.
    Steps outside ``pitch`` (least, most spacing) are left out; with none inside, the rows' median
    spacing is returned.
    """
    steps = [np.diff(np.sort(table[r.members, :2] @ u)) for r in rows]
    flat = np.concatenate(steps) if steps else np.zeros(0)
    single = flat[(flat >= pitch[0]) & (flat <= pitch[1])]
    return float(np.median(single)) if single.size else float(np.median([r.d for r in rows]))


def lattice_breaks(
    table: FloatArray,
    members: IntArray,
    u: FloatArray,
    pitch: tuple[float, float],
    *,
    off_lattice_z: float = 4.0,
    min_offset_m: float = 0.08,
) -> list[IntArray]:
    """The landmarks ``members`` of one aligned set, split where a step between consecutive ones (along unit
    ``u``) is off the lattice of the set's median single step (``pitch`` bounds a single step) by more than
    ``min_offset_m`` and ``off_lattice_z`` standard deviations. Used on sets too irregular to be one row.
    """
    s, sigma = along_line(table, members, np.zeros(2), u)
    order = np.argsort(s)
    s, sigma, members = s[order], sigma[order], members[order]
    step = np.diff(s)
    single = step[(step >= pitch[0]) & (step <= pitch[1])]
    if single.size == 0:
        return [members]
    d = float(np.median(single))
    e = step - np.maximum(np.rint(step / d), 1) * d
    off = (np.abs(e) > min_offset_m) & (np.abs(e) > off_lattice_z * np.sqrt(sigma[:-1] ** 2 + sigma[1:] ** 2))
    return np.split(members, np.flatnonzero(off) + 1)


def _lines(table: FloatArray, rows: list[RowModel], u: FloatArray, max_offset_m: float = 0.1) -> list[IntArray]:
    """The landmarks of ``rows`` by line: rows whose offsets across ``u`` are within ``max_offset_m`` (a
    row's pieces either side of a cross aisle) together."""
    v = np.array([-u[1], u[0]])
    offsets = np.array([np.median(table[r.members, :2] @ v) for r in rows])
    order = np.argsort(offsets)
    breaks = np.flatnonzero(np.diff(offsets[order]) > max_offset_m) + 1
    return [np.concatenate([rows[i].members for i in group]) for group in np.split(order, breaks)]


def _steps(table: FloatArray, rows: list[RowModel], u: FloatArray, d: float) -> _Steps:
    parts: list[tuple[IntArray, FloatArray, FloatArray, IntArray, FloatArray, FloatArray]] = []
    for index, members in enumerate(_lines(table, rows, u)):
        s, sigma = along_line(table, members, np.zeros(2), u)
        order = np.argsort(s)
        s, sigma = s[order], sigma[order]
        step = np.diff(s)
        k = np.maximum(np.rint(step / d).astype(np.int64), 1)
        e = step - k * d
        spread = np.sqrt(sigma[:-1] ** 2 + sigma[1:] ** 2)
        parts.append((np.full(step.size, index, dtype=np.int64), s[:-1], s[1:], k, e, spread))
    if not parts:
        empty = np.zeros(0)
        return _Steps(np.zeros(0, dtype=np.int64), empty, empty, np.zeros(0, dtype=np.int64), empty, empty)
    return _Steps(*(np.concatenate([p[i] for p in parts]) for i in range(6)))


def _spanning(steps: _Steps, x: float) -> IntArray:
    """Index of the step containing along position ``x`` in each row that spans it."""
    inside = np.flatnonzero((steps.lo < x) & (steps.hi > x))
    return inside


def _clustered(candidates: list[tuple[float, float]], d: float) -> FloatArray:
    """One cut per group of overlapping candidate intervals (lo, hi): the middle of their common part."""
    if not candidates:
        return np.zeros(0)
    out = []
    ordered = sorted(candidates)
    lo, hi = ordered[0]
    for a, b in ordered[1:]:
        if a < hi - 0.25 * d:
            lo, hi = max(lo, a), min(hi, b)
            continue
        out.append(0.5 * (lo + hi))
        lo, hi = a, b
    out.append(0.5 * (lo + hi))
    return np.asarray(out)


def block_cuts(
    table: FloatArray,
    rows: list[RowModel],
    u: FloatArray,
    d: float,
    *,
    off_lattice_z: float = 4.0,
    min_offset_m: float = 0.08,
    min_empty_rows: int = 4,
    slot_tolerance: float = 0.25,
) -> FloatArray:
    """Along positions (metres, ``table`` coordinates projected on unit ``u``) where a cross aisle cuts the region.

    Parameters
    ----------
    table : ndarray of float64, shape (N, 5)
        Landmarks ``x, y, sxx, sxy, syy``, metres and m^2.
    rows : list of RowModel
        The rows of one region; rows on one line (pieces either side of a cross aisle) are taken
        together.
    u : ndarray of float64, shape (2,)
        The region's row direction.
    d : float
        Its spacing, metres (e.g. :func:`step_spacing`).
    off_lattice_z, min_offset_m : float
        The rows spanning a place step off the lattice there when the mean of their steps' residuals
        exceeds ``min_offset_m`` and this many of its standard deviations (from the landmarks'
        covariances), and at least half of them (two, if more than one row spans it) are off by more
        than ``min_offset_m`` on that side. A cross aisle within ``min_offset_m`` of one bay is,
        by the uprights alone, a bay.
    min_empty_rows : int
        Fewest rows that must all have the same slot empty for an on-lattice cross aisle.
    slot_tolerance : float
        How close (in spacings) the empty slots of different rows must be to count as one column.

    Returns
    -------
    ndarray of float64, shape (C,)
        Sorted cut positions: where the rows spanning a place step off the lattice, or where every
        one of at least ``min_empty_rows`` rows spanning it has an empty slot there.
    """
    steps = _steps(table, rows, u, d)
    large = np.abs(steps.e) > min_offset_m
    cuts: list[tuple[float, float]] = []
    for i in np.flatnonzero(large):
        span = _spanning(steps, 0.5 * float(steps.lo[i] + steps.hi[i]))
        mean = float(steps.e[span].mean())
        spread = float(np.sqrt(np.sum(np.maximum(steps.sigma[span], 1e-3) ** 2))) / span.size
        agree = int(np.sum(large[span] & (np.sign(steps.e[span]) == np.sign(mean))))
        if (
            abs(mean) > max(min_offset_m, off_lattice_z * spread)
            and agree >= np.ceil(0.5 * span.size)
            and (agree >= 2 or span.size == 1)
        ):
            cuts.append((float(steps.lo[span].max()), float(steps.hi[span].min())))
    gaps = np.flatnonzero(steps.k >= 2)
    slots = [
        (steps.row[i], steps.lo[i] + j * (steps.hi[i] - steps.lo[i]) / steps.k[i])
        for i in gaps
        for j in range(1, int(steps.k[i]))
    ]
    if slots:
        slot_row = np.array([r for r, _ in slots])
        slot_x = np.array([x for _, x in slots])
        for x in slot_x:
            span = _spanning(steps, float(x))
            rows_here = np.unique(slot_row[np.abs(slot_x - x) <= slot_tolerance * d])
            if span.size >= min_empty_rows and np.isin(steps.row[span], rows_here).all():
                cuts.append((float(x) - 0.5 * slot_tolerance * d, float(x) + 0.5 * slot_tolerance * d))
    return _clustered(cuts, d)


def split_rows(
    table: FloatArray, rows: list[RowModel], cuts: FloatArray, u: FloatArray, d: float
) -> list[tuple[int, RowModel]]:
    """Each row's pieces between ``cuts`` (along ``u``), with the block each lies in (0 before the first cut).

    A piece keeps its row's line; its spacing is ``d`` and its phase and count are its own. Pieces
    of a single landmark are dropped (the landmark is left free).
    """
    out: list[tuple[int, RowModel]] = []
    for row in rows:
        block = np.searchsorted(cuts, table[row.members, :2] @ u)
        for b in np.unique(block):
            members = row.members[block == b]
            if members.size < 2:
                continue
            if members.size == row.members.size:
                out.append((int(b), row))
                continue
            s, _ = along_line(table, members, row.centre, row.direction)
            first, slots = lattice_phase(s, d)
            out.append((int(b), row._replace(members=members, d=d, first=first, n=int(slots.max()) + 1)))
    return out

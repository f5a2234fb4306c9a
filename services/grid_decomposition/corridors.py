"""Corridors first: a corridor band is never cut; rooms open onto it where no wall was drawn part from it."""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt

from services.grid_decomposition.arrays import components_stats, label_boxes, label_counts, lookup, nonzero_rc
from services.grid_decomposition.radiogram import Line


@dataclass(frozen=True)
class Band:
    """A corridor band between the parallel lines ``offset_a_px < offset_b_px`` of one angle.

    Along the lines (``t = cos(angle) * x + sin(angle) * y``) it runs from ``t0_px`` to ``t1_px``.
    """

    angle_rad: float
    offset_a_px: int
    offset_b_px: int
    t0_px: int
    t1_px: int


def _coordinates(
    shape: tuple[int, int], top: int, left: int, angle_rad: float
) -> tuple[npt.NDArray[np.int32], npt.NDArray[np.int32]]:
    """Across (``u``, the lines' offsets) and along (``t``) coordinates of a window's pixels, rounded."""
    x = np.arange(left, left + shape[1], dtype=np.float32)[None, :]
    y = np.arange(top, top + shape[0], dtype=np.float32)[:, None]
    s, c = np.float32(np.sin(angle_rad)), np.float32(np.cos(angle_rad))
    along = c * x + s * y
    return _across(shape, top, left, angle_rad), np.rint(along, out=along).astype(np.int32)


def _across(shape: tuple[int, int], top: int, left: int, angle_rad: float) -> npt.NDArray[np.int32]:
    """The across coordinate ``u`` of :func:`_coordinates` alone."""
    x = np.arange(left, left + shape[1], dtype=np.float32)[None, :]
    y = np.arange(top, top + shape[0], dtype=np.float32)[:, None]
    s, c = np.float32(np.sin(angle_rad)), np.float32(np.cos(angle_rad))
    across = -s * x + c * y
    return np.rint(across, out=across).astype(np.int32)


def window_coordinates(
    shape: tuple[int, int], top: int, left: int, lines: list[Line]
) -> dict[float, tuple[npt.NDArray[np.int32], npt.NDArray[np.int32]]]:
    """:func:`_coordinates` of a window for every angle of the lines (rounded as a band's ``angle_rad``)."""
    return {angle: _coordinates(shape, top, left, angle) for angle in {round(ln.angle_rad, 4) for ln in lines}}


def _runs(flags: npt.NDArray[np.bool_]) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Starts and ends (exclusive) of the runs of True."""
    padded = np.zeros(flags.size + 2, dtype=bool)
    padded[1:-1] = flags
    edges = np.flatnonzero(padded[1:] != padded[:-1])  # a start, then its end, and so on
    return edges[0::2], edges[1::2]


def _row_runs(
    flags: npt.NDArray[np.bool_],
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Row, start and end (exclusive) of the runs of True along every row, row by row and left to right."""
    padded = np.zeros((flags.shape[0], flags.shape[1] + 2), dtype=bool)
    padded[:, 1:-1] = flags
    rows, edges = nonzero_rc(padded[:, 1:] != padded[:, :-1])  # a start, then its end, and so on
    return rows[0::2], edges[0::2], edges[1::2]


def _walls_along(
    offset: npt.NDArray[np.int32],
    along: npt.NDArray[np.int32],
    rows: npt.NDArray[np.int64],
    n_across: int,
    along_start: int,
    n_along: int,
    tolerance_px: int,
) -> npt.NDArray[np.bool_]:
    """Per offset in ``rows`` (sorted, distinct) and along place: an occupied pixel within ``tolerance_px`` across.

    ``offset`` and ``along`` are the occupied pixels' offsets across (0 to ``n_across`` - 1) and along-line places
    (``along_start`` to ``along_start + n_along - 1``). Only the offsets within the tolerance of ``rows`` are
    rastered (each such offset once, in order, so a row's neighbours are consecutive).
    """
    lo, hi = np.maximum(rows - tolerance_px, 0), np.minimum(rows + tolerance_px + 1, n_across)
    marks = np.zeros(n_across + 1, dtype=np.int32)
    np.add.at(marks, lo, 1)
    np.add.at(marks, hi, -1)
    near = np.cumsum(marks[:-1]) > 0
    compact = np.cumsum(near) - 1  # the raster row of a near offset
    pick = near[offset]
    raster_c = np.zeros((int(compact[-1]) + 2, n_along), dtype=np.int32)
    raster = np.zeros((int(compact[-1]) + 1, n_along), dtype=bool)
    raster[compact[offset[pick]], along[pick] - along_start] = True
    np.cumsum(raster, axis=0, out=raster_c[1:])
    return np.asarray(raster_c[compact[hi - 1] + 1] - raster_c[compact[lo]] > 0, dtype=bool)


def _corner_range(values: npt.NDArray[np.int32]) -> tuple[int, int]:
    """Least and largest of a window's :func:`_coordinates` (monotone along every row and every column: at corners)."""
    corners = values[:: max(values.shape[0] - 1, 1), :: max(values.shape[1] - 1, 1)]
    return int(corners.min()), int(corners.max())


def _by_offset(table: npt.NDArray[np.int64], first: int) -> npt.NDArray[np.int64]:
    """``table`` (one entry per offset from ``first`` on) indexed by the offset itself, as ``np.take`` reads an index:
    ``np.take(_by_offset(table, first), offsets)`` is ``np.take(table, offsets - first)`` for offsets from ``first`` to
    ``first + table.size - 1``, without the whole-window subtraction (a negative offset is taken from the end)."""
    # offsets from the end up to -first (negative ones), from the start up to first + table.size (the others)
    size = max(table.size, -first) if first < 0 else first + table.size
    out = np.zeros(size, dtype=table.dtype)
    out[np.arange(first, first + table.size) % size] = table  # an offset's place as np.take reads it
    return out


def corridor_bands(
    region: npt.NDArray[np.bool_],
    occupied: npt.NDArray[np.bool_],
    lines: list[Line],
    *,
    top: int,
    left: int,
    resolution_m: float,
    min_width_m: float = 1.0,
    max_width_m: float = 3.0,
    min_length_m: float = 6.0,
    min_length_widths: float = 3.0,
    min_clear: float = 0.9,
    min_side_wall: float = 0.3,
    min_wall: float = 0.35,
    tolerance_px: int = 2,
    coordinates: dict[float, tuple[npt.NDArray[np.int32], npt.NDArray[np.int32]]] | None = None,
    tilted: list[Line] | None = None,
) -> list[Band]:
    """Corridor bands of one region: long clear strips between two parallel lines with walls on both.

    For every pair of parallel lines ``min_width_m`` to ``max_width_m`` apart, the strip between them
    (``tolerance_px`` in from each line) is clear where at least ``min_clear`` of its cross-section lies in
    ``region``. A clear run at least ``min_length_m`` and ``min_length_widths`` widths long is a band when
    an occupied cell lies within ``tolerance_px`` of each line over at least ``min_side_wall`` of the run
    and of both lines together over ``min_wall``: a side may open onto rooms over long stretches. Bands
    are taken best walled first; one whose strip lies mostly inside a band already taken is left out (a
    narrower pair of lines inside a corridor). The bands of the ``tilted`` lines (:func:`tilted_lines`, at angles
    of their own) are taken after all those of ``lines``: only where the building's own lines find no corridor.

    ``region`` and ``occupied`` are windows whose top-left pixel is (``top``, ``left``) of the image the
    lines were drawn in; ``coordinates`` are :func:`window_coordinates` of that window (for ``lines`` and
    ``tilted``) when the caller has them.
    """
    shape = (region.shape[0], region.shape[1])
    later = {round(ln.angle_rad, 4) for ln in tilted or []} - {round(ln.angle_rad, 4) for ln in lines}
    lines = lines + (tilted or [])
    min_w, max_w = round(min_width_m / resolution_m), round(max_width_m / resolution_m)
    found: list[tuple[float, Band]] = []
    if coordinates is None:
        coordinates = window_coordinates(shape, top, left, lines)
    occupied_at: npt.NDArray[np.intp] | None = None  # the occupied pixels' flat indices, once for every angle
    for angle, (u, t) in sorted(coordinates.items()):
        (u0, u1), (t0, t1) = _corner_range(u), _corner_range(t)
        nu, nt = u1 - u0 + 1, t1 - t0 + 1
        offsets = np.array(
            sorted({round(ln.offset_px) - u0 for ln in lines if round(ln.angle_rad, 4) == angle} & set(range(nu))),
            dtype=np.int64,
        )
        # every pair of lines min_w to max_w apart at once, in the order (a, then b) a double loop takes them
        first, second = np.triu_indices(offsets.size, 1)
        a_px, b_px = offsets[first], offsets[second]
        wide = (b_px - a_px >= min_w) & (b_px - a_px <= max_w)
        a_px, b_px = a_px[wide], b_px[wide]
        if a_px.size == 0:
            continue
        width = b_px - a_px
        lo, hi = a_px + tolerance_px + 1, b_px - tolerance_px
        # the counts below each strip's edges: per block of offsets between two edges, summed down the blocks
        bounds = np.unique(np.concatenate([lo, hi]))
        # only the rows and columns that hold a strip's pixels are counted: no other pixel is in any strip
        box = band_box(u, t, (int(bounds[0]) + u0, int(bounds[-1]) - 1 + u0), (t0, t0 + nt - 1))
        block = np.take(_by_offset(np.searchsorted(bounds, np.arange(nu), side="right") * nt - t0, u0), u[box])
        block += t[box]
        # the pixels per (block, along) place and of them those in the region: one count of block * 2 + region
        block *= 2
        block += region[box]
        counts = np.bincount(block.ravel(), minlength=2 * (bounds.size + 1) * nt).reshape(-1, 2 * nt)
        every_c = np.cumsum(counts[:, 0::2] + counts[:, 1::2], axis=0)
        inside_c = np.cumsum(counts[:, 1::2], axis=0)
        lo, hi = np.searchsorted(bounds, lo), np.searchsorted(bounds, hi)
        total = every_c[hi] - every_c[lo]
        clear = (total > 0) & (inside_c[hi] - inside_c[lo] >= min_clear * np.maximum(total, 1))
        length = np.maximum(round(min_length_m / resolution_m), np.rint(min_length_widths * width).astype(np.int64))
        pair, starts, ends = _row_runs(clear)
        long = ends - starts >= length[pair]
        pair, starts, ends = pair[long], starts[long], ends[long]
        if pair.size == 0:
            continue
        # the share of a run walled along each line: prefix sums along the lines that bound a long run
        rows, row_of = np.unique(np.concatenate([a_px[pair], b_px[pair]]), return_inverse=True)
        walls_c = np.zeros((rows.size, nt + 1), np.int32)
        if occupied_at is None:
            occupied_at = np.flatnonzero(occupied)
        walls = _walls_along(np.take(u, occupied_at) - u0, np.take(t, occupied_at), rows, nu, t0, nt, tolerance_px)
        np.cumsum(walls, axis=1, out=walls_c[:, 1:])
        row_a, row_b = row_of[: pair.size], row_of[pair.size :]
        n_run = (ends - starts).astype(np.float64)
        side_a = (walls_c[row_a, ends] - walls_c[row_a, starts]).astype(np.float64) / n_run
        side_b = (walls_c[row_b, ends] - walls_c[row_b, starts]).astype(np.float64) / n_run
        walled = (np.minimum(side_a, side_b) >= min_side_wall) & ((side_a + side_b) / 2 >= min_wall)
        for p, s, e, score in zip(
            pair[walled].tolist(), starts[walled].tolist(), ends[walled].tolist(),
            ((side_a + side_b) / 2)[walled].tolist(), strict=True,
        ):
            found.append((score, Band(angle, int(a_px[p]) + u0, int(b_px[p]) + u0, s + t0, e - 1 + t0)))
    bands: list[Band] = []
    taken = np.zeros(shape, dtype=bool)
    for _, band in sorted(found, key=lambda f: (f[1].angle_rad in later, -f[0])):
        strip = band_mask(band, *coordinates[band.angle_rad])
        if taken[strip].mean() <= 0.5:
            bands.append(band)
            taken |= strip
    return bands


def _tilt_of(t: npt.NDArray[np.float64], u: npt.NDArray[np.float64]) -> float:
    """The angle (radians) of the least-squares line ``u`` on ``t``: the pixels' tilt off the along direction."""
    dt = t - t.mean()
    return float(np.arctan(np.dot(dt, u - u.mean()) / max(float(np.dot(dt, dt)), 1e-9)))


def _longest_stretches(
    offset: npt.NDArray[np.int64],
    along: npt.NDArray[np.int64],
    peak_i: npt.NDArray[np.intp],
    peak_o: npt.NDArray[np.intp],
    n_offsets: int,
    max_gap_px: float,
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Per peak (tilt ``peak_i``, offset ``peak_o``): the first longest stretch of the places along the lines
    (``along``, per pixel) of the pixels within one offset of it (``offset``, per tilt and pixel), with gaps
    up to ``max_gap_px``: its first and last place and how many places it holds.

    Every peak must have a pixel within one offset of it; the offsets lie from 1 to ``n_offsets`` - 2.
    """
    a0 = int(along.min())
    n_along = int(along.max()) - a0 + 1
    which = np.full(offset.shape[0] * n_offsets, -1, dtype=np.int64)  # per tilt and offset (flat): its peak
    which[peak_i * n_offsets + peak_o] = np.arange(peak_i.size)
    flat = offset + n_offsets * np.arange(offset.shape[0])[:, None]
    # only the pixels within one offset of some peak are looked at
    close = which >= 0
    close[1:] |= close[:-1].copy()
    close[:-1] |= which[1:] >= 0
    tilt, pixel = np.nonzero(close[flat])
    flat = flat[tilt, pixel]
    place = along[pixel] - a0
    seen = np.zeros((peak_i.size, n_along), dtype=bool)  # per peak: the places of the pixels within one offset
    for step in (-1, 0, 1):
        peak = which[flat + step]
        hit = peak >= 0
        seen[peak[hit], place[hit]] = True
    # per peak its distinct places in order: a new stretch where the peak changes or after a gap
    peaks, places = np.nonzero(seen)
    starts = np.flatnonzero(np.r_[True, (peaks[1:] != peaks[:-1]) | (np.diff(places) > max_gap_px)])
    sizes = np.diff(np.r_[starts, places.size])
    owner = peaks[starts]
    longest = np.maximum.reduceat(sizes, np.flatnonzero(np.r_[True, owner[1:] != owner[:-1]]))
    best = np.flatnonzero(sizes == longest[owner])
    best = best[np.unique(owner[best], return_index=True)[1]]  # the first of a peak's longest
    first = starts[best]
    return places[first] + a0, places[first + sizes[best] - 1] + a0, sizes[best]


def tilted_lines(
    walls: npt.NDArray[np.bool_],
    lines: list[Line],
    *,
    top: int,
    left: int,
    resolution_m: float,
    min_tilt_deg: float = 1.0,
    max_tilt_deg: float = 3.0,
    tilt_step_deg: float = 0.5,
    min_support_m: float = 3.0,
    fit_px: int = 4,
    min_thin: float = 0.6,
    max_gap_m: float = 1.0,
    pair_width_m: tuple[float, float] = (1.0, 3.0),
) -> list[Line]:
    """Lines along walls a few degrees off the lines' angles: a wing of a building the map drew askew.

    For every angle of ``lines``, the ``walls`` pixels (a window whose top-left pixel is (``top``, ``left``) of
    the image the lines were drawn in) within one pixel of every offset are counted at tilts of
    ``tilt_step_deg`` up to ``max_tilt_deg`` either side of the angle (a Hough transform in a narrow fan). A
    tilted line is a maximum of those counts over its neighbours in tilt and offset, at least ``min_tilt_deg``
    off the angle (closer, the angle's own lines follow the wall within a band's tolerance) and with at least
    ``min_support_m`` of wall on it, where one stretch of wall within one pixel of it (gaps up to ``max_gap_m``)
    is seen at ``min_support_m`` of places along it, holds at least ``min_thin`` of the wall pixels within
    ``fit_px`` of it there (a wall, not a cloud of clutter), and those pixels run at its tilt within half a
    step (least squares): a wall at the angle itself lies on tilted lines too, but runs at the angle. Only
    lines with another of their tilt ``pair_width_m`` away (the two sides a corridor band needs) are returned.
    """
    rows, cols = nonzero_rc(walls)
    if rows.size == 0:
        return []
    x = (cols + left).astype(np.float64)
    y = (rows + top).astype(np.float64)
    steps = round(max_tilt_deg / tilt_step_deg)
    tilts = np.radians(tilt_step_deg * np.arange(-steps, steps + 1))
    half_step = math.radians(tilt_step_deg) / 2
    min_support = min_support_m / resolution_m
    max_gap_px = max_gap_m / resolution_m
    out: list[Line] = []
    for angle in sorted({round(ln.angle_rad, 4) for ln in lines}):
        across = np.rint(-np.sin(angle + tilts)[:, None] * x[None, :] + np.cos(angle + tilts)[:, None] * y[None, :])
        start = int(across.min()) - 1
        n = int(across.max()) - start + 2
        offset = across.astype(np.int64) - start  # per tilt and pixel: its offset's index, 1 to n - 2
        flat = offset + n * np.arange(tilts.size)[:, None]
        counts = np.bincount(flat.ravel(), minlength=n * tilts.size).reshape(tilts.size, n).astype(np.float32)
        near = counts.copy()
        near[:, 1:] += counts[:, :-1]
        near[:, :-1] += counts[:, 1:]
        peak = (near == cv2.dilate(near, np.ones((3, 5), np.uint8))) & (near >= min_support)
        peak[np.abs(tilts) < math.radians(min_tilt_deg)] = False
        if not peak.any():
            continue
        t = np.cos(angle) * x + np.sin(angle) * y
        u = -np.sin(angle) * x + np.cos(angle) * y
        peak_i, peak_o = np.nonzero(peak)
        # the stretch of wall along each line (gaps up to max_gap_px) seen at most places along it
        first_along, last_along, places = _longest_stretches(
            offset, np.rint(t).astype(np.int64), peak_i, peak_o, n, max_gap_px
        )
        # per tilt, its pixels in order of offset (then of pixel): the pixels within ``fit_px`` of a peak's offset
        # are one slice of them, in the order a stable sort of those pixels by offset gives
        by_offset: dict[int, tuple[npt.NDArray[np.intp], npt.NDArray[np.int64]]] = {}
        for p in np.flatnonzero(places >= min_support).tolist():
            i, o = int(peak_i[p]), int(peak_o[p])
            if i not in by_offset:
                order = np.argsort(offset[i].astype(np.int16) if n < 2**15 else offset[i], kind="stable")  # radix
                by_offset[i] = order, offset[i, order]
            order, ordered = by_offset[i]
            lo, hi = int(np.searchsorted(ordered, o - fit_px)), int(np.searchsorted(ordered, o + fit_px, side="right"))
            near_px = order[lo:hi]
            off = np.abs(ordered[lo:hi] - o)
            t_near = t[near_px]
            span = (t_near >= first_along[p] - 0.5) & (t_near <= last_along[p] + 0.5)
            if np.count_nonzero(span & (off <= 1)) < min_thin * np.count_nonzero(span):
                continue
            if abs(_tilt_of(t_near[span], u[near_px][span]) - tilts[i]) <= half_step:
                out.append(Line(round(angle + float(tilts[i]), 4), float(o + start), float(near[i, o]) * resolution_m,
                                resolution_m, True))
    lo, hi = round(pair_width_m[0] / resolution_m), round(pair_width_m[1] / resolution_m)
    return [
        a for a in out
        if any(b.angle_rad == a.angle_rad and lo <= abs(b.offset_px - a.offset_px) <= hi for b in out)
    ]


def band_box(
    u: npt.NDArray[np.int32], t: npt.NDArray[np.int32], across: tuple[int, int], along: tuple[int, int]
) -> tuple[slice, slice]:
    """Rows and columns of a window that hold every pixel with ``u`` in ``across`` and ``t`` in ``along``
    (inclusive ranges).

    ``u`` and ``t`` (:func:`_coordinates`) run monotone along every row and every column (a rounded sum with
    one term fixed), so a row or column holds such a pixel only where both its ranges, from end to end,
    meet the wanted ones.
    """

    def meets(a: npt.NDArray[np.int32], b: npt.NDArray[np.int32], lo: int, hi: int) -> npt.NDArray[np.bool_]:
        return np.asarray((np.maximum(a, b) >= lo) & (np.minimum(a, b) <= hi), dtype=bool)

    rows = np.flatnonzero(meets(u[:, 0], u[:, -1], *across) & meets(t[:, 0], t[:, -1], *along))
    cols = np.flatnonzero(meets(u[0], u[-1], *across) & meets(t[0], t[-1], *along))
    if rows.size == 0 or cols.size == 0:
        return slice(0, 0), slice(0, 0)
    return slice(int(rows[0]), int(rows[-1]) + 1), slice(int(cols[0]), int(cols[-1]) + 1)


def band_mask(band: Band, u: npt.NDArray[np.int32], t: npt.NDArray[np.int32]) -> npt.NDArray[np.bool_]:
    """The pixels between a band's lines and within its run (``u``, ``t``: the pixels' coordinates)."""
    out = np.zeros(u.shape, dtype=bool)
    box = band_box(u, t, (band.offset_a_px, band.offset_b_px), (band.t0_px, band.t1_px))
    ub, tb = u[box], t[box]
    out[box] = (ub >= band.offset_a_px) & (ub <= band.offset_b_px) & (tb >= band.t0_px) & (tb <= band.t1_px)
    return out


def _side_cuts(
    band: Band, u: npt.NDArray[np.int32], t: npt.NDArray[np.int32], thickness_px: int
) -> npt.NDArray[np.bool_]:
    """Both side lines of a band over its run, ``thickness_px`` either side of each line."""
    out = np.zeros(u.shape, dtype=bool)
    across = (band.offset_a_px - thickness_px, band.offset_b_px + thickness_px)
    box = band_box(u, t, across, (band.t0_px, band.t1_px))
    ub, tb = u[box], t[box]
    along = (tb >= band.t0_px) & (tb <= band.t1_px)
    near_a = np.abs(ub - band.offset_a_px) <= thickness_px
    near_b = np.abs(ub - band.offset_b_px) <= thickness_px
    out[box] = along & (near_a | near_b)
    return out


def part_rooms_from_corridors(
    segments: npt.NDArray[np.int32],
    occupied: npt.NDArray[np.bool_],
    lines: list[Line],
    candidates: npt.NDArray[np.bool_],
    *,
    resolution_m: float,
    room_min_area_m2: float = 8.0,
    room_min_radius_m: float = 1.0,
    room_min_solidity: float = 0.6,
    cut_thickness_px: int = 1,
    margin_px: int = 4,
    joinable: npt.NDArray[np.bool_] | None = None,
    join_min_share: float = 0.8,
) -> npt.NDArray[np.int32]:
    """Part the rooms from the corridor bands of candidate regions, along the bands' side lines.

    In every region ``k`` with ``candidates[k]`` the corridor bands (:func:`corridor_bands`, of ``lines`` and the
    :func:`tilted_lines` of the walls round the region: a corridor in a wing the map drew askew) are found and
    the region is cut along both side lines of every band over its run. A 4-connected piece that holds no
    square of a band's strip (at most, say, the end of a band crossing the other's side line) becomes a
    region of its own when it is room-like: at least ``room_min_area_m2``, a disc
    of ``room_min_radius_m`` fits in it and its area is at least ``room_min_solidity`` of its convex
    hull's. Every other piece and the cut pixels stay in the band's region: a band is never cut across,
    and a piece that is no room (a corner, a wall's niche) stays with the corridor. With ``joinable``
    (per region id: may join a corridor), regions beside ``k`` that lie along one of its bands join it: the
    corridor's pieces cut apart before.

    Returns
    -------
    (H, W) int32
        The segments with the parted rooms numbered after the existing ones.
    """
    out = segments.copy()
    next_id = int(segments.max()) + 1
    min_area = room_min_area_m2 / resolution_m**2
    min_radius = room_min_radius_m / resolution_m
    boxes = label_boxes(segments)
    for k in np.flatnonzero(candidates).tolist():
        own = boxes[k - 1] if 0 < k <= len(boxes) else None
        if own is None:
            continue
        # the window holds the walls round the region too
        top, left = max(0, own[0].start - margin_px), max(0, own[1].start - margin_px)
        bottom, right = own[0].stop + margin_px, own[1].stop + margin_px
        region = segments[top:bottom, left:right] == k
        shape = (region.shape[0], region.shape[1])
        walls = occupied[top:bottom, left:right]
        tilted = tilted_lines(walls, lines, top=top, left=left, resolution_m=resolution_m)
        coordinates = window_coordinates(shape, top, left, lines + tilted)
        bands = corridor_bands(
            region, walls, lines, top=top, left=left, resolution_m=resolution_m, coordinates=coordinates,
            tilted=tilted,
        )
        if not bands:
            continue
        cut = np.zeros(shape, dtype=bool)
        for band in bands:
            cut |= _side_cuts(band, *coordinates[band.angle_rad], cut_thickness_px)
        pieces = region & ~cut
        n, labels, stats = components_stats(pieces.astype(np.uint8), 4)
        offered = stats[:, cv2.CC_STAT_AREA] >= min_area
        offered[0] = False
        for band in bands:  # a band's piece holds a square of its strip, not only the end of a crossing band
            width = band.offset_b_px - band.offset_a_px
            held = np.bincount(labels[band_mask(band, *coordinates[band.angle_rad]) & pieces], minlength=n)
            offered &= held < width**2
        window = out[top:bottom, left:right]
        for p in np.flatnonzero(offered):
            x, y = stats[p, cv2.CC_STAT_LEFT], stats[p, cv2.CC_STAT_TOP]
            box = (slice(y, y + stats[p, cv2.CC_STAT_HEIGHT]), slice(x, x + stats[p, cv2.CC_STAT_WIDTH]))
            piece = labels[box] == p
            area = int(stats[p, cv2.CC_STAT_AREA])
            clearance = cv2.distanceTransform(np.pad(piece, 1).astype(np.uint8), cv2.DIST_L2, 5)
            if clearance.max() < min_radius:
                continue
            outline, _ = cv2.findContours(piece.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
            if area < room_min_solidity * cv2.contourArea(cv2.convexHull(np.concatenate(outline))):
                continue
            window[box][piece] = next_id
            next_id += 1
        if joinable is not None:
            out = _join_along(  # out is ours: joined in place
                out, int(k), bands, joinable, min_share=join_min_share, tolerance_px=cut_thickness_px + 1
            )
    return out


def _join_along(
    segments: npt.NDArray[np.int32],
    k: int,
    bands: list[Band],
    joinable: npt.NDArray[np.bool_],
    *,
    min_share: float,
    tolerance_px: int,
) -> npt.NDArray[np.int32]:
    """Join region ``k`` and the regions beside it that lie along one of its bands: pieces of the corridor.

    A ``joinable`` region touching ``k`` (or a region joined before it) joins when at least ``min_share``
    of it lies between the lines of a band (widened by ``tolerance_px``), wherever along them, and that
    part holds a square of the band's width. ``segments`` (the caller's own) is joined in place and returned.
    """
    n = int(segments.max()) + 1
    offered = np.zeros(n, dtype=bool)  # the rooms parted just now (ids past ``joinable``) never join
    offered[: joinable.size] = joinable[:n]
    offered[[0, k]] = False
    if not offered.any():
        return segments
    # only the box round ``k`` and the regions that may join (and the tolerance round them) is looked at
    looked = offered.copy()
    looked[k] = True
    inside = lookup(looked, segments)
    rows, cols = np.flatnonzero(inside.any(axis=1)), np.flatnonzero(inside.any(axis=0))
    top, left = max(int(rows[0]) - tolerance_px, 0), max(int(cols[0]) - tolerance_px, 0)
    box = slice(top, int(rows[-1]) + 1 + tolerance_px), slice(left, int(cols[-1]) + 1 + tolerance_px)
    window = segments[box]
    size = label_counts(window, n)[0]  # from the runs
    along = np.zeros(n, dtype=bool)
    across = {a: _across((window.shape[0], window.shape[1]), top, left, a) for a in {band.angle_rad for band in bands}}
    for band in bands:
        u = across[band.angle_rad]
        strip = (u >= band.offset_a_px - tolerance_px) & (u <= band.offset_b_px + tolerance_px)
        held = np.bincount(window[strip], minlength=n)
        along |= (held >= min_share * size) & (held >= (band.offset_b_px - band.offset_a_px) ** 2)
    along &= offered
    if not along.any():
        return segments
    corridor = window == k
    ring = np.ones((2 * tolerance_px + 1, 2 * tolerance_px + 1), np.uint8)
    while True:
        touching = np.bincount(window[cv2.dilate(corridor.view(np.uint8), ring).view(bool)], minlength=n) > 0
        new = touching & along
        if not new.any():
            window[corridor] = k  # a view of segments
            return segments
        along &= ~new
        corridor |= lookup(new, window)

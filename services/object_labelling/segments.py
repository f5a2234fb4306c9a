"""Curvature detection and segment estimation on the range and height contour.

The contour ``s(b)`` is compared with itself shifted by ``w`` cones; the difference signal has
a positive peak where the contour steps away from the camera (an object's far edge) and a
negative one where it steps towards it. Peaks of both signs, found separately with
:func:`scipy.signal.find_peaks`, are the putative object boundaries; the obstacle cones between
consecutive boundaries form one segment with its width, height and range.
"""

from __future__ import annotations

import itertools
import math
from typing import NamedTuple

import numpy as np
import numpy.typing as npt
from scipy.signal import find_peaks

from services.object_labelling.errors import ObjectLabellingError
from services.object_labelling.range_scan import MAX_RANGE_M, RangeHeightScan


class Segment(NamedTuple):
    """An object proposal: cones ``[start, stop)`` of a scan and their extent.

    ``width_m`` is the floor-plane distance between the closest points of the first and last
    obstacle cones (the visible extent: a side face seen obliquely adds to it); ``height_m`` the
    highest obstacle point; ``range_m`` the closest range; ``bearing_rad`` the mean bearing; the
    pixel box is (row_min, col_min, row_max, col_max), inclusive.
    """

    start: int
    stop: int
    width_m: float
    height_m: float
    range_m: float
    bearing_rad: float
    box: tuple[int, int, int, int]


def _peak_steps(signal: npt.NDArray[np.float64], shift: int, min_step: float) -> npt.NDArray[np.intp]:
    """Cone indices where ``signal`` steps by at least ``min_step`` over ``shift`` cones (first cone after).

    A peak at ``diff[i]`` says the contour changed between cones ``i`` and ``i + shift``; the
    candidate boundary is put at the largest single-cone step of the same sign inside that window.
    """
    diff = signal[shift:] - signal[:-shift]
    steps = np.diff(signal)  # steps[p - 1] = signal[p] - signal[p - 1]
    found = []
    for sign in (1.0, -1.0):
        peaks, _ = find_peaks(sign * diff, height=min_step)
        if peaks.size:
            window = peaks[:, None] + np.arange(shift)  # indices into steps: p - 1 for p in (i, i + shift]
            found.append(peaks + 1 + np.argmax(sign * steps[window], axis=1))
    return np.concatenate(found) if found else np.zeros(0, dtype=np.intp)


def range_breaks(
    scan: RangeHeightScan, *, max_range_m: float, incidence_rad: float = 0.1745, noise_sigmas: float = 3.0
) -> npt.NDArray[np.bool_]:
    """Per pair of neighbouring cones (n - 1,), whether their closest points are too far apart for one surface.

    Adaptive breakpoint test (Borges and Aldon 2004): a surface seen at an incidence angle of at
    least ``incidence_rad`` moves the closest point by at most ``r sin(dphi) / sin(incidence - dphi)``
    from one cone (width ``dphi``) to the next, plus ``noise_sigmas`` times the depth noise
    ``sigma(r) = 1.2 mm + 1.9 mm r^2`` (structured-light camera, r in metres). Cones without an
    obstacle count as a point at ``max_range_m`` on their centre bearing.
    """
    free = ~(np.isfinite(scan.ranges_m) & np.isfinite(scan.forward_m))
    ranges = np.where(free, max_range_m, scan.ranges_m)
    x = np.where(free, max_range_m * np.cos(scan.bearings_rad), scan.forward_m)
    y = np.where(free, max_range_m * np.sin(scan.bearings_rad), scan.left_m)
    gap = np.hypot(np.diff(x), np.diff(y))
    dphi = float(np.abs(np.diff(scan.bearings_rad)).mean()) if ranges.size > 1 else 0.0
    near = np.minimum(ranges[1:], ranges[:-1])
    allowed = near * math.sin(dphi) / math.sin(incidence_rad - dphi) + noise_sigmas * (0.0012 + 0.0019 * near**2)
    return np.asarray(gap > allowed)


def boundaries(
    scan: RangeHeightScan,
    *,
    shift_cones: int = 4,
    min_step_m: float = 0.09,
    max_range_m: float = MAX_RANGE_M,
    min_height_ratio: float = 0.3,
    incidence_rad: float = 0.1745,
) -> npt.NDArray[np.intp]:
    """Sorted unique cone indices where an object ends (the first cone after the boundary).

    Candidates are the peaks of the shifted difference ``s(b) - s(b - shift_cones)`` of the range
    and of the height contour (at least ``min_step_m``), each placed on the largest single-cone
    step in its window. A range candidate is kept where that step is a depth discontinuity
    (:func:`range_breaks`), not a surface seen at a slant; a height candidate where the height
    changes by at least ``min_height_ratio`` of the taller side (a head above the shoulders or a
    mast above a truck body is one object). Cones without an obstacle read as ``max_range_m`` and
    height 0, so the edge of an object in front of free space is a boundary too.
    """
    if shift_cones < 1 or min_step_m <= 0 or not 0 <= min_height_ratio < 1:
        raise ObjectLabellingError(
            f"need shift_cones >= 1, min_step_m > 0 and 0 <= min_height_ratio < 1, got {shift_cones}, "
            f"{min_step_m}, {min_height_ratio}"
        )
    n = scan.ranges_m.size
    if n <= shift_cones:
        return np.zeros(0, dtype=np.intp)
    finite = np.isfinite(scan.ranges_m)
    ranges = np.where(finite, scan.ranges_m, max_range_m)
    heights = np.where(finite, scan.heights_m, 0.0)
    by_range = _peak_steps(ranges, shift_cones, min_step_m)
    by_range = by_range[range_breaks(scan, max_range_m=max_range_m, incidence_rad=incidence_rad)[by_range - 1]]
    by_height = _peak_steps(heights, shift_cones, min_step_m)
    step = np.abs(heights[by_height] - heights[by_height - 1])
    by_height = by_height[step >= min_height_ratio * np.maximum(heights[by_height], heights[by_height - 1])]
    edges = np.concatenate((by_range, by_height))
    return np.unique(edges[(edges > 0) & (edges < n)])


def segments(
    scan: RangeHeightScan,
    *,
    shift_cones: int = 4,
    min_step_m: float = 0.09,
    max_range_m: float = MAX_RANGE_M,
    min_cones: int = 3,
) -> list[Segment]:
    """Object segments between consecutive boundaries of ``scan`` (see :func:`boundaries`).

    Cones without an obstacle are dropped from a segment; a segment keeps only its longest run of
    obstacle cones and needs ``min_cones`` of them.
    """
    edges = np.concatenate(
        (
            [0],
            boundaries(scan, shift_cones=shift_cones, min_step_m=min_step_m, max_range_m=max_range_m),
            [scan.ranges_m.size],
        )
    )
    occupied = np.isfinite(scan.ranges_m) & np.isfinite(scan.forward_m)
    found = []
    for start, stop in itertools.pairwise(edges):
        cones = np.flatnonzero(occupied[start:stop]) + start
        if cones.size < min_cones:
            continue
        runs = np.split(cones, np.flatnonzero(np.diff(cones) > 1) + 1)
        run = max(runs, key=len)
        if run.size < min_cones:
            continue
        first, last = run[0], run[-1]
        width = float(np.hypot(scan.forward_m[first] - scan.forward_m[last], scan.left_m[first] - scan.left_m[last]))
        box = (
            int(scan.row_min[run].min()),
            int(scan.col_min[run].min()),
            int(scan.row_max[run].max()),
            int(scan.col_max[run].max()),
        )
        found.append(
            Segment(
                int(first),
                int(last) + 1,
                width,
                float(scan.heights_m[run].max()),
                float(scan.ranges_m[run].min()),
                float(scan.bearings_rad[run].mean()),
                box,
            )
        )
    return found

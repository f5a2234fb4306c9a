"""Curvature detection and segment estimation on the range and height contour.

The contour ``s(b)`` is compared with itself shifted by ``w`` cones; the difference signal has
a positive peak where the contour steps away from the camera (an object's far edge) and a
negative one where it steps towards it. Peaks of both signs, found separately with
:func:`scipy.signal.find_peaks`, are the putative object boundaries; the obstacle cones between
consecutive boundaries form one segment with its width, height and range.
"""

from __future__ import annotations

import itertools
from typing import NamedTuple

import numpy as np
import numpy.typing as npt
from scipy.signal import find_peaks

from services.object_labelling.errors import ObjectLabellingError
from services.object_labelling.range_scan import RangeHeightScan


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


def _boundaries(signal: npt.NDArray[np.float64], shift: int, min_step: float) -> npt.NDArray[np.intp]:
    """Cone indices where ``signal`` steps by at least ``min_step`` (first cone after the step).

    A peak at ``diff[i]`` says the contour changed between cones ``i`` and ``i + shift``; the
    boundary is put at the largest single-cone step of the same sign inside that window.
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


def boundaries(
    scan: RangeHeightScan, *, shift_cones: int = 4, min_step_m: float = 0.09, max_range_m: float = 5.0
) -> npt.NDArray[np.intp]:
    """Sorted unique cone indices where the range or the height contour jumps by ``min_step_m``.

    Cones without an obstacle (or without depth) read as ``max_range_m`` and height 0, so the
    edge of an object in front of free space is a boundary too.
    """
    if shift_cones < 1 or min_step_m <= 0:
        raise ObjectLabellingError(f"shift_cones must be >= 1 and min_step_m > 0, got {shift_cones}, {min_step_m}")
    n = scan.ranges_m.size
    if n <= shift_cones:
        return np.zeros(0, dtype=np.intp)
    ranges = np.where(np.isfinite(scan.ranges_m), scan.ranges_m, max_range_m)
    heights = np.where(np.isfinite(scan.ranges_m), scan.heights_m, 0.0)
    edges = np.concatenate(
        (_boundaries(ranges, shift_cones, min_step_m), _boundaries(heights, shift_cones, min_step_m))
    )
    return np.unique(edges[(edges > 0) & (edges < n)])


def segments(
    scan: RangeHeightScan,
    *,
    shift_cones: int = 4,
    min_step_m: float = 0.09,
    max_range_m: float = 5.0,
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

"""Splitting segments that are several rooms joined by narrow necks (doorways without a line)."""

from __future__ import annotations

import cv2
import numpy as np
import numpy.typing as npt

from services.grid_decomposition.arrays import components_stats_runs, lookup
from services.grid_decomposition.segments import fill_from_neighbours, renumber


def split_at_necks(
    segments: npt.NDArray[np.int32],
    free: npt.NDArray[np.bool_],
    *,
    resolution_m: float,
    neck_half_width_m: float = 0.5,
    min_core_area_m2: float = 1.0,
    max_growth_m: float = 3.0,
    distance: npt.NDArray[np.float32] | None = None,
) -> npt.NDArray[np.int32]:
    """Split every segment whose free space, shrunk by ``neck_half_width_m``, falls into several cores.

    Free pixels farther than ``neck_half_width_m`` from any obstacle form cores; a segment holding
    two or more cores of at least ``min_core_area_m2`` is two rooms joined through a passage
    narrower than twice that half-width (a doorway whose wall got no decomposition line). Its
    pixels go to the core they reach first growing inside the segment (geodesic Voronoi).

    Parameters
    ----------
    segments : (H, W) int32
        Segment id per pixel, 0 off free space.
    free : (H, W) bool
    resolution_m : float
        Metres per pixel.
    distance : (H, W) float32, optional
        ``cv2.distanceTransform(free, cv2.DIST_L2, 5)`` when the caller has it already.

    Returns
    -------
    (H, W) int32
        Segment ids 1..N (consecutive), 0 where ``segments`` is 0.
    """
    seg = np.asarray(segments, dtype=np.int32)
    dist = cv2.distanceTransform(free.astype(np.uint8), cv2.DIST_L2, 5) if distance is None else distance
    # a 4-neighbour in another segment (none off the image); each pair of neighbours compared once
    border = np.zeros(seg.shape, dtype=bool)
    across = seg[:, 1:] != seg[:, :-1]
    border[:, 1:] |= across
    border[:, :-1] |= across
    down = seg[1:] != seg[:-1]
    border[1:] |= down
    border[:-1] |= down
    core = (dist > neck_half_width_m / resolution_m) & (seg > 0) & ~border
    n, parts, stats, (label, length) = components_stats_runs(core.view(np.uint8), 4)
    big = stats[:, cv2.CC_STAT_AREA] >= min_core_area_m2 / resolution_m**2
    big[0] = False
    # each core's segment, from the first pixel of each run of one core along the rows (a core lies in one segment)
    first = np.cumsum(length) - length
    owner = np.zeros(n, dtype=np.int64)
    owner[label] = seg.ravel()[first]
    n_seg = int(seg.max()) + 1
    cores_per_seg = np.bincount(owner[big], minlength=n_seg)
    split = cores_per_seg >= 2
    split[0] = False
    if not split.any():
        return renumber(seg)
    in_split = lookup(split, seg)
    # within the box round the segments split: nothing outside it is marked or filled
    rows, cols = np.flatnonzero(in_split.any(axis=1)), np.flatnonzero(in_split.any(axis=0))
    box = (slice(int(rows[0]), int(rows[-1]) + 1), slice(int(cols[0]), int(cols[-1]) + 1))
    inside, cores = in_split[box], parts[box]
    marker = np.where(inside & big[cores], cores + n_seg, 0).astype(np.int32)
    # one fill: it stops by itself once every reachable pixel is taken
    grown = fill_from_neighbours(
        marker, inside, max_iterations=10 * max(1, round(max_growth_m / resolution_m / 10)), overwrite=True
    )
    out = seg.copy()
    out[box] = np.where(inside & (grown > 0), grown, seg[box])
    return renumber(out, copy=False)  # out is ours

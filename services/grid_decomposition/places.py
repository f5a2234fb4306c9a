"""Unsupervised place categorisation (paper C): ray-cast features per free pixel, k-means clusters."""

from __future__ import annotations

import contextlib
import functools
import math
import threading

import cv2
import numpy as np
import numpy.typing as npt
from threadpoolctl import ThreadpoolController

from services.grid_decomposition.arrays import nonzero_rc

N_FEATURES = 13
CLUSTERING = threading.Lock()
"""Held by each clustering under one-thread limits: threadpoolctl's limits are the process's, restored on exit."""


@functools.cache
def _thread_pools() -> ThreadpoolController:
    return ThreadpoolController()


def one_thread() -> contextlib.AbstractContextManager[object]:
    """``threadpool_limits(1)`` (every thread pool of the process: OpenMP, BLAS) without looking the pools up again.

    ``threadpool_limits`` lists the process's loaded libraries at every call (about 1 ms); the pools are listed
    once, at the first clustering, when scikit-learn and its OpenMP are loaded.
    """
    limiter: contextlib.AbstractContextManager[object] = _thread_pools().limit(limits=1)
    return limiter


def cast_rays(
    obstacle: npt.NDArray[np.bool_],
    rows: npt.NDArray[np.int64],
    cols: npt.NDArray[np.int64],
    *,
    n_beams: int,
    max_range_px: float,
    distance: npt.NDArray[np.float32] | None = None,
) -> npt.NDArray[np.float64]:
    """Simulated laser ranges from given pixels, by sphere tracing on the obstacle distance map.

    ``distance`` is ``cv2.distanceTransform((~obstacle).astype(np.uint8), cv2.DIST_L2, 3)``, when the caller
    has it.

    Returns
    -------
    (N, n_beams) float64
        Range in pixels of each beam (beam ``k`` at ``2 pi k / n_beams``), capped at ``max_range_px``.
    """
    dist = cv2.distanceTransform((~obstacle).astype(np.uint8), cv2.DIST_L2, 3) if distance is None else distance
    h, w = obstacle.shape
    # distances by flat index; a pixel off the map reads an obstacle pixel's 0, so a ray leaving the map stops
    flat = dist.ravel()
    off_map = int(np.argmax(obstacle))
    if not obstacle.flat[off_map]:  # no obstacle: a 0 of its own
        flat, off_map = np.append(flat, np.float32(0.0)), flat.size
    angles = np.arange(n_beams) * (2 * math.pi / n_beams)
    dx, dy = np.cos(angles).astype(np.float32), np.sin(angles).astype(np.float32)
    n = rows.size
    x0 = np.repeat(cols.astype(np.float32), n_beams)
    y0 = np.repeat(rows.astype(np.float32), n_beams)
    ux, uy = np.tile(dx, n), np.tile(dy, n)
    t = np.zeros(n * n_beams, dtype=np.float32)
    active = np.arange(n * n_beams)
    ta = t.copy()  # the active beams' own starts, directions and ranges, compacted as beams stop
    # pixel indices in 32 bits when the image's flat indices fit (half the memory traffic of 64)
    signed, unsigned = (np.int32, np.uint32) if flat.size < 2**31 else (np.int64, np.uint64)
    for _ in range(64):
        if active.size == 0:
            break
        xi = np.rint(x0 + ta * ux).astype(signed)
        yi = np.rint(y0 + ta * uy).astype(signed)
        outside = (xi.view(unsigned) >= w) | (yi.view(unsigned) >= h)  # negative ones too
        at = np.multiply(yi, w, out=yi)
        at += xi
        at[outside] = off_map
        d = np.take(flat, at)
        go = (d >= 1.0) & (ta < max_range_px)
        # a beam's range is where it stops: written once then (not every step), and the survivors' indices found
        # once for the six compactions (a boolean index finds them again each time)
        stop = np.flatnonzero(~go)
        t[active[stop]] = ta[stop]
        keep = np.flatnonzero(go)
        active, x0, y0, ux, uy, d = (np.take(v, keep) for v in (active, x0, y0, ux, uy, d))
        ta = np.take(ta, keep) + np.maximum(d - 0.5, 1.0)
    t[active] = ta  # beams still going after the last step
    return np.minimum(t, max_range_px).reshape(n, n_beams).astype(np.float64)


def raycast_features(ranges: npt.NDArray[np.float64], *, gap_threshold: float) -> npt.NDArray[np.float64]:
    """The thirteen geometric features of paper C's Table I (after Mozos et al.) per scan.

    Mean and standard deviation of the ranges; mean and standard deviation of the differences
    between consecutive ranges; area, perimeter and perimeter^2 / area of the scan polygon;
    number of gaps (consecutive differences above ``gap_threshold``); kurtosis of the ranges;
    the two principal-component variances of the end points, their ratio, and the distance from
    the scan origin to the end points' centroid.

    Parameters
    ----------
    ranges : (N, B) float64
        Ranges (any length unit; ``gap_threshold`` in the same unit), beams evenly spaced over 2 pi.

    Returns
    -------
    (N, 13) float64
    """
    n, b = ranges.shape
    angles = np.arange(b) * (2 * math.pi / b)
    diff = np.abs(ranges - np.roll(ranges, -1, axis=1))
    x, y = ranges * np.cos(angles), ranges * np.sin(angles)
    area = 0.5 * np.abs(np.sum(x * np.roll(y, -1, axis=1) - np.roll(x, -1, axis=1) * y, axis=1))
    perimeter = np.sum(np.hypot(x - np.roll(x, -1, axis=1), y - np.roll(y, -1, axis=1)), axis=1)
    mx, my = x.mean(axis=1), y.mean(axis=1)
    cxx = ((x - mx[:, None]) ** 2).mean(axis=1)
    cyy = ((y - my[:, None]) ** 2).mean(axis=1)
    cxy = ((x - mx[:, None]) * (y - my[:, None])).mean(axis=1)
    half_tr, det = (cxx + cyy) / 2, cxx * cyy - cxy**2
    root = np.sqrt(np.maximum(half_tr**2 - det, 0.0))
    pc1, pc2 = half_tr + root, np.maximum(half_tr - root, 1e-9)
    flat = np.ptp(ranges, axis=1) == 0
    kurt = np.zeros(n)
    if (~flat).any():
        kurt[~flat] = _kurtosis(ranges[~flat])
    return np.stack(
        [
            ranges.mean(axis=1),
            ranges.std(axis=1),
            diff.mean(axis=1),
            diff.std(axis=1),
            area,
            perimeter,
            perimeter**2 / np.maximum(area, 1e-9),
            (diff > gap_threshold).sum(axis=1).astype(np.float64),
            kurt,
            pc1,
            pc2,
            pc1 / pc2,
            np.hypot(mx, my),
        ],
        axis=1,
    )


def _kurtosis(rows: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """``scipy.stats.kurtosis(rows, axis=1)`` (Fisher, biased) with scipy's own expressions, so the same floats.

    scipy's argument checks and its cancellation warning cost more than the arithmetic.
    """
    mean = np.mean(rows, axis=1, keepdims=True)
    square = (rows - mean) ** 2
    m2 = np.mean(square, axis=1)
    m4 = np.mean(square**2, axis=1)
    with np.errstate(all="ignore"):
        zero = m2 <= (np.finfo(m2.dtype).eps * mean[:, 0]) ** 2
        vals: npt.NDArray[np.float64] = np.where(zero, np.nan, m4 / m2**2.0) - 3
    return vals


def categorize_places(
    obstacle: npt.NDArray[np.bool_],
    free: npt.NDArray[np.bool_],
    *,
    resolution_m: float,
    n_categories: int = 8,
    sample_spacing_m: float = 0.4,
    max_samples: int = 8000,
    n_beams: int = 32,
    max_range_m: float = 12.0,
    gap_threshold_m: float = 1.0,
    seed: int = 0,
    distance: npt.NDArray[np.float32] | None = None,
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Cluster free pixels into place categories by the shape of simulated scans (k-means).

    Free pixels on a grid of ``sample_spacing_m`` (widened so that there are at most about
    ``max_samples`` of them on large maps) are ray-cast, described by
    :func:`raycast_features` (lengths in metres, log-compressed where heavy-tailed, standardised)
    and clustered into ``n_categories`` with k-means; categories are renumbered by mean range so
    that the numbering is stable (0 = most confined). ``distance`` is the obstacles' distance map
    (:func:`cast_rays`), when the caller has it.

    Returns
    -------
    rows, cols, category : (N,) int64
        The sampled pixels and their category.
    """
    spacing_m = max(sample_spacing_m, math.sqrt(float(np.count_nonzero(free)) / max(max_samples, 1)) * resolution_m)
    step = max(1, round(spacing_m / resolution_m))
    rows, cols = nonzero_rc(free[step // 2 :: step, step // 2 :: step])  # the grid's free pixels, in raster order
    rows, cols = rows * step + step // 2, cols * step + step // 2
    if rows.size == 0:
        return rows.astype(np.int64), cols.astype(np.int64), np.zeros(0, np.int64)
    ranges = cast_rays(
        obstacle, rows, cols, n_beams=n_beams, max_range_px=max_range_m / resolution_m, distance=distance
    )
    feats = raycast_features(ranges * resolution_m, gap_threshold=gap_threshold_m)
    for k in (4, 5, 6, 9, 10, 11):
        feats[:, k] = np.log1p(feats[:, k])
    k = min(n_categories, rows.size)
    from sklearn.cluster import KMeans  # scikit-learn is imported when first needed
    from sklearn.preprocessing import StandardScaler

    with CLUSTERING, one_thread():
        scaled = StandardScaler().fit_transform(feats)
        model = KMeans(k, n_init=3, random_state=seed).fit(scaled)
    order = np.argsort(np.argsort(model.cluster_centers_[:, 0]))
    return rows.astype(np.int64), cols.astype(np.int64), order[model.labels_].astype(np.int64)

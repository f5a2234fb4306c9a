"""Segmentation of a landmark map into aligned sets: closed-form Hough transform and DBSCAN (paper A, 2.1)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import numpy.typing as npt
from scipy.ndimage import gaussian_filter1d
from scipy.spatial import cKDTree

from services.pillar_mapping.lean import dbscan, find_peaks

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]


class HoughPairs(NamedTuple):
    """Closed-form Hough intersections of point pairs.

    ``i``, ``j`` (M,) point indices; ``alpha`` (M,) direction of the line through both, radians
    in [-pi/2, pi/2); ``rho`` (M,) its distance from the origin along the normal
    ``(-sin alpha, cos alpha)``, metres. Two points' sinusoids ``rho = x cos t + y sin t``
    intersect exactly at ``t = alpha + pi/2``.
    """

    i: IntArray
    j: IntArray
    alpha: FloatArray
    rho: FloatArray


def wrap_half(angle: npt.ArrayLike) -> FloatArray:
    """Line directions wrapped to [-pi/2, pi/2)."""
    return np.asarray((np.asarray(angle, dtype=np.float64) + 0.5 * np.pi) % np.pi - 0.5 * np.pi)


def hough_pairs(points: FloatArray, *, min_length_m: float, max_length_m: float) -> HoughPairs:
    """Intersections of the Hough sinusoids of every pair of points ``min_length_m``..``max_length_m`` apart.

    Limiting pairs to a neighbourhood keeps their number linear in the map size; the
    intersections are exact, with no discretised accumulator.
    """
    pairs = cKDTree(points).query_pairs(max_length_m, output_type="ndarray").astype(np.int64)
    i, j = pairs[:, 0], pairs[:, 1]
    delta = points[j] - points[i]
    keep = np.hypot(delta[:, 0], delta[:, 1]) >= min_length_m
    i, j, delta = i[keep], j[keep], delta[keep]
    alpha = wrap_half(np.arctan2(delta[:, 1], delta[:, 0]))
    rho = -points[i, 0] * np.sin(alpha) + points[i, 1] * np.cos(alpha)
    return HoughPairs(i, j, alpha, rho)


def dominant_orientations(
    alpha: FloatArray,
    *,
    bin_rad: float = float(np.deg2rad(0.25)),
    min_separation_rad: float = float(np.deg2rad(1.5)),
    min_fraction: float = 0.02,
    max_orientations: int = 16,
) -> FloatArray:
    """Peaks of the (circular, smoothed) histogram of pair directions, strongest first.

    A discretised pass over the Hough space, as in the paper, only to find where most
    intersections lie; peaks below ``min_fraction`` of the pairs' total are ignored.
    """
    if alpha.size == 0:
        return np.zeros(0)
    bins = round(np.pi / bin_rad)
    hist = np.bincount(((alpha + 0.5 * np.pi) / np.pi * bins).astype(np.int64) % bins, minlength=bins)
    smooth = gaussian_filter1d(hist.astype(np.float64), 2.0, mode="wrap")
    spread = round(np.deg2rad(1.5) / bin_rad)
    mass = np.convolve(np.concatenate([hist[-spread:], hist, hist[:spread]]), np.ones(2 * spread + 1), "valid")
    peaks = find_peaks(np.concatenate([smooth, smooth[:1]]), distance=max(1, int(min_separation_rad / bin_rad)))
    peaks = peaks[peaks < bins]
    peaks = peaks[mass[peaks] >= min_fraction * alpha.size]
    peaks = peaks[np.argsort(-mass[peaks])][:max_orientations]
    return np.asarray(-0.5 * np.pi + (peaks + 0.5) * np.pi / bins, dtype=np.float64)


def local_orientations(
    points: FloatArray,
    pairs: HoughPairs,
    *,
    tile_m: float = 40.0,
    per_tile: int = 4,
    min_pairs: int = 50,
    min_separation_rad: float = float(np.deg2rad(1.5)),
) -> FloatArray:
    """Dominant orientations of every neighbourhood (``tile_m`` square tiles of the pairs' midpoints), merged.

    One histogram over a whole hall is ruled by its biggest region, whose lattice diagonals can
    outnumber a small region's rows at another angle; each tile's own ``per_tile`` strongest
    peaks (tiles with at least ``min_pairs`` pairs), and the whole map's, are kept instead, and
    merged where closer than ``min_separation_rad``, the one with more pairs in the whole map first.

    Returns
    -------
    ndarray of float64, shape (K,)
        Radians in [-pi/2, pi/2), the most supported in the whole map first.
    """
    if pairs.alpha.size == 0:
        return np.zeros(0)
    mid = 0.5 * (points[pairs.i] + points[pairs.j])
    cell = np.floor(mid / tile_m).astype(np.int64)
    cell -= cell.min(axis=0)
    _, tile = np.unique(cell[:, 0] * (int(cell[:, 1].max()) + 1) + cell[:, 1], return_inverse=True)  # row order
    tile = tile.ravel()
    found = dominant_orientations(pairs.alpha, max_orientations=per_tile).tolist() + [
        peak
        for t in range(int(tile.max()) + 1)
        if np.count_nonzero(tile == t) >= min_pairs
        for peak in dominant_orientations(pairs.alpha[tile == t], max_orientations=per_tile)
    ]
    around = np.sort(pairs.alpha)
    around = np.concatenate([around - np.pi, around, around + np.pi])  # directions wrap every pi
    peaks = np.asarray(found, dtype=np.float64)
    support = (np.searchsorted(around, peaks + min_separation_rad, side="right")
               - np.searchsorted(around, peaks - min_separation_rad, side="left")).tolist()
    kept: list[float] = []
    for k in np.argsort(support)[::-1]:
        if all(abs(float(wrap_half(found[k] - other))) >= min_separation_rad for other in kept):
            kept.append(float(found[k]))
    return np.asarray(kept, dtype=np.float64)


def refine_orientation(
    points: FloatArray,
    pairs: HoughPairs,
    orientation_rad: float,
    *,
    tolerance_rad: float = float(np.deg2rad(2.5)),
    max_offset_m: float = 0.12,
) -> float:
    """Mean direction (radians) of the aligned pairs near a histogram peak, long pairs weighing most.

    Repeated with the tolerance halved down to a fifth, so pairs of neighbouring peaks drop out.
    """
    # the mean moves at most the tolerance at each pass, so later passes look only at pairs within twice the
    # sum of the tolerances of the first direction
    candidates = np.abs(wrap_half(pairs.alpha - orientation_rad)) <= 2 * (1.0 + 0.5 + 0.25 + 0.2) * tolerance_rad
    alpha = pairs.alpha[candidates]
    delta = points[pairs.j[candidates]] - points[pairs.i[candidates]]
    weight = np.sum(delta**2, axis=1)
    for scale in (1.0, 0.5, 0.25, 0.2):
        deviation = wrap_half(alpha - orientation_rad)
        normal = np.array([-np.sin(orientation_rad), np.cos(orientation_rad)])
        near = (np.abs(deviation) <= scale * tolerance_rad) & (np.abs(delta @ normal) <= max_offset_m)
        if not near.any():
            break
        orientation_rad = float(
            wrap_half(orientation_rad + np.sum(weight[near] * deviation[near]) / np.sum(weight[near]))
        )
    return orientation_rad


def segment_aligned(
    points: FloatArray,
    pairs: HoughPairs,
    orientation_rad: float,
    *,
    tolerance_rad: float = float(np.deg2rad(2.5)),
    max_offset_m: float = 0.12,
    eps_m: float = 0.08,
    metres_per_rad: float = 2.0,
    along_scale: float = 0.01,
    min_samples: int = 4,
) -> IntArray:
    """Label points by the aligned set they belong to along one dominant orientation.

    The intersections within ``tolerance_rad`` of ``orientation_rad``, of pairs whose points are
    at most ``max_offset_m`` apart across that orientation (so pairs bridging two close parallel
    rows drop out), are clustered by DBSCAN on (offset of the pair's midpoint along the
    orientation's normal, ``metres_per_rad`` times its angle's deviation, ``along_scale`` times
    the midpoint's position along the orientation). The offset is measured at the pair itself,
    so a small angle error far from the origin does not smear it, and the along term keeps two
    close rows apart when a slight angle error makes their offsets meet at opposite ends. Each
    point takes the cluster most of its pairs fell in.

    Returns
    -------
    ndarray of int64, shape (N,)
        Set label per point, -1 for points in no set.
    """
    labels = np.full(len(points), -1, dtype=np.int64)
    deviation = wrap_half(pairs.alpha - orientation_rad)
    normal = np.array([-np.sin(orientation_rad), np.cos(orientation_rad)])
    offset = np.abs((points[pairs.j] - points[pairs.i]) @ normal)
    near = (np.abs(deviation) <= tolerance_rad) & (offset <= max_offset_m)
    if near.sum() < min_samples:
        return labels
    mid = 0.5 * (points[pairs.i[near]] + points[pairs.j[near]])
    along = mid @ np.array([normal[1], -normal[0]])
    features = np.column_stack([mid @ normal, metres_per_rad * deviation[near], along_scale * along])
    clusters = dbscan(features, eps=eps_m, min_samples=min_samples)
    good = clusters >= 0
    if not good.any():
        return labels
    ends = np.concatenate([pairs.i[near][good], pairs.j[near][good]])
    votes = np.concatenate([clusters[good], clusters[good]])
    width = int(votes.max()) + 1
    counts = np.bincount(ends * width + votes, minlength=len(points) * width).reshape(len(points), width)
    voted = counts.sum(axis=1) > 0
    labels[voted] = np.argmax(counts[voted], axis=1)
    return labels

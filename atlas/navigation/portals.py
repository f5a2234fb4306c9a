"""Portals: where two regions of the segment layer meet, one point per pair of neighbouring regions."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from atlas.navigation.grid import Frame


@dataclass(frozen=True, slots=True)
class Portal:
    """The passage between regions ``a`` < ``b``.

    ``x_m``, ``y_m`` is the point of their shared boundary nearest the boundary's mean (so it lies
    on the boundary even when that is bent or in pieces); ``width_m`` is the boundary's length
    counted in cell sides (exact for straight axis-aligned boundaries, up to 41 % long for
    diagonal ones).
    """

    a: int
    b: int
    x_m: float
    y_m: float
    width_m: float


def find_portals(segments: npt.NDArray[np.integer], frame: Frame) -> dict[tuple[int, int], Portal]:
    """Every pair of 4-neighbouring cells of different non-zero region ids, grouped by region pair.

    Parameters
    ----------
    segments : (H, W) integer array
        Region id per cell, 0 where no region (the ``place_segments`` layer).
    frame : Frame
        Where the grid lies.

    Returns
    -------
    dict
        ``(a, b) -> Portal`` with ``a < b``.
    """
    seg = np.asarray(segments).astype(np.int64, copy=False)
    res = frame.resolution_m
    pieces = []
    for axis in (1, 0):  # neighbours along x, then along y
        lo = seg[:, :-1] if axis == 1 else seg[:-1, :]
        hi = seg[:, 1:] if axis == 1 else seg[1:, :]
        meet = (lo != hi) & (lo > 0) & (hi > 0)
        rows, cols = np.nonzero(meet)
        # the boundary between the two cells: a cell edge shared by (row, col) and the next cell
        xs = frame.origin_x_m + (cols + (1.0 if axis == 1 else 0.5)) * res
        ys = frame.origin_y_m + (rows + (0.5 if axis == 1 else 1.0)) * res
        pieces.append((np.minimum(lo[meet], hi[meet]), np.maximum(lo[meet], hi[meet]), xs, ys))
    a = np.concatenate([p[0] for p in pieces])
    if a.size == 0:
        return {}
    b = np.concatenate([p[1] for p in pieces])
    x = np.concatenate([p[2] for p in pieces])
    y = np.concatenate([p[3] for p in pieces])
    pair = a * (int(b.max()) + 1) + b
    _, inverse, counts = np.unique(pair, return_inverse=True, return_counts=True)
    mean_x = np.bincount(inverse, weights=x) / counts
    mean_y = np.bincount(inverse, weights=y) / counts
    off = (x - mean_x[inverse]) ** 2 + (y - mean_y[inverse]) ** 2
    order = np.lexsort((off, inverse))
    first = order[np.r_[0, np.flatnonzero(np.diff(inverse[order])) + 1]]
    return {
        (int(a[i]), int(b[i])): Portal(int(a[i]), int(b[i]), float(x[i]), float(y[i]), float(n * res))
        for i, n in zip(first, counts[inverse[first]], strict=True)
    }

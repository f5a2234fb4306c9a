"""The segment layer's grid with its free cells: point location, straight-leg checks and grid search.

Cells are addressed (row, col) with row 0 at the lowest y, as in :class:`shared.store.GridLayer`;
everything that leaves this module is in map metres.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from shared.store import GridLayer

FREE_BELOW = 50
"""Occupancy values ``0 <= v < FREE_BELOW`` are free (more likely free than occupied); -1 (unknown) and
50..100 are not. Routes only use free cells."""
MAX_SEARCH_CELLS = 40_000
"""Largest grid a leg's grid search works on; bigger crops are downsampled (a coarse cell is free only if all
its cells are)."""

BoolGrid = npt.NDArray[np.bool_]
Point = tuple[float, float]


@dataclass(frozen=True, slots=True)
class Frame:
    """Where a grid lies: cell side (metres), the map position of cell (0, 0)'s outer corner, and its shape."""

    resolution_m: float
    origin_x_m: float
    origin_y_m: float
    shape: tuple[int, int]

    @classmethod
    def of(cls, layer: GridLayer) -> Frame:
        rows, cols = layer.data.shape
        return cls(layer.resolution_m, layer.origin_x_m, layer.origin_y_m, (int(rows), int(cols)))

    def cell(self, x_m: float, y_m: float) -> tuple[int, int]:
        """(row, col) of the cell holding (x, y); may lie outside the grid."""
        return (math.floor((y_m - self.origin_y_m) / self.resolution_m),
                math.floor((x_m - self.origin_x_m) / self.resolution_m))

    def centre(self, row: float, col: float) -> Point:
        """Map position of the centre of cell (row, col)."""
        return (self.origin_x_m + (col + 0.5) * self.resolution_m, self.origin_y_m + (row + 0.5) * self.resolution_m)

    def inside(self, row: int, col: int) -> bool:
        return 0 <= row < self.shape[0] and 0 <= col < self.shape[1]


def polygon_cells(rings: Sequence[npt.NDArray[np.float64]], frame: Frame) -> BoolGrid:
    """Cells of ``frame`` whose centres the polygons (rings (K, 2) in map metres) cover."""
    shift = 4
    scale = float(1 << shift) / frame.resolution_m
    polygons = [np.round((ring - (frame.origin_x_m, frame.origin_y_m)) * scale - 0.5 * (1 << shift)
                         ).astype(np.int32) for ring in rings]
    covered = np.zeros(frame.shape, dtype=np.uint8)
    cv2.fillPoly(covered, polygons, 1, cv2.LINE_8, shift)
    inside: BoolGrid = covered > 0
    return inside


def free_cells(occupancy: GridLayer, frame: Frame) -> BoolGrid:
    """Which cells of ``frame`` are free in ``occupancy`` (sampled at cell centres; outside it: not free).

    The occupancy layer may be newer than the segment layer and cover a different extent or
    resolution, so it is resampled by coordinates rather than assumed aligned.
    """
    occ = Frame.of(occupancy)
    rows = np.arange(frame.shape[0])
    cols = np.arange(frame.shape[1])
    ys = frame.origin_y_m + (rows + 0.5) * frame.resolution_m
    xs = frame.origin_x_m + (cols + 0.5) * frame.resolution_m
    occ_rows = np.floor((ys - occ.origin_y_m) / occ.resolution_m).astype(np.int64)
    occ_cols = np.floor((xs - occ.origin_x_m) / occ.resolution_m).astype(np.int64)
    row_ok = (occ_rows >= 0) & (occ_rows < occ.shape[0])
    col_ok = (occ_cols >= 0) & (occ_cols < occ.shape[1])
    values = occupancy.data[np.clip(occ_rows, 0, occ.shape[0] - 1)[:, None],
                            np.clip(occ_cols, 0, occ.shape[1] - 1)[None, :]].astype(np.int16)
    free: BoolGrid = (values >= 0) & (values < FREE_BELOW) & row_ok[:, None] & col_ok[None, :]
    return free


def nearest_cell(mask: BoolGrid, frame: Frame, x_m: float, y_m: float, *, tolerance_m: float
                 ) -> tuple[int, int] | None:
    """The ``mask`` cell whose centre is nearest (x, y), within ``tolerance_m`` metres; None if there is none.

    The cell holding the point wins when it is in the mask. Only a window of the tolerance's size
    is searched.
    """
    row, col = frame.cell(x_m, y_m)
    if frame.inside(row, col) and mask[row, col]:
        return row, col
    reach = max(1, math.ceil(tolerance_m / frame.resolution_m))
    if not (-reach <= row < frame.shape[0] + reach and -reach <= col < frame.shape[1] + reach):
        return None
    r0, r1 = max(0, row - reach), min(frame.shape[0], row + reach + 1)
    c0, c1 = max(0, col - reach), min(frame.shape[1], col + reach + 1)
    if r0 >= r1 or c0 >= c1:
        return None
    rr, cc = np.nonzero(mask[r0:r1, c0:c1])
    if rr.size == 0:
        return None
    cx = (x_m - frame.origin_x_m) / frame.resolution_m - 0.5
    cy = (y_m - frame.origin_y_m) / frame.resolution_m - 0.5
    distance = np.hypot(rr + r0 - cy, cc + c0 - cx) * frame.resolution_m
    best = int(np.argmin(distance))
    if distance[best] > tolerance_m:
        return None
    return int(rr[best] + r0), int(cc[best] + c0)


def segment_clear(mask: BoolGrid, frame: Frame, a: Point, b: Point) -> bool:
    """Whether the straight segment a -> b (map metres) stays on ``mask`` cells (sampled every half cell)."""
    length = math.dist(a, b)
    n = max(2, math.ceil(length / (0.5 * frame.resolution_m)) + 1)
    t = np.linspace(0.0, 1.0, n)
    xs = a[0] + (b[0] - a[0]) * t
    ys = a[1] + (b[1] - a[1]) * t
    cols = np.floor((xs - frame.origin_x_m) / frame.resolution_m).astype(np.int64)
    rows = np.floor((ys - frame.origin_y_m) / frame.resolution_m).astype(np.int64)
    if rows.min() < 0 or cols.min() < 0 or rows.max() >= frame.shape[0] or cols.max() >= frame.shape[1]:
        return False
    return bool(mask[rows, cols].all())


def _grid_graph(free: BoolGrid) -> tuple[coo_matrix, npt.NDArray[np.int64]]:
    """8-connected graph of the ``free`` cells (cell sides as weights; no corner cutting) and cell -> node."""
    index = np.full(free.shape, -1, dtype=np.int64)
    index[free] = np.arange(int(free.sum()))
    sources: list[npt.NDArray[np.int64]] = []
    targets: list[npt.NDArray[np.int64]] = []
    weights: list[npt.NDArray[np.float64]] = []
    rows, cols = free.shape
    for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
        r0, r1 = 0, rows - dr
        c0, c1 = max(0, -dc), cols - max(0, dc)
        here = free[r0:r1, c0:c1]
        there = free[r0 + dr:r1 + dr, c0 + dc:c1 + dc]
        ok: BoolGrid = here & there
        if dr and dc:  # a diagonal step needs both cells beside it free
            ok &= free[r0 + dr:r1 + dr, c0:c1] & free[r0:r1, c0 + dc:c1 + dc]
        sources.append(index[r0:r1, c0:c1][ok])
        targets.append(index[r0 + dr:r1 + dr, c0 + dc:c1 + dc][ok])
        weights.append(np.full(int(ok.sum()), math.hypot(dr, dc)))
    n = int(free.sum())
    graph = coo_matrix((np.concatenate(weights), (np.concatenate(sources), np.concatenate(targets))), shape=(n, n))
    return graph, index


def grid_path(mask: BoolGrid, frame: Frame, a: Point, b: Point, *, within: tuple[slice, slice] | None = None,
              snap_m: float = 1.0) -> list[Point] | None:
    """A short path a -> b (map metres) over ``mask`` cells, as corner points, or None if there is none.

    Dijkstra on the 8-connected free cells of the ``within`` crop (default: the whole grid),
    downsampled to at most :data:`MAX_SEARCH_CELLS` cells, then shortened by dropping every point
    the previous kept point sees in a straight line on ``mask``. The ends may lie up to ``snap_m``
    off the mask. The result starts at ``a`` and ends at ``b``.
    """
    rows, cols = within if within is not None else (slice(0, frame.shape[0]), slice(0, frame.shape[1]))
    crop = mask[rows, cols]
    factor = max(1, math.ceil(math.sqrt(crop.size / MAX_SEARCH_CELLS)))
    if factor > 1:
        h, w = crop.shape[0] // factor * factor, crop.shape[1] // factor * factor
        crop = np.asarray(crop[:h, :w].reshape(h // factor, factor, w // factor, factor).all(axis=(1, 3)),
                          dtype=np.bool_)
    coarse = Frame(frame.resolution_m * factor, frame.origin_x_m + cols.start * frame.resolution_m,
                   frame.origin_y_m + rows.start * frame.resolution_m, (int(crop.shape[0]), int(crop.shape[1])))
    start = nearest_cell(crop, coarse, *a, tolerance_m=snap_m + coarse.resolution_m)
    goal = nearest_cell(crop, coarse, *b, tolerance_m=snap_m + coarse.resolution_m)
    if start is None or goal is None:
        return None
    graph, index = _grid_graph(crop)
    s, g = int(index[start]), int(index[goal])
    _, predecessors = dijkstra(graph, directed=False, indices=s, return_predecessors=True)
    if s != g and predecessors[g] < 0:
        return None
    chain = [g]
    while chain[-1] != s:
        chain.append(int(predecessors[chain[-1]]))
    cells = np.argwhere(crop)[chain[::-1]]
    points = [a, *(coarse.centre(float(r), float(c)) for r, c in cells), b]
    return _shortcut(points, mask, frame)


def _shortcut(points: list[Point], mask: BoolGrid, frame: Frame) -> list[Point]:
    """``points`` with every point dropped that the last kept point sees straight on ``mask``."""
    kept = [points[0]]
    i = 0
    while i < len(points) - 1:
        j = i + 1
        while j + 1 < len(points) and segment_clear(mask, frame, points[i], points[j + 1]):
            j += 1
        kept.append(points[j])
        i = j
    return kept


def region_slices(segments: npt.NDArray[np.integer]) -> dict[int, tuple[slice, slice]]:
    """Bounding slices (rows, cols) of every region id present in ``segments``."""
    found = ndimage.find_objects(segments.astype(np.int32, copy=False))
    return {i + 1: (s[0], s[1]) for i, s in enumerate(found) if s is not None}


def grown(slices: tuple[slice, slice], shape: tuple[int, int], cells: int) -> tuple[slice, slice]:
    """``slices`` widened by ``cells`` on every side, clipped to ``shape``."""
    rows, cols = slices
    return (slice(max(0, rows.start - cells), min(shape[0], rows.stop + cells)),
            slice(max(0, cols.start - cells), min(shape[1], cols.stop + cells)))

"""How much an occupancy grid changed between two versions, as the decomposition sees it."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import cv2
import numpy as np
import numpy.typing as npt

from services.grid_decomposition.errors import DecompositionError
from services.grid_decomposition.pipeline import FREE_PERCENT, OCCUPIED_PERCENT

if TYPE_CHECKING:  # the store (SQLAlchemy) is no import of the decomposition
    from shared.store import GridLayer

UNKNOWN, FREE, UNCERTAIN, OCCUPIED = 0, 1, 2, 3
"""Cell classes of :func:`occupancy_classes`."""

_ALIGN_TOLERANCE_CELLS = 1e-3


def occupancy_classes(occupancy: npt.NDArray[np.integer]) -> npt.NDArray[np.uint8]:
    """Class of every cell with :func:`decompose`'s thresholds: unknown, free, uncertain or occupied.

    Parameters
    ----------
    occupancy : (H, W) integer
        -1 unknown, 0..100 occupancy percent (values outside count as unknown).

    Returns
    -------
    (H, W) uint8
        :data:`UNKNOWN` (0), :data:`FREE` (below 25 %), :data:`UNCERTAIN` or :data:`OCCUPIED`
        (above 65 %).

    Examples
    --------
    >>> occupancy_classes(np.array([[-1, 0, 50, 100]], dtype=np.int8)).tolist()
    [[0, 1, 2, 3]]
    """
    occ = np.asarray(occupancy)
    if occ.ndim != 2 or not np.issubdtype(occ.dtype, np.integer):
        raise DecompositionError(f"occupancy must be a 2-D integer grid, got {occ.dtype} of shape {occ.shape}")
    occ16 = occ.astype(np.int16)
    classes = np.full(occ.shape, UNKNOWN, dtype=np.uint8)
    classes[(occ16 >= 0) & (occ16 < FREE_PERCENT)] = FREE
    classes[(occ16 >= FREE_PERCENT) & (occ16 <= OCCUPIED_PERCENT)] = UNCERTAIN
    classes[(occ16 > OCCUPIED_PERCENT) & (occ16 <= 100)] = OCCUPIED
    return classes


def changed_fraction(before: GridLayer, after: GridLayer) -> float:
    """How much of the map changed: the larger of the explored share and the structural share.

    * explored: cells known in one grid only, over the cells known in either (new ground mapped,
      or ground forgotten);
    * structural: cells known in both whose class (:func:`occupancy_classes`) differs, over the
      cells that are uncertain or occupied in either.

    The second share is measured against the obstacles, not all known cells, because obstacles
    are sparse: in a lidar map of a warehouse uprights and walls fill 1-3 % of the known cells,
    so even an entirely different rack layout changes only 2-4 % of them.

    The grids are compared in map coordinates: a grid that grew (the occupancy layer extends as
    robots explore) is padded with unknown cells. Grids of different resolution, or whose origins
    are not a whole number of cells apart, cannot be compared cell by cell and count as entirely
    changed.

    Parameters
    ----------
    before, after : GridLayer
        Occupancy layers (-1 unknown, 0..100), row 0 = lowest y.

    Returns
    -------
    float
        In [0, 1]; 0 when nothing differs (also when neither grid has a known cell).
    """
    res = before.resolution_m
    if not math.isclose(res, after.resolution_m, rel_tol=1e-9):
        return 1.0
    offset = np.array([after.origin_y_m - before.origin_y_m, after.origin_x_m - before.origin_x_m]) / res
    shift = np.rint(offset).astype(np.int64)
    if np.any(np.abs(offset - shift) > _ALIGN_TOLERANCE_CELLS):
        return 1.0
    a, b = occupancy_classes(before.data), occupancy_classes(after.data)
    # b's cell (r, c) is a's cell (r + shift[0], c + shift[1]); the overlap in a's cells is [lo, hi)
    lo = np.maximum(0, shift)
    hi = np.maximum(lo, np.minimum(a.shape, shift + b.shape))
    over_a = a[lo[0] : hi[0], lo[1] : hi[1]]
    over_b = b[lo[0] - shift[0] : hi[0] - shift[0], lo[1] - shift[1] : hi[1] - shift[1]]
    known_a, known_b = over_a != UNKNOWN, over_b != UNKNOWN
    obstacle_a, obstacle_b = over_a >= UNCERTAIN, over_b >= UNCERTAIN
    explored, known, obstacle = (int(np.count_nonzero(known_a ^ known_b)), int(np.count_nonzero(known_a | known_b)),
                                 int(np.count_nonzero(obstacle_a | obstacle_b)))
    for whole, over in ((a, over_a), (b, over_b)):  # cells outside the overlap
        outside_known = int(np.count_nonzero(whole != UNKNOWN) - np.count_nonzero(over != UNKNOWN))
        explored += outside_known
        known += outside_known
        obstacle += int(np.count_nonzero(whole >= UNCERTAIN) - np.count_nonzero(over >= UNCERTAIN))
    structural = int(np.count_nonzero(known_a & known_b & (over_a != over_b)))
    return max(explored / known if known else 0.0, structural / obstacle if obstacle else 0.0)


def unchanged_cells(
    before: npt.NDArray[np.integer],
    after: npt.NDArray[np.integer],
    *,
    resolution_m: float,
    covered: npt.NDArray[np.bool_] | None = None,
    margin_m: float = 0.05,
    jitter_m: float = 0.0,
) -> npt.NDArray[np.bool_]:
    """Cells of the same class (:func:`occupancy_classes`) in both grids, and not within ``margin_m`` of a changed one.

    A cell whose class differs counts as the same when each grid has the other's class within ``jitter_m`` of it:
    a map drawn again shifted by a fraction of a cell (a growing map whose origin moved, a SLAM pass that
    nudged the walls) moves every wall by a cell, which is no change of the room behind it. A wall that
    appeared or went, and ground seen further than ``jitter_m`` beyond what was seen, are changes.

    Parameters
    ----------
    before, after : (H, W) integer
        Occupancy of the same cells (-1 unknown, 0..100).
    resolution_m : float
        Metres per cell.
    covered : (H, W) bool, optional
        Cells ``before`` held (the grid grew: the others are changed); all by default.
    margin_m : float
        A cell this close to a changed one counts as changed (a wall drawn one cell over moves its neighbours).
    jitter_m : float
        How far a cell's content may have moved and still be the same (0: cell by cell).

    Returns
    -------
    (H, W) bool
    """
    b, a = np.asarray(before), np.asarray(after)
    if b.shape != a.shape or (covered is not None and covered.shape != a.shape):
        raise DecompositionError(f"grids differ in shape: {b.shape}, {a.shape}"
                                 + ("" if covered is None else f", {covered.shape}"))
    if not resolution_m > 0:
        raise DecompositionError(f"resolution_m must be positive, got {resolution_m}")
    if jitter_m < 0:
        raise DecompositionError(f"jitter_m must not be negative, got {jitter_m}")
    cb, ca = occupancy_classes(b), occupancy_classes(a)
    changed = cb != ca
    jitter = round(jitter_m / resolution_m)
    if jitter > 0:
        disk = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * jitter + 1,) * 2)
        near_b = np.stack([cv2.dilate((cb == c).astype(np.uint8), disk) for c in range(OCCUPIED + 1)]) > 0
        near_a = np.stack([cv2.dilate((ca == c).astype(np.uint8), disk) for c in range(OCCUPIED + 1)]) > 0
        rows, cols = np.arange(cb.shape[0])[:, None], np.arange(cb.shape[1])[None, :]
        changed &= ~(near_b[ca, rows, cols] & near_a[cb, rows, cols])
    if covered is not None:
        changed |= ~covered
    reach = round(margin_m / resolution_m)
    if reach > 0:
        changed = cv2.dilate(changed.astype(np.uint8), np.ones((2 * reach + 1,) * 2, np.uint8)) > 0
    return np.asarray(~changed)

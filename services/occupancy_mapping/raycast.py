"""Free-space rasterisation of one scan into a grid patch, without a Python loop over beams.

Coordinates are continuous cell coordinates ``(col, row)`` of the patch, with cell centres at
integer values. Two methods give the same cells up to boundary pixels:

- :attr:`RayCasting.POLYGON` fills the polygon sensor -> consecutive beam ends with
  ``cv2.fillPoly`` (fast; assumes the beams sweep monotonically, as every laser scanner does);
- :attr:`RayCasting.SAMPLED` samples every ray at half-cell steps (exact per ray, slower).
"""

from __future__ import annotations

from enum import Enum

import cv2
import numpy as np
import numpy.typing as npt

_SHIFT = 4  # cv2 fixed-point fraction bits for sub-cell vertex positions


class RayCasting(Enum):
    """How the free space of a scan is rasterised."""

    POLYGON = "polygon"
    SAMPLED = "sampled"


def free_space_mask(
    origin_cr: npt.NDArray[np.float64],
    ends_cr: npt.NDArray[np.float64],
    returned: npt.NDArray[np.bool_],
    no_return: npt.NDArray[np.bool_],
    shape: tuple[int, int],
    *,
    method: RayCasting = RayCasting.POLYGON,
) -> npt.NDArray[np.bool_]:
    """Cells swept by the beams from ``origin_cr`` to ``ends_cr``.

    Beams without a return are always cast as single rays: a polygon through them and their
    returned neighbours would sweep the space behind nearby obstacles.

    Parameters
    ----------
    origin_cr : (2,) float64
        Sensor position, (col, row) in patch cells.
    ends_cr : (n, 2) float64
        Where each beam's free space ends, (col, row) in patch cells, in scan order.
    returned : (n,) bool
        Beams that ended on an obstacle.
    no_return : (n,) bool
        Beams that clear free space without an obstacle at their end; beams in neither mask are
        ignored (the polygon closes back to the sensor across them).
    shape : (rows, cols)
        Patch shape; every point must lie inside it.
    method : RayCasting
        Rasterisation method.

    Returns
    -------
    (rows, cols) bool
    """
    if method is RayCasting.POLYGON:
        polygon = _polygon_mask(origin_cr, ends_cr, returned, shape)
        return polygon | _sampled_mask(origin_cr, ends_cr, no_return, shape) if no_return.any() else polygon
    return _sampled_mask(origin_cr, ends_cr, returned | no_return, shape)


def _polygon_mask(
    origin_cr: npt.NDArray[np.float64],
    ends_cr: npt.NDArray[np.float64],
    usable: npt.NDArray[np.bool_],
    shape: tuple[int, int],
) -> npt.NDArray[np.bool_]:
    vertices = np.where(usable[:, None], ends_cr, origin_cr[None, :])
    vertices = np.vstack([origin_cr[None, :], vertices])
    fixed = np.rint(vertices * (1 << _SHIFT)).astype(np.int32)
    canvas = np.zeros(shape, dtype=np.uint8)
    cv2.fillPoly(canvas, [fixed.reshape(-1, 1, 2)], 1, lineType=cv2.LINE_8, shift=_SHIFT)
    return canvas.astype(bool)


def _sampled_mask(
    origin_cr: npt.NDArray[np.float64],
    ends_cr: npt.NDArray[np.float64],
    usable: npt.NDArray[np.bool_],
    shape: tuple[int, int],
) -> npt.NDArray[np.bool_]:
    mask = np.zeros(shape, dtype=bool)
    ends = ends_cr[usable]
    if ends.size == 0:
        return mask
    delta = ends - origin_cr[None, :]
    length = np.hypot(delta[:, 0], delta[:, 1])
    steps = int(np.ceil(length.max() * 2.0)) + 1
    t = np.linspace(0.0, 1.0, steps)[None, :]
    cols = np.rint(origin_cr[0] + delta[:, 0:1] * t).astype(np.intp)
    rows = np.rint(origin_cr[1] + delta[:, 1:2] * t).astype(np.intp)
    mask[rows.ravel(), cols.ravel()] = True
    return mask

"""Room structure: walls without furniture, for doorways and necks."""

from __future__ import annotations

import cv2
import numpy as np
import numpy.typing as npt


def furniture(
    obstacle: npt.NDArray[np.bool_],
    *,
    resolution_m: float,
    max_area_m2: float = 1.0,
    max_extent_m: float = 1.2,
) -> npt.NDArray[np.bool_]:
    """Free-standing small obstacles: furniture, bins, pillars, table legs, clutter.

    An 8-connected obstacle component is furniture when it does not touch the map border, covers
    at most ``max_area_m2`` and its bounding box is at most ``max_extent_m`` on its longer side.
    Walls, even short free-standing pieces, are longer; furniture pushed against a wall is part
    of the wall's component and stays.

    Parameters
    ----------
    obstacle : (H, W) bool
        Occupied or unknown cells.
    resolution_m : float
        Metres per cell.

    Returns
    -------
    (H, W) bool
        The furniture cells (a subset of ``obstacle``).
    """
    n, parts, stats, _ = cv2.connectedComponentsWithStats(obstacle.astype(np.uint8), connectivity=8)
    h, w = obstacle.shape
    x, y = stats[:, cv2.CC_STAT_LEFT], stats[:, cv2.CC_STAT_TOP]
    bw, bh = stats[:, cv2.CC_STAT_WIDTH], stats[:, cv2.CC_STAT_HEIGHT]
    inner = (x > 0) & (y > 0) & (x + bw < w) & (y + bh < h)
    small = (stats[:, cv2.CC_STAT_AREA] * resolution_m**2 <= max_area_m2) & (
        np.maximum(bw, bh) * resolution_m <= max_extent_m
    )
    keep = inner & small
    keep[0] = False
    return np.asarray(keep[parts], dtype=bool)

"""Clutter inside units: furniture and the unseen space behind it, as obstacles of the world.

The seed's world (section 3.4) draws a unit's inside free, and says where K(W,M) is lost on real maps: "the
clutter caused by furniture and things" (section 3.9.4). A laser map draws a desk, a shelf or a table group as a
blob of occupied cells (its faces the laser saw) and unknown cells (what lay behind them) inside a room. Given
the units, every such blob is explained on its own: drawn as an obstacle of one class (occupied, for furniture
drawn black, or unexplained, for the unseen space behind it), whichever the sensor model prefers, when that gain
in log likelihood beats a prior cost per obstacle (so that a speck stays unexplained) and the blob is no bigger
than a piece of furniture (a unit stretched over unexplored space stays a misfit). The blobs do not interact,
so this is the exact maximum of the posterior over obstacles for the given units; the chain does not see them
(units are fitted as the seed fits them).
"""

from __future__ import annotations

from typing import NamedTuple

import cv2
import numpy as np
import numpy.typing as npt

from services.floor_plan.likelihood import CellClass


class Clutter(NamedTuple):
    """The world's rendering with its clutter obstacles and what they are."""

    classes_world: npt.NDArray[np.uint8]  # C_W with the obstacles drawn (same shape as the map)
    obstacles: npt.NDArray[np.int32]  # 0 outside obstacles, else the obstacle's number 1..drawn
    drawn: int  # how many obstacles
    drawn_occupied: int  # how many of them are drawn occupied (the rest unexplained)


def explain_clutter(
    classes_map: npt.NDArray[np.uint8], classes_world: npt.NDArray[np.uint8], log_table: npt.NDArray[np.float64],
    *, max_cells: int, log_cost: float,
) -> Clutter:
    """Draw the non-free blobs of the map inside the world's free space as obstacles where they pay.

    Parameters
    ----------
    classes_map, classes_world : (H, W) uint8
        C_M and C_W (:class:`~services.floor_plan.likelihood.CellClass`).
    log_table : (3, 3) float
        ``log p[C_W][C_M]`` (:func:`~services.floor_plan.likelihood.log_sensor_table`).
    max_cells : int
        The largest blob (8-connected non-free map cells that C_W draws free) an obstacle may be.
    log_cost : float
        The prior's cost of one obstacle (nats, >= 0): a blob is drawn when its gain in log likelihood is larger.

    >>> from services.floor_plan.likelihood import log_sensor_table
    >>> cm = np.zeros((6, 6), np.uint8); cm[1:3, 1:3] = CellClass.WALL; cm[4, 4] = CellClass.UNKNOWN
    >>> out = explain_clutter(cm, np.zeros_like(cm), log_sensor_table(), max_cells=9, log_cost=4.0)
    >>> out.drawn, int(out.classes_world[1, 1]), int(out.classes_world[4, 4])  # the speck is not worth one
    (1, 2, 0)
    """
    if classes_map.shape != classes_world.shape:
        raise ValueError(f"C_M {classes_map.shape} and C_W {classes_world.shape} differ in shape")
    if max_cells < 1 or log_cost < 0:
        raise ValueError(f"need max_cells >= 1 and log_cost >= 0, got {max_cells}, {log_cost}")
    blobs = (classes_world == CellClass.FREE) & (classes_map != CellClass.FREE)
    count, labels, stats, _ = cv2.connectedComponentsWithStats(blobs.astype(np.uint8), connectivity=8)
    cells = labels[blobs]
    seen = classes_map[blobs]
    gains = [np.bincount(cells, weights=log_table[c, seen] - log_table[CellClass.FREE, seen], minlength=count)
             for c in (CellClass.WALL, CellClass.UNKNOWN)]
    as_wall = gains[0] >= gains[1]
    take = (np.maximum(gains[0], gains[1]) > log_cost) & (stats[:, cv2.CC_STAT_AREA] <= max_cells)
    take[0] = False
    number = np.zeros(count, np.int32)
    number[take] = np.arange(1, int(take.sum()) + 1, dtype=np.int32)
    obstacles = number[labels]
    mask = obstacles > 0
    out = classes_world.copy()
    out[mask] = np.where(as_wall, np.uint8(CellClass.WALL), np.uint8(CellClass.UNKNOWN))[labels[mask]]
    return Clutter(out, obstacles, int(take.sum()), int((take & as_wall).sum()))


def explain_exterior(
    classes_map: npt.NDArray[np.uint8], classes_world: npt.NDArray[np.uint8], log_table: npt.NDArray[np.float64],
    *, max_cells: int, log_cost: float,
) -> Clutter:
    """Draw the occupied blobs of the map just outside the world's walls as wall obstacles where they pay.

    A wall's ragged outer edge, a pillar or a radiator against it, a wall of a space no unit explains: every
    8-connected blob of occupied map cells that C_W draws unknown (outside every unit and wall) and that touches a
    wall C_W draws, as a polygon (its outline simplified by Douglas-Peucker to within one cell, filled over the cells
    C_W draws unknown), when that polygon's gain in log likelihood beats ``log_cost`` and the blob is no larger than
    ``max_cells``. Blobs further from the walls (objects seen through windows and doors) are left alone.

    >>> from services.floor_plan.likelihood import log_sensor_table
    >>> cm = np.ones((8, 12), np.uint8); cm[3, 1:9] = CellClass.WALL; cm[6, 10] = CellClass.WALL
    >>> cw = np.ones_like(cm); cw[4:, :] = CellClass.WALL  # a wall drawn below the map's ragged edge
    >>> out = explain_exterior(cm, cw, log_sensor_table(), max_cells=50, log_cost=4.0)
    >>> out.drawn, int(out.classes_world[3, 5]), int(out.classes_world[2, 5])
    (1, 2, 1)
    """
    if classes_map.shape != classes_world.shape:
        raise ValueError(f"C_M {classes_map.shape} and C_W {classes_world.shape} differ in shape")
    if max_cells < 1 or log_cost < 0:
        raise ValueError(f"need max_cells >= 1 and log_cost >= 0, got {max_cells}, {log_cost}")
    outside = classes_world == CellClass.UNKNOWN
    blobs = outside & (classes_map == CellClass.WALL)
    count, labels, stats, _ = cv2.connectedComponentsWithStats(blobs.astype(np.uint8), connectivity=8)
    near = cv2.dilate((classes_world == CellClass.WALL).astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    touching = np.zeros(count, bool)
    touching[labels[blobs & near]] = True
    out = classes_world.copy()
    obstacles = np.zeros(classes_map.shape, np.int32)
    drawn = 0
    for i in np.flatnonzero(touching & (stats[:, cv2.CC_STAT_AREA] <= max_cells)):
        x, y, w, h = (int(v) for v in stats[i, :4])
        window = (slice(y, y + h), slice(x, x + w))
        contours, _ = cv2.findContours((labels[window] == i).astype(np.uint8), cv2.RETR_EXTERNAL,
                                       cv2.CHAIN_APPROX_SIMPLE)
        polygon = np.zeros((h, w), np.uint8)
        cv2.fillPoly(polygon, [cv2.approxPolyDP(c, 1.0, True) for c in contours], 1)
        cells = polygon.astype(bool) & outside[window]
        seen = classes_map[window][cells]
        if float(np.sum(log_table[CellClass.WALL, seen] - log_table[CellClass.UNKNOWN, seen])) > log_cost:
            drawn += 1
            out[window][cells] = CellClass.WALL
            obstacles[window][cells] = drawn
    return Clutter(out, obstacles, drawn, drawn)

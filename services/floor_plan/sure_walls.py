"""The unit walls a floor plan is sure of, as map cells: evidence another stage can cut its regions along.

A unit's wall is *sure* where the map draws it over most of its length: along each of a unit's four walls, a
position counts as drawn when an occupied cell of C_M lies across the wall's band (widened by
``tolerance_cells`` on both sides); doors of the plan in that wall are left out of the count. A wall drawn over
at least ``min_drawn_share`` of the rest is sure, and its whole band is returned, the stretches the map leaves
open included: a room's wall that the laser did not see where the room opens onto the corridor is the line the
plan continues the wall along.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from services.floor_plan.frame import to_map, to_work
from services.floor_plan.likelihood import CellClass
from services.floor_plan.pipeline import FloorPlan
from services.floor_plan.world import Side, wall_band


def sure_walls(
    plan: FloorPlan, *, min_drawn_share: float = 0.6, min_length_m: float = 1.0, tolerance_cells: int = 1,
    inner_only: bool = True, flank_m: float = 1.0,
) -> npt.NDArray[np.bool_]:
    """The bands of the unit walls the map draws over at least ``min_drawn_share`` of their length.

    Parameters
    ----------
    plan : FloorPlan
    min_drawn_share : float
        Share (0..1) of a wall's positions, doors left out, with an occupied cell across the band.
    min_length_m : float
        Shorter walls are not looked at.
    tolerance_cells : int
        The band is widened by this many cells on both sides when looking for occupied cells.

    Returns
    -------
    (H, W) bool
        Map cells (GridLayer order, ``plan.classes_map``'s shape) of the sure walls' bands.
    """
    if not 0.0 <= min_drawn_share <= 1.0:
        raise ValueError(f"min_drawn_share must be in [0, 1], got {min_drawn_share}")
    frame = plan.frame
    if not plan.units:
        return np.zeros(plan.classes_map.shape, dtype=bool)
    t = _wall_cells(plan)
    occupied = to_work(frame, (plan.classes_map == CellClass.WALL).astype(np.uint8), fill=0) > 0
    door = np.zeros(occupied.shape, dtype=bool)
    for d in plan.doors:
        door[d.rect.r0 : d.rect.r1 + 1, d.rect.c0 : d.rect.c1 + 1] = True
    h, w = occupied.shape
    out = np.zeros(occupied.shape, dtype=np.uint8)
    least = max(1, round(min_length_m / plan.resolution_m))
    k = tolerance_cells
    flank = max(1, round(flank_m / plan.resolution_m))
    for unit in plan.units:
        for side in Side:
            band = wall_band(unit.rect, side, t)
            across_rows = side in (Side.TOP, Side.BOTTOM)  # the band runs along columns
            if across_rows:
                r0, r1 = max(band.r0 - k, 0), min(band.r1 + k, h - 1)
                c0, c1 = max(band.c0, 0), min(band.c1, w - 1)
                drawn = occupied[r0 : r1 + 1, c0 : c1 + 1].any(axis=0)
                opening = door[band.r0 : band.r1 + 1, c0 : c1 + 1].any(axis=0) if band.r0 >= 0 else None
            else:
                r0, r1 = max(band.r0, 0), min(band.r1, h - 1)
                c0, c1 = max(band.c0 - k, 0), min(band.c1 + k, w - 1)
                drawn = occupied[r0 : r1 + 1, c0 : c1 + 1].any(axis=1)
                opening = door[r0 : r1 + 1, band.c0 : band.c1 + 1].any(axis=1) if band.c0 >= 0 else None
            rest = ~opening if opening is not None else np.ones(drawn.shape, dtype=bool)
            if drawn.size < least or not rest.any():
                continue
            if np.count_nonzero(drawn & rest) < min_drawn_share * np.count_nonzero(rest):
                continue
            cut = _flanked_gaps(drawn, min_run=flank) if inner_only else np.ones(drawn.shape, dtype=bool)
            if across_rows:
                out[max(band.r0, 0) : band.r1 + 1, c0 : c1 + 1][:, cut] = 1
            else:
                out[r0 : r1 + 1, max(band.c0, 0) : band.c1 + 1][cut] = 1
    return to_map(frame, out, fill=0) > 0


def _wall_cells(plan: FloorPlan) -> int:
    """The plan's wall band in cells: a unit's polygon runs along the middle of its walls, so it is one band
    shorter than the unit's rectangle along each side (the frame's turn keeps lengths)."""
    unit = plan.units[0]
    (x0, y0), (x1, y1) = unit.polygon_xy_m[0], unit.polygon_xy_m[1]
    return max(1, round(unit.rect.cols - float(np.hypot(x1 - x0, y1 - y0)) / plan.resolution_m))


def _flanked_gaps(drawn: npt.NDArray[np.bool_], *, min_run: int) -> npt.NDArray[np.bool_]:
    """The positions of open stretches along a wall that a drawn run at least as long as the stretch, and at least
    ``min_run``, flanks on both sides (a wall the map leaves open in places), with the drawn runs themselves."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], drawn.astype(np.int8), [0]])))
    starts, ends = edges[0::2], edges[1::2]  # drawn runs [start, end)
    out = drawn.copy()
    for i in range(len(starts) - 1):
        gap = starts[i + 1] - ends[i]
        need = min_run
        if ends[i] - starts[i] >= need and ends[i + 1] - starts[i + 1] >= need:
            out[ends[i] : starts[i + 1]] = True
    return out

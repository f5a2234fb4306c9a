"""Regions cut along the walls another stage is sure of (the floor plan's unit walls).

The floor-plan stage (:mod:`services.floor_plan`) explains a map as rectangular units with straight walls
and says which of them the map draws over most of their length
(:func:`~services.floor_plan.sure_walls.sure_walls`): there a region that crosses the wall through the stretch
the map leaves open (a room whose front the laser did not see, opening onto the corridor; no neck, so no
doorway is found there) is two rooms. A region is cut along those walls where the cut leaves at least two
pieces of ``min_piece_px`` each; smaller pieces and the wall's own cells go back to the piece they touch.
"""

from __future__ import annotations

import cv2
import numpy as np
import numpy.typing as npt

from services.grid_decomposition.segments import fill_from_neighbours


def split_at_walls(
    segments: npt.NDArray[np.int32], walls: npt.NDArray[np.bool_], *, min_piece_px: int,
    keep: npt.NDArray[np.bool_] | None = None,
) -> npt.NDArray[np.int32]:
    """Cut every region that a wall crosses into the pieces the wall leaves, where two or more are large.

    Parameters
    ----------
    segments : (H, W) int32
        Region id per pixel, 0 where no region.
    walls : (H, W) bool
        Cells of walls a region must not cross (:func:`~services.floor_plan.sure_walls.sure_walls`).
    min_piece_px : int
        Pieces smaller than this (4-connected, off the walls) are no region of their own.
    keep : (H, W) bool, optional
        Regions with a pixel here are left alone (racks, aisles, warehouse floors).

    Returns
    -------
    (H, W) int32
        The regions, the cut ones as their largest piece (the old id) and new ids above the old maximum.
    """
    if segments.shape != walls.shape:
        raise ValueError(f"walls of shape {walls.shape} on segments of shape {segments.shape}")
    out = np.array(segments, dtype=np.int32, copy=True)
    crossed = np.unique(segments[walls & (segments > 0)])
    if keep is not None and crossed.size:
        crossed = np.setdiff1d(crossed, np.unique(segments[keep & (segments > 0)]))
    next_id = int(segments.max()) + 1
    for k in crossed.tolist():
        rows, cols = np.nonzero(segments == k)
        box = np.s_[rows.min() : rows.max() + 1, cols.min() : cols.max() + 1]
        region = segments[box] == k
        n, pieces, stats, _ = cv2.connectedComponentsWithStats((region & ~walls[box]).astype(np.uint8), connectivity=4)
        large = [i for i in range(1, n) if stats[i, cv2.CC_STAT_AREA] >= min_piece_px]
        if len(large) < 2:
            continue
        large.sort(key=lambda i: -stats[i, cv2.CC_STAT_AREA])
        local = np.zeros(region.shape, dtype=np.int32)
        for rank, i in enumerate(large):
            local[pieces == i] = k if rank == 0 else next_id + rank - 1
        next_id += len(large) - 1
        local = fill_from_neighbours(local, region, max_iterations=region.size)
        local[region & (local == 0)] = k  # cut off from every large piece: it stays with the region
        out[box] = np.where(region, local, out[box])
    return out

"""Stable region ids: each region of a new decomposition takes the id of the previous region it continues.

A decomposition numbers its regions afresh; a live map must not (a key a WMS or an operator holds, a
block, must keep naming the same place). The previous decomposition's region ids are read on the new
grid (the map may have grown, so both grids are aligned by their origins), the two are matched one to
one by overlap (Hungarian assignment on IoU,
:func:`~services.grid_decomposition.continuity.match_regions`), matched regions keep the old id
and every other region gets a fresh id above every id handed out before (never reused).
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import networkx as nx
import numpy as np
import numpy.typing as npt

from services.grid_decomposition.change import unchanged_cells
from services.grid_decomposition.continuity import RegionPrior, match_regions
from services.grid_decomposition.errors import DecompositionError
from services.grid_decomposition.pipeline import Decomposition
from shared.store import GridLayer

IdGrid = npt.NDArray[np.integer]
NEXT_ID_KEY = "next_region_id"
"""Segment layer meta: the first region id never handed out on this map."""


class StableIds(NamedTuple):
    """``lut[new_id]`` is the stable id of each region of the new decomposition (0 for 0); ``next_id`` the
    first id never handed out; ``carried`` how many regions kept an id of the previous decomposition."""

    lut: npt.NDArray[np.int64]
    next_id: int
    carried: int


def ids_on_grid(
    ids: IdGrid,
    *,
    resolution_m: float,
    origin_xy_m: tuple[float, float],
    shape: tuple[int, int],
    to_resolution_m: float,
    to_origin_xy_m: tuple[float, float],
) -> npt.NDArray[np.int64]:
    """Region ids of one grid read at the cell centres of another (nearest cell; 0 outside the first grid).

    Parameters
    ----------
    ids : (H, W) integer
        Region id per cell, row 0 at the lowest y (GridLayer order), cells of ``resolution_m`` metres
        from ``origin_xy_m`` (map metres, the lower-left corner).
    shape, to_resolution_m, to_origin_xy_m
        The grid to read them on.

    Returns
    -------
    (shape) int64
    """
    if resolution_m <= 0 or to_resolution_m <= 0:
        raise DecompositionError(f"resolutions must be positive, got {resolution_m} and {to_resolution_m}")
    h, w = ids.shape
    ys = to_origin_xy_m[1] + (np.arange(shape[0]) + 0.5) * to_resolution_m
    xs = to_origin_xy_m[0] + (np.arange(shape[1]) + 0.5) * to_resolution_m
    rows = np.floor((ys - origin_xy_m[1]) / resolution_m).astype(np.int64)
    cols = np.floor((xs - origin_xy_m[0]) / resolution_m).astype(np.int64)
    ok_r, ok_c = (rows >= 0) & (rows < h), (cols >= 0) & (cols < w)
    out = np.asarray(ids, dtype=np.int64)[np.clip(rows, 0, h - 1)[:, None], np.clip(cols, 0, w - 1)[None, :]]
    return np.where(ok_r[:, None] & ok_c[None, :], out, 0)


def stable_ids(before: IdGrid | None, after: IdGrid, *, next_id: int, min_overlap: float = 0.5) -> StableIds:
    """Stable ids for the regions of ``after``: the matched previous id (:func:`match_regions`), else a fresh
    one from ``next_id`` up (raised above every id of ``before`` first, so none is ever handed out twice).

    ``before`` is the previous decomposition's stable ids on the grid of ``after`` (:func:`ids_on_grid`), or
    None for the first decomposition.
    """
    a = np.asarray(after, dtype=np.int64)
    matched = {} if before is None else match_regions(before, a, min_overlap=min_overlap)
    fresh = max(next_id, 1, int(np.max(before, initial=0)) + 1 if before is not None else 1)
    lut = np.zeros(int(a.max(initial=0)) + 1, dtype=np.int64)
    for rid in np.unique(a[a > 0]).tolist():
        if rid in matched:
            lut[rid] = matched[rid]
        else:
            lut[rid], fresh = fresh, fresh + 1
    return StableIds(lut, fresh, len(matched))


def region_prior(previous: GridLayer, reference: GridLayer, occupancy: GridLayer, *,
                 jitter_m: float = 0.15) -> RegionPrior:
    """The previous decomposition as a prior for decomposing ``occupancy``
    (:func:`~services.grid_decomposition.continuity.keep_regions`): ``previous`` is its segment layer, ``reference``
    the occupancy it was made from; both are read on the grid of ``occupancy`` (aligned by their origins, cells
    ``reference`` did not cover are changed).

    Content moved by up to ``jitter_m`` is unchanged (:func:`~services.grid_decomposition.change.unchanged_cells`):
    a map drawn again, shifted by a fraction of a cell or nudged by a SLAM pass, moves every wall by a cell or
    two: on the growing ubremen map 25-31 % of the wall cells are no wall in the next step where its origin moved
    (1-7 % elsewhere), and compared cell by cell that unsettled whole rooms and lost their keys."""
    shape, to_resolution_m = occupancy.data.shape, occupancy.resolution_m
    to_origin_xy_m = (occupancy.origin_x_m, occupancy.origin_y_m)
    regions = ids_on_grid(previous.data, resolution_m=previous.resolution_m,
                          origin_xy_m=(previous.origin_x_m, previous.origin_y_m), shape=shape,
                          to_resolution_m=to_resolution_m, to_origin_xy_m=to_origin_xy_m)
    # occupancy read shifted by 2, so that the 0 read off the reference grid tells those cells apart
    before = ids_on_grid(np.asarray(reference.data, dtype=np.int64) + 2, resolution_m=reference.resolution_m,
                         origin_xy_m=(reference.origin_x_m, reference.origin_y_m), shape=shape,
                         to_resolution_m=to_resolution_m, to_origin_xy_m=to_origin_xy_m)
    return RegionPrior(regions, unchanged_cells(before - 2, occupancy.data, resolution_m=to_resolution_m,
                                                covered=before > 0, jitter_m=jitter_m))


def renumber(decomposition: Decomposition, lut: npt.NDArray[np.int64]) -> Decomposition:
    """The decomposition with region ``k`` renamed ``lut[k]``: segments, regions and topology alike."""
    if lut.size <= int(decomposition.segments.max(initial=0)):
        raise DecompositionError(f"the id table has {lut.size} entries for region ids up to "
                                 f"{decomposition.segments.max()}")
    mapping = {k: int(lut[k]) for k in decomposition.regions}
    return dataclasses.replace(
        decomposition,
        segments=lut[decomposition.segments].astype(np.int32),
        regions={mapping[k]: info._replace(region_id=mapping[k]) for k, info in decomposition.regions.items()},
        topology=nx.relabel_nodes(decomposition.topology, mapping),
    )


def carry_keys(decomposition: Decomposition, previous: GridLayer | None, *,
               min_overlap: float = 0.5) -> tuple[Decomposition, StableIds]:
    """``decomposition`` renumbered with stable ids (:func:`stable_ids`) against ``previous``, the segment layer
    of the decomposition before (None for the first); the first id never handed out is read from its meta
    (:data:`NEXT_ID_KEY`), so ids freed by regions that vanished are not reused either."""
    before, next_id = None, 1
    if previous is not None:
        before = ids_on_grid(previous.data, resolution_m=previous.resolution_m,
                             origin_xy_m=(previous.origin_x_m, previous.origin_y_m),
                             shape=decomposition.segments.shape, to_resolution_m=decomposition.resolution_m,
                             to_origin_xy_m=decomposition.origin_xy_m)
        stored = previous.meta.get(NEXT_ID_KEY)
        next_id = max(int(previous.data.max(initial=0)) + 1, stored if isinstance(stored, int) else 1)
    ids = stable_ids(before, decomposition.segments, next_id=next_id, min_overlap=min_overlap)
    return renumber(decomposition, ids.lut), ids

"""Stable region ids: each region of a new decomposition takes the id of the previous region it continues.

A decomposition numbers its regions afresh; a live map must not (a key a WMS or an operator holds, a
block, must keep naming the same place). The previous decomposition's region ids are read on the new
grid (the map may have grown, so both grids are aligned by their origins), the two are matched one to
one by overlap (Hungarian assignment on IoU, :func:`match_regions`), matched regions keep the old id
and every other region gets a fresh id above every id handed out before (never reused).
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import networkx as nx
import numpy as np
import numpy.typing as npt
from scipy.optimize import linear_sum_assignment
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

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


def match_regions(before: IdGrid, after: IdGrid, *, min_overlap: float = 0.5) -> dict[int, int]:
    """One-to-one matching of the regions of ``after`` to those of ``before`` (same grid, 0 = none): new -> old.

    A pair may match when more than ``min_overlap`` of either region lies in the other (a room seen
    partly before and whole now, a corridor cut shorter). Among those, the assignment maximises the
    summed IoU (:func:`scipy.optimize.linear_sum_assignment`, per group of regions linked by candidate
    pairs, so a map of thousands of regions never builds a dense matrix of them all).
    """
    b, a = np.asarray(before, dtype=np.int64), np.asarray(after, dtype=np.int64)
    if b.shape != a.shape:
        raise DecompositionError(f"region grids differ in shape: {b.shape} and {a.shape}")
    both = (b > 0) & (a > 0)
    if not both.any():
        return {}
    pairs, inter = np.unique(np.stack([b[both], a[both]]), axis=1, return_counts=True)
    size_b = np.bincount(b.ravel(), minlength=int(b.max()) + 1)
    size_a = np.bincount(a.ravel(), minlength=int(a.max()) + 1)
    old, new = pairs
    sb, sa = size_b[old], size_a[new]
    ok = (inter > min_overlap * sb) | (inter > min_overlap * sa)
    old, new, inter, sb, sa = old[ok], new[ok], inter[ok], sb[ok], sa[ok]
    if old.size == 0:
        return {}
    iou = inter / (sb + sa - inter)
    olds, old_i = np.unique(old, return_inverse=True)
    news, new_i = np.unique(new, return_inverse=True)
    n_old = olds.size
    graph = coo_matrix((np.ones(old.size), (old_i, n_old + new_i)), shape=(n_old + news.size,) * 2)
    _, group = connected_components(graph, directed=False)
    out: dict[int, int] = {}
    for g in np.unique(group[old_i]):
        pick = group[old_i] == g
        rows, row_i = np.unique(old_i[pick], return_inverse=True)
        cols, col_i = np.unique(new_i[pick], return_inverse=True)
        weight = np.zeros((rows.size, cols.size))
        weight[row_i, col_i] = iou[pick]
        r, c = linear_sum_assignment(weight, maximize=True)
        for i, j in zip(r.tolist(), c.tolist(), strict=True):
            if weight[i, j] > 0:
                out[int(news[cols[j]])] = int(olds[rows[i]])
    return out


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

"""The previous decomposition as a prior: where a growing map did not change, its regions stay as they were.

A decomposition of a map seen in part cuts rooms at its frontier into pieces that the next decomposition, with
more of the map seen, cuts differently; and a change far away (a line found, a texture region moved) can move
a border the map around it gives no new reason to move. On a live map each such flicker retires a region's key
(:mod:`~services.grid_decomposition.keys`). So a region of the previous decomposition whose cells' map content
did not change (:func:`~services.grid_decomposition.change.unchanged_cells`, up to ``max_changed_share`` of
them) keeps its unchanged cells, and a new region that continues it (the one-to-one overlap match of
:func:`match_regions`) is it, grown (:func:`keep_regions`). Regions over changed map are the new decomposition's,
and so is a new region found mostly on ground no settled region keeps: kept cells inside it would leave both
in ragged pieces. Two settled regions the new decomposition holds as one stay apart only across a doorway:
where their border is wider than any door and not narrow for the smaller of them, they were one room cut where
it was seen in part, and the join stands (:func:`joined_regions`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import numpy.typing as npt
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from services.grid_decomposition.errors import DecompositionError
from services.grid_decomposition.segments import fill_from_neighbours, join_small_regions

IdGrid = npt.NDArray[np.integer]


class RegionPrior(NamedTuple):
    """The previous decomposition on the grid being decomposed.

    ``regions`` (H, W) integer: previous region id per cell (0 none); ``unchanged`` (H, W) bool: cells whose map
    content is as it was then (:func:`~services.grid_decomposition.change.unchanged_cells`).
    """

    regions: IdGrid
    unchanged: npt.NDArray[np.bool_]


def match_regions(before: IdGrid, after: IdGrid, *, min_overlap: float = 0.5) -> dict[int, int]:
    """One-to-one matching of the regions of ``after`` to those of ``before`` (same grid, 0 = none): new -> old.

    A pair may match when more than ``min_overlap`` of either region lies in the other (a room seen
    partly before and whole now, a corridor cut shorter). Among those, the assignment maximises the
    summed IoU (:func:`scipy.optimize.linear_sum_assignment`, per group of regions linked by candidate
    pairs, so a map of thousands of regions never builds a dense matrix of them all).
    """
    from scipy.optimize import linear_sum_assignment  # imported when first needed (decompose loads it early)

    b, a = np.asarray(before, dtype=np.int64), np.asarray(after, dtype=np.int64)
    if b.shape != a.shape:
        raise DecompositionError(f"region grids differ in shape: {b.shape} and {a.shape}")
    both = (b > 0) & (a > 0)
    if not both.any():
        return {}
    size_b = np.bincount(b.ravel(), minlength=int(b.max()) + 1)
    size_a = np.bincount(a.ravel(), minlength=int(a.max()) + 1)
    pair, inter = np.unique(b[both] * size_a.size + a[both], return_counts=True)
    old, new = pair // size_a.size, pair % size_a.size
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


def keep_regions(
    segments: IdGrid,
    prior: RegionPrior,
    *,
    max_changed_share: float = 0.2,
    min_overlap: float = 0.5,
    min_area_px: int = 1,
    join_min_border_px: int = 0,
    join_min_width_share: float = 0.6,
    door_rooms: npt.NDArray[np.bool_] | None = None,
    sliver_max_px: int = 0,
    first_seen_max_px: int = 0,
    first_seen_min_border_px: int = 0,
    first_seen_min_px: int = 1,
    apart: npt.NDArray[np.bool_] | None = None,
) -> npt.NDArray[np.int32]:
    """``segments`` with the regions of ``prior`` kept where the map did not change.

    A previous region with at most ``max_changed_share`` of its cells changed is *settled*: its unchanged cells
    that are in a region now are its again, and a new region matched to it (:func:`match_regions`, at
    ``min_overlap``) is it, grown into what was seen since. A new region that continues no previous one and of
    which at most ``min_overlap`` lies on those kept cells is a place found anew (a room seen through its door
    before, entered now) and stands whole; one lying mostly on them is a piece of them and gives way. Everything
    else is as ``segments`` has it. A region left in pieces keeps its largest; smaller pieces than
    ``min_area_px`` join a neighbouring region, and so does a whole region smaller than that (a settled region of
    which a few cells are unchanged and off ``apart``: the neighbour it shares the longest border with, none when it
    touches none, :func:`~services.grid_decomposition.segments.join_small_regions`). Settled regions the new
    decomposition holds as one are one previous region when their border allows it (:func:`joined_regions`, at
    ``join_min_border_px`` and ``join_min_width_share``; a border of 0 cells keeps every previous border). A room
    the new decomposition parted at the door it is seen through (mostly on ``door_rooms``) and that continues a
    settled region takes the kept cells of other settled regions inside it when they are fewer than
    ``sliver_max_px`` per region:
    floor just inside its door that a hall or corridor held while the room was seen in part is no room of its own,
    and the door's line is where the room ends (:func:`_slivers_to_door_rooms`; 0 keeps them all). Two regions
    of the result first seen at this step, touching along more than a door's width, are one room the frontier
    of what was seen cut at a line (:func:`_join_first_seen`, at ``first_seen_max_px``,
    ``first_seen_min_border_px`` and ``first_seen_min_px``; 0 keeps them apart); regions mostly on
    ``apart`` (places found anew at every step, such as racks) never join so, nor take a small region.

    Parameters
    ----------
    segments : (H, W) integer
        Region id per cell of the new decomposition, 0 where no region.
    prior : RegionPrior
        On the same grid.
    door_rooms : (H, W) bool, optional
        Cells of the rooms the new decomposition parted from a hall or corridor at a door's line
        (:func:`~services.grid_decomposition.fans.split_fans`).

    Returns
    -------
    (H, W) int32
        Regions numbered 1..n afresh (their ids are for :mod:`~services.grid_decomposition.keys` to carry).
    """
    seg = np.asarray(segments, dtype=np.int64)
    before = np.asarray(prior.regions, dtype=np.int64)
    if before.shape != seg.shape or prior.unchanged.shape != seg.shape:
        raise DecompositionError(f"prior of shape {before.shape} / {prior.unchanged.shape} on segments of {seg.shape}")
    if not 0.0 <= max_changed_share <= 1.0:
        raise DecompositionError(f"max_changed_share must be in [0, 1], got {max_changed_share}")
    size = np.bincount(before.ravel(), minlength=int(before.max(initial=0)) + 1)
    changed = np.bincount(before[~prior.unchanged], minlength=size.size)
    settled = (size > 0) & (changed <= max_changed_share * size)
    settled[0] = False
    if join_min_border_px > 0:
        before = joined_regions(before, seg, settled, min_border_px=join_min_border_px,
                                min_width_share=join_min_width_share)
    base = int(seg.max(initial=0)) + 1  # settled region k is base + k; new ones keep their own numbers
    lut = np.arange(base, dtype=np.int64)
    matches = match_regions(before, seg, min_overlap=min_overlap)
    for new, old in matches.items():
        if settled[old]:
            lut[new] = base + old
    out = np.take(lut, seg)
    keep = settled[before] & prior.unchanged & (seg > 0)
    if door_rooms is not None and sliver_max_px > 0:
        keep &= ~_slivers_to_door_rooms(seg, before, keep, door_rooms, lut - base, max_px=sliver_max_px)
    # a new region that continues no previous one and lies mostly on ground the settled regions do not hold is
    # a place found anew (a room seen through its door before, now entered): it stands whole
    continues = np.zeros(base, dtype=bool)
    continues[list(matches)] = True
    on_kept = np.bincount(seg[keep], minlength=base)
    anew = ~continues & (on_kept <= min_overlap * np.bincount(seg.ravel(), minlength=base))
    keep &= ~np.take(anew, seg)
    out[keep] = base + before[keep]
    present = np.bincount(out.ravel()) > 0
    present[0] = False
    kept = _largest_pieces(np.where(present, np.cumsum(present), 0).astype(np.int32)[out], min_area_px)
    # a settled region whose unchanged cells are a few (the rest changed, or now on places found anew) is no region
    kept = join_small_regions(kept, min_area_px=min_area_px, apart=apart)
    if first_seen_max_px <= 0:
        return kept
    seen = before > 0 if apart is None else (before > 0) | apart
    return _join_first_seen(kept, seen, max_seen_share=min_overlap, max_px=first_seen_max_px,
                            min_border_px=first_seen_min_border_px, min_px=first_seen_min_px)


def _join_first_seen(
    segments: npt.NDArray[np.int32],
    seen: npt.NDArray[np.bool_],
    *,
    max_seen_share: float,
    max_px: int,
    min_border_px: int,
    min_px: int,
) -> npt.NDArray[np.int32]:
    """``segments`` with pairs of first-seen regions that one room's frontier parted made one region.

    A region is first seen when at most ``max_seen_share`` of it lies on ``seen`` (the previous regions' cells
    and any that must stay apart).
    Two first-seen regions, each of at least ``min_px`` cells and together of at most ``max_px`` (a room, not a
    wing), whose border (4-connected pairs of cells) is at least ``min_border_px`` long are one: a room seen for
    the first time whose unexplored side left a door's line across it; the prior holds it whole from the next
    step on. Groups chained by such pairs take the number of their lowest member; the others keep theirs.
    """
    n = int(segments.max(initial=0)) + 1
    size = np.bincount(segments.ravel(), minlength=n)
    on_seen = np.bincount(segments[seen], minlength=n)
    first_seen = (size >= max(min_px, 1)) & (on_seen <= max_seen_share * size)
    first_seen[0] = False
    a = np.concatenate([segments[:, :-1].ravel(), segments[:-1, :].ravel()]).astype(np.int64)
    b = np.concatenate([segments[:, 1:].ravel(), segments[1:, :].ravel()]).astype(np.int64)
    both = (a != b) & first_seen[a] & first_seen[b]
    if not both.any():
        return segments
    pair, border = np.unique(np.minimum(a[both], b[both]) * n + np.maximum(a[both], b[both]), return_counts=True)
    lo, hi = pair // n, pair % n
    join = (border >= min_border_px) & (size[lo] + size[hi] <= max_px)
    if not join.any():
        return segments
    graph = coo_matrix((np.ones(int(join.sum())), (lo[join], hi[join])), shape=(n, n))
    component = np.asarray(connected_components(graph, directed=False)[1], dtype=np.int64)
    lowest = np.full(int(component.max()) + 1, n, dtype=np.int64)
    np.minimum.at(lowest, component, np.arange(n))
    lut = lowest[component]
    present = np.bincount(lut, minlength=n) > 0  # number the regions 1..m again
    present[0] = False
    return np.where(present, np.cumsum(present), 0).astype(np.int32)[lut][segments]


def _slivers_to_door_rooms(
    seg: npt.NDArray[np.int64],
    before: npt.NDArray[np.int64],
    keep: npt.NDArray[np.bool_],
    door_rooms: npt.NDArray[np.bool_],
    continued: npt.NDArray[np.int64],
    *,
    max_px: int,
) -> npt.NDArray[np.bool_]:
    """The kept cells (``keep``) that a door room of ``seg`` takes from other previous regions that a new region
    continues too: per door room and previous region, fewer than ``max_px`` of them (a border moved, no region taken
    over). A door room is a new region mostly on ``door_rooms`` that continues a settled region (``continued[k]``, the
    previous id of new region ``k``, below 1 for none)."""
    n = continued.size
    size = np.bincount(seg.ravel(), minlength=n)
    door_room = (2 * np.bincount(seg[door_rooms], minlength=n) > size) & (continued > 0)
    goes_on = np.zeros(int(before.max()) + 1, dtype=bool)  # previous regions a new region continues
    goes_on[continued[continued > 0]] = True
    taken: npt.NDArray[np.bool_] = keep & np.take(door_room, seg) & np.take(goes_on, before)
    taken &= before != np.take(continued, seg)
    if not taken.any():
        return taken
    pair = seg[taken] * (int(before.max()) + 1) + before[taken]
    _, inverse, count = np.unique(pair, return_inverse=True, return_counts=True)
    taken[taken] = (count < max_px)[inverse]
    return taken


def joined_regions(
    before: IdGrid,
    after: IdGrid,
    settled: npt.NDArray[np.bool_],
    *,
    min_border_px: int,
    min_width_share: float,
) -> npt.NDArray[np.int64]:
    """``before`` with settled regions that ``after`` holds as one and that no doorway parts made one region.

    Two settled previous regions (``settled`` per id) each lying mostly (over half) in the same region of
    ``after`` are parted only by their border. It is no doorway when it is longer than ``min_border_px`` (the
    widest door) and at least ``min_width_share`` of the smaller region's width (the square root of its area):
    a wall stub or a frontier that cut one room, not a door between two. Such pairs, and the groups they chain
    into, take the id of their largest member (which is settled, as they all are).

    The border's length is the mean of the two regions' cells touching the other (4-connected): a straight
    border of n cells is n long.
    """
    b = np.asarray(before, dtype=np.int64)
    a = np.asarray(after, dtype=np.int64)
    n = int(b.max(initial=0)) + 1
    m = int(a.max(initial=0)) + 1
    size = np.bincount(b.ravel(), minlength=n)
    inside = b > 0
    if n * m <= b.size:  # few enough pairs of ids: count them all
        every = np.bincount(b[inside] * m + a[inside], minlength=n * m)
        pair = np.flatnonzero(every)
        count = every[pair]
    else:
        pair, count = np.unique(b[inside] * m + a[inside], return_counts=True)
    host = np.zeros(n, dtype=np.int64)  # the region of ``after`` holding most (over half) of each previous one
    most = 2 * count > size[pair // m]
    host[pair[most] // m] = pair[most] % m
    candidate = settled[:n] & (host > 0)
    if np.count_nonzero(candidate) < 2:
        return b
    touching = []  # (cell, region it touches) for cells of candidates next to another candidate of the same host
    flat = b.ravel()
    host_of = np.where(candidate, host, 0)  # a candidate's host, 0 for every other id
    w = b.shape[1]
    # the cells where the id changes to the next row's or column's (a pair of cells either way), then their hosts
    down = np.flatnonzero(b[1:] != b[:-1])  # cell ``down`` and the one below it, ``down + w``
    across = np.flatnonzero(b[:, 1:] != b[:, :-1])
    across += across // max(w - 1, 1)  # cell ``across`` and the one right of it, ``across + 1``
    for first, step in ((down, w), (across, 1)):
        second = first + step
        own_host = host_of[flat[first]]
        pair = first[(own_host > 0) & (own_host == host_of[flat[second]])]
        touching += [(pair + step) * n + flat[pair], pair * n + flat[pair + step]]
    cell_other = np.unique(np.concatenate(touching))
    if cell_other.size == 0:
        return b
    own_other = flat[cell_other // n] * n + cell_other % n
    edge, cells_touching = np.unique(own_other, return_counts=True)
    first, second = edge // n, edge % n
    key = np.minimum(first, second) * n + np.maximum(first, second)
    pairs, inverse = np.unique(key, return_inverse=True)
    border = np.bincount(inverse, weights=cells_touching) / 2
    lo, hi = pairs // n, pairs % n
    width = np.sqrt(np.minimum(size[lo], size[hi]))
    join = (border > min_border_px) & (border >= min_width_share * width)
    if not join.any():
        return b
    graph = coo_matrix((np.ones(int(join.sum())), (lo[join], hi[join])), shape=(n, n))
    component = np.asarray(connected_components(graph, directed=False)[1], dtype=np.int64)
    largest = np.zeros(int(component.max()) + 1, dtype=np.int64)
    order = np.argsort(size, kind="stable")  # the largest member written last
    largest[component[order]] = order
    lut = largest[component]
    lut[0] = 0
    out: npt.NDArray[np.int64] = lut[b]
    return out


def _largest_pieces(segments: npt.NDArray[np.int32], min_area_px: int) -> npt.NDArray[np.int32]:
    """Each region's pieces (4-connected) other than its largest: smaller than ``min_area_px``, to a neighbour."""
    from skimage.measure import label as connected_labels  # imported when first needed (it loads scipy.ndimage)

    pieces = np.asarray(connected_labels(segments, background=0, connectivity=1))  # type: ignore[no-untyped-call]
    area = np.bincount(pieces.ravel())
    owner = np.zeros(area.size, dtype=np.int64)
    owner[pieces.ravel()] = segments.ravel()
    order = np.lexsort((-area[1:], owner[1:])) + 1  # by region, largest piece first
    first = np.r_[True, owner[order][1:] != owner[order][:-1]]
    small = np.zeros(area.size, dtype=bool)
    small[order[~first]] = area[order[~first]] < min_area_px
    drop = np.take(small, pieces)
    if not drop.any():
        return segments
    return fill_from_neighbours(np.where(drop, 0, segments), drop, overwrite=True)

"""Free space the regions leave loose on real maps: the dots of sparse rays, pieces of a room seen only in rays.

A lidar looking through the gaps of a wall into a room it never enters leaves a few thin fans of rays there,
each ray a dotted line of free cells with unknown between the dots. The regions are 4-connected pieces of free
space: a dot is a piece too small to be a region and is dropped, and a fan whose rays are a few cells apart
falls into pieces that touch nothing, each its own tiny region. The ground truth draws one room there. The
dots between the rays of a region's own fan, flanked by it on both sides, are its floor too, and so are the dots
beyond a fan's end or beside it that walls and floor close in, inside the room's walls. Dots a region's label took
far from its body, through a door into another room, are that room's. A region mostly of rays whose border with a
larger region the laser saw through, no occupied cell near any of it, is part of that region's fan.
"""

from __future__ import annotations

import cv2
import numpy as np
import numpy.typing as npt
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from services.grid_decomposition.arrays import (
    border_steps,
    label_boxes,
    label_counts,
    lookup,
    near,
    near_at,
    nonzero_rc,
)
from services.grid_decomposition.openings import join_pairs
from services.grid_decomposition.segments import fill_from_neighbours


class _Regions:
    """A segment image and what both loose steps read of it, each found once: the regions' sizes and whether each
    touches another (8-neighbours)."""

    def __init__(self, segments: npt.NDArray[np.int32]) -> None:
        self.segments = segments
        self.n = int(segments.max(initial=0)) + 1
        self._size: npt.NDArray[np.int64] | None = None
        self._touching: npt.NDArray[np.bool_] | None = None

    @property
    def size(self) -> npt.NDArray[np.int64]:
        if self._size is None:
            self._size = label_counts(self.segments, self.n)[0]
        return self._size

    @property
    def touching(self) -> npt.NDArray[np.bool_]:
        if self._touching is None:
            self._touching = _touching(self.segments, self.n)
        return self._touching


def join_isolated_pieces(
    segments: npt.NDArray[np.int32], occupied: npt.NDArray[np.bool_], *, max_area_px: int, gap_px: int
) -> npt.NDArray[np.int32]:
    """``segments`` with small regions that touch no other region joined when at most ``gap_px`` apart.

    A region under ``max_area_px`` that no other region touches (8-neighbours) is a piece of free space with
    unknown space round it: pieces of one fan of rays when they lie within ``gap_px`` of each other through
    unknown or loose free cells (never through an obstacle or another region). Each joins the lowest id of
    its group. Regions that touch another are left alone (the room stage joins those).

    Parameters
    ----------
    segments : (H, W) int32
        Region id per cell, 0 where none.
    occupied : (H, W) bool
    max_area_px, gap_px : int
    """
    return _join_isolated(_Regions(segments), occupied, max_area_px=max_area_px, gap_px=gap_px).segments


def _join_isolated(regions: _Regions, occupied: npt.NDArray[np.bool_], *, max_area_px: int, gap_px: int) -> _Regions:
    """:func:`join_isolated_pieces` of ``regions``: the same object when none join."""
    segments, n = regions.segments, regions.n
    small = regions.size < max_area_px
    small[0] = False
    if np.count_nonzero(small) < 2:
        return regions
    isolated = small & ~regions.touching
    if np.count_nonzero(isolated) < 2:
        return regions
    seeds = lookup(_own_ids(isolated), segments)  # their ids, 0 elsewhere: one lookup by runs
    half = max(1, (gap_px + 1) // 2)
    grown = fill_from_neighbours(  # in the seeds' own image, read no more
        seeds, ~occupied & (segments == 0) & near(seeds > 0, half), max_iterations=half, overwrite=True
    )
    a_parts, b_parts = [], []
    for a, b in ((grown[:, 1:], grown[:, :-1]), (grown[1:, :], grown[:-1, :])):
        meet = (a > 0) & (b > 0) & (a != b)
        a_parts.append(a[meet])
        b_parts.append(b[meet])
    a_ids, b_ids = np.concatenate(a_parts), np.concatenate(b_parts)
    if a_ids.size == 0:
        return regions
    graph = coo_matrix((np.ones(a_ids.size), (a_ids, b_ids)), shape=(n, n))
    _, group = connected_components(graph, directed=False)
    lowest = np.full(n, n, dtype=np.int64)
    np.minimum.at(lowest, group, np.arange(n))
    lut = lowest[group].astype(np.int32)
    return _Regions(lookup(lut, segments))


def _own_ids(flags: npt.NDArray[np.bool_]) -> npt.NDArray[np.int32]:
    """Per region id: the id itself where flagged, else 0 (``lookup`` of it is ``np.where(lookup(flags), ids, 0)``)."""
    return np.where(flags, np.arange(flags.size, dtype=np.int32), np.int32(0))


def fill_lone_regions(
    segments: npt.NDArray[np.int32],
    free: npt.NDArray[np.bool_],
    occupied: npt.NDArray[np.bool_],
    *,
    reach_px: int,
    min_area_px: int,
) -> npt.NDArray[np.int32]:
    """``segments`` with the loose free cells within ``reach_px`` of a region that touches no other given to it.

    A region no other touches (8-neighbours) is a room seen alone, through the gaps of its walls: the dots of
    its rays round it (free cells no region holds, with unknown between them) are its floor. They join it when
    it reaches them within ``reach_px`` through unknown and loose cells, never through an obstacle. Regions
    under ``min_area_px`` (specks) take none, nor does any region that touches another: the rays round a room
    with neighbours also leave it through its windows and doors, where the ground truth draws no room.

    Parameters
    ----------
    segments : (H, W) int32
        Region id per cell, 0 where none.
    free, occupied : (H, W) bool
    reach_px, min_area_px : int
    """
    return _fill_lone(_Regions(segments), free, occupied, reach_px=reach_px, min_area_px=min_area_px)


def _fill_lone(
    regions: _Regions, free: npt.NDArray[np.bool_], occupied: npt.NDArray[np.bool_], *, reach_px: int, min_area_px: int
) -> npt.NDArray[np.int32]:
    """:func:`fill_lone_regions` of ``regions``."""
    segments = regions.segments
    loose = free & (segments == 0)
    if not loose.any():
        return segments
    lone = regions.size >= min_area_px
    lone[0] = False
    lone &= ~regions.touching
    if not lone.any():
        return segments
    seeds = lookup(_own_ids(lone), segments)  # their ids, 0 elsewhere: one lookup by runs
    way = ~occupied & (segments == 0) & near(seeds > 0, reach_px)
    grown = fill_from_neighbours(seeds, way, max_iterations=reach_px, overwrite=True)  # the seeds' own image
    out: npt.NDArray[np.int32] = np.where(loose, grown, segments)
    return out


def join_and_fill_loose(
    segments: npt.NDArray[np.int32],
    free: npt.NDArray[np.bool_],
    occupied: npt.NDArray[np.bool_],
    *,
    max_area_px: int,
    gap_px: int,
    reach_px: int,
    min_area_px: int,
) -> npt.NDArray[np.int32]:
    """:func:`join_isolated_pieces` then :func:`fill_lone_regions`, the regions' sizes and touching flags found
    once when no piece joins (the same segments then)."""
    joined = _join_isolated(_Regions(segments), occupied, max_area_px=max_area_px, gap_px=gap_px)
    return _fill_lone(joined, free, occupied, reach_px=reach_px, min_area_px=min_area_px)


def _touching(segments: npt.NDArray[np.int32], n: int) -> npt.NDArray[np.bool_]:
    """(n,) whether each region has an 8-neighbour cell of another region.

    Each pair of 8-neighbours is compared once (4 of the 8 offsets), with the region mask made once.
    """
    inside = segments > 0
    touches = np.zeros(n, dtype=bool)
    for a, b, a_in, b_in in (
        (segments[:, :-1], segments[:, 1:], inside[:, :-1], inside[:, 1:]),
        (segments[:-1, :], segments[1:, :], inside[:-1, :], inside[1:, :]),
        (segments[:-1, :-1], segments[1:, 1:], inside[:-1, :-1], inside[1:, 1:]),
        (segments[:-1, 1:], segments[1:, :-1], inside[:-1, 1:], inside[1:, :-1]),
    ):
        meet = a != b
        meet &= a_in
        meet &= b_in
        touches[a[meet]] = True
        touches[b[meet]] = True
    return touches


def fill_between(
    segments: npt.NDArray[np.int32],
    free: npt.NDArray[np.bool_],
    occupied: npt.NDArray[np.bool_],
    *,
    reach_px: int,
    floor: npt.NDArray[np.bool_],
) -> npt.NDArray[np.int32]:
    """``segments`` with each loose free cell that one region flanks on two opposite sides given to that region.

    A dot of a ray (a free cell no region holds) with cells of one region's floor within ``reach_px`` straight
    ahead and straight behind it, along a row, a column or a diagonal, and no occupied cell between them, lies
    between two pieces of that floor: between two rays of its fan, in a notch of its outline. The dots of rays
    that leave a region through its windows and doors lie beyond it, flanked by it on one side only, and stay
    loose. A region's cells off ``floor`` (the furniture and unseen pockets a room's segment covers) flank no dot
    and the look passes them: a pocket between two fans that the furniture fill gave the corridor across its
    wall does not take the rays along its edge. The four directions are taken in turn, each seeing the cells the
    ones before gave.

    Parameters
    ----------
    segments : (H, W) int32
        Region id per cell, 0 where none.
    free, occupied : (H, W) bool
    reach_px : int
        Along a diagonal a step counts as sqrt(2) cells.
    floor : (H, W) bool
        The cells where a region's label is floor one walks on: the free cells and the cleaning's streaks.
    """
    loose = free & (segments == 0)
    if not loose.any() or not segments.any():
        return segments
    rows, cols = nonzero_rc(loose & near(segments > 0, reach_px))  # a flanked cell has a region within reach
    out = segments.copy()
    diagonal_px = int(reach_px / np.sqrt(2.0))
    for dr, dc, reach in ((0, 1, reach_px), (1, 0, reach_px), (1, 1, diagonal_px), (1, -1, diagonal_px)):
        loose_now = out[rows, cols] == 0  # the cells given in a direction before are no longer looked at
        rows, cols = rows[loose_now], cols[loose_now]
        ahead = _nearest(out, occupied, floor, rows, cols, dr, dc, reach)
        flanked = np.flatnonzero(ahead > 0)  # only these are looked behind
        behind = _nearest(out, occupied, floor, rows[flanked], cols[flanked], -dr, -dc, reach)
        take = flanked[behind == ahead[flanked]]
        out[rows[take], cols[take]] = ahead[take]
    return out


def _nearest(
    region: npt.NDArray[np.int32],
    stop: npt.NDArray[np.bool_],
    floor: npt.NDArray[np.bool_],
    rows: npt.NDArray[np.int64],
    cols: npt.NDArray[np.int64],
    dr: int,
    dc: int,
    reach: int,
) -> npt.NDArray[np.int32]:
    """Per cell (rows, cols), the region of the first region cell on ``floor`` in steps of (dr, dc) when it comes
    within ``reach`` steps and before any ``stop`` cell or the image's edge; 0 otherwise. Region cells off the
    floor are passed."""
    h, w = region.shape
    # per cell the steps the image's edge leaves it, at most reach; the cells looked up by flat index
    room = np.full(rows.size, reach)
    if dr:
        np.minimum(room, h - 1 - rows if dr > 0 else rows, out=room)
    if dc:
        np.minimum(room, w - 1 - cols if dc > 0 else cols, out=room)
    at, step = rows * w + cols, dr * w + dc
    flat_region, flat_stop, flat_floor = region.ravel(), stop.ravel(), floor.ravel()
    found = np.zeros(rows.size, dtype=np.int32)
    open_ = np.arange(rows.size)  # the cells still looking
    for k in range(1, reach + 1):
        open_ = open_[room[open_] >= k]
        if open_.size == 0:
            break
        cell = at[open_] + k * step
        seen = flat_region[cell] * flat_floor[cell]
        found[open_] = seen
        open_ = open_[(seen == 0) & ~flat_stop[cell]]
    return found


def fill_enclosed(
    segments: npt.NDArray[np.int32],
    free: npt.NDArray[np.bool_],
    occupied: npt.NDArray[np.bool_],
    doorways: npt.NDArray[np.bool_],
    *,
    reach_px: int,
    enclosed_px: int,
    min_area_px: int,
    floor: npt.NDArray[np.bool_],
) -> npt.NDArray[np.int32]:
    """``segments`` with the loose free cells that walls and floor close in given to the nearest region in view.

    A dot of a ray (a free cell no region holds) looks along its row and its column, four ways, each up to the
    first obstacle, doorway line or region cell. When at least three of the four ways meet one within
    ``enclosed_px``, the dot lies inside a room's walls (a dot beyond a building's outer wall sees nothing
    outwards), and it takes the region whose floor it meets nearest within ``reach_px``: the floor of its room
    seen beyond the fan's end, never across a wall or a doorway line. A region's cells off ``floor`` (furniture
    and unseen pockets its segment covers) close the room as walls do, and give the dot their region only when
    no region's floor is in reach: a pocket behind a corridor's wall that the furniture fill gave the corridor
    does not take the rays of the room it lies in. Regions under ``min_area_px`` (specks) take none. The
    dots it meets no region near in line with are :func:`fill_near`'s.

    Parameters
    ----------
    segments : (H, W) int32
        Region id per cell, 0 where none.
    free, occupied, doorways : (H, W) bool
        ``doorways``: the closed doorway lines and cuts between regions; they close a room as its walls do.
    reach_px, enclosed_px, min_area_px : int
    floor : (H, W) bool
        The cells where a region's label is floor one walks on: the free cells and the cleaning's streaks.
    """
    loose = free & (segments == 0)
    if not loose.any() or not segments.any():
        return segments
    takes = _takers(segments, min_area_px)
    rows, cols = nonzero_rc(loose)
    met, steps, enclosed = _enclosed(segments, occupied | doorways, rows, cols, enclosed_px)
    rows, cols, met, steps = rows[enclosed], cols[enclosed], met[:, enclosed], steps[:, enclosed]  # only these take
    may_take = (met > 0) & (steps <= reach_px)
    may_take[may_take] = takes[met[may_take]]
    # the nearest region met on its floor that may take, else the nearest met off it, else none
    beyond = enclosed_px + reach_px + 1
    cost = np.where(may_take, steps + beyond * ~_met_on(floor, rows, cols, steps, may_take), 2 * beyond)
    way = np.argmin(cost, axis=0)
    region = np.take_along_axis(np.where(may_take, met, 0), way[None], axis=0)[0]
    take = region > 0
    out = segments.copy()
    out[rows[take], cols[take]] = region[take]
    return out


def fill_near(
    segments: npt.NDArray[np.int32],
    free: npt.NDArray[np.bool_],
    occupied: npt.NDArray[np.bool_],
    doorways: npt.NDArray[np.bool_],
    *,
    reach_px: int,
    enclosed_px: int,
    min_area_px: int,
) -> npt.NDArray[np.int32]:
    """``segments`` with the loose free cells inside a room's walls given to the region that grows to them first.

    The dots :func:`fill_enclosed` leaves: a free cell no region holds, closed in on three of the four ways along
    its row and column within ``enclosed_px`` (by an obstacle, a doorway line or a region, the cells that step
    gave counted), that sees no region in line within reach — beside a fan's end or its outline, off its rows and
    columns. It is the floor of the room whose walls close it in, seen in dots: it takes the region that grows to
    it first within ``reach_px`` steps (8-neighbours) through cells no region holds, never through an obstacle or
    a doorway line. Regions under ``min_area_px`` (specks) take none.

    Parameters
    ----------
    segments : (H, W) int32
        Region id per cell, 0 where none.
    free, occupied, doorways : (H, W) bool
        ``free``: the floor seen, streaks the cleaning took out included.
    reach_px, enclosed_px, min_area_px : int
    """
    loose = free & (segments == 0)
    if not loose.any() or not segments.any():
        return segments
    closed = occupied | doorways
    rows, cols = nonzero_rc(loose)
    enclosed = _enclosed(segments, closed, rows, cols, enclosed_px)[2]
    if not enclosed.any():
        return segments
    dots = np.zeros(segments.shape, dtype=bool)
    dots[rows[enclosed], cols[enclosed]] = True
    takes = _takers(segments, min_area_px)
    # a growth of reach_px steps to a dot passes only cells within reach_px of it (chessboard)
    size = 2 * reach_px + 1
    way = cv2.dilate(dots.view(np.uint8), np.ones((size, size), np.uint8)).view(bool)
    way &= ~closed
    way &= segments == 0
    grown = fill_from_neighbours(lookup(_own_ids(takes), segments), way, max_iterations=reach_px, overwrite=True)
    out: npt.NDArray[np.int32] = np.where(dots & (grown > 0), grown, segments)
    return out


def _takers(segments: npt.NDArray[np.int32], min_area_px: int) -> npt.NDArray[np.bool_]:
    """Per region id: whether it may take dots (at least ``min_area_px`` cells: no speck, never id 0)."""
    takes: npt.NDArray[np.bool_] = label_counts(segments, int(segments.max()) + 1)[0] >= min_area_px
    takes[0] = False
    return takes


def _enclosed(
    segments: npt.NDArray[np.int32],
    closed: npt.NDArray[np.bool_],
    rows: npt.NDArray[np.int64],
    cols: npt.NDArray[np.int64],
    enclosed_px: int,
) -> tuple[npt.NDArray[np.int32], npt.NDArray[np.int64], npt.NDArray[np.bool_]]:
    """For each cell (rows, cols): what it meets first right, left, down and up (4, N: -1 a ``closed`` cell, a
    region's id, 0 nothing before the image's edge), the steps to it, and whether at least three of the four ways
    meet something within ``enclosed_px`` (the cell lies inside a room's walls)."""
    met, steps = _first_met(np.where(closed, np.int32(-1), segments), rows, cols)
    within = met != 0
    within[within] = steps[within] <= enclosed_px
    return met, steps, np.count_nonzero(within, axis=0) >= 3


def _met_on(
    mask: npt.NDArray[np.bool_], rows: npt.NDArray[np.int64], cols: npt.NDArray[np.int64],
    steps: npt.NDArray[np.int64], looked: npt.NDArray[np.bool_],
) -> npt.NDArray[np.bool_]:
    """(4, N) ``mask`` at the cell :func:`_first_met` met each way (right, left, down, up of (rows, cols),
    ``steps`` away) where ``looked`` (4, N), False elsewhere."""
    out = np.zeros(steps.shape, dtype=bool)
    for k, (dr, dc) in enumerate(((0, 1), (0, -1), (1, 0), (-1, 0))):
        i = np.flatnonzero(looked[k])
        out[k, i] = mask[rows[i] + dr * steps[k, i], cols[i] + dc * steps[k, i]]
    return out


def _first_met(
    seen: npt.NDArray[np.int32], rows: npt.NDArray[np.int64], cols: npt.NDArray[np.int64]
) -> tuple[npt.NDArray[np.int32], npt.NDArray[np.int64]]:
    """(4, N) the first nonzero ``seen`` value right, left, down and up of each cell (rows, cols) on its row or
    column (0 if none before the image's edge), and the steps to it: the nonzero cells in row and in column order,
    each cell's neighbours among them by one binary search."""
    h, w = seen.shape
    met = np.zeros((4, rows.size), dtype=np.int32)
    steps = np.zeros((4, rows.size), dtype=np.int64)
    for k, (image, line, at, length) in enumerate(((seen, rows, cols, w), (cv2.transpose(seen), cols, rows, h))):
        flat = image.ravel()
        hits = np.flatnonzero(flat)
        query = line * length + at
        after = np.searchsorted(hits, query)  # the first nonzero cell after the query (the query cell is 0)
        for side, index in ((0, after), (1, after - 1)):
            ok = (index >= 0) & (index < hits.size)
            cell = hits[np.clip(index, 0, hits.size - 1)]  # (a region's cells are nonzero: never empty)
            ok &= cell // length == line
            met[2 * k + side] = np.where(ok, flat[cell], 0)
            steps[2 * k + side] = np.where(ok, np.abs(cell - query), 0)
    return met, steps


def give_far_pieces(
    segments: npt.NDArray[np.int32],
    occupied: npt.NDArray[np.bool_],
    places: npt.NDArray[np.bool_],
    *,
    far_px: int,
    reach_px: int,
) -> npt.NDArray[np.int32]:
    """``segments`` with the pieces of a region lying far from its body given to the region that reaches them.

    A region is floor one can walk: a piece of it that touches its largest piece nowhere (8-neighbours) and lies
    everywhere more than ``far_px`` from it is dots of rays the region's first labels took with it, seen through
    a door into another room (a corridor's label on the dots of the rooms along it). Such a piece takes, cell by
    cell, the region that grows to it first through cells the map does not call occupied, within ``reach_px``
    steps; a cell none reaches keeps its region. Rack places (racks, aisles) are in pieces by design: their
    cells neither move nor pass the growth.

    Parameters
    ----------
    segments : (H, W) int32
        Region id per cell, 0 where none.
    occupied, places : (H, W) bool
    far_px, reach_px : int
    """
    far = np.zeros(segments.shape, dtype=bool)
    for k, box in enumerate(label_boxes(segments), start=1):
        if box is None:
            continue
        own = (segments[box] == k).astype(np.uint8)
        n, pieces, stats, _ = cv2.connectedComponentsWithStats(own, connectivity=8)
        if n <= 2:
            continue
        body = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
        away = cv2.distanceTransform((pieces != body).astype(np.uint8), cv2.DIST_L2, 5) > far_px
        # a piece is far when every cell of it is: its cells near the body counted per piece
        near_count = np.bincount(pieces[~away].ravel(), minlength=n)
        far_piece = near_count == 0
        far_piece[0] = False
        far[box] |= far_piece[pieces]
    far &= ~places
    if not far.any():
        return segments
    kept = np.where(far, np.int32(0), segments)
    # a growth of reach_px steps reaching a far cell passes only cells within reach_px of it (chessboard)
    size = 2 * reach_px + 1
    within = cv2.dilate(far.view(np.uint8), np.ones((size, size), np.uint8)).view(bool)
    grown = fill_from_neighbours(kept, within & ~(occupied | places) & (kept == 0), max_iterations=reach_px)
    out = segments.copy()
    take = far & (grown > 0)
    out[take] = grown[take]
    return out


def join_ray_pieces(
    segments: npt.NDArray[np.int32],
    occupied: npt.NDArray[np.bool_],
    rays: npt.NDArray[np.bool_],
    joinable: npt.NDArray[np.bool_],
    *,
    seen_px: float,
    min_border_px: int,
    min_ray_share: float = 0.5,
) -> npt.NDArray[np.int32]:
    """``segments`` with each region of rays joined to a larger region it borders where the laser saw no wall.

    A region at least ``min_ray_share`` of whose cells are ``rays`` (thin free space the cleaning kept) is space the
    laser looked into, not floor it drove on. Where its border with a larger region (4-neighbour pixel pairs, at
    least ``min_border_px`` of them) has no ``occupied`` cell within ``seen_px`` of any of its cells, the laser saw
    through that border along its whole length: no wall and no jamb of a door lies between them (a doorway's jambs
    are walls the laser hit beside the border, or within it), so the rays are the larger region's own, parted by the
    lines and cuts drawn through the unknown between them. Such a region joins the larger region with which it
    shares the longest such border. Only ``joinable`` regions (per id: off the warehouse floors and rack places)
    join or take others. Ids 1..M (consecutive) when any join; else ``segments`` as given.

    Parameters
    ----------
    segments : (H, W) int32
        Region id per cell, 0 where none.
    occupied, rays : (H, W) bool
    joinable : (N + 1,) bool
    seen_px : float
        The chamfer radius within which an occupied cell walls a border cell.
    min_border_px : int
    min_ray_share : float
    """
    n = int(segments.max(initial=0)) + 1
    if n < 3:
        return segments
    size, on_rays = label_counts(segments, n, rays)
    of_rays = (on_rays >= min_ray_share * np.maximum(size, 1)) & joinable[:n] & (size > 0)
    of_rays[0] = False
    if not of_rays.any():
        return segments
    keys, rows, cols = [], [], []
    for dy, dx, r, c, key in border_steps(segments, n):
        a, b = key // n, key % n
        mine = (of_rays[a] | of_rays[b]) & joinable[a] & joinable[b]  # (few: the rays' borders)
        keys += [key[mine], key[mine]]
        rows += [r[mine], r[mine] + dy]
        cols += [c[mine], c[mine] + dx]
    key = np.concatenate(keys)
    if key.size == 0:
        return segments
    walled = near_at(occupied, np.concatenate(rows), np.concatenate(cols), seen_px, 5)
    pair, which = np.unique(key, return_inverse=True)
    length = np.bincount(which, minlength=pair.size) // 2  # each pixel pair counted from both its cells
    open_border = (np.bincount(which, walled, minlength=pair.size) == 0) & (length >= min_border_px)
    a, b = pair // n, pair % n
    small, large = np.where(size[a] < size[b], a, b), np.where(size[a] < size[b], b, a)
    take = open_border & of_rays[small] & (size[small] < size[large])
    if not take.any():
        return segments
    small, large, length = small[take], large[take], length[take]
    order = np.lexsort((-length, small))  # per region of rays, its longest open border first
    first = np.ones(order.size, dtype=bool)
    first[1:] = small[order][1:] != small[order][:-1]
    return join_pairs(segments, small[order][first], large[order][first])

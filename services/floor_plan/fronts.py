"""Rooms cut along their open fronts: the line between two side walls that both end free on it.

A row of offices opens onto a corridor over its whole width: the walls between the offices end at the corridor,
with nothing across the front but, at most, a short cap at each wall's end. The units and the room level
(:mod:`services.floor_plan.rooms`) see no wall there, and where one unit stands over an office and the corridor in
front of it no boundary rule can keep them apart. The ipa ground truth (and the grid decomposition, which cuts its
faces along the wall lines' extensions) closes each office along the line joining its side walls' ends. Here that
line is found in the map alone (:func:`open_fronts`): two walls along one axis, at least ``front_side_m`` long, whose
ends lie on one line ``front_min_m`` to ``front_max_m`` apart, each end free (no wall running on along the front
beyond a cap, free space beyond it), the line between them open, and free space in front of the line over its
whole width for ``front_ahead_m`` (a corridor or hall, not a doorway into a narrow passage). A room that such a
line splits into pieces of ``slant_min_piece_m2`` or more is re-cut into them (:func:`split_at_fronts`).
"""

from __future__ import annotations

import cv2
import numpy as np
import numpy.typing as npt
from scipy import ndimage

from services.floor_plan.rooms import Room, RoomSettings
from services.floor_plan.slanted import recut
from services.floor_plan.world import World


def open_fronts(free: npt.NDArray[np.bool_], *, resolution_m: float, settings: RoomSettings) -> npt.NDArray[np.bool_]:
    """The open fronts of the map (see the module docstring), drawn one cell wide across the gap and the two walls'
    ends.

    Parameters
    ----------
    free : (H, W) bool
        The free cells of C_M (laser beams' traces free) in the world's frame.

    Returns
    -------
    (H, W) bool
        Cells on a front line; none when ``settings.front_max_m`` is None.
    """
    out = np.zeros(free.shape, np.bool_)
    if settings.front_max_m is None:
        return out
    walls = (~free).astype(np.uint8)
    run = _odd(settings.barrier_m, resolution_m)
    along_cols = cv2.morphologyEx(walls, cv2.MORPH_OPEN, np.ones((run, 1), np.uint8)) > 0
    along_rows = cv2.morphologyEx(walls, cv2.MORPH_OPEN, np.ones((1, run), np.uint8)) > 0
    for transpose in (False, True):
        for flip in (False, True):
            view = out.T if transpose else out
            g, along, across = (free.T, along_rows.T, along_cols.T) if transpose else (free, along_cols, along_rows)
            if flip:
                view, g, along, across = view[::-1], g[::-1], along[::-1], across[::-1]
            for row, c0, c1 in _fronts(g, along, across, resolution_m=resolution_m, settings=settings):
                view[row, c0 : c1 + 1] = True
    return out


def _fronts(free: npt.NDArray[np.bool_], along: npt.NDArray[np.bool_], across: npt.NDArray[np.bool_], *,
            resolution_m: float, settings: RoomSettings) -> list[tuple[int, int, int]]:
    """Fronts below the lower ends of walls running along the columns: (row, first column, last column), from the
    outer face of one wall to the outer face of the other. ``along``: barrier cells on runs along the columns,
    ``across``: along the rows."""
    def cells(metres: float) -> int:
        return max(1, round(metres / resolution_m))

    side, cap, ahead, corner = (cells(m) for m in (settings.front_side_m, settings.front_cap_m,
                                                    settings.front_ahead_m, settings.front_corner_m))
    least, most = cells(settings.front_min_m), cells(settings.front_max_m or 0.0)
    offset, thick = cells(settings.front_offset_m), cells(settings.max_wall_m)
    h, w = free.shape
    long = cv2.morphologyEx(along.astype(np.uint8), cv2.MORPH_OPEN,
                            np.ones((2 * (side // 2) + 1, 1), np.uint8)) > 0
    ends = long & ~np.r_[long[1:], np.zeros((1, w), np.bool_)]
    _, _, stats, _ = cv2.connectedComponentsWithStats(ends.astype(np.uint8), connectivity=8)
    found: list[tuple[int, int, int]] = []  # (row of the end, first column, last column)
    for x, y, width, height, _ in stats[1:].tolist():
        row, c0, c1 = y + height - 1, x, x + width - 1
        if width > thick or row + 1 + cap + ahead > h:
            continue
        beyond = free[row + 1 : row + 2 + cap, (c0 + c1) // 2]
        if not beyond.any():
            continue
        first = row + 1 + int(np.argmax(beyond))
        if not free[first : first + ahead, max(c0 - 1, 0) : c1 + 2].all():
            continue  # a door jamb, a wall drawn in steps: the wall goes on
        band = across[max(row - cap, 0) : row + cap + 1]
        left, right = max(c0 - corner - 1, 0), min(c1 + corner + 1, w - 1)
        if band[:, left : c0 + 1].any(axis=0).all() or band[:, c1 : right + 1].any(axis=0).all():
            continue  # a corner: the wall turns along the front
        found.append((row, c0, c1))
    found.sort(key=lambda e: e[1])
    out: list[tuple[int, int, int]] = []
    for i, (ra, a0, a1) in enumerate(found):
        for rb, b0, b1 in found[i + 1 :]:
            gap = b0 - a1 - 1
            if gap > most:
                break
            if gap < least or abs(ra - rb) > offset:
                continue
            row = max(ra, rb)
            open_ = free[row, a1 + 1 : b0].mean() >= settings.min_open_share
            clear = free[row + 1 + cap : row + 1 + cap + ahead, a0 : b1 + 1].all()
            if open_ and clear and _closed(free, across, row, (a0, a1), (b0, b1), side=side, settings=settings):
                out.append((row, a0, b1))
            break  # the nearest end along the line only
    return out


def _closed(free: npt.NDArray[np.bool_], across: npt.NDArray[np.bool_], row: int, a: tuple[int, int],
            b: tuple[int, int], *, side: int, settings: RoomSettings) -> bool:
    """Whether the space behind a front at ``row`` between walls ``a`` and ``b`` (their first and last columns) is an
    office: closed at its back by a wall across (``across``, over ``min_open_share`` of the width) at least ``side``
    and at most ``corridor_length_ratio`` widths behind the front (deeper: a stretch of corridor between two doors
    facing each other), and the side walls run on to it (each over ``min_open_share`` of the depth)."""
    share = settings.min_open_share
    width = b[0] - a[1] - 1
    reach = min(row, round((settings.corridor_length_ratio or 1.0) * width))
    behind = across[row - reach : row, a[1] + 1 : b[0]][::-1]
    hit = behind.any(axis=0)
    if reach < side or hit.mean() < share:
        return False
    depth = int(np.median(behind.argmax(axis=0)[hit]))
    if depth < side:
        return False
    rows = slice(row - depth, row + 1)
    sides = [(~free[rows, max(c0 - 1, 0) : c1 + 2]).any(axis=1).mean() for c0, c1 in (a, b)]
    return bool(min(sides) >= share)


def _odd(metres: float, resolution_m: float) -> int:
    """``metres`` in cells, odd (OpenCV's opening by an even kernel comes back shifted by a cell)."""
    return 2 * (round(metres / resolution_m) // 2) + 1


def split_at_fronts(rooms: list[Room], cells: npt.NDArray[np.int32], world: World, free: npt.NDArray[np.bool_],
                    fronts: npt.NDArray[np.bool_], *, resolution_m: float,
                    settings: RoomSettings) -> tuple[list[Room], npt.NDArray[np.int32]]:
    """Rooms that a front splits into pieces of ``slant_min_piece_m2`` or more, re-cut into their pieces.

    A room's parts reach each other through its own cells and the free cells no room holds (a unit's wall band over
    free space, a sliver between units); a front splits a room where the room's cells that were reached through
    those from each other no longer are with the front taken out. The pieces on the far side of every front from the
    largest piece are rooms of their own; the rest stays one room.

    Parameters
    ----------
    rooms : list of Room
        The rooms so far (:func:`~services.floor_plan.slanted.split_at_slanted_walls`).
    cells : (H, W) int32
        Each room's index + 1 on its free cells (cells of the world's frame).
    free : (H, W) bool
        The free cells of C_M (traces free).
    fronts : (H, W) bool
        :func:`open_fronts`.

    Returns
    -------
    list of Room, (H, W) int32
        As :func:`~services.floor_plan.slanted.split_at_slanted_walls` returns them.
    """
    if not fronts.any():
        return rooms, cells
    least = max(1, round(settings.slant_min_piece_m2 / resolution_m**2))
    on = np.unique(cells[fronts])
    region = np.zeros(cells.shape, np.int32)
    split = []
    boxes = ndimage.find_objects(cells)
    spare = free & (cells == 0)
    for k in on[on > 0].tolist():
        box = boxes[k - 1]
        box = tuple(slice(max(s.start - 1, 0), s.stop + 1) for s in box)
        own = cells[box] == k
        reach = own | spare[box]
        whole, _ = ndimage.label(reach)
        pieces, n = ndimage.label(reach & ~fronts[box])
        # the room's cells per piece, and which whole each piece lies in
        size = np.bincount(pieces[own], minlength=n + 1)
        size[0] = 0
        big = np.flatnonzero(size >= least)
        if big.size < 2:
            continue
        within = np.zeros(n + 1, np.int64)
        within[pieces[own]] = whole[own]
        main = int(big[np.argmax(size[big])])
        apart = [int(b) for b in big if b != main and np.count_nonzero(within[big] == within[b]) >= 2]
        if not apart:
            continue
        label = np.zeros(n + 1, np.int32)
        label[1:] = 1  # the largest piece and everything no front parts from it
        for i, b in enumerate(apart, start=2):
            label[b] = i
        top = int(region.max())
        region[box] = np.where(own, np.where(pieces > 0, label[pieces], 1) + top, region[box])
        split.append(k)
    if not split:
        return rooms, cells
    return recut(rooms, world, cells, split, region, resolution_m=resolution_m)

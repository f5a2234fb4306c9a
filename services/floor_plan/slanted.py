"""Rooms cut along walls that run slanted through the working frame.

The room level (:mod:`services.floor_plan.rooms`) cuts units along rows and columns, so a wall that runs at an
angle to the frame (office_e's pentagon, explained along one of its five sides) cuts nothing, and the units on
both sides of it each hold a piece of both rooms. Here a room's free space is cut along the straight wall lines of
the map that run slanted (:func:`~services.floor_plan.detectors.wall_line_segments`, the lines the slanted walls of
:mod:`services.floor_plan.walls` are cut along too; drawn by :func:`line_mask`). Where such a line splits a room
into pieces of ``slant_min_piece_m2`` or more, the room is no longer made of its rectangles: its free space is
re-cut into the regions that the map's wall lines of every direction enclose, one room each
(:func:`split_at_slanted_walls`). A room that shares such a region with a re-cut room (the rectangles of two units
cut the space between slanted walls where no wall stands) is re-cut too, so that the region is one room; a room
neither splits nor joins keeps its parts as they are.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import numpy.typing as npt
from scipy import ndimage

from services.floor_plan.likelihood import CellClass
from services.floor_plan.rooms import Room, RoomSettings
from services.floor_plan.world import Rect, World

_LINE_CELLS = 3
"""Width of a drawn wall line: 4-connected free space never leaks across it."""


def room_cells(rooms: list[Room], shape: tuple[int, int]) -> npt.NDArray[np.int32]:
    """Each room's index + 1 painted over its parts (cells of the frame; where parts overlap the smaller wins)."""
    items = sorted(((r, k) for k, room in enumerate(rooms, start=1) for r in room.parts),
                   key=lambda item: -item[0].rows * item[0].cols)
    out = np.zeros(shape, np.int32)
    for r, k in items:
        out[r.r0 : r.r1 + 1, r.c0 : r.c1 + 1] = k
    return out


def slanted(lines: npt.NDArray[np.float64], min_angle_rad: float) -> npt.NDArray[np.float64]:
    """The lines (``x0, y0, x1, y1``) at least ``min_angle_rad`` from both axes of the frame."""
    angle = np.arctan2(lines[:, 3] - lines[:, 1], lines[:, 2] - lines[:, 0])
    out: npt.NDArray[np.float64] = lines[np.abs((angle + np.pi / 4) % (np.pi / 2) - np.pi / 4) >= min_angle_rad]
    return out


def line_mask(lines: npt.NDArray[np.float64], shape: tuple[int, int], *, reach_cells: float) -> npt.NDArray[np.bool_]:
    """``lines`` (``x0, y0, x1, y1``) drawn ``_LINE_CELLS`` wide and prolonged by ``reach_cells`` at both ends (a
    dashed wall whose last dash stops short of the wall it meets)."""
    out = np.zeros(shape, np.uint8)
    for x0, y0, x1, y1 in lines.tolist():
        d = reach_cells / max(math.hypot(x1 - x0, y1 - y0), 1.0)
        ex, ey = (x1 - x0) * d, (y1 - y0) * d
        cv2.line(out, (round(x0 - ex), round(y0 - ey)), (round(x1 + ex), round(y1 + ey)), 1, _LINE_CELLS)
    return out.astype(np.bool_)


def _split(painted: npt.NDArray[np.int32], free: npt.NDArray[np.bool_], lines: npt.NDArray[np.bool_],
           least: int) -> list[int]:
    """The rooms (indices + 1 in ``painted``, over all their parts' cells) that ``lines`` cut into two or more
    pieces holding at least ``least`` free cells each."""
    inside = painted > 0
    whole, _ = ndimage.label(inside)
    pieces, _ = ndimage.label(inside & ~lines)
    at = (pieces > 0) & free
    # every (room, whole component, piece) once (as one integer), with the piece's free cells in that room
    n_whole, n_pieces = int(whole.max()) + 1, int(pieces.max()) + 1
    room, part, piece = (a[at].astype(np.int64) for a in (painted, whole, pieces))
    keys, size = np.unique((room * n_whole + part) * n_pieces + piece, return_counts=True)
    rooms_of, count = np.unique(keys[size >= least] // n_pieces, return_counts=True)  # (room, whole) of the big ones
    return sorted(set((rooms_of[count >= 2] // n_whole).tolist()))


def split_at_slanted_walls(
    rooms: list[Room], world: World, classes: npt.NDArray[np.uint8], lines: npt.NDArray[np.float64], *,
    resolution_m: float, reach_m: float, settings: RoomSettings,
) -> tuple[list[Room], npt.NDArray[np.int32]]:
    """Rooms that a slanted wall line splits, re-cut along the map's wall lines (see the module docstring).

    Parameters
    ----------
    rooms : list of Room
        From :func:`~services.floor_plan.rooms.group_rooms`.
    world : World
        The units, cells of ``classes``' frame.
    classes : (H, W) uint8
        C_M in the working frame.
    lines : (N, 4) float
        The map's wall lines in every direction (:func:`~services.floor_plan.detectors.wall_line_segments`,
        ``x0, y0, x1, y1``, cells of ``classes``), drawn prolonged by ``reach_m`` at both ends.

    Returns
    -------
    list of Room, (H, W) int32
        The rooms, sorted (a re-cut room keeps its type; its units and parts are those of the room it came from
        that its free space overlaps), and each room's index + 1 on its free cells (0 elsewhere, and on the wall
        lines through a re-cut room).
    """
    free = classes == CellClass.FREE
    painted = room_cells(rooms, classes.shape)
    cells = np.where(free, painted, 0).astype(np.int32)
    if settings.slant_min_angle_rad is None:
        return rooms, cells
    reach = reach_m / resolution_m
    across = slanted(lines, settings.slant_min_angle_rad)
    least = max(1, round(settings.slant_min_piece_m2 / resolution_m**2))
    split = _split(painted, free, line_mask(across, classes.shape, reach_cells=reach), least) if len(across) else []
    if not split:
        return rooms, cells
    region, _ = ndimage.label(free & ~line_mask(lines, classes.shape, reach_cells=reach))
    size = np.bincount(region.ravel())
    size[0] = 0
    if settings.slant_join_max_m2 is not None:
        small = size <= settings.slant_join_max_m2 / resolution_m**2
        split = _sharing(cells, region, small, split, least,
                         walls=(line_mask(across, classes.shape, reach_cells=reach),
                                line_mask(lines, classes.shape, reach_cells=reach)),
                         min_share=settings.slant_join_share)
    region = np.where(np.isin(cells, split) & (size[region] >= least), region, 0)
    return recut(rooms, world, cells, split, region, resolution_m=resolution_m)


def recut(rooms: list[Room], world: World, cells: npt.NDArray[np.int32], split: list[int],
          region: npt.NDArray[np.int32], *, resolution_m: float) -> tuple[list[Room], npt.NDArray[np.int32]]:
    """The rooms ``split`` (indices + 1 in ``cells``) replaced by the regions of ``region`` (labels > 0 over their
    cells), one room each: a re-cut room keeps its type, its units and parts are those of the room it came from that
    its free space overlaps. Returns the rooms, sorted, and each room's index + 1 on its cells (0 on the cells of a
    split room that no region holds)."""
    kept = [(room, k) for k, room in enumerate(rooms, start=1) if k not in split]
    recut_rooms: list[tuple[Room, tuple[slice, slice], npt.NDArray[np.bool_]]] = []
    for r, box in enumerate(ndimage.find_objects(region), start=1):
        if box is None:
            continue
        at = region[box] == r
        source = rooms[int(np.bincount(cells[box][at]).argmax()) - 1]
        parts = tuple(p for p in source.parts if _covers(p, box, at))
        units = tuple(u for u in source.units if _covers(world.units[u], box, at))
        recut_rooms.append((Room(units or source.units, parts or source.parts, source.room_type,
                                 float(at.sum()) * resolution_m**2), box, at))
    every = [room for room, _ in kept] + [room for room, _, _ in recut_rooms]
    order = sorted(range(len(every)), key=lambda i: every[i])
    rank = np.empty(len(every), np.int32)
    rank[order] = np.arange(1, len(every) + 1, dtype=np.int32)
    lut = np.zeros(len(rooms) + 1, np.int32)
    for i, (_, k) in enumerate(kept):
        lut[k] = rank[i]
    labels = lut[cells]
    for i, (_, box, at) in enumerate(recut_rooms, start=len(kept)):
        labels[box][at] = rank[i]
    ordered = [every[i] for i in order]
    return ordered, labels


def _sharing(cells: npt.NDArray[np.int32], region: npt.NDArray[np.int32], small: npt.NDArray[np.bool_],
             split: list[int], least: int, *, walls: tuple[npt.NDArray[np.bool_], npt.NDArray[np.bool_]],
             min_share: float) -> list[int]:
    """``split`` and every room joined to it through a region (index of ``region``) that ``small`` allows and that
    slanted lines (``walls[0]``) outline over at least ``min_share`` of the wall lines (``walls[1]``) round it: two
    rooms (indices + 1 in ``cells``) are joined where each holds at least ``least`` cells of such a region."""
    at = (cells > 0) & (region > 0)
    at &= small[region]
    n = int(cells.max()) + 1
    keys, count = np.unique(region[at].astype(np.int64) * n + cells[at], return_counts=True)
    keys = keys[count >= least]
    regions, rooms = keys // n, keys % n
    boxes = ndimage.find_objects(region)
    held = np.unique(regions[np.diff(regions, prepend=-1) == 0])  # regions two or more rooms hold
    outlined = [r for r in held.tolist() if _slanted_share(region, r, boxes[r - 1], walls) >= min_share]
    keep = np.isin(regions, outlined)
    regions, rooms = regions[keep], rooms[keep]
    out = set(split)
    while True:
        more = set(rooms[np.isin(regions, regions[np.isin(rooms, list(out))])].tolist()) - out
        if not more:
            return sorted(out)
        out |= more


def _slanted_share(region: npt.NDArray[np.int32], r: int, box: tuple[slice, slice],
                   walls: tuple[npt.NDArray[np.bool_], npt.NDArray[np.bool_]]) -> float:
    """The share of the wall lines (``walls[1]``) beside region ``r`` (within ``_LINE_CELLS`` - 1 cells, the lines
    it stops at) that are slanted (``walls[0]``)."""
    reach = _LINE_CELLS - 1
    rows = slice(max(box[0].start - reach, 0), box[0].stop + reach)
    cols = slice(max(box[1].start - reach, 0), box[1].stop + reach)
    near = ndimage.binary_dilation(region[rows, cols] == r, iterations=reach)
    every = np.count_nonzero(near & walls[1][rows, cols])
    return np.count_nonzero(near & walls[0][rows, cols]) / every if every else 0.0


def _covers(rect: Rect, box: tuple[slice, slice], at: npt.NDArray[np.bool_]) -> bool:
    """Whether ``rect`` holds a cell of ``at`` (a mask over the window ``box``)."""
    r0, c0 = box[0].start, box[1].start
    rows = slice(max(rect.r0 - r0, 0), max(rect.r1 + 1 - r0, 0))
    cols = slice(max(rect.c0 - c0, 0), max(rect.c1 + 1 - c0, 0))
    return bool(at[rows, cols].any())

"""The room level of a floor plan: units joined through open boundaries are one room.

A room (seed 003's sense, and the ipa ground truth's) is a connected set of space units linked by open boundaries:
no wall and no door between them. A unit is a rectangle, so an L-shaped room, a corridor with bends or a hall with
alcoves is several units. And a unit may stand over a wall: two rooms with a door between them that the world
explains as one rectangle. So the room level works on **parts**: each unit's free space cut along the lines across
it that are mostly wall (:func:`unit_parts`). Two parts border each other where their free spaces face each other
across at most ``max_gap_m`` (a shared wall, a cut, a sliver the world leaves unexplained), or two parts of one unit
across the band of wall lines that cut them apart (at most ``max_wall_m``: the cut runs across the whole unit, also
where its free space runs on through the band, a corridor past the cross wall of the offices beside it), over at
least ``min_contact_m``; the boundary is **open** where no barrier of the map lies across it, position by position
(:func:`boundaries`). A door is a short opening in a wall, so parts whose boundary is open over ``min_open_share``
of the shorter side, and from whose open part free space runs on into both (``min_depth_share``), are one room,
unless the boundary is the end of a corridor at a room or hall much wider and deeper than the corridor
(:func:`corridor_end`): the ground truth's rooms and a reader of a floor plan cut a corridor there, however open it
is. Rooms are the connected components of the open boundaries (:func:`group_rooms`); a room smaller than
``min_room_m2`` (a sliver between units) joins the neighbour it shares the longest open length with. Walls running
slanted through the frame cut no rectangle: the pipeline then re-cuts the rooms they split
(:mod:`services.floor_plan.slanted`). Barriers are cells that are not free lying on a straight run along the wall's
direction at least ``barrier_m`` long (:func:`barriers`): walls drawn occupied or unknown, not the unknown speckle,
laser streaks and clutter dots of a real map's free space.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import NamedTuple

import cv2
import numpy as np
import numpy.typing as npt
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from services.floor_plan.likelihood import CellClass
from services.floor_plan.world import Rect, UnitType, World
from shared.furniture import FurnitureRule, furniture_pieces


@dataclass(frozen=True)
class RoomSettings:
    """When two units are one room; lengths in metres, shares in [0, 1]."""

    min_open_share: float = 0.7
    """A boundary open over at least this share of the shorter side is no door: the two parts are one room."""
    min_depth_share: float = 0.5
    """... and free space runs on from its open part into both units over at least this share of their depth."""
    barrier_m: float = 0.3
    """Cells that are not free stop the way between two units (and cut a unit) where they run on in a line
    at least this long, along rows or columns: a wall, drawn occupied or (as some maps draw them) unknown; not
    the unknown speckle and clutter dots of a real map's free space."""
    max_gap_m: float = 0.3
    """Units whose free spaces are at most this far apart border each other (a shared wall is 0.1 m); two parts of one
    unit border each other across the band of wall lines that cut them apart (at most ``max_wall_m``)."""
    min_contact_m: float = 0.5
    """Units border each other only where their free spaces face each other over at least this length."""
    margin_m: float = 0.1
    """A boundary is looked at this far into both units too (a map wall a cell off the unit's wall)."""
    cut_share: float = 0.2
    """A line of cells across a unit of which at least this share is not free is a wall the unit stands over:
    the room level cuts the unit there."""
    min_part_m: float = 0.5
    """No part thinner than this is cut off a unit."""
    max_wall_m: float = 1.0
    """A band of lines across a unit thicker than this is no wall (furniture, unexplored space): no cut, unless its
    core (``cut_core_share``) is thin enough."""
    cut_core_share: float | None = 0.75
    """A band thicker than ``max_wall_m`` is cut at its core where that is no thicker: the lines whose share of
    barrier cells is at least this share of the band's highest (a wall with cupboards against it: the wall's lines
    are nearly all barrier, the cupboards' much less); None: a thick band is never cut."""
    cut_core_step: float = 0.6
    """... where the band's lines next to the core are at most this share of its highest: the share steps up into the
    core (from the cupboards to the wall); a slanted wall across the unit ramps up line by line and is not cut."""
    corridor_length_ratio: float | None = 3.0
    """A part at least this many times as long (away from a boundary) as it is wide (along it) is a corridor
    there; None: no corridor ends (:func:`corridor_end`)."""
    corridor_width_share: float = 0.5
    """A corridor ends at a part at least 1 / this share as wide along their boundary ..."""
    corridor_room_depth: float = 2.5
    """... and at least this many corridor widths deep: a room or hall the corridor opens into, not a corridor
    it turns into (those are about as deep as it is wide). The two are not one room, however open."""
    min_room_m2: float | None = 0.5
    """A room of parts smaller than this (a sliver between units, a doorway's corner) joins the neighbouring room it
    shares the longest open length with; None: no such joins."""
    slant_min_angle_rad: float | None = math.radians(15.0)
    """The map's wall lines (``FloorPlanSettings.slant_line_m``, :mod:`services.floor_plan.slanted`) at least this far
    from both axes of the frame split rooms (axis-parallel walls cut the units already); None: rooms are made of
    rectangles only."""
    slant_min_piece_m2: float = 1.0
    """A room is re-cut where a slanted line or an open front splits it into pieces at least this large."""
    slant_join_max_m2: float | None = 50.0
    """A room holding a piece (``slant_min_piece_m2`` or more) of a region the wall lines enclose that a re-cut room
    holds a piece of too is re-cut as well, where the region is at most this large: the rectangles of two units cut
    a room between slanted walls in two where no wall stands, and the re-cut makes it one region. A larger region
    is a hall, or space that leaks past the lines (a real scan's beams): no join through it. None: only the rooms a
    slanted line splits are re-cut."""
    slant_join_share: float = 0.25
    """... and where slanted lines are at least this share of the wall lines round the region: a room between
    slanted walls, not a corridor or room of walls along the frame with a chamfered corner."""
    front_max_m: float | None = 4.0
    """An open front (:mod:`services.floor_plan.fronts`: the line joining two side walls' free ends, an office's whole
    front onto a corridor) is at most this wide between the walls; None: rooms are not cut at open fronts."""
    front_min_m: float = 1.5
    """... and at least this wide (narrower: a passage, the aisle between two rows of cubicles)."""
    front_side_m: float = 2.0
    """Both side walls run back from the front at least this far."""
    front_offset_m: float = 0.15
    """The two walls' ends lie on one line within this much."""
    front_cap_m: float = 0.2
    """A wall's end may be capped by a short wall across it this thick (a T at the end of an office wall)..."""
    front_corner_m: float = 0.75
    """... reaching at most this far beyond the wall's side: a wall running on along the front is a corner (an
    alcove, a hall's side wall turning into its neighbours' fronts), not a free end."""
    front_ahead_m: float = 1.2
    """Free space runs on ahead of the front, over its whole width, at least this far: a corridor or a hall in front,
    not a door jamb (a door is narrower) nor a passage between furniture."""
    doorway_max_m: float | None = 1.2
    """A part at most this wide that open boundaries join to parts on two opposite sides, each of them wider than it
    by more than ``min_open_share`` (a unit filling a doorway between two rooms), joins neither through them; None:
    no such rule."""
    free_piece_min_m2: float | None = 0.25
    """A piece of free space at least this large that no room reaches through free space (a laser beam's streak cut
    off from its room by a cell or two of grey, the space past a gap in a wall) takes, in ``rooms.png``, the one room
    within ``free_piece_reach_m`` of it; smaller pieces (speckle) and None: such space stays unlabelled."""
    free_piece_reach_m: float = 0.15
    """... at most this far from the piece (a piece with no room or two rooms that near stays unlabelled)."""


class Boundary(NamedTuple):
    """Two units whose free spaces face each other: ``length_m`` along the boundary, ``open_share`` of it open."""


    units: tuple[int, int]
    length_m: float
    open_share: float
    """The open length as a share of the shorter of the two units' sides along the boundary: a door is a short
    opening in a long wall, and units that face each other over a part of both their sides only (a unit
    reaching across a wall into a corridor) have little."""
    depth_share: float
    """How far free space runs into the units from the open part of the boundary before a wall, as a share of
    each unit's depth (the smaller of the two): a unit that reaches across a wall into its neighbour's space
    (its own room lies behind that wall) has little."""
    corridor_end: bool = False
    """One part is a corridor that ends here at a much wider and deeper part (:func:`corridor_end`)."""


class Part(NamedTuple):
    """A rectangle of a unit's free space (``rect``: interior cells) between the walls that run across it."""

    unit: int
    rect: Rect


class Room(NamedTuple):
    """A room of the floor plan: its parts (and so its units, sorted), type and area (of its parts' free space)."""

    units: tuple[int, ...]
    parts: tuple[Rect, ...]
    room_type: UnitType
    area_m2: float


class Barriers(NamedTuple):
    """The cells that are not free and lie on a straight run of such cells, along rows and along columns."""

    along_rows: npt.NDArray[np.bool_]
    along_cols: npt.NDArray[np.bool_]


def barriers(cells: npt.NDArray[np.bool_], *, run_cells: int) -> Barriers:
    """The ``cells`` that lie on a straight run of them at least ``run_cells`` long.

    Parameters
    ----------
    cells : (H, W) bool
        E.g. the cells of C_M that are not free.
    """
    blocked = np.asarray(cells, np.uint8)
    k = max(1, run_cells)
    along_rows = cv2.morphologyEx(blocked, cv2.MORPH_OPEN, np.ones((1, k), np.uint8)) > 0
    along_cols = cv2.morphologyEx(blocked, cv2.MORPH_OPEN, np.ones((k, 1), np.uint8)) > 0
    return Barriers(along_rows, along_cols)


def unit_parts(
    world: World, barrier: Barriers, *, wall_cells: int, resolution_m: float, settings: RoomSettings,
) -> list[Part]:
    """Each unit's free space cut along the lines of cells across it that are mostly barrier running along the
    line (a wall the unit stands over: two rooms with a door between them that the world explains as one
    unit). A band of such lines thicker than ``max_wall_m`` is no wall but furniture or unexplored space, and
    pieces thinner than ``min_part_m`` are not cut off. Rows first, then columns within each piece.

    Parameters
    ----------
    barrier : Barriers
        :func:`barriers` of C_M in the world's frame.
    """
    least = max(1, round(settings.min_part_m / resolution_m))
    most = max(1, round(settings.max_wall_m / resolution_m))
    out: list[Part] = []
    for uid, rect in sorted(world.units.items()):
        inner = rect.inner(wall_cells)
        if inner.r0 > inner.r1 or inner.c0 > inner.c1:
            continue
        core = None if settings.cut_core_share is None else (settings.cut_core_share, settings.cut_core_step)
        for piece in _cut(barrier, inner, least, most, settings.cut_share, core, rows=True):
            out.extend(Part(uid, p) for p in _cut(barrier, piece, least, most, settings.cut_share, core, rows=False))
    return out


def _cut(barrier: Barriers, rect: Rect, least: int, most: int, share: float, core: tuple[float, float] | None, *,
         rows: bool) -> list[Rect]:
    """``rect`` cut at its bands of at most ``most`` rows (or columns) whose share of barrier cells running along
    them reaches ``share``, leaving no piece under ``least``; a band is cut only where some of those cells lie off
    the wall lines across the band at the rectangle's edges (within ``least``, the unit's own wall drawn a little
    inside it). A wall as thick as ``barrier_m`` runs across itself too: a corridor unit that covers the thick wall at
    its side has every column through it blocked by that wall alone about as much as by a cross wall with a door in
    it, and would be cut at each door jamb into door-wide pieces, each open over its whole width to the room behind
    the door (and so one room with it). A band thicker than ``most`` is cut at its core instead (the lines of at least
    ``core[0]`` times its highest share, where those are at most ``most`` thick and the lines next to them at most
    ``core[1]`` times it): a wall with cupboards standing
    against it is one band, thicker than a wall, but its own lines are far more barrier than the cupboards'."""
    blocked = barrier.along_rows if rows else barrier.along_cols
    crop = blocked[rect.r0 : rect.r1 + 1, rect.c0 : rect.c1 + 1]
    walls = (barrier.along_rows | barrier.along_cols)[rect.r0 : rect.r1 + 1, rect.c0 : rect.c1 + 1]
    edge = walls.mean(axis=0 if rows else 1) >= share  # the wall lines across the bands
    start, stop = _edge_run(edge[:least]), edge.size - _edge_run(edge[::-1][:least])
    shares = crop.mean(axis=1 if rows else 0)
    line = shares >= share
    if core is not None:
        line = _cores(line, shares, *core, most=most)
    inside: npt.NDArray[np.bool_] = line.copy()  # a rectangle all edge (a thin unit along a wall): the share alone
    if start < stop:
        inside = np.asarray((crop[:, start:stop] if rows else crop[start:stop]).any(axis=1 if rows else 0))
    n = line.size
    line[:least] = line[n - least :] = False  # a wall a little inside the unit's own is no cut
    edges = np.flatnonzero(np.diff(np.r_[False, line, False].astype(np.int8)))
    lo, out = 0, list[tuple[int, int]]()
    for s, e in zip(edges[::2], edges[1::2], strict=True):
        if s - lo >= least and e - s <= most and inside[s:e].any():
            out.append((lo, int(s) - 1))
            lo = int(e)
    out.append((lo, n - 1))
    first = rect.r0 if rows else rect.c0
    return [rect._replace(r0=first + a, r1=first + b) if rows else rect._replace(c0=first + a, c1=first + b)
            for a, b in out]


def _cores(line: npt.NDArray[np.bool_], shares: npt.NDArray[np.float64], core: float, step: float, *,
           most: int) -> npt.NDArray[np.bool_]:
    """``line`` with each run longer than ``most`` narrowed to the span of its lines of at least ``core`` times the
    run's highest share, where that span is at most ``most`` lines and the run's lines next to it at most ``step``
    times that highest share."""
    out = line.copy()
    edges = np.flatnonzero(np.diff(np.r_[False, line, False].astype(np.int8)))
    for s, e in zip(edges[::2], edges[1::2], strict=True):
        if e - s <= most:
            continue
        run = shares[s:e]
        hit = np.flatnonzero(run >= core * run.max())
        beside = run[[i for i in (hit[0] - 1, hit[-1] + 1) if 0 <= i < run.size]]
        if hit[-1] - hit[0] < most and (beside <= step * run.max()).all():
            out[s:e] = False
            out[s + hit[0] : s + hit[-1] + 1] = True
    return out


def _edge_run(line: npt.NDArray[np.bool_]) -> int:
    """How many of ``line``'s first entries are True before the first False."""
    return int(line.size if line.all() else np.argmin(line))


def boundaries(parts: list[Part], barrier: Barriers, *, resolution_m: float,
               settings: RoomSettings) -> list[Boundary]:
    """Every pair of parts whose free spaces face each other, with how open the map is between them.

    Parameters
    ----------
    parts : list of Part
        From :func:`unit_parts`.
    barrier : Barriers
        :func:`barriers` of C_M in the world's frame.

    Returns
    -------
    list of Boundary
        ``units`` are indices into ``parts``; parts whose free spaces overlap count as fully open (whether one
        is a corridor ending at the other is judged as if the one sticking into the other stopped at it).
    """
    if len(parts) < 2:
        return []
    inner = np.array([p.rect for p in parts], np.int64).reshape(-1, 4)  # r0, r1, c0, c1
    # parts of one unit face each other across the band of wall lines that cut them apart (at most max_wall_m)
    unit = np.array([p.unit for p in parts])
    gap_cells = round(settings.max_gap_m / resolution_m)
    gap = np.where(unit[:, None] == unit[None, :], max(gap_cells, round(settings.max_wall_m / resolution_m)),
                   gap_cells)
    contact = max(1, round(settings.min_contact_m / resolution_m))
    margin = round(settings.margin_m / resolution_m)
    r0, r1, c0, c1 = (inner[:, k] for k in range(4))
    # cells strictly between two intervals (negative: they overlap by that many cells, less one)
    row_gap = np.maximum(r0[:, None], r0[None, :]) - np.minimum(r1[:, None], r1[None, :]) - 1
    col_gap = np.maximum(c0[:, None], c0[None, :]) - np.minimum(c1[:, None], c1[None, :]) - 1
    stacked = (row_gap >= 0) & (row_gap <= gap) & (-col_gap - 1 >= contact)
    beside = (col_gap >= 0) & (col_gap <= gap) & (-row_gap - 1 >= contact)
    overlap = (row_gap < 0) & (col_gap < 0)
    pairs = np.argwhere(np.triu(stacked | beside | overlap, k=1))
    out = []
    for i, j in pairs:
        a, b = Rect(*inner[i]), Rect(*inner[j])
        if overlap[i, j]:
            length = min(a.r1, b.r1) - max(a.r0, b.r0) + 1
            abutting = _abut(a, b)
            out.append(Boundary((int(i), int(j)), length * resolution_m, 1.0, 1.0,
                                abutting is not None and corridor_end(*abutting, settings)))
            continue
        vertical = bool(stacked[i, j])  # the cross lines run along rows
        # walls between stacked parts run along rows; beside in the map is stacked in the transpose
        w = barrier.along_rows if vertical else barrier.along_cols.T
        if not vertical:
            a, b = Rect(a.c0, a.c1, a.r0, a.r1), Rect(b.c0, b.c1, b.r0, b.r1)
        top, bottom = (a, b) if a.r1 < b.r0 else (b, a)
        cols = slice(max(a.c0, b.c0), min(a.c1, b.c1) + 1)
        rows = slice(max(top.r1 + 1 - margin, top.r0), min(bottom.r0 - 1 + margin, bottom.r1) + 1)
        open_ = ~w[rows, cols].any(axis=0)
        depth = 0.0
        if open_.any():
            up = _free_run(w[top.r0 : top.r1 + 1, cols][::-1, open_])
            down = _free_run(w[bottom.r0 : bottom.r1 + 1, cols][:, open_])
            depth = min(float(up.mean()) / top.rows, float(down.mean()) / bottom.rows)
        side = min(a.c1 - a.c0, b.c1 - b.c0) + 1
        out.append(Boundary((int(i), int(j)), open_.size * resolution_m, float(open_.sum()) / side, depth,
                            corridor_end(a, b, settings)))
    return out


def corridor_end(a: Rect, b: Rect, settings: RoomSettings) -> bool:
    """Whether one of two stacked parts (``a`` above ``b`` or below it: their boundary runs along the columns)
    is a corridor that ends there at a room or hall: at least ``corridor_length_ratio`` times as long (rows) as
    wide (columns), at most ``corridor_width_share`` as wide as the other, which is at least
    ``corridor_room_depth`` corridor widths deep. A corridor turning a corner meets a part about as deep as it is
    wide; an alcove or the leg of an L-shaped room is not that long."""
    if settings.corridor_length_ratio is None:
        return False
    narrow, wide = (a, b) if a.cols <= b.cols else (b, a)
    return (narrow.rows >= settings.corridor_length_ratio * narrow.cols
            and narrow.cols <= settings.corridor_width_share * wide.cols
            and wide.rows >= settings.corridor_room_depth * narrow.cols)


def _abut(a: Rect, b: Rect) -> tuple[Rect, Rect] | None:
    """Two overlapping rectangles made to abut, stacked (transposed when they end up side by side): the one that
    sticks into the other stops at it on that side, whichever gives up the least share of its cells; None when
    neither can (one holds the other's whole extent on every side it crosses)."""
    best: tuple[float, Rect, Rect, bool] | None = None
    for x, y in ((a, b), (b, a)):
        for cut, stacked in ((x._replace(r1=y.r0 - 1), True), (x._replace(r0=y.r1 + 1), True),
                             (x._replace(c1=y.c0 - 1), False), (x._replace(c0=y.c1 + 1), False)):
            if cut.r0 > cut.r1 or cut.c0 > cut.c1 or not x.contains(cut) or cut == x:
                continue
            lost = 1.0 - cut.rows * cut.cols / (x.rows * x.cols)
            if best is None or lost < best[0]:
                best = (lost, cut, y, stacked)
    if best is None:
        return None
    _, p, q, stacked = best
    if stacked:
        return p, q
    return Rect(p.c0, p.c1, p.r0, p.r1), Rect(q.c0, q.c1, q.r0, q.r1)


def _free_run(walls: npt.NDArray[np.bool_]) -> npt.NDArray[np.int64]:
    """Per column, how many cells from row 0 down come before the first wall (all of them when none)."""
    hit = walls.any(axis=0)
    runs: npt.NDArray[np.int64] = np.where(hit, walls.argmax(axis=0), walls.shape[0]).astype(np.int64)
    return runs


def group_rooms(
    world: World, classes: npt.NDArray[np.uint8], types: Mapping[int, UnitType], *, wall_cells: int,
    resolution_m: float, settings: RoomSettings,
) -> list[Room]:
    """The rooms of a world: the units' parts joined through open boundaries (see the module docstring).

    Parameters
    ----------
    world : World
        Units in cells of ``classes``' frame.
    classes : (H, W) uint8
        C_M (:class:`CellClass`) in the world's frame.
    types : mapping of unit id to UnitType
        Each unit's type; a room takes the type covering most of its area.
    wall_cells : int
        Thickness of a unit's walls, cells.

    Returns
    -------
    list of Room
        Sorted by their units; every part of every unit is in exactly one room.
    """
    blocked = barriers(classes != CellClass.FREE, run_cells=round(settings.barrier_m / resolution_m))
    parts = unit_parts(world, blocked, wall_cells=wall_cells, resolution_m=resolution_m, settings=settings)
    if not parts:
        return []
    joined = []
    found = boundaries(parts, blocked, resolution_m=resolution_m, settings=settings)
    for b in found:
        if (b.open_share >= settings.min_open_share and b.depth_share >= settings.min_depth_share
                and not b.corridor_end):
            joined.append(b.units)
    if settings.doorway_max_m is not None:
        door = _doorways(parts, joined, most=round(settings.doorway_max_m / resolution_m),
                         share=settings.min_open_share)
        joined = [u for u in joined if u[0] not in door and u[1] not in door]
    edges = np.array(joined, np.int64).reshape(-1, 2)
    n = len(parts)
    _, component = connected_components(coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n)),
                                        directed=False)
    if settings.min_room_m2 is not None:
        component = _absorb_small(component, parts, found, least_m2=settings.min_room_m2, resolution_m=resolution_m)
    rooms = []
    for k in np.unique(component):
        members = [parts[i] for i in np.flatnonzero(component == k)]
        area = [m.rect.rows * m.rect.cols * resolution_m**2 for m in members]
        by_type: dict[UnitType, float] = {}
        for m, a in zip(members, area, strict=True):
            by_type[types[m.unit]] = by_type.get(types[m.unit], 0.0) + a
        room_type = max(by_type, key=lambda t: by_type[t])
        rooms.append(Room(tuple(sorted({m.unit for m in members})), tuple(m.rect for m in members), room_type,
                          sum(area)))
    return sorted(rooms)


def _doorways(parts: list[Part], joined: list[tuple[int, int]], *, most: int, share: float) -> set[int]:
    """The parts (indices) at most ``most`` cells wide along their boundaries that ``joined`` links to parts on both
    opposite sides (above and below, or left and right), each of those wider than the part by more than ``share``
    (the part is a short opening in their walls): units standing in a doorway."""
    sides: dict[int, list[tuple[int, int]]] = {}
    for i, j in joined:
        sides.setdefault(i, []).append((i, j))
        sides.setdefault(j, []).append((j, i))
    out = set()
    for p, pairs in sides.items():
        a = parts[p].rect
        for along_rows in (True, False):  # neighbours above / below (boundary along the rows), left / right
            width = a.cols if along_rows else a.rows
            if width > most:
                continue
            before = after = False
            for _, q in pairs:
                b = parts[q].rect
                lo, hi = (b.r1 < a.r0, b.r0 > a.r1) if along_rows else (b.c1 < a.c0, b.c0 > a.c1)
                if not (lo or hi):
                    continue
                if width >= share * (b.cols if along_rows else b.rows):
                    break
                before, after = before or lo, after or hi
            else:
                if before and after:
                    out.add(p)
    return out


def _absorb_small(component: npt.NDArray[np.int32], parts: list[Part], found: list[Boundary], *, least_m2: float,
                  resolution_m: float) -> npt.NDArray[np.int32]:
    """Rooms (``component`` per part) smaller than ``least_m2`` joined to the neighbouring room, at least as large,
    that they share the longest open length with (their boundaries, open or not)."""
    size = np.bincount(component, weights=[p.rect.rows * p.rect.cols * resolution_m**2 for p in parts])
    best: dict[int, tuple[float, int]] = {}
    for b in found:
        i, j = (int(component[u]) for u in b.units)
        for small, other in ((i, j), (j, i)):
            open_m = b.length_m * b.open_share
            if small != other and size[small] < least_m2 <= size[other] and open_m > best.get(small, (-1.0, 0))[0]:
                best[small] = (open_m, other)
    if not best:
        return component
    links = np.array([[a, b] for a, (_, b) in best.items()], np.int64)
    n = size.size
    _, merged = connected_components(coo_matrix((np.ones(len(links)), (links[:, 0], links[:, 1])), shape=(n, n)),
                                     directed=False)
    out: npt.NDArray[np.int32] = merged[component].astype(np.int32)
    return out


def room_keys(rooms: list[Room]) -> list[str]:
    """A key per room: ``r<first unit id>``, and ``r<id>.<n>`` for the n-th further room starting at the same unit
    (a unit cut into parts of several rooms). It stays while the room's first unit keeps its id."""
    seen: dict[int, int] = {}
    keys = []
    for room in rooms:
        n = seen.get(room.units[0], 0)
        seen[room.units[0]] = n + 1
        keys.append(f"r{room.units[0]}" + (f".{n}" if n else ""))
    return keys


def wall_fringe(occupancy: npt.NDArray[np.integer], free: npt.NDArray[np.bool_], *, depth_cells: int,
                min_wall_cells: int = 1, inside_max_cells: int = 0,
                inside_min_depth_cells: int = 2) -> npt.NDArray[np.bool_]:
    """The wall fringe: free cells that are not clearly free, within ``depth_cells`` of a wall and joined to it
    through such cells (8-connected), but not the inside of a piece of furniture (:func:`furniture_insides` with
    ``inside_max_cells`` and ``inside_min_depth_cells``; 0: none is).

    Not clearly free is more than 1 percent above the map's clearest free cell: an image's grey edge along its walls
    (antialiasing), a live map's cells seen free fewer times than its clamp. A wall is a connected piece of cells
    that are not free of at least ``min_wall_cells``: a room's walls, not a desk, bin or chair leg standing in it
    (a furnished map's furniture drawn grey keeps its labels). The ipa ground truth leaves that edge out of every
    room, and the grid decomposition never labels it (its cleaning turns it to wall, the same rule). A cupboard
    drawn as a dark outline filled light grey against a wall is one piece with the wall, and its light inside reads
    free but not clearly free: it is the room's floor under the cupboard (the ground truth counts it), no edge.

    Parameters
    ----------
    occupancy : (H, W) integer
        -1 unknown, 0..100 percent (a bare image's free cells keep their darkness, :func:`read_map`).
    free : (H, W) bool
        The free cells of C_M.
    """
    occ = np.asarray(occupancy)
    if not free.any():
        return np.zeros(free.shape, np.bool_)
    unclear = free & (occ > int(occ[free].min()) + 1)
    _, pieces, stats, _ = cv2.connectedComponentsWithStats((~free).astype(np.uint8), connectivity=8)
    big = stats[:, cv2.CC_STAT_AREA] >= min_wall_cells
    big[0] = False
    wall = big[pieces].astype(np.uint8)
    size = 2 * max(1, depth_cells) + 1
    near = cv2.dilate(wall, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (size, size))) > 0
    candidate = unclear & near
    if not candidate.any():
        return np.zeros(free.shape, np.bool_)
    n, parts = cv2.connectedComponents(candidate.astype(np.uint8), connectivity=8)
    touching = np.zeros(n, np.bool_)
    touching[np.unique(parts[candidate & (cv2.dilate(wall, np.ones((3, 3), np.uint8)) > 0)])] = True
    touching[0] = False
    out: npt.NDArray[np.bool_] = touching[parts]
    if inside_max_cells > 0:
        out &= ~furniture_insides(free, max_cells=inside_max_cells, min_depth_cells=inside_min_depth_cells)
    return out


def furniture_insides(free: npt.NDArray[np.bool_], *, max_cells: int, min_depth_cells: int) -> npt.NDArray[np.bool_]:
    """The free space enclosed in a piece of furniture: 8-connected pieces of ``free`` of at most ``max_cells``, off
    the map's border, holding a cell at least ``min_depth_cells`` from every cell that is not free (the light inside
    of a cupboard drawn as an outline; not the one-cell light line along a wall drawn grey, nor a speck)."""
    mask = np.asarray(free, np.uint8)
    n, parts, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    keep = stats[:, cv2.CC_STAT_AREA] <= max_cells
    keep[0] = False
    keep[np.unique(np.r_[parts[0], parts[-1], parts[:, 0], parts[:, -1]])] = False
    if not keep.any():
        return np.zeros(mask.shape, np.bool_)
    depth = cv2.distanceTransform(mask, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    deep = np.zeros(n, np.bool_)
    deep[np.unique(parts[depth >= min_depth_cells])] = True
    out: npt.NDArray[np.bool_] = (keep & deep)[parts]
    return out


@dataclass(frozen=True)
class FurnitureSettings(FurnitureRule):
    """What non-free pieces of a map are furniture standing on a room's floor: the grid decomposition's rule
    (:class:`shared.furniture.FurnitureRule`, with its numbers), and no piece of a dotted wall; lengths in metres."""

    dots_gap_m: float = 0.35
    """A piece on a dotted wall is no furniture: pieces that, with gaps up to this long closed along rows or columns,
    make a line at least ``dots_line_m`` long."""
    dots_line_m: float = 1.0
    pocket_max_m2: float = 4.0
    """Furniture fused to a wall: a pocket of unseen space inside the building (an 8-connected piece of unknown cells
    that unknown cells and beam traces do not link to the map's border) at most this large, shaped like a piece of
    furniture (:func:`furniture_pockets`); 0: none. A cupboard drawn in the map's unknown grey against a wall drawn
    black is such a pocket; the clutter obstacles' cap."""
    pocket_min_fill: float = 0.8
    """... rectangular: it fills at least this share of its minimum-area rectangle (not a triangle of unseen space
    where walls meet at an angle, nor the L or T of a wall's grey core at a junction) ..."""
    pocket_min_thickness_m: float = 0.25
    """... at least this thick (the rectangle's shorter side; a thinner grey line is the core of a wall drawn grey
    between two black faces) ..."""
    pocket_max_elongation: float = 5.0
    """... and at most this many times as long as thick (a longer thin pocket is a wall's grey core)."""
    pocket_reach_m: float = 0.15
    """A pocket no room touches (a cupboard drawn with a dark outline) takes the one room label within this of it."""
    pocket_cut_thickness_m: float | None = 0.65
    """Furniture joined to a wall's grey core, or to other unseen space by a wall's antialiased edge (a line of grey
    cells along a black wall), is no pocket of its own: the unknown cells are also opened by a square
    ``pocket_min_thickness_m`` wide (links thinner than a pocket fall away) and the opening's pieces are pockets by the
    same guards when they are at least this thick (thinner pieces cut out of a larger one are a wall's stub, 0.3-0.4 m,
    or a pillar against a wall, up to 0.6 m across on ipa's NLB); None: no opening."""


def furniture(cells: npt.NDArray[np.bool_], *, resolution_m: float,
              settings: FurnitureSettings) -> npt.NDArray[np.bool_]:
    """The 8-connected pieces of ``cells`` (non-free cells) that are furniture (:class:`FurnitureSettings`), off the
    map's border."""
    mask = np.asarray(cells, np.uint8)
    _, found, found_stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    parts, stats = np.asarray(found, np.int32), np.asarray(found_stats, np.int32)
    keep = furniture_pieces(mask, parts, stats, resolution_m=resolution_m, rule=settings)
    gap, run = max(1, round(settings.dots_gap_m / resolution_m)), max(1, round(settings.dots_line_m / resolution_m))
    for close, line in ((np.ones((1, gap), np.uint8), np.ones((1, run), np.uint8)),
                        (np.ones((gap, 1), np.uint8), np.ones((run, 1), np.uint8))):
        dotted = cv2.morphologyEx(cv2.morphologyEx(mask, cv2.MORPH_CLOSE, close), cv2.MORPH_OPEN, line) > 0
        keep[np.unique(parts[dotted & (mask > 0)])] = False
    keep[0] = False
    out: npt.NDArray[np.bool_] = keep[parts]
    return out


def furniture_pockets(unknown: npt.NDArray[np.bool_], traces: npt.NDArray[np.bool_], *, resolution_m: float,
                      settings: FurnitureSettings) -> npt.NDArray[np.bool_]:
    """Furniture the map draws in its unknown grey, fused to a wall (:class:`FurnitureSettings` ``pocket_*``): the
    8-connected pieces of ``unknown`` (C_M's unknown cells, ``traces`` among them) off the map's border, at most
    ``pocket_max_m2``, rectangular, thick and short enough to be furniture rather than a triangle of unseen space or a
    wall's grey core; and the pieces, at least ``pocket_cut_thickness_m`` thick, that an opening of ``unknown`` by a
    square ``pocket_min_thickness_m`` wide cuts from a wall's grey core or from the line of grey cells along a wall;
    their cells that are not ``traces``.

    In ipa's furnished maps nearly all furniture is drawn in the map's unknown grey; against a wall drawn black it
    is a piece of its own, which the non-free pieces of :func:`furniture` (the wall and the cupboard are one piece)
    cannot tell from the wall."""
    if settings.pocket_max_m2 <= 0:
        return np.zeros(unknown.shape, np.bool_)
    min_cells = settings.pocket_min_thickness_m / resolution_m
    out = _pockets(unknown, resolution_m=resolution_m, settings=settings, min_cells=min_cells)
    if settings.pocket_cut_thickness_m is not None:
        side = max(1, round(min_cells))
        opened = cv2.morphologyEx(unknown.astype(np.uint8), cv2.MORPH_OPEN, np.ones((side, side), np.uint8)) > 0
        out |= _pockets(opened, resolution_m=resolution_m, settings=settings,
                        min_cells=settings.pocket_cut_thickness_m / resolution_m)
    cells: npt.NDArray[np.bool_] = out & ~traces
    return cells


def _pockets(unknown: npt.NDArray[np.bool_], *, resolution_m: float, settings: FurnitureSettings,
             min_cells: float) -> npt.NDArray[np.bool_]:
    """The 8-connected pieces of ``unknown`` off the map's border that pass :func:`furniture_pockets`' guards, at least
    ``min_cells`` thick."""
    mask = np.asarray(unknown, np.uint8)
    _, found, found_stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    parts, stats = np.asarray(found, np.int32), np.asarray(found_stats, np.int32)
    h, w = mask.shape
    x, y = stats[:, cv2.CC_STAT_LEFT], stats[:, cv2.CC_STAT_TOP]
    bw, bh, area = stats[:, cv2.CC_STAT_WIDTH], stats[:, cv2.CC_STAT_HEIGHT], stats[:, cv2.CC_STAT_AREA]
    keep = ((x > 0) & (y > 0) & (x + bw < w) & (y + bh < h) & (area <= settings.pocket_max_m2 / resolution_m**2)
            & (np.minimum(bw, bh) >= min_cells))  # the box's shorter side bounds the rectangle's from above
    keep[0] = False
    for k in np.flatnonzero(keep).tolist():
        box = parts[y[k] : y[k] + bh[k], x[k] : x[k] + bw[k]] == k
        rows, cols = np.divmod(np.flatnonzero(box), box.shape[1])
        _, (side_a, side_b), _ = cv2.minAreaRect(np.stack([cols, rows], axis=1).astype(np.float32))
        long_side, short_side = max(side_a, side_b) + 1, min(side_a, side_b) + 1
        keep[k] = (area[k] >= settings.pocket_min_fill * long_side * short_side and short_side >= min_cells
                   and long_side <= settings.pocket_max_elongation * short_side)
    out: npt.NDArray[np.bool_] = keep[parts]
    return out


def furniture_reach(insides: npt.NDArray[np.bool_], blocked: npt.NDArray[np.bool_], *,
                    reach_cells: int) -> npt.NDArray[np.uint8]:
    """Where the insides of furniture (:func:`furniture_insides`) look for their room: 2 on an inside, 1 on the cells
    of ``blocked`` (not free) within ``reach_cells`` of one, 0 elsewhere (:func:`join_insides`)."""
    size = 2 * max(1, reach_cells) + 1
    near = cv2.dilate(insides.astype(np.uint8), cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (size, size))) > 0
    out: npt.NDArray[np.uint8] = np.where(insides, 2, near & blocked).astype(np.uint8)
    return out


def join_insides(labels: npt.NDArray[np.integer], reach: npt.NDArray[np.uint8]) -> npt.NDArray[np.int32]:
    """``labels`` with each label found on the insides of furniture only (``reach`` 2, :func:`furniture_reach`: a
    cupboard's inside the world explains as a room of its own) replaced there by the label nearest to it through the
    furniture round it (``reach`` 1): the room the cupboard stands in (the grid decomposition's ``inside_furniture``).
    Insides that share their label with other cells, and those no other label reaches, keep theirs."""
    lab = np.asarray(labels, np.int32)
    inside = reach == 2
    n = int(lab.max()) + 1
    total = np.bincount(lab.ravel(), minlength=n)
    own = (total == np.bincount(lab[inside].ravel(), minlength=n)) & (total > 0)
    own[0] = False
    target = inside & own[lab]
    if not target.any():
        return lab
    base = np.where(target, 0, lab).astype(np.int32)
    grown = fill_free(base, (reach > 0) | (base > 0))
    return np.where(target & (grown > 0), grown, lab).astype(np.int32)


def label_furniture(labels: npt.NDArray[np.integer], pieces: npt.NDArray[np.bool_], *,
                    reach_cells: int = 1) -> npt.NDArray[np.int32]:
    """``labels`` with each 8-connected piece of ``pieces`` given the label of the cells round it (within
    ``reach_cells``), where they hold one label only (furniture standing in one room; a piece between two rooms keeps
    none)."""
    out = np.asarray(labels, np.int32).copy()
    n, parts = cv2.connectedComponents(pieces.astype(np.uint8), connectivity=8)
    if n < 2:
        return out
    size = 2 * max(1, reach_cells) + 1
    near_piece = np.ones((3, 3), np.uint8) if reach_cells <= 1 else cv2.getStructuringElement(cv2.MORPH_ELLIPSE,
                                                                                               (size, size))
    ring = cv2.dilate(parts.astype(np.float32), near_piece).astype(np.int64)  # ids exact in float32
    near = (ring > 0) & (parts == 0) & (out > 0)
    pairs = np.unique(np.stack([ring[near], out[near].astype(np.int64)], axis=1), axis=0)
    label = np.zeros(n, np.int64)
    label[pairs[:, 0]] = pairs[:, 1]
    label[np.bincount(pairs[:, 0], minlength=n) != 1] = 0
    label[0] = 0
    return np.where(parts > 0, label[parts], out).astype(np.int32)


def fill_free(labels: npt.NDArray[np.integer], free: npt.NDArray[np.bool_]) -> npt.NDArray[np.int32]:
    """Labels grown through free space: every free cell takes the label nearest to it through free cells.

    Parameters
    ----------
    labels : (H, W) integer
        Ids on the cells the world explains, 0 elsewhere.
    free : (H, W) bool
        Free cells of the map.

    Returns
    -------
    (H, W) int32
        Ids on every free cell that free space links to a labelled cell, 0 elsewhere (and off free cells).
    """
    out = np.where(free, labels, 0).astype(np.int32)
    hole = free & (out == 0)
    square = np.ones((3, 3), np.uint8)
    while True:  # one ring of cells a round, within the box of the cells still to fill
        rows, cols = np.flatnonzero(hole.any(axis=1)), np.flatnonzero(hole.any(axis=0))
        if rows.size == 0:
            return out
        box = (slice(max(int(rows[0]) - 1, 0), int(rows[-1]) + 2), slice(max(int(cols[0]) - 1, 0), int(cols[-1]) + 2))
        grown = cv2.dilate(out[box].astype(np.float32), square)  # ids below 2**24 are exact in float32
        take = hole[box] & (grown > 0)
        if not take.any():
            return out  # free cells free space links to no label
        out[box][take] = grown[take].astype(np.int32)
        hole[box] &= ~take


def cut_off_free(labels: npt.NDArray[np.integer], free: npt.NDArray[np.bool_], *,
                 min_cells: int) -> npt.NDArray[np.bool_]:
    """The 8-connected pieces of ``free`` cells that hold no label and have at least ``min_cells`` cells: free space
    that no labelled cell reaches through free space."""
    _, parts, stats, _ = cv2.connectedComponentsWithStats((free & (np.asarray(labels) == 0)).astype(np.uint8),
                                                          connectivity=8)
    keep = stats[:, cv2.CC_STAT_AREA] >= min_cells
    keep[0] = False
    out: npt.NDArray[np.bool_] = keep[parts]
    return out

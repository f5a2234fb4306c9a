"""A corridor the room stage cut in pieces is one region again, and the rooms that leak into it part from it."""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np
import numpy.typing as npt

from services.grid_decomposition.arrays import (
    components_stats,
    components_stats_runs,
    label_boxes,
    label_counts,
    lookup,
)
from services.grid_decomposition.corridors import (
    Band,
    _runs,
    band_box,
    band_mask,
    corridor_bands,
    tilted_lines,
    window_coordinates,
)
from services.grid_decomposition.radiogram import Line
from services.grid_decomposition.segments import fill_from_neighbours


def _room_like(piece: npt.NDArray[np.bool_], *, min_area_px: float, min_radius_px: float) -> bool:
    """At least ``min_area_px``, and a disc of ``min_radius_px`` fits in it with its holes (furniture) filled."""
    if np.count_nonzero(piece) < min_area_px:
        return False
    outline, _ = cv2.findContours(np.pad(piece, 1).astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    filled = cv2.drawContours(np.zeros((piece.shape[0] + 2, piece.shape[1] + 2), np.uint8), outline, -1, 1, -1)
    return bool(cv2.distanceTransform(filled, cv2.DIST_L2, 5).max() >= min_radius_px)


def _shallow(strip: npt.NDArray[np.bool_], part: npt.NDArray[np.bool_], top: int, left: int, ratio: float) -> bool:
    """``part`` (placed at ``top``, ``left`` in the window of ``strip``) reaches less than ``ratio`` times the length
    of its front on the strip away from it (its front: its pixels 4-connected to the strip's; its reach: its
    largest distance from the strip's pixels in its box, one pixel round)."""
    h, w = part.shape
    y0, x0 = max(top - 1, 0), max(left - 1, 0)
    y1, x1 = min(top + h + 1, strip.shape[0]), min(left + w + 1, strip.shape[1])
    placed = np.zeros((y1 - y0, x1 - x0), dtype=bool)
    placed[top - y0 : top - y0 + h, left - x0 : left - x0 + w] = part
    near = strip[y0:y1, x0:x1].astype(np.uint8)
    beside = cv2.dilate(near, np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]], np.uint8)) > 0
    front = np.count_nonzero(placed & beside)
    if front == 0:
        return False
    depth = cv2.distanceTransform(1 - near, cv2.DIST_L2, 5)[placed].max()
    return bool(depth < ratio * front)


def _beyond_the_wall_line(
    corridor: npt.NDArray[np.bool_],
    widening: npt.NDArray[np.bool_] | None,
    band: Band,
    walls: npt.NDArray[np.bool_],
    u: npt.NDArray[np.int32],
    t: npt.NDArray[np.int32],
    *,
    tolerance_px: int,
    step_px: int,
    max_open_px: int,
    doorway_depth_px: int,
) -> npt.NDArray[np.bool_]:
    """The pixels of ``corridor`` (a band's strip and the pieces about to join it) that lie beyond the corridor's
    wall line within the band's run: up to ``step_px`` beyond a side line along which no wall stands back, in
    8-connected pieces reaching more than ``doorway_depth_px`` beyond it (the room's floor inside a doorway in a wall
    on the line; a piece no deeper is the doorway itself), and more than ``step_px`` beyond it in a ``widening``
    (floor past the step a wall standing back may take). A side's wall stands back at ``t`` where walls lie more
    than ``tolerance_px`` and up to ``step_px`` beyond its line along more than ``max_open_px``, openings (doors)
    of at most ``max_open_px`` between such stretches included: floor in front of it (between cupboards along the
    corridor) is the corridor's."""
    out_px = max(tolerance_px, step_px)
    box = band_box(u, t, (band.offset_a_px - out_px, band.offset_b_px + out_px), (band.t0_px, band.t1_px))
    ub, tb = u[box], t[box]
    run = (tb >= band.t0_px) & (tb <= band.t1_px)
    along = run & walls[box]
    n = band.t1_px - band.t0_px + 1
    at = np.clip(tb - band.t0_px, 0, n - 1)
    doors = np.zeros(ub.shape, dtype=bool)
    for beyond in (band.offset_a_px - ub, ub - band.offset_b_px):  # how far past the side's line, outwards
        back = np.bincount(tb[along & (beyond > tolerance_px) & (beyond <= out_px)] - band.t0_px, minlength=n) > 0
        stepped = ~_long_runs(~_long_runs(back, max_open_px), max_open_px)
        doors |= (beyond > 0) & (beyond <= step_px) & ~stepped[at]
    doors &= run & corridor[box]
    if widening is not None:  # a widening's floor is the corridor's up to the step, beyond it the rooms' mouths
        doors &= ~widening[box]
    if doors.any():  # a piece no deeper than a wall is the doorway itself; one reaching further is in the room
        n_d, parts, _ = components_stats(doors.view(np.uint8), 8)
        reach = np.zeros(n_d, dtype=np.int64)
        np.maximum.at(reach, parts[doors], np.maximum(band.offset_a_px - ub, ub - band.offset_b_px)[doors])
        doors &= (reach > doorway_depth_px)[parts]
    found = np.zeros(corridor.shape, dtype=bool)
    found[box] = doors
    if widening is not None:
        far = (u < band.offset_a_px - step_px) | (u > band.offset_b_px + step_px)
        found |= widening & corridor & far & (t >= band.t0_px) & (t <= band.t1_px)
    return found


def _open_onto_rooms(
    out: npt.NDArray[np.int32], corridor: npt.NDArray[np.bool_], beyond: npt.NDArray[np.bool_]
) -> None:
    """Each 8-connected piece of ``beyond`` (floor past the corridor's wall line) whose outline off the ``corridor``
    meets other regions of ``out`` along more pixels than walls (pixels in no region): the mouth or the inside of
    a doorway of the rooms it opens onto, given to them in ``out`` and taken out of ``corridor`` (both in place,
    grown from those regions). Floor the walls close (a recess, a niche in front of a wall) stays the corridor's."""
    rows, cols = np.flatnonzero(beyond.any(axis=1)), np.flatnonzero(beyond.any(axis=0))
    if rows.size == 0:
        return
    window = slice(max(int(rows[0]) - 1, 0), int(rows[-1]) + 2), slice(max(int(cols[0]) - 1, 0), int(cols[-1]) + 2)
    labels, near, far = out[window], corridor[window], beyond[window]
    rooms = np.where(near, 0, labels).astype(np.int32)  # the regions the pieces may go to
    n, parts, stats = components_stats(far.view(np.uint8), 8)
    cross = np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]], np.uint8)
    open_pieces = np.zeros(far.shape, dtype=bool)
    for p in range(1, n):
        x, y, w, h = stats[p, :4]
        box = slice(max(y - 1, 0), y + h + 1), slice(max(x - 1, 0), x + w + 1)
        piece = parts[box] == p
        ring = (cv2.dilate(piece.view(np.uint8), cross) > 0) & ~piece & ~near[box]
        if np.count_nonzero(ring & (rooms[box] > 0)) > np.count_nonzero(ring & (labels[box] == 0)):
            open_pieces[box] |= piece
    if not open_pieces.any():
        return
    grown = fill_from_neighbours(rooms, open_pieces, max_iterations=10**6)
    given = open_pieces & (grown > 0)
    labels[given] = grown[given]
    near[given] = False


def _long_runs(flags: npt.NDArray[np.bool_], min_length: int, *, inner: bool = False) -> npt.NDArray[np.bool_]:
    """The runs of True longer than ``min_length``; with ``inner`` only those with False on both ends."""
    starts, ends = _runs(flags)
    wide = ends - starts > min_length
    if inner:
        wide &= (starts > 0) & (ends < flags.size)
    marks = np.zeros(flags.size + 1, dtype=np.int32)
    np.add.at(marks, starts[wide], 1)
    np.add.at(marks, ends[wide], -1)
    return np.cumsum(marks[:-1]) > 0


def _walled_parts(
    band: Band,
    walls: npt.NDArray[np.bool_],
    u: npt.NDArray[np.int32],
    t: npt.NDArray[np.int32],
    *,
    tolerance_px: int,
    max_open_px: int,
    max_side_open_px: int,
    min_length_px: int,
    min_length_widths: float,
    step_px: int,
) -> list[Band]:
    """The parts of a band between its junctions and the halls open onto it.

    A side is walled at ``t`` where a wall pixel lies within ``tolerance_px`` of its line, or up to ``step_px``
    beyond it along more than ``max_open_px`` (a wall standing back a little, where the corridor widens in front
    of a room whose wall is further out, still walls it; a jamb or a wall's end beyond the line does not). Where
    both sides are open over more than ``max_open_px`` the corridor meets a hall or crosses another corridor;
    where one side is open over more than ``max_side_open_px`` between two walled stretches of it a hall lies
    along it (wider than an office's open front): it is no corridor there. Parts shorter than ``min_length_px`` and
    ``min_length_widths`` widths are left out.
    """
    out_px = max(tolerance_px, step_px)
    box = band_box(u, t, (band.offset_a_px - out_px, band.offset_b_px + out_px), (band.t0_px, band.t1_px))
    u, t = u[box], t[box]
    along = (t >= band.t0_px) & (t <= band.t1_px) & walls[box]
    n = band.t1_px - band.t0_px + 1
    sides = []
    for beyond in (band.offset_a_px - u, u - band.offset_b_px):  # how far past the side's line, outwards
        on_line = np.bincount(t[along & (np.abs(beyond) <= tolerance_px)] - band.t0_px, minlength=n) > 0
        back = np.bincount(t[along & (beyond > tolerance_px) & (beyond <= out_px)] - band.t0_px, minlength=n) > 0
        sides.append(on_line | _long_runs(back, max_open_px))
    side_a, side_b = sides
    length = max(min_length_px, round(min_length_widths * (band.offset_b_px - band.offset_a_px)))
    parts = []
    for s0, e0 in zip(*_runs(~_long_runs(~side_a & ~side_b, max_open_px)), strict=True):
        a, b = side_a[s0:e0], side_b[s0:e0]
        cuts = _long_runs(~a, max_side_open_px, inner=True) | _long_runs(~b, max_side_open_px, inner=True)
        parts += [
            replace(band, t0_px=band.t0_px + int(s0 + s), t1_px=band.t0_px + int(s0 + e) - 1)
            for s, e in zip(*_runs(~cuts), strict=True)
            if e - s >= length
        ]
    return parts


def _part_beyond(
    out: npt.NDArray[np.int32],
    strip: npt.NDArray[np.bool_],
    along: npt.NDArray[np.bool_],
    size: npt.NDArray[np.int64],
    next_id: int,
    *,
    min_piece_share: float,
    min_area_px: float,
    min_depth_ratio: float,
) -> int:
    """Part from every region lying at least ``min_piece_share`` in a band's ``strip`` each 8-connected part it holds
    outside the strip, wholly ``along`` the band's run (beyond its side lines, not past its ends), of at least
    ``min_area_px`` and reaching away from the strip at least ``min_depth_ratio`` times its front on it: a room seen
    through a gap in the corridor's wall, not the corridor widening. A ray is a diagonal line of cells: 8-connected,
    the rays of the room's fan stay with it. ``out`` is parted in place (new ids from ``next_id``); returns the next
    free id."""
    held = np.bincount(out[strip], minlength=size.size)
    held[0] = 0
    boxes = label_boxes(out)
    for k in np.flatnonzero(held >= min_piece_share * np.maximum(size, 1)).tolist():
        own = boxes[k - 1]
        assert own is not None  # k holds pixels of the strip
        _, parts, stats = components_stats(((out[own] == k) & ~strip[own]).view(np.uint8), 8)
        for p in np.flatnonzero(stats[1:, cv2.CC_STAT_AREA] >= min_area_px).tolist():
            x, y, w, h = stats[p + 1, :4]
            part = parts[y : y + h, x : x + w] == p + 1
            if not along[own][y : y + h, x : x + w][part].all():
                continue
            if _shallow(strip, part, own[0].start + y, own[1].start + x, min_depth_ratio):
                continue
            out[own][y : y + h, x : x + w][part] = next_id
            next_id += 1
    return next_id


def join_corridor_pieces(
    segments: npt.NDArray[np.int32],
    lines: list[Line],
    joinable: npt.NDArray[np.bool_],
    *,
    resolution_m: float,
    min_piece_share: float = 0.5,
    min_pieces_share: float = 0.5,
    room_min_area_m2: float = 4.0,
    room_min_radius_m: float = 1.0,
    max_open_m: float = 2.0,
    max_side_open_m: float = 6.0,
    min_length_m: float = 6.0,
    min_length_widths: float = 3.0,
    wall_step_m: float = 0.75,
    room_min_depth_ratio: float = 0.4,
    beyond_min_area_m2: float = 0.0,
    beyond_min_depth_ratio: float = 1.0,
    tolerance_px: int = 2,
    margin_px: int = 4,
    occupied: npt.NDArray[np.bool_] | None = None,
    past_wall_line_to_rooms: bool = True,
    doorway_depth_m: float = 0.3,
) -> tuple[npt.NDArray[np.int32], int]:
    """Make every corridor band that the room stage cut in pieces one region; part the rooms leaking into it.

    The bands (:func:`~services.grid_decomposition.corridors.corridor_bands`) are looked for in the union
    of the ``joinable`` regions (per region id: a room region, no warehouse floor), with every pixel in no
    region as wall: a corridor's walls are often drawn as a grey band with few occupied cells. With
    ``occupied``, bands are looked for along the :func:`~services.grid_decomposition.corridors.tilted_lines` of its
    walls round those regions too (a corridor in a wing the map drew askew), after those of ``lines``. A band ends
    where both its sides are open over more than ``max_open_m`` (a junction, a hall it enters) and where
    one side is open over more than ``max_side_open_m`` between walled stretches (a hall along it); a side is
    walled where a wall lies on its line, or up to ``wall_step_m`` beyond it for more than ``max_open_m`` (a wall
    stepping back a little, in front of a room whose wall stands further out, is no opening). A band is
    a corridor cut in pieces when the regions lying at least ``min_piece_share`` inside its strip hold at
    least ``min_pieces_share`` of the strip: a band through the middle of a room (an aisle beside desks)
    is a small part of the room's region and is left alone. The strip of such a band becomes one region;
    what each region it crossed keeps outside the strip splits into 4-connected parts. A region the strip
    only clipped (less than ``min_piece_share`` inside) keeps its largest part; other parts stay regions
    when room-like (at least ``room_min_area_m2``, a ``room_min_radius_m`` disc fits with its furniture
    holes filled, and reaching away from the strip at least ``room_min_depth_ratio`` times the length of its front
    on it: a room lies off the corridor, a piece along it shallower than that is the corridor widening in front
    of the doors beside it), the largest keeping the region's id, and the rest (a door's niche, a sliver along the
    wall) joins the corridor where it touches it. The rest of the corridor's own region parted off where
    the corridor turns is its other arm when that arm's band is taken too (an L); the bands are passed
    twice, so the order they are found in does not matter.

    With ``past_wall_line_to_rooms``, the floor about to join the corridor that lies beyond its wall line goes to
    the rooms it opens onto (:func:`_beyond_the_wall_line`, :func:`_open_onto_rooms`): where a side's wall is on
    its line, a piece inside a doorway reaching more than ``doorway_depth_m`` (a wall's thickness) past the line
    (the room stage cut the room along the furniture behind its door); in a widening, the floor more than
    ``wall_step_m`` past the line (the mouths of rooms whose walls stop short of the corridor's wall line); each
    only when it meets other regions along more of its outline than walls. Floor in front of a wall standing back
    (between cupboards along the corridor) and recesses walls close stay the corridor's.

    With ``beyond_min_area_m2`` above 0, a band that is no corridor cut in pieces still parts, from each region
    lying at least ``min_piece_share`` in its strip (the corridor's own piece), every 8-connected part it holds
    beyond the band's side lines and within its run of at least that area that reaches away from the strip at least
    ``beyond_min_depth_ratio`` times its front on it: a room seen through a gap in the corridor's wall (the gap no
    doorway: the room's side did not widen), not the corridor widening in front of a door nor its going on past
    the band's end (:func:`_part_beyond`).

    Returns
    -------
    (H, W) int32
        The segments; the corridor takes the id of the region that held most of its strip, parted
        rooms beyond the first of a region are numbered after the existing ids.
    int
        The first id of the rooms parted beyond a band's side line (every id from it on is one).
    """
    region = lookup(np.r_[False, joinable[1:]], segments)  # a joinable region's pixels (a lookup per run)
    if not region.any():
        return segments, int(segments.max()) + 1
    rows, cols = np.flatnonzero(region.any(axis=1)), np.flatnonzero(region.any(axis=0))
    top, left = max(0, int(rows[0]) - margin_px), max(0, int(cols[0]) - margin_px)
    box = slice(top, int(rows[-1]) + 1 + margin_px), slice(left, int(cols[-1]) + 1 + margin_px)
    window = segments[box]
    inside = region[box]
    walls = window == 0
    shape = (window.shape[0], window.shape[1])
    tilted = [] if occupied is None else tilted_lines(
        occupied[box], lines, top=top, left=left, resolution_m=resolution_m
    )
    coordinates = window_coordinates(shape, top, left, lines + tilted)
    step_px = round(wall_step_m / resolution_m)
    found = corridor_bands(
        inside, walls, lines, top=top, left=left, resolution_m=resolution_m, min_length_m=min_length_m,
        min_length_widths=min_length_widths, tolerance_px=tolerance_px, coordinates=coordinates, tilted=tilted,
    )
    if not found:
        return segments, int(segments.max()) + 1
    bands = [
        part
        for band in found
        for part in _walled_parts(
            band, walls, *coordinates[band.angle_rad], tolerance_px=tolerance_px,
            max_open_px=round(max_open_m / resolution_m), max_side_open_px=round(max_side_open_m / resolution_m),
            min_length_px=round(min_length_m / resolution_m),
            min_length_widths=min_length_widths, step_px=step_px,
        )
    ]
    out = window.copy()
    next_id = int(segments.max()) + 1
    taken = np.zeros(shape, dtype=bool)
    parted_from: dict[int, int] = {}  # the rooms parted from a corridor's own region
    made: set[int] = set()
    limits = {
        "min_area_px": room_min_area_m2 / resolution_m**2,
        "min_radius_px": room_min_radius_m / resolution_m,
    }
    # a band that does not qualify may after another band parted its region (the other arm of an L): two passes
    wholes = [band_mask(band, *coordinates[band.angle_rad]) & inside for band in bands]
    size = label_counts(out, int(out.max()) + 1)[0]  # np.bincount of every pixel, from the runs
    for i in list(range(len(bands))) * 2:
        if i in made:
            continue
        strip = wholes[i] & ~taken
        n = size.size
        held = np.bincount(out[strip], minlength=n)
        held[0] = 0
        pieces = held >= min_piece_share * np.maximum(size, 1)
        if held[pieces].sum() < min_pieces_share * np.count_nonzero(strip):
            continue
        # the rest of a corridor's region parted from it where the corridor turns (an L) is its other arm
        corridor_id = int(np.argmax(held))
        arm = corridor_id in parted_from
        corridor_id = parted_from.get(corridor_id, corridor_id)
        crossed = np.flatnonzero(held)
        corridor = strip.copy()
        widening = None  # the room-like pieces along the strip shallower than their front (seldom any)
        boxes = label_boxes(out)
        for k in crossed.tolist():
            own = boxes[k - 1]
            assert own is not None  # k holds pixels of the strip
            n_parts, parts, stats, runs = components_stats_runs(((out[own] == k) & ~strip[own]).view(np.uint8), 4)
            areas = stats[:, cv2.CC_STAT_AREA].copy()
            areas[0] = 0
            no_room = np.ones(n_parts, dtype=bool)
            no_room[0] = False
            keeps = arm or k != corridor_id  # the largest room-like piece keeps the region's id
            if keeps and not pieces[k] and n_parts > 1:  # a room the strip only clipped keeps its rest, however small
                no_room[int(np.argmax(areas))] = keeps = False
            for p in np.argsort(-areas)[: np.count_nonzero(areas >= limits["min_area_px"])].tolist():
                if not no_room[p]:
                    continue
                x, y, w, h = stats[p, :4]
                part = parts[y : y + h, x : x + w] == p
                if not _room_like(part, **limits):
                    continue
                if _shallow(strip, part, own[0].start + y, own[1].start + x, room_min_depth_ratio):
                    if widening is None:
                        widening = np.zeros(shape, dtype=bool)
                    widening[own][y : y + h, x : x + w] |= part
                    continue  # a widening of the corridor along it, in front of the rooms beside it
                no_room[p] = False
                if keeps:
                    keeps = False
                else:
                    out[own][y : y + h, x : x + w][part] = next_id
                    if k == corridor_id:
                        parted_from[next_id] = corridor_id
                    next_id += 1
            corridor[own] |= lookup(no_room, parts, runs)  # spread by the labelling's own runs
        # the pieces that are no room join the corridor only where they touch it
        n_parts, parts = cv2.connectedComponents(corridor.astype(np.uint8), connectivity=4)
        touching = np.zeros(n_parts, dtype=bool)
        touching[parts[strip]] = True
        touching[0] = False
        corridor = lookup(touching, parts)
        if past_wall_line_to_rooms:
            beyond = _beyond_the_wall_line(
                corridor, widening, bands[i], walls, *coordinates[bands[i].angle_rad], tolerance_px=tolerance_px,
                step_px=step_px, max_open_px=round(max_open_m / resolution_m),
                doorway_depth_px=round(doorway_depth_m / resolution_m),
            )
            _open_onto_rooms(out, corridor, beyond)
        out[corridor] = corridor_id
        taken |= corridor
        made.add(i)
        size = label_counts(out, int(out.max()) + 1)[0]
    first_beyond = next_id
    for i in sorted(set(range(len(bands))) - made) if beyond_min_area_m2 > 0 else []:  # no corridor cut in pieces
        t = coordinates[bands[i].angle_rad][1]
        next_id = _part_beyond(
            out, wholes[i] & ~taken, (t >= bands[i].t0_px) & (t <= bands[i].t1_px), size, next_id,
            min_piece_share=min_piece_share, min_area_px=beyond_min_area_m2 / resolution_m**2,
            min_depth_ratio=beyond_min_depth_ratio,
        )
        size = label_counts(out, int(out.max()) + 1)[0]
    result = segments.copy()
    result[box] = out
    return result, first_beyond

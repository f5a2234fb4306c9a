"""Rooms: furniture told from walls, face regions joined, cut at doorways and cleaned."""

from __future__ import annotations

import math

import cv2
import numpy as np
import numpy.typing as npt

from services.grid_decomposition.arrays import (
    Components,
    components,
    components_stats,
    components_stats_runs,
    label_boxes,
    label_counts,
    label_max,
    lookup,
    nonzero_rc,
    short_of,
)
from services.grid_decomposition.basins import join_furnished_groups, join_room_pieces
from services.grid_decomposition.doorways import draw_cuts, find_doorways, off_a_door_jamb, opens_an_arm
from services.grid_decomposition.necks import split_at_necks
from services.grid_decomposition.openings import join_pairs
from services.grid_decomposition.segments import (
    fill_from_neighbours,
    merge_open_segments,
    merge_small_segments,
    renumber,
    split_along,
)
from shared.furniture import FurnitureRule, furniture_pieces


def furniture(
    obstacle: npt.NDArray[np.bool_],
    *,
    resolution_m: float,
    labelled: Components | None = None,
) -> npt.NDArray[np.bool_]:
    """Free-standing obstacles: furniture, bins, pillars, table legs, clutter, desks and cabinets.

    The 8-connected obstacle components that are furniture by :func:`shared.furniture.furniture_pieces` with its
    default numbers (small pieces that are no piece of wall, solid blocks that are not elongated, off the map
    border): the floor plan's rule too, without its dotted-wall step.

    Parameters
    ----------
    obstacle : (H, W) bool
        Occupied or unknown cells.
    resolution_m : float
        Metres per cell.
    labelled : Components, optional
        ``components(obstacle)``, when already labelled.

    Returns
    -------
    (H, W) bool
        The furniture cells (a subset of ``obstacle``).
    """
    labelled = components(obstacle) if labelled is None else labelled
    keep = furniture_pieces(obstacle, labelled.labels, labelled.stats, resolution_m=resolution_m,
                            rule=FurnitureRule())
    return labelled.spread(keep)


def wall_furniture(
    obstacle: npt.NDArray[np.bool_],
    *,
    resolution_m: float,
    min_thickness_m: float = 0.55,
    max_area_m2: float = 3.0,
) -> npt.NDArray[np.bool_]:
    """Furniture pushed against a wall: the thick parts of obstacles, off the map border.

    Walls are thin: an opening of the obstacle mask with a disk ``min_thickness_m`` wide removes
    them and leaves cupboards, desks and shelves standing against them (and pillars, which are
    furniture to :func:`furniture` as well). Parts of at most ``max_area_m2`` not touching the
    map border are returned; a room's segment covers them like the furniture standing free in it
    (the room's floor is under them).

    Returns
    -------
    (H, W) bool
        A subset of ``obstacle``.
    """
    radius = max(1, round(min_thickness_m / resolution_m / 2))
    disk = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))
    thick = cv2.morphologyEx(obstacle.astype(np.uint8), cv2.MORPH_OPEN, disk)
    n, parts, stats, runs = components_stats_runs(thick, 8)
    keep = stats[:, cv2.CC_STAT_AREA] <= max_area_m2 / resolution_m**2
    keep[0] = False
    keep[np.unique(np.r_[parts[0], parts[-1], parts[:, 0], parts[:, -1]])] = False
    return lookup(keep, parts, runs) if n > 1 else np.zeros(obstacle.shape, dtype=bool)


def segment_rooms(
    segments: npt.NDArray[np.int32],
    clutter: npt.NDArray[np.bool_],
    floor: npt.NDArray[np.bool_],
    closed: npt.NDArray[np.bool_],
    *,
    resolution_m: float,
    door_max_width_m: float = 2.5,
    door_widening_m: float = 0.3,
    door_max_depth_m: float = 1.0,
    corridor_length_m: float = 2.0,
    room_min_area_m2: float = 1.5,
    room_min_half_width_m: float = 0.4,
    neck_half_width_m: float = 0.0,
    join_saddle_ratio: float = 0.8,
    join_solidity: float = 0.8,
    island_max_extent_m: float = 3.0,
    desk_max_extent_m: float = 4.5,
    desk_max_elongation: float = 2.5,
    desk_min_thickness_m: float = 0.6,
    desk_small_m2: float = 0.25,
    desk_small_extent_m: float = 0.7,
    desk_wall_reach_m: float = 0.5,
    table_min_thickness_m: float = 0.3,
    table_clearance_m: float = 0.8,
    line_doors: npt.NDArray[np.bool_] | None = None,
    rays: npt.NDArray[np.bool_] | None = None,
    occupied: npt.NDArray[np.bool_] | None = None,
    lone_max_ray_share: float = 0.5,
    outside_min_open_share: float = 0.4,
    outside_reach_m: float = 6.0,
    arm_min_width_m: float = 2.0,
    arm_wall_from_m: float = 0.2,
    arm_wall_m: float = 0.8,
    arm_wall_share: float = 0.8,
    block_max_run_m: float = 1.5,
    jamb_reach_m: float = 0.4,
    jamb_seen_m: float = 0.1,
    jamb_run_m: float = 0.5,
    jamb_run_share: float = 0.9,
    jamb_min_angle_deg: float = 60.0,
) -> tuple[npt.NDArray[np.int32], npt.NDArray[np.bool_]]:
    """Rooms from the face regions: join open borders, take in furniture, cut at doorways, absorb slivers.

    Segments on warehouse floors (``floor``) are left as they are.

    1. Touching segments whose shared border is mostly open (not on ``closed``: wall evidence
       and doorways closed along lines) are one room (:func:`merge_open_segments`).
    2. Furniture (``clutter``) takes the room around it: a room's area is its floor plan.
    3. Rooms joined through a neck are split (:func:`split_at_necks`, when
       ``neck_half_width_m`` > 0), and doorways found from the free space itself
       (:func:`find_doorways`) cut rooms apart; a cut across a corridor, which goes on for
       ``corridor_length_m`` on both sides about as wide as the cut, is no doorway, nor is a cut across a strip
       that furniture against one of its walls narrows (:func:`~services.grid_decomposition.doorways.bumps_a_strip`),
       nor a cut with an end on a table (when ``table_min_thickness_m`` > 0): an obstacle island the laser
       hit, at most ``island_max_extent_m`` across, of which at least 0.3 survives an opening
       with a disc ``table_min_thickness_m`` wide (a dash of wall is thinner), compact (its
       minimum-area rectangle at most ``desk_max_elongation`` times as long as wide), with floor
       all round it within ``table_clearance_m`` and no obstacles there on two opposite sides (an
       obstacle standing in a doorway, between its jambs, is no table). A
       doorway is an opening in a wall; the gap between a table and a wall is a passage round it.
       Nor is a cut at least ``arm_min_width_m`` wide across the mouth of a room's arm
       (:func:`~services.grid_decomposition.doorways.opens_an_arm`: one end meets a straight wall side-on, the other
       a corner; ``arm_wall_share`` of the wall beside an end, ``arm_wall_from_m`` to ``arm_wall_m`` from it along
       the cut's normal, shows where it runs on): the pieces met along its normal within ``arm_wall_m`` of its
       middle are one room, even where a line closed the mouth as a doorway (``arm_min_width_m`` 0 turns this off).
       Nor is a cut between a side wall and a block standing out from the facing wall, ending along the cut within
       ``block_max_run_m`` (with ``occupied``; :func:`~services.grid_decomposition.doorways.block_beside_a_wall`,
       0 turns it off). Nor is a cut from a doorway's jamb into the room behind it
       (:func:`~services.grid_decomposition.doorways.off_a_door_jamb`, with ``occupied``): one end within
       ``jamb_reach_m`` of an end of another cut at least ``jamb_min_angle_deg`` across it, whose wall runs on beyond
       that end along it (``jamb_run_share`` of the next ``jamb_run_m`` not free) while this cut's does not, and the
       other end with no occupied cell within ``jamb_seen_m``: the free space behind a door reaches round its jamb
       down the room's side to a shadow the laser left, which is the room's inside, not a second opening
       (``jamb_reach_m`` 0 turns it off).
    4. Pieces smaller than ``room_min_area_m2``, or narrower than twice ``room_min_half_width_m``
       everywhere (aisles between shelves, strips along a wall), join the neighbour they share the
       longest border with (:func:`merge_small_segments`). Such a piece with no neighbour is no
       room when it is mostly thin laser rays (more than ``lone_max_ray_share`` of its pixels on
       ``rays``) and lies outside the building: at least ``outside_min_open_share`` of 32 beams
       from its middle meet no ``occupied`` cell within ``outside_reach_m`` (:func:`open_share`;
       beside an outer wall about half of them escape). That is a bundle of rays seen through
       the outer wall, with no floor of its own; rays into a small room nobody entered have the
       room's walls round them and stay a room.
    5. Pieces of one furnished room join (:func:`join_room_pieces`, when ``join_saddle_ratio`` > 0):
       no neck between them on the clearance map (furniture and obstacle islands at most
       ``island_max_extent_m`` across count as floor), a union about as convex as a room
       (``join_solidity``), furniture near their border.
    6. Pieces that only furniture separates join when together they are room-shaped
       (:func:`join_furnished_groups`, when ``desk_max_extent_m`` > 0): an open-plan office cut
       round its desk clusters (:func:`desk_clusters`: obstacle islands up to ``desk_max_extent_m``
       across, solid, compact, or chairs up to ``desk_small_m2``; the laser saw them), linked by
       borders that end on them and not on a doorway between walls (free-space cuts with both ends
       on walls, gaps closed along lines, ``line_doors``, off the furniture), with more furniture
       than wall (within ``desk_wall_reach_m`` of both) between them, whose union fills
       ``join_solidity`` of its hull.

    Parameters
    ----------
    segments : (H, W) int32
        Region id per free pixel from the faces, 0 elsewhere.
    clutter, floor, closed : (H, W) bool
        Furniture (:func:`furniture`); pixels of warehouse floors; closed line pixels.
    rays, occupied : (H, W) bool, optional
        Thin free space the map cleaning kept (``Cleaning.rays``); occupied cells (walls).
    resolution_m : float
        Metres per pixel.

    Returns
    -------
    segments : (H, W) int32
        Region ids 1..N; 0 on walls, unknown space and furniture on warehouse floors.
    cuts : (H, W) bool
        The doorways found off the lines (cut pixels).
    """
    seg = merge_open_segments(segments, closed, fixed=_share(segments, floor) > 0.5)
    cut = np.zeros(seg.shape, dtype=bool)
    cuts = np.zeros((0, 2, 2))
    fixed = _share(seg, floor) > 0.5
    # in merge_open_segments' new array (this function's own): furniture on a fixed segment is cleared in place
    seg = fill_from_neighbours(seg, clutter, overwrite=True)
    on_fixed = lookup(fixed, seg)
    np.copyto(seg, 0, where=clutter & on_fixed)
    space = (seg > 0) & ~on_fixed  # a pixel cleared here is no space either way
    if not space.any():  # warehouse floors only (a rack hall): no room to split, cut or clean up
        return renumber(seg, copy=False), cut  # seg is this function's own
    clearance = np.asarray(cv2.distanceTransform(space.astype(np.uint8), cv2.DIST_L2, 5), dtype=np.float32)
    if neck_half_width_m > 0:
        seg = split_at_necks(
            seg, space, resolution_m=resolution_m, neck_half_width_m=neck_half_width_m, distance=clearance
        )
    if door_max_width_m > 0 and space.any():
        cuts = find_doorways(
            space,
            resolution_m=resolution_m,
            max_width_m=door_max_width_m,
            widening_m=door_widening_m,
            max_depth_m=door_max_depth_m,
            corridor_length_m=corridor_length_m,
            hit=occupied,
            block_max_run_m=block_max_run_m,
        )
        if table_min_thickness_m > 0 and cuts.size:  # passing a table is no doorway: a cut ending on one is dropped
            cuts = cuts[
                ~ends_on_tables(
                    cuts,
                    seg == 0,
                    occupied,
                    max_extent_px=island_max_extent_m / resolution_m,
                    min_thickness_px=table_min_thickness_m / resolution_m,
                    max_elongation=desk_max_elongation,
                    clearance_px=round(table_clearance_m / resolution_m),
                )
            ]
        mouths = np.zeros((0, 2, 2))
        if arm_min_width_m > 0 and cuts.size:
            mouth = opens_an_arm(
                ~space,
                cuts,
                min_width_px=arm_min_width_m / resolution_m,
                from_px=max(1, round(arm_wall_from_m / resolution_m)),
                to_px=round(arm_wall_m / resolution_m),
                share=arm_wall_share,
            )
            cuts, mouths = cuts[~mouth], cuts[mouth]
        if jamb_reach_m > 0 and occupied is not None and cuts.size:
            cuts = cuts[
                ~off_a_door_jamb(
                    cuts, space, occupied, reach_px=jamb_reach_m / resolution_m,
                    run_px=max(1, round(jamb_run_m / resolution_m)), share=jamb_run_share,
                    seen_px=round(jamb_seen_m / resolution_m), max_cos=math.cos(math.radians(jamb_min_angle_deg)),
                )
            ]
        cut = draw_cuts(cuts, seg.shape) & space
        seg = split_along(seg, cut)
        if len(mouths):
            seg = _join_across(seg, mouths, fixed=_share(seg, floor) > 0.5, reach_px=round(arm_wall_m / resolution_m))
    widest = label_max(seg, clearance, int(seg.max()) + 1)[0]  # clearance >= 0: a max per segment
    narrow = widest * resolution_m < room_min_half_width_m
    rooms = merge_small_segments(
        seg,
        min_area_px=max(1, round(room_min_area_m2 / resolution_m**2)),
        fixed=_share(seg, floor) > 0.5,
        absorb=narrow,
        lone_dropped=_outside_rays(seg, narrow, rays, occupied, lone_max_ray_share, outside_min_open_share,
                                   round(outside_reach_m / resolution_m)),
    )
    if join_saddle_ratio > 0:
        rooms = join_furnished_pieces(
            rooms,
            clutter,
            floor,
            resolution_m=resolution_m,
            island_max_extent_m=island_max_extent_m,
            saddle_ratio=join_saddle_ratio,
            solidity=join_solidity,
        )
    if desk_max_extent_m > 0:
        desks = desk_clusters(
            rooms == 0,
            max_extent_px=desk_max_extent_m / resolution_m,
            compact_from_px=island_max_extent_m / resolution_m,
            max_elongation=desk_max_elongation,
            min_thickness_px=desk_min_thickness_m / resolution_m,
            small_px=desk_small_m2 / resolution_m**2,
            small_extent_px=desk_small_extent_m / resolution_m,
        )
        standing = clutter | desks
        if occupied is not None:  # furniture is something the laser hit, not unknown space between rays
            parts = components(standing)
            seen = np.zeros(len(parts.stats), dtype=bool)
            seen[parts.labels.ravel()[np.flatnonzero(occupied & standing)]] = True
            seen[0] = False
            standing = parts.spread(seen)
        rooms = join_furnished_groups(
            rooms,
            standing,
            doors=_wall_doors(cuts, line_doors, standing),
            wall_reach_px=desk_wall_reach_m / resolution_m,
            fixed=_share(rooms, floor) > 0.5,
            min_solidity=join_solidity,
        )
    return rooms, cut


def join_furnished_pieces(
    segments: npt.NDArray[np.int32],
    clutter: npt.NDArray[np.bool_],
    floor: npt.NDArray[np.bool_],
    *,
    resolution_m: float,
    island_max_extent_m: float = 3.0,
    saddle_ratio: float = 0.8,
    solidity: float = 0.8,
) -> npt.NDArray[np.int32]:
    """Step 5 of :func:`segment_rooms`: :func:`join_room_pieces` with ``clutter`` and the obstacle islands at
    most ``island_max_extent_m`` across (:func:`islands` of the pixels in no segment) as the furniture,
    segments mostly on ``floor`` (warehouse floors) never joined. Ids 1..M (consecutive); ``segments`` itself when
    fewer than two segments may join (a rack hall: every segment on a warehouse floor) and its ids are 1..M already."""
    fixed = _share(segments, floor) > 0.5
    if np.count_nonzero(~fixed[1:]) < 2:  # no pair to join: the clearance and the islands are not needed
        return renumber(np.asarray(segments, dtype=np.int32), copy=False)
    # an island has segment pixels all round it: only the box round them (and a pixel more) is labelled
    inside = segments > 0
    rows, cols = np.flatnonzero(inside.any(axis=1)), np.flatnonzero(inside.any(axis=0))
    box = (slice(max(int(rows[0]) - 1, 0), int(rows[-1]) + 2), slice(max(int(cols[0]) - 1, 0), int(cols[-1]) + 2))
    standing = clutter.copy()
    standing[box] |= islands(segments[box] == 0, max_extent_px=island_max_extent_m / resolution_m)
    return join_room_pieces(
        segments,
        standing,
        resolution_m=resolution_m,
        fixed=fixed,
        min_saddle_ratio=saddle_ratio,
        min_solidity=solidity,
    )


def inside_furniture(
    segments: npt.NDArray[np.int32],
    fixed: npt.NDArray[np.bool_],
    *,
    resolution_m: float,
    max_area_m2: float = 1.5,
    island_max_extent_m: float = 3.0,
    reach_m: float = 1.0,
) -> npt.NDArray[np.int32]:
    """Free space inside a piece of furniture is the floor of the room the furniture stands in.

    A segment smaller than ``max_area_m2`` that touches no other segment (8-connected) and that the
    obstacles round it enclose as an island (the parts of the pixels in no segment that touch it, 8-connected,
    with it: off the map border and at most ``island_max_extent_m`` across, as :func:`islands`) is the inside of
    a cupboard or a hollow pillar the laser saw into, not a room anyone enters: it joins the segment nearest to
    it within ``reach_m``. A closet behind a room's wall (the wall reaches farther) keeps its segment; so do
    segments with ``fixed`` (per id) and those with no other segment within reach.
    """
    seg = np.asarray(segments, dtype=np.int32)
    n = int(seg.max()) + 1
    area = label_counts(seg, n)[0]
    small = (area > 0) & (area < max_area_m2 / resolution_m**2) & ~np.asarray(fixed[:n], dtype=bool)
    small[0] = False
    if not small.any():
        return seg
    h, w = seg.shape
    boxes = label_boxes(seg)
    square = np.ones((3, 3), np.uint8)
    rings: dict[int, tuple[tuple[slice, slice], npt.NDArray[np.bool_]]] = {}
    for k in np.flatnonzero(small).tolist():  # alone: nothing but its own pixels and no segment round it
        box = boxes[k - 1]
        if box is None:  # (a small segment has pixels: never)
            continue
        near = (slice(max(0, box[0].start - 1), box[0].stop + 1), slice(max(0, box[1].start - 1), box[1].stop + 1))
        piece = seg[near] == k
        ring = cv2.dilate(piece.view(np.uint8), square).view(bool) & ~piece
        if not np.any(seg[near][ring]):
            rings[k] = near, ring
    lone = np.zeros(n, dtype=bool)
    lone[list(rings)] = True
    extent = round(island_max_extent_m / resolution_m)
    reach = max(1, round(reach_m / resolution_m))
    out = seg.copy()
    for k, (near, ring) in rings.items():
        # the obstacle parts round it, labelled where an island round it can reach
        top, left = max(0, near[0].start - extent), max(0, near[1].start - extent)
        bottom, right = min(h, near[0].stop + extent), min(w, near[1].stop + extent)
        _, parts, stats = components_stats((seg[top:bottom, left:right] == 0).view(np.uint8), 8)
        at_piece = parts[near[0].start - top : near[0].stop - top, near[1].start - left : near[1].stop - left]
        round_it = np.unique(at_piece[ring])
        x0, y0 = stats[round_it, cv2.CC_STAT_LEFT], stats[round_it, cv2.CC_STAT_TOP]
        x1, y1 = x0 + stats[round_it, cv2.CC_STAT_WIDTH], y0 + stats[round_it, cv2.CC_STAT_HEIGHT]
        inner = (x0.min() > 0) and (y0.min() > 0) and (x1.max() < right - left) and (y1.max() < bottom - top)
        # an edge of the labelled window is the map's border or more than the extent away
        if not inner or max(x1.max() - x0.min(), y1.max() - y0.min()) > extent:
            continue
        around = (slice(max(0, near[0].start - reach), near[0].stop + reach),
                  slice(max(0, near[1].start - reach), near[1].stop + reach))
        window = seg[around]
        away = cv2.distanceTransform((window != k).view(np.uint8), cv2.DIST_L2, 5)
        other = (window > 0) & ~lone[window] & (away <= reach)
        if other.any():
            out[around][window == k] = window[other][np.argmin(away[other])]
    return out


def ends_on_tables(
    cuts: npt.NDArray[np.float64],
    blocked: npt.NDArray[np.bool_],
    occupied: npt.NDArray[np.bool_] | None,
    *,
    max_extent_px: float,
    min_thickness_px: float,
    max_elongation: float,
    min_solid: float = 0.3,
    reach_px: int = 2,
    clearance_px: int,
    min_open: float = 0.9,
) -> npt.NDArray[np.bool_]:
    """Per cut ((G, 2, 2): two (x, y) ends): whether an end lies within ``reach_px`` of a table.

    A table is an 8-connected part of ``blocked`` standing free (:func:`islands`: off the map border, at
    most ``max_extent_px`` across) that holds an ``occupied`` cell (the laser hit it: not unknown space
    between rays), is solid (at least ``min_solid`` of it survives an opening with a disc
    ``min_thickness_px`` wide: a dash of wall is thinner) and compact (its minimum-area rectangle at most
    ``max_elongation`` times as long as wide) and stands in a room, not in a doorway: at least ``min_open`` of
    the ring ``clearance_px`` round it is free (not ``blocked``), and what is not free in the ring does not lie
    on two opposite sides of it (jambs; sectors of 30 degrees). Only the parts the cuts end at are looked at.
    """
    flags = np.zeros(len(cuts), dtype=bool)
    rows, cols = np.flatnonzero(~blocked.all(axis=1)), np.flatnonzero(~blocked.all(axis=0))
    if cuts.size == 0 or rows.size == 0:
        return flags
    # an island has free pixels all round it: only the box round the free pixels (and a pixel more) is labelled
    top, left = max(int(rows[0]) - 1, 0), max(int(cols[0]) - 1, 0)
    box = (slice(top, int(rows[-1]) + 2), slice(left, int(cols[-1]) + 2))
    blocked = blocked[box]
    occupied = None if occupied is None else occupied[box]
    labelled = components(blocked)
    parts, stats = labelled.labels, labelled.stats
    h, w = blocked.shape
    offsets = np.arange(-reach_px, reach_px + 1)
    x = np.clip(np.rint(cuts[..., 0]).astype(np.int64)[..., None, None] - left + offsets[None, :], 0, w - 1)
    y = np.clip(np.rint(cuts[..., 1]).astype(np.int64)[..., None, None] - top + offsets[:, None], 0, h - 1)
    at = parts[y, x].reshape(len(cuts), -1)  # the parts within reach of either end
    standing = np.zeros(len(stats), dtype=bool)
    standing[np.unique(at)] = True
    standing &= islands(blocked, max_extent_px=max_extent_px, labelled=labelled, flags=True)
    radius = max(1, round(min_thickness_px / 2))
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))
    ring_disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * clearance_px + 1, 2 * clearance_px + 1))
    for k in np.flatnonzero(standing).tolist():  # the tests in turn, each only for an island that passed the others
        x0, y0, bw, bh = (int(v) for v in stats[k, :4])
        own = (slice(y0, y0 + bh), slice(x0, x0 + bw))
        part = parts[own] == k
        if occupied is not None and not occupied[own][part].any():  # not seen
            standing[k] = False
            continue
        rows, cols = nonzero_rc(part)
        _, (side_a, side_b), _ = cv2.minAreaRect(np.stack([cols, rows], axis=1).astype(np.float32))
        if max(side_a, side_b) + 1 > max_elongation * (min(side_a, side_b) + 1):  # not compact
            standing[k] = False
            continue
        solid = cv2.morphologyEx(np.pad(part, radius).astype(np.uint8), cv2.MORPH_OPEN, disc)
        if np.count_nonzero(solid) < min_solid * rows.size:
            standing[k] = False
            continue
        # floor all round it: not an obstacle standing in a doorway
        y1, x1 = max(y0 - clearance_px, 0), max(x0 - clearance_px, 0)
        around = (slice(y1, y0 + bh + clearance_px), slice(x1, x0 + bw + clearance_px))
        mine = np.zeros(parts[around].shape, dtype=np.uint8)
        mine[y0 - y1 : y0 - y1 + bh, x0 - x1 : x0 - x1 + bw] = part
        ring = cv2.dilate(mine, ring_disc).astype(bool) & ~mine.astype(bool)
        if np.count_nonzero(ring & ~blocked[around]) < min_open * np.count_nonzero(ring):
            standing[k] = False
            continue
        # nor between two jambs: obstacles in the ring on opposite sides of it (sectors of 30 degrees)
        ry, rx = nonzero_rc(ring & blocked[around])
        angle = np.arctan2(ry - rows.mean() - (y0 - y1), rx - cols.mean() - (x0 - x1))
        hit = np.bincount(np.floor((angle + np.pi) / (np.pi / 6)).astype(np.int64) % 12, minlength=12) > 0
        standing[k] = not bool((hit & np.roll(hit, 6)).any())
    return np.asarray(standing[at].any(axis=1), dtype=bool)


def _join_across(
    seg: npt.NDArray[np.int32], cuts: npt.NDArray[np.float64], *, fixed: npt.NDArray[np.bool_], reach_px: int
) -> npt.NDArray[np.int32]:
    """``seg`` with the segments met along each cut's normal through its middle, up to ``reach_px`` each way or the
    first pixel in no segment, one segment (but no fixed one); ids 1..M in order."""
    width = np.linalg.norm(cuts[:, 1] - cuts[:, 0], axis=1)
    u = (cuts[:, 1] - cuts[:, 0]) / np.maximum(width, 1e-9)[:, None]
    normal = np.stack([-u[:, 1], u[:, 0]], axis=1)
    h, w = seg.shape
    t = np.arange(-reach_px, reach_px + 1, dtype=np.float64)
    pts = cuts.mean(axis=1)[:, None, :] + t[None, :, None] * normal[:, None, :]
    x = np.clip(np.rint(pts[..., 0]).astype(np.int64), 0, w - 1)
    y = np.clip(np.rint(pts[..., 1]).astype(np.int64), 0, h - 1)
    ids = seg[y, x].astype(np.int64)  # (G, 2 * reach + 1), the middle at reach_px
    # each way from the middle, only up to the first pixel in no segment
    gone = np.zeros_like(ids, dtype=bool)
    gone[:, reach_px:] = np.cumsum(ids[:, reach_px:] == 0, axis=1) > 0
    gone[:, : reach_px + 1] |= np.cumsum((ids[:, : reach_px + 1] == 0)[:, ::-1], axis=1)[:, ::-1] > 0
    ids[gone | fixed[ids]] = 0
    a, b = ids[:, :-1].ravel(), ids[:, 1:].ravel()
    ok = (a > 0) & (b > 0) & (a != b)
    return join_pairs(seg, a[ok], b[ok])


def _wall_doors(
    cuts: npt.NDArray[np.float64],
    line_doors: npt.NDArray[np.bool_] | None,
    standing: npt.NDArray[np.bool_],
    reach_px: int = 2,
) -> npt.NDArray[np.bool_]:
    """Raster of the doorways between walls, widened by a pixel (the border a doorway leaves runs beside it):
    the doorway cuts with no end within ``reach_px`` of ``standing`` and the gaps closed along lines
    (``line_doors``) that come no nearer to it."""
    size = 2 * reach_px + 1
    near = cv2.dilate(standing.astype(np.uint8), np.ones((size, size), np.uint8)).astype(bool)
    h, w = standing.shape
    ends = np.rint(cuts).astype(np.int64)
    on = near[np.clip(ends[..., 1], 0, h - 1), np.clip(ends[..., 0], 0, w - 1)]
    raster = draw_cuts(cuts[~on.any(axis=1)], (h, w))
    if line_doors is not None and line_doors.any():  # the gaps labelled in the box round them, spread by runs
        rows, cols = np.flatnonzero(line_doors.any(axis=1)), np.flatnonzero(line_doors.any(axis=0))
        box = (slice(int(rows[0]), int(rows[-1]) + 1), slice(int(cols[0]), int(cols[-1]) + 1))
        gaps = components(line_doors[box])
        beside = np.zeros(len(gaps.stats), dtype=bool)
        beside[gaps.labels[near[box]]] = True
        beside[0] = True
        raster[box] |= gaps.spread(~beside)
    return np.asarray(cv2.dilate(raster.astype(np.uint8), np.ones((3, 3), np.uint8)), dtype=bool)


def _outside_rays(
    seg: npt.NDArray[np.int32],
    narrow: npt.NDArray[np.bool_],
    rays: npt.NDArray[np.bool_] | None,
    occupied: npt.NDArray[np.bool_] | None,
    max_ray_share: float,
    min_open_share: float,
    reach_px: int,
) -> npt.NDArray[np.bool_] | None:
    """Per segment id: narrow, mostly on ``rays`` and open on at least ``min_open_share`` of its sides."""
    if rays is None or occupied is None:
        return None
    out = narrow & (_share(seg, rays) > max_ray_share)
    ids = np.flatnonzero(out)
    if ids.size:
        boxes = label_boxes(seg, int(ids.max()))
        middles = np.zeros((ids.size, 2), dtype=np.int64)
        for i, k in enumerate(ids.tolist()):
            box = boxes[k - 1]
            assert box is not None  # a narrow segment has pixels
            rows, cols = nonzero_rc(seg[box] == k)
            j = np.argmin((rows - rows.mean()) ** 2 + (cols - cols.mean()) ** 2)  # its pixel nearest its centroid
            middles[i] = rows[j] + box[0].start, cols[j] + box[1].start
        out[ids] = open_share(occupied, middles, reach_px=reach_px) >= min_open_share
    return out


def open_share(
    occupied: npt.NDArray[np.bool_], points: npt.NDArray[np.int64], *, reach_px: int, n_beams: int = 32
) -> npt.NDArray[np.float64]:
    """(K,) share of ``n_beams`` beams from each (row, col) point that meet no ``occupied`` cell within ``reach_px``.

    Unknown space does not stop a beam; a beam leaving the map escapes.
    """
    angle = np.linspace(0.0, 2 * np.pi, n_beams, endpoint=False)
    step = np.arange(1, max(1, reach_px) + 1, dtype=np.float64)
    rows = np.rint(points[:, 0, None, None] + step[None, None, :] * np.sin(angle)[None, :, None]).astype(np.int64)
    cols = np.rint(points[:, 1, None, None] + step[None, None, :] * np.cos(angle)[None, :, None]).astype(np.int64)
    h, w = occupied.shape
    inside = (rows >= 0) & (rows < h) & (cols >= 0) & (cols < w)
    hit = inside & occupied[np.clip(rows, 0, h - 1), np.clip(cols, 0, w - 1)]
    share: npt.NDArray[np.float64] = 1.0 - hit.any(axis=2).mean(axis=1)
    return share


def islands(
    blocked: npt.NDArray[np.bool_], *, max_extent_px: float, labelled: Components | None = None, flags: bool = False
) -> npt.NDArray[np.bool_]:
    """Parts of ``blocked`` standing free: 8-connected, off the map border, at most ``max_extent_px`` across.

    Chairs, tables and clutter the furniture rule left as obstacles (a cluster of chairs, a large
    table); walls reach farther or touch the map border (the unknown outside). With ``flags``, one flag
    per part of ``labelled`` (or of ``blocked``) instead of the mask.
    """
    labelled = components(blocked) if labelled is None else labelled
    stats = labelled.stats
    h, w = blocked.shape
    x, y = stats[:, cv2.CC_STAT_LEFT], stats[:, cv2.CC_STAT_TOP]
    bw, bh = stats[:, cv2.CC_STAT_WIDTH], stats[:, cv2.CC_STAT_HEIGHT]
    keep = (x > 0) & (y > 0) & (x + bw < w) & (y + bh < h) & (np.maximum(bw, bh) <= max_extent_px)
    keep[0] = False
    return np.asarray(keep if flags else labelled.spread(keep), dtype=bool)


def desk_clusters(
    blocked: npt.NDArray[np.bool_],
    *,
    max_extent_px: float,
    compact_from_px: float,
    max_elongation: float,
    min_thickness_px: float,
    min_solid: float = 0.3,
    small_px: float = 0.0,
    small_extent_px: float = 0.0,
) -> npt.NDArray[np.bool_]:
    """Bulky obstacles standing free in a room: desk clusters, tables, cabinets, chairs; not pieces of wall.

    :func:`islands` up to ``max_extent_px`` across that are small (at most ``small_px`` pixels and
    ``small_extent_px`` across: a chair, a bin; not a dash of wall) or solid (at least
    ``min_solid`` of them survives an opening with a disc ``min_thickness_px`` wide: a desk is
    deeper than a wall is thick, so a T or an L of walls, even thick ones, is not) and, when
    longer than ``compact_from_px``, compact (their minimum-area rectangle at most
    ``max_elongation`` times as long as wide: a row of cupboards along a corridor is long).
    """
    # an island has free pixels all round it: only the box round the free pixels (and a pixel more) is labelled,
    # whose border no island touches (as none touches the map's)
    free = ~blocked
    rows, cols = np.flatnonzero(free.any(axis=1)), np.flatnonzero(free.any(axis=0))
    out = np.zeros(blocked.shape, dtype=bool)
    if rows.size == 0:
        return out
    box = (
        slice(max(int(rows[0]) - 1, 0), int(rows[-1]) + 2),
        slice(max(int(cols[0]) - 1, 0), int(cols[-1]) + 2),
    )
    blocked = blocked[box]
    labelled = components(blocked)
    keep = islands(blocked, max_extent_px=max_extent_px, labelled=labelled)
    parts, stats = labelled.labels, labelled.stats
    radius = max(1, round(min_thickness_px / 2))
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))
    thick = cv2.morphologyEx(keep.astype(np.uint8), cv2.MORPH_OPEN, disc).astype(bool)
    ok = np.bincount(parts[thick], minlength=len(stats)) >= min_solid * np.maximum(stats[:, cv2.CC_STAT_AREA], 1)
    ok |= (stats[:, cv2.CC_STAT_AREA] <= small_px) & (
        np.maximum(stats[:, cv2.CC_STAT_WIDTH], stats[:, cv2.CC_STAT_HEIGHT]) <= small_extent_px
    )
    ok[0] = False
    large = np.zeros(len(stats), dtype=bool)
    large[np.unique(parts[keep])] = True
    large &= ok & (np.maximum(stats[:, cv2.CC_STAT_WIDTH], stats[:, cv2.CC_STAT_HEIGHT]) > compact_from_px)
    for k in np.flatnonzero(large).tolist():
        x, y, bw, bh = (int(v) for v in stats[k, :4])
        rows, cols = nonzero_rc(parts[y : y + bh, x : x + bw] == k)
        _, (side_a, side_b), _ = cv2.minAreaRect(np.stack([cols, rows], axis=1).astype(np.float32))
        ok[k] = max(side_a, side_b) + 1 <= max_elongation * (min(side_a, side_b) + 1)
    out[box] = keep & labelled.spread(ok)
    return out


def free_standing(
    obstacle: npt.NDArray[np.bool_],
    *,
    resolution_m: float,
    max_extent_m: float = 2.0,
    min_clearance_m: float = 0.3,
    labelled: Components | None = None,
) -> npt.NDArray[np.bool_]:
    """Obstacles standing free in a room: :func:`islands` at most ``max_extent_m`` across with floor all round them.

    A desk cluster, a table with its chairs or a pile of boxes is one obstacle too large for
    :func:`furniture`; along a line through it, the gaps between it and the walls looked like
    doorways and cut an open-plan office into pieces. A doorway is an opening in a wall, and an
    obstacle with at least ``min_clearance_m`` of floor between it and every other obstacle is no
    wall. An obstacle closer than that to a wall (a blob of clutter in a doorway, a door frame,
    the end of a dotted wall) is left to the walls.

    Parameters
    ----------
    obstacle : (H, W) bool
        Occupied or unknown cells.
    resolution_m : float
        Metres per cell.
    labelled : Components, optional
        ``components(obstacle)``, when already labelled.

    Returns
    -------
    (H, W) bool
        A subset of ``obstacle``.
    """
    labelled = components(obstacle) if labelled is None else labelled
    isl = islands(obstacle, max_extent_px=max_extent_m / resolution_m, labelled=labelled)
    if not isl.any():
        return isl
    # an island is kept when its least distance to the other obstacles, in metres, reaches the clearance: when
    # none of its pixels falls short of it (the distance transform read only at the islands, as one dilation)
    short = short_of(obstacle & ~isl, resolution_m, min_clearance_m)
    short &= isl
    keep = np.ones(len(labelled.stats), dtype=bool)
    keep[labelled.labels.ravel()[np.flatnonzero(short)]] = False  # an island is a whole component of the obstacles
    keep[0] = False
    return np.asarray(labelled.spread(keep) & isl, dtype=bool)


def _share(segments: npt.NDArray[np.int32], mask: npt.NDArray[np.bool_]) -> npt.NDArray[np.float64]:
    """(N + 1,) share of each segment's pixels inside ``mask``."""
    n = int(segments.max()) + 1
    if not mask.any():  # no warehouse floor (an office): no segment has a share in it
        return np.zeros(n)
    area, inside = label_counts(segments, n, mask)
    share: npt.NDArray[np.float64] = inside / np.maximum(area, 1)
    return share

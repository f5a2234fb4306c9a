"""Occupancy of faces and edges, wall evidence along lines with doorway closing, edge cogency."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import cv2
import numpy as np
import numpy.typing as npt

from services.grid_decomposition.arrays import label_counts
from services.grid_decomposition.doorways import across_a_corridor, block_beside_a_wall, widens
from services.grid_decomposition.subdivision import LineGroup, Subdivision, line_endpoints

DOOR_MIN_PX = 5


class EdgeCogency(NamedTuple):
    """Per-face and per-edge occupancy and the cogency of edges (paper B, section II-D).

    Attributes
    ----------
    face_occupancy : (F + 1,) float64
        ``O(f)``: mean occupancy (occupied and unknown = 1, free = 0) of each face; index 0 unused.
    face_free_px : (F + 1,) int64
        Free pixels per face.
    edge_occupancy : (E,) float64
        ``O(e)``: fraction of the edge's pixels on wall evidence (doorways closed).
    edge_door_px : (E,) int64
        Pixels of the edge on a closed doorway gap.
    cogent : (E,) bool
        ``C(e) = |O(f1) - O(f2)| > t1 or O(e) > t2``; the dual link is connected where False.
    """

    face_occupancy: npt.NDArray[np.float64]
    face_free_px: npt.NDArray[np.int64]
    edge_occupancy: npt.NDArray[np.float64]
    edge_door_px: npt.NDArray[np.int64]
    cogent: npt.NDArray[np.bool_]

    @property
    def door(self) -> npt.NDArray[np.bool_]:
        """(E,) bool: cogent edges holding a closed doorway of at least ``DOOR_MIN_PX`` pixels."""
        return self.cogent & (self.edge_door_px >= DOOR_MIN_PX)


def post_stretches(
    posts: npt.NDArray[np.bool_],
    lo: npt.NDArray[np.int64],
    hi: npt.NDArray[np.int64],
    *,
    post_min_px: int = 1,
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """The free stretches ``[start, end)`` between the posts of each disjoint gap ``[lo, hi)`` of a profile, and the
    gap of each (ascending). A post is a run of at least ``post_min_px`` samples of ``posts`` (a shorter one is the
    rim of a post's tolerance disc that the line only grazes; a gap lies within one line)."""
    size = posts.size
    span = np.zeros(size + 1, dtype=np.int64)
    np.add.at(span, lo, 1)
    np.add.at(span, hi, -1)
    post = np.asarray(posts, dtype=bool)
    if post_min_px > 1:
        p_edge = np.diff(np.r_[0, post.astype(np.int8), 0])
        p_starts, p_ends = np.flatnonzero(p_edge == 1), np.flatnonzero(p_edge == -1)
        short = (p_ends - p_starts) < post_min_px
        grazed = np.zeros(size + 1, dtype=np.int64)
        np.add.at(grazed, p_starts[short], 1)
        np.add.at(grazed, p_ends[short], -1)
        post = post & ~(np.cumsum(grazed)[:-1] > 0)
    free = ~post & (np.cumsum(span)[:-1] > 0)
    edge = np.diff(np.r_[0, free.astype(np.int8), 0])
    run_start, run_end = np.flatnonzero(edge == 1), np.flatnonzero(edge == -1)
    return run_start, run_end, np.searchsorted(lo, run_start, side="right") - 1


def close_doorways(
    profile: npt.NDArray[np.bool_],
    *,
    min_wall_px: int,
    max_door_px: int,
    posts: npt.NDArray[np.bool_] | None = None,
    post_wall_px: int = 0,
    post_min_px: int = 1,
    first: npt.NDArray[np.int64] | None = None,
) -> tuple[npt.NDArray[np.bool_], npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Wall runs of a 1-D occupancy profile and the doorway-sized gaps between them.

    Runs shorter than ``min_wall_px`` (furniture legs, rack uprights) are not walls; gaps of at
    most ``max_door_px`` between two wall runs are candidate doorways. With ``posts`` (small
    obstacles on the line, no wall runs), a wider gap of at most ``2 * max_door_px`` is one too
    when posts in it leave no free stretch wider than ``max_door_px``: two doors side by side
    with a post or door frame between them (a real map draws the post as a speck, no wall), in a
    wall: both wall runs beside such a gap are at least ``post_wall_px`` long. A run across a line
    no longer than a wall is thick is a wall crossing it, not one along it: a line from wall to wall
    across a room through its furniture is no row of doors. A post is one the line passes through: a
    run of at least ``post_min_px`` samples (a line that only grazes the rim of a post's tolerance
    disc, one sample, passes beside it).
    ``first`` (ascending) is where each profile begins when several lines' profiles come one
    after the other: runs and gaps never cross from one line to the next.

    Returns
    -------
    wall : (N,) bool
        The wall runs.
    gap_start, gap_end : (G,) int64
        Candidate doorways ``[gap_start, gap_end)``.
    """
    size = profile.size
    wall = np.zeros(size, dtype=bool)
    if size == 0:
        return wall, np.zeros(0, np.int64), np.zeros(0, np.int64)
    on = np.asarray(profile, dtype=bool)
    line_start = np.zeros(size + 1, dtype=bool)  # one more: the end of the last line
    line_start[0] = line_start[size] = True
    if first is not None:
        line_start[first] = True
    before = np.zeros(size, dtype=bool)
    before[1:] = on[:-1]
    after = np.zeros(size, dtype=bool)
    after[:-1] = on[1:]
    starts = np.flatnonzero(on & ~(before & ~line_start[:-1]))
    ends = np.flatnonzero(on & ~(after & ~line_start[1:])) + 1
    long = (ends - starts) >= min_wall_px
    starts, ends = starts[long], ends[long]
    if starts.size == 0:
        return wall, np.zeros(0, np.int64), np.zeros(0, np.int64)
    cover = np.zeros(size + 1, dtype=np.int64)
    np.add.at(cover, starts, 1)
    np.add.at(cover, ends, -1)
    wall[:] = np.cumsum(cover)[:-1] > 0
    line = np.searchsorted(np.flatnonzero(line_start[:-1]), starts, side="right")
    same = line[1:] == line[:-1]
    gaps = starts[1:] - ends[:-1]
    small = same & (gaps <= max_door_px)
    if posts is not None:
        wide = np.flatnonzero(same & ~small & (gaps <= 2 * max_door_px))
        if wide.size:  # a wide gap split by posts: more than one free stretch, none wider than a door
            lo, hi = ends[wide], starts[wide + 1]  # disjoint: a wall run lies between two gaps
            run_start, run_end, gap_of = post_stretches(posts, lo, hi, post_min_px=post_min_px)
            stretches = np.bincount(gap_of, minlength=wide.size)
            widest = np.zeros(wide.size, dtype=np.int64)
            np.maximum.at(widest, gap_of, run_end - run_start)
            walled = np.minimum(ends[wide] - starts[wide], ends[wide + 1] - starts[wide + 1]) >= post_wall_px
            small[wide] = (stretches > 1) & (widest <= max_door_px) & walled
    return wall, ends[:-1][small].astype(np.int64), starts[1:][small].astype(np.int64)


def _line_samples(
    ends: list[tuple[tuple[int, int], tuple[int, int]]], shape: tuple[int, int]
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Pixels of ``np.rint(np.linspace(x0, x1, n))`` (and y), ``n = int(hypot) + 1``, inside the image, of every line.

    The samples of each line in order, lines one after the other, with each sample's line. Only the
    samples of a range covering the image are computed (the lines reach far beyond it), with
    numpy's linspace expressions: ``i * step + start``, the last one ``stop``.
    """
    h, w = shape
    pieces: list[tuple[int, int, int, float, float, float, float, int, int, int]] = []
    for k, ((x0, y0), (x1, y1)) in enumerate(ends):
        n = int(math.hypot(x1 - x0, y1 - y0)) + 1
        div = n - 1
        sx = float(x1 - x0) / div if div > 0 else 0.0
        sy = float(y1 - y0) / div if div > 0 else 0.0
        lo, hi = 0, n - 1
        for start, step, size in ((x0, sx, w), (y0, sy, h)):
            if step != 0.0:  # inside the image (-1 < value < size) in a range of i, with a margin
                a, b = (-1 - start) / step, (size - start) / step
                lo, hi = max(lo, math.floor(min(a, b)) - 2), min(hi, math.ceil(max(a, b)) + 2)
        if lo <= hi:
            pieces.append((k, lo, hi, float(x0), float(y0), sx, sy, n, x1, y1))
    if not pieces:
        empty = np.zeros(0, np.int64)
        return empty, empty, empty
    k_, lo_, hi_, x0_, y0_, sx_, sy_, n_, x1_, y1_ = (np.array(v) for v in zip(*pieces, strict=True))
    count = hi_ - lo_ + 1
    i = np.arange(int(count.sum())) - np.repeat(np.cumsum(count) - count - lo_, count)
    fi = i.astype(np.float64)
    x = fi * np.repeat(sx_, count) + np.repeat(x0_, count)
    y = fi * np.repeat(sy_, count) + np.repeat(y0_, count)
    # the last sample of a line is its end (linspace's endpoint), where the range reaches it
    last = np.cumsum(count)[(hi_ == n_ - 1) & (n_ > 1)] - 1
    has_last = (hi_ == n_ - 1) & (n_ > 1)
    x[last], y[last] = x1_[has_last], y1_[has_last]
    xs, ys = np.rint(x).astype(np.int64), np.rint(y).astype(np.int64)
    inside = (xs.view(np.uint64) < w) & (ys.view(np.uint64) < h)  # negative ones too
    return xs[inside], ys[inside], np.repeat(k_, count)[inside]


def wall_evidence(
    occupied: npt.NDArray[np.bool_],
    groups: Sequence[LineGroup],
    *,
    tolerance_px: int,
    min_wall_px: int,
    max_door_px: int,
    widening_px: int,
    max_depth_px: int,
    posts: npt.NDArray[np.bool_] | None = None,
    post_wall_px: int = 0,
    post_min_px: int = 1,
    corridor_length_px: int = 0,
    hit: npt.NDArray[np.bool_] | None = None,
    max_thickness_px: int = 0,
    block_max_run_px: int = 0,
    side_by_side_out: npt.NDArray[np.bool_] | None = None,
) -> tuple[npt.NDArray[np.bool_], npt.NDArray[np.bool_]]:
    """Rasters of wall evidence and closed doorways along every line.

    Along each line the wall mask (dilated by ``tolerance_px``, so slightly crooked walls still
    sit on their line) is read as a 1-D profile; doorway-sized gaps between wall runs
    (:func:`close_doorways`) are closed when the free space behind them widens by at least
    ``widening_px`` on both sides within ``max_depth_px`` of the line (a doorway between rooms);
    a gap that stays as narrow on one side is a corridor or a passage between blocks, left open,
    and so is a gap across a corridor that widens only through the doors in its side walls
    (with ``corridor_length_px`` > 0, :func:`~services.grid_decomposition.doorways.across_a_corridor`).
    With both, a gap split by posts into doors side by side is left open when a part of it from
    post to post lies across a corridor: doors side by side are doors of one wall, and a corridor's
    width is no door (a line from a room's floor through its door and on across the corridor). And doors side by side
    are doors: a gap split by posts is left open when behind none of its stretches between posts at least
    ``min_wall_px`` wide the floor widens on both sides with the posts in the way (:func:`widens` with ``posts`` as
    its furniture): the line of a side wall drawn on across a corridor into the hall it opens onto, the hall's
    furniture beside the line taken for posts.

    Parameters
    ----------
    occupied : (H, W) bool
        Walls: occupied and unknown cells without furniture.
    groups : sequence of LineGroup
    tolerance_px, min_wall_px, max_door_px, widening_px, max_depth_px : int
        Pixels.
    posts : (H, W) bool, optional
        Free-standing obstacles (furniture, specks): posts between doors (:func:`close_doorways`).
    post_wall_px : int
        The wall runs beside doors split by posts are at least this long (:func:`close_doorways`).
    post_min_px : int
        A post splits a gap when the line runs through it for at least this many samples (:func:`close_doorways`).
    corridor_length_px : int
        See :func:`~services.grid_decomposition.doorways.across_a_corridor`; 0 turns it off.
    hit, max_thickness_px, block_max_run_px : (H, W) bool, int, int
        With ``hit`` (the occupied cells) and ``block_max_run_px`` > 0, a gap between a wall running straight past
        one end and a block at the other (thicker than ``max_thickness_px`` across the line, ending along it within
        ``block_max_run_px``, hit by the laser) is left open
        (:func:`~services.grid_decomposition.doorways.block_beside_a_wall`): a cupboard or table standing out into
        a room is no jamb.
    side_by_side_out : (H, W) bool, optional
        Set where a gap split by posts was left open because the floor widens behind none of its stretches (the line
        pixels, dilated by one pixel as ``wall``): a line across open floor between furniture.

    Returns
    -------
    wall, door : (H, W) bool
        Line pixels (dilated by one pixel) lying on wall evidence, and those on a closed doorway.
    """
    h, w = occupied.shape
    k = 2 * tolerance_px + 1
    disk = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k))
    near = cv2.dilate(occupied.astype(np.uint8), disk) > 0
    # posts within a round disc of the tolerance: the 5 x 5 "ellipse" reaches 2 px across a line over 3 samples on
    # two of its sides and over 1 on the other two, a round disc over 1 on all four (a rim the line only grazes)
    across, along = np.mgrid[-tolerance_px : tolerance_px + 1, -tolerance_px : tolerance_px + 1]
    round_disk = (across * across + along * along <= tolerance_px * tolerance_px).astype(np.uint8)
    near_post = None if posts is None else cv2.dilate(posts.astype(np.uint8), round_disk) > 0
    wall = np.zeros((h, w), dtype=bool)
    door = np.zeros((h, w), dtype=bool)
    # every line's pixels at once (lines in order, each from one end to the other), each line clipped to its
    # group's mask; the profiles one after the other, closed in one call: runs and gaps stay within a line
    lines = [(g, line) for g, group in enumerate(groups) for line in group.lines]
    xs, ys, of = _line_samples([line_endpoints(line, (h, w)) for _, line in lines], (h, w))
    group_of = np.array([g for g, _ in lines], dtype=np.int64)[of] if lines else of
    keep = np.ones(xs.size, dtype=bool)
    for g, group in enumerate(groups):
        if group.mask is not None:
            mine = np.flatnonzero(group_of == g)
            keep[mine] = group.mask[ys[mine], xs[mine]]
    xs, ys, of = xs[keep], ys[keep], of[keep]
    first = np.flatnonzero(np.r_[True, of[1:] != of[:-1]]) if of.size else of
    post_profile = None if near_post is None else near_post[ys, xs]
    on_wall, g0, g1 = close_doorways(
        near[ys, xs], min_wall_px=min_wall_px, max_door_px=max_door_px,
        posts=post_profile, post_wall_px=post_wall_px, post_min_px=post_min_px, first=first,
    )
    wall[ys[on_wall], xs[on_wall]] = True
    if g0.size:  # every line's gaps in one call: each gap's answer is its own
        ends = np.stack(
            [np.stack([xs[g0], ys[g0]], axis=1), np.stack([xs[g1 - 1], ys[g1 - 1]], axis=1)], axis=1
        ).astype(np.float64)
        doorway = widens(
            near,
            ends,
            widening_px=widening_px,
            max_depth_px=max_depth_px + tolerance_px,
            depth_step_px=max(1, max_depth_px // 4),
            corridor_length_px=corridor_length_px,
        )
        if hit is not None and block_max_run_px > 0 and doorway.any():
            # a cupboard standing out beside a side wall is no jamb (walls and hits widened by the lines' tolerance)
            doorway[doorway] = ~block_beside_a_wall(
                near, ends[doorway], hit=cv2.dilate(hit.astype(np.uint8), disk) > 0, run_px=min_wall_px,
                max_thickness_px=max_thickness_px + 2 * tolerance_px, max_run_px=block_max_run_px,
                tolerance_px=tolerance_px, max_depth_px=max_depth_px, depth_step_px=max(1, max_depth_px // 4),
                widening_px=widening_px, corridor_length_px=corridor_length_px,
            )
        split = np.flatnonzero(doorway & (g1 - g0 > max_door_px))
        if post_profile is not None and corridor_length_px > 0 and split.size:
            # doors side by side are doors of one wall: no part of the gap from post to post spans a corridor's
            # width (a line from a room's floor through its door and across the corridor beyond, specks in it)
            r0, r1, of_run = post_stretches(post_profile, g0[split], g1[split], post_min_px=post_min_px)
            i, j = np.triu_indices(r0.size)
            same = of_run[i] == of_run[j]
            s0, s1, of_gap = r0[i[same]], r1[j[same]], of_run[i[same]]
            stretch_ends = np.stack(
                [np.stack([xs[s0], ys[s0]], axis=1), np.stack([xs[s1 - 1], ys[s1 - 1]], axis=1)], axis=1
            ).astype(np.float64)
            corridor = across_a_corridor(near, stretch_ends, widening_px=widening_px, length_px=corridor_length_px)
            doorway[split[np.unique(of_gap[corridor])]] = False
        split = np.flatnonzero(doorway & (g1 - g0 > max_door_px))
        if post_profile is not None and near_post is not None and split.size:
            # doors side by side are doors: behind at least one stretch between the posts that one can pass (at least
            # a wall's least run wide) the floor widens on both sides, its furniture and posts in the way. Where none
            # does, the line crosses open floor between furniture: a side wall's line drawn on across a corridor into
            # the hall it opens onto, each stretch between a wall or a block the line runs along and the next block
            r0, r1, of_run = post_stretches(post_profile, g0[split], g1[split], post_min_px=post_min_px)
            passable = r1 - r0 >= min_wall_px
            r0, r1, of_run = r0[passable], r1[passable], of_run[passable]
            stretch_ends = np.stack(
                [np.stack([xs[r0], ys[r0]], axis=1), np.stack([xs[r1 - 1], ys[r1 - 1]], axis=1)], axis=1
            ).astype(np.float64)
            door_like = widens(
                near, stretch_ends, widening_px=widening_px, max_depth_px=max_depth_px + tolerance_px,
                depth_step_px=max(1, max_depth_px // 4), furniture=near_post,
            )
            judged = np.bincount(of_run, minlength=split.size) > 0
            failed = split[judged & (np.bincount(of_run[door_like], minlength=split.size) == 0)]
            doorway[failed] = False
            if side_by_side_out is not None and failed.size:
                span = np.zeros(xs.size + 1, dtype=np.int64)
                np.add.at(span, g0[failed], 1)
                np.add.at(span, g1[failed], -1)
                crossed = np.cumsum(span)[:-1] > 0
                side_by_side_out[ys[crossed], xs[crossed]] = True
        cover = np.zeros(xs.size + 1, dtype=np.int64)
        np.add.at(cover, g0[doorway], 1)
        np.add.at(cover, g1[doorway], -1)
        opened = np.cumsum(cover)[:-1] > 0
        wall[ys[opened], xs[opened]] = True
        door[ys[opened], xs[opened]] = True
    kernel = np.ones((3, 3), np.uint8)
    solid = cv2.dilate((wall & ~door).astype(np.uint8), kernel) > 0
    wall = cv2.dilate(wall.astype(np.uint8), kernel) > 0
    door = (cv2.dilate(door.astype(np.uint8), kernel) > 0) & ~(solid & occupied)
    if side_by_side_out is not None and side_by_side_out.any():
        side_by_side_out[:] = cv2.dilate(side_by_side_out.astype(np.uint8), kernel) > 0
    return wall, door


def edge_cogency(
    sub: Subdivision,
    occupancy: npt.NDArray[np.int16],
    free: npt.NDArray[np.bool_],
    wall: npt.NDArray[np.bool_],
    door: npt.NDArray[np.bool_],
    *,
    face_disparity_threshold: float = 0.5,
    edge_occupancy_threshold: float = 0.5,
) -> EdgeCogency:
    """Occupancy of faces and edges and the cogency of every edge.

    Parameters
    ----------
    sub : Subdivision
    occupancy : (H, W) int16
        Occupancy percent, -1 unknown (counted as 100).
    free : (H, W) bool
    wall, door : (H, W) bool
        From :func:`wall_evidence`.
    face_disparity_threshold, edge_occupancy_threshold : float
        ``t1`` and ``t2`` of paper B.
    """
    faces = sub.face_image.ravel()
    n = sub.n_faces + 1
    count, free_px = label_counts(sub.face_image, n, free)
    area = count.astype(np.float64)
    # a face's sum of its pixels' occupancy in [0, 1] in raster order, as bincount adds them, without the zeros (adding
    # 0.0 changes no sum: the same bits), each the percent / 100 (unknown 1) at those pixels alone: no float image;
    # face 0 (lines and obstacles) is set to 1 below
    grid = occupancy.ravel()
    some = np.flatnonzero((faces > 0) & (grid != 0))
    percent = grid[some]
    occ_sum = np.bincount(faces[some], weights=np.where(percent < 0, 1.0, percent / 100.0), minlength=n)
    face_occ = np.divide(occ_sum, area, out=np.ones(n), where=area > 0)
    free_px[0] = 0
    face_occ[0] = 1.0
    e_n = np.diff(sub.edge_starts)
    edge_index = np.repeat(np.arange(sub.n_edges), e_n)
    e_wall = np.bincount(edge_index, weights=wall.ravel()[sub.edge_pixels], minlength=sub.n_edges)
    e_door = np.bincount(edge_index, weights=door.ravel()[sub.edge_pixels], minlength=sub.n_edges)
    safe = np.maximum(e_n, 1)
    edge_occ = e_wall / safe
    a, b = sub.edge_faces[:, 0], sub.edge_faces[:, 1]
    disparity = np.abs(face_occ[a] - face_occ[b])
    cogent = (disparity > face_disparity_threshold) | (edge_occ > edge_occupancy_threshold)
    return EdgeCogency(face_occ, free_px, edge_occ, e_door.astype(np.int64), cogent)

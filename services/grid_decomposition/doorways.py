"""Doorways found from the free space itself, whatever the decomposition lines: narrow passages between walls."""

from __future__ import annotations

import math

import cv2
import numpy as np
import numpy.typing as npt

from services.grid_decomposition.arrays import nonzero_rc


def _centre_runs(
    blocked: npt.NDArray[np.bool_],
    points: npt.NDArray[np.float64],
    direction: npt.NDArray[np.float64],
    reach_px: int,
) -> npt.NDArray[np.int64]:
    """Length of the unblocked run through each point along its direction (0 where the point is blocked).

    Parameters
    ----------
    blocked : (H, W) bool
    points : (..., 2) float64
        (x, y) pixels.
    direction : (..., 2) float64
        Unit (x, y) direction per point (broadcast against ``points``).
    reach_px : int
        Runs are counted up to this many pixels each way.
    """
    h, w = blocked.shape
    flat = np.ascontiguousarray(blocked).ravel()
    shape = np.broadcast_shapes(points.shape, direction.shape)[:-1]
    px, py = (np.broadcast_to(points[..., i], shape).ravel() for i in (0, 1))
    dx, dy = (np.broadcast_to(direction[..., i], shape).ravel() for i in (0, 1))
    run = np.full(px.size, -1, dtype=np.int64)
    # each way from the point, the first stop (a blocked or off-image sample) at 0, 1, 2, ... steps, else
    # reach_px + 1: looked for in ever longer stretches, only for the points not stopped yet (the samples are the
    # same floats as along the whole reach at once)
    for sign in (1.0, -1.0):
        first = np.full(px.size, reach_px + 1, dtype=np.int64)
        todo = np.arange(px.size)
        begin, length = 0, 8
        while todo.size and begin <= reach_px:
            t = sign * np.arange(begin, min(begin + length, reach_px + 1), dtype=np.float64)
            # the samples' whole-number columns and rows, in place, then the flat index from them in float64 (whole
            # numbers far below 2**53: the same integers)
            x = np.multiply(t, dx[todo, None])
            x += px[todo, None]
            np.rint(x, out=x)
            y = np.multiply(t, dy[todo, None])
            y += py[todo, None]
            np.rint(y, out=y)
            stop = x >= 0  # off the image (or not a number) a sample is a stop whatever it reads
            stop &= x < w
            stop &= y >= 0
            stop &= y < h
            np.logical_not(stop, out=stop)
            y *= w
            y += x  # the index is only kept in the image
            stop |= np.take(flat, y.astype(np.int64), mode="clip")
            step = np.argmax(stop, axis=1)  # the first stop, or 0 where there is none
            hit = stop[np.arange(todo.size), step]
            first[todo[hit]] = begin + step[hit]
            todo = todo[~hit]
            begin, length = begin + t.size, 2 * length
        run += first
    out: npt.NDArray[np.int64] = np.maximum(run, 0).reshape(shape)
    return out


def _gap_frame(
    ends: npt.NDArray[np.float64],
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Width, unit direction along, unit normal and middle of each gap ``ends`` (G, 2, 2)."""
    span = ends[:, 1] - ends[:, 0]
    width = np.linalg.norm(span, axis=1)
    u = span / np.maximum(width, 1e-9)[:, None]
    normal = np.stack([-u[:, 1], u[:, 0]], axis=1)
    return width, u, normal, ends.mean(axis=1)


def widens(
    blocked: npt.NDArray[np.bool_],
    ends: npt.NDArray[np.float64],
    *,
    widening_px: float,
    max_depth_px: int,
    depth_step_px: int,
    clearance: npt.NDArray[np.floating] | None = None,
    room_margin_px: float = 0.0,
    corridor_length_px: int = 0,
    furniture: npt.NDArray[np.bool_] | None = None,
) -> npt.NDArray[np.bool_]:
    """Gaps behind which the free space widens on both sides: doorways, not corridors or passages.

    On each side of a gap, at depths ``depth_step_px, 2 * depth_step_px, ... <= max_depth_px``
    along its normal (past the thickness of the wall it pierces), the free run through the gap's
    middle parallel to the gap is measured. A doorway opens on both sides into space at least
    ``widening_px`` wider than itself; a corridor crossing the gap, or a passage between blocks,
    stays as narrow on one side. With ``clearance``, the space on each side must also hold a
    disc wider than the gap by ``room_margin_px`` on its radius, reached straight along the
    normal (a parallel run can leak through another doorway of a corridor; a disc cannot).
    With ``corridor_length_px`` > 0, a gap across a stretch of corridor is no doorway either
    (:func:`across_a_corridor`): a run that widens only through a door in the corridor's side
    wall, or a notch of a ragged wall, does not make the corridor a doorway. With ``furniture``,
    the runs stop at it too (the floor's width beside the gap, furniture standing on it), while
    the depth reached along the normal is the walls' (a path passes beside a table).

    Parameters
    ----------
    blocked : (H, W) bool
        Walls.
    ends : (G, 2, 2) float64
        The two ends (x, y) of each gap, pixels.
    clearance : (H, W) float, optional
        Distance to the nearest wall, pixels.
    furniture : (H, W) bool, optional
        Obstacles standing on the floor: they bound the runs, not the depth reached.

    Returns
    -------
    (G,) bool
    """
    if len(ends) == 0:
        return np.zeros(0, dtype=bool)
    width, u, normal, mid = _gap_frame(ends)
    need = width + widening_px
    depths = np.arange(depth_step_px, max_depth_px + 1, depth_step_px, dtype=np.float64)
    reach = math.ceil(float(need.max())) + 1
    door = np.ones(len(ends), dtype=bool)
    bounds = blocked if furniture is None else blocked | furniture
    for sign in (1.0, -1.0):
        reachable = _free_depth(blocked, mid, sign * normal, max_depth_px)
        points = mid[:, None, :] + sign * depths[None, :, None] * normal[:, None, :]
        runs = _centre_runs(bounds, points, np.broadcast_to(u[:, None, :], points.shape), reach)
        runs[depths[None, :] > reachable[:, None]] = 0
        door &= runs.max(axis=1) >= need
    if clearance is not None:
        door &= _room_on_both_sides(blocked, clearance, mid, normal, width / 2.0 + room_margin_px, max_depth_px)
    if corridor_length_px > 0 and door.any():
        door[door] = ~across_a_corridor(blocked, ends[door], widening_px=widening_px, length_px=corridor_length_px)
    return door


def across_a_corridor(
    blocked: npt.NDArray[np.bool_],
    ends: npt.NDArray[np.float64],
    *,
    widening_px: float,
    length_px: int,
    length_ratio: float = 1.5,
    max_wide_share: float = 0.7,
    step_px: int = 2,
    chunk: int = 256,
) -> npt.NDArray[np.bool_]:
    """(G,) bool: gaps across a stretch of corridor, not doorways.

    On both sides of the gap the free space goes on straight along its normal for at least
    ``length_px`` (and ``length_ratio`` times the gap's width: a band longer than it is wide),
    and over that length the free run through the gap's middle parallel to the gap reaches the
    gap's width plus ``widening_px`` at fewer than ``max_wide_share`` of the depths (every
    ``step_px``): the space behind the gap is a band about as wide as the gap, a corridor, and
    where it widens it does so through openings in its side walls (office doors, a notch of a
    ragged wall), not into a room. A doorway opens into a room or crosses a corridor's wall: on
    at least one side the space is wider than the gap over most of its depth, or it ends.

    Parameters
    ----------
    blocked : (H, W) bool
        Walls.
    ends : (G, 2, 2) float64
        The two ends (x, y) of each gap, pixels.
    """
    if len(ends) == 0:
        return np.zeros(0, dtype=bool)
    width, u, normal, mid = _gap_frame(ends)
    length = np.maximum(float(length_px), np.ceil(length_ratio * width))
    # the band goes on straight along the normal on both sides (a cheap test first: most gaps fail it)
    out = np.ones(len(ends), dtype=bool)
    for sign in (1.0, -1.0):
        out &= _free_depth(blocked, mid, sign * normal, int(length.max())) >= length
    candidates = np.flatnonzero(out)
    for first in range(0, candidates.size, chunk):
        at = candidates[first : first + chunk]
        for sign in (1.0, -1.0):
            out[at] &= _narrow_behind(blocked, width[at] + widening_px, u[at], sign * normal[at], mid[at], length[at],
                                      max_wide_share=max_wide_share, step_px=step_px)
    return out


def _narrow_behind(
    blocked: npt.NDArray[np.bool_],
    need: npt.NDArray[np.float64],
    u: npt.NDArray[np.float64],
    direction: npt.NDArray[np.float64],
    mid: npt.NDArray[np.float64],
    length: npt.NDArray[np.float64],
    *,
    max_wide_share: float,
    step_px: int,
) -> npt.NDArray[np.bool_]:
    """(G,) bool: going from each gap's middle along ``direction`` (every ``step_px`` up to its ``length``), the free
    run through the middle parallel to the gap (along ``u``) reaches ``need`` at fewer than ``max_wide_share`` of
    the depths: the space behind the gap is a band no wider than that over most of its length."""
    depths = np.arange(step_px, float(length.max()) + 1, step_px, dtype=np.float64)
    inside = depths[None, :] <= length[:, None]
    points = mid[:, None, :] + depths[None, :, None] * direction[:, None, :]
    runs = _centre_runs(blocked, points, np.broadcast_to(u[:, None, :], points.shape), math.ceil(float(need.max())) + 1)
    wide = (runs >= need[:, None]) & inside
    return np.asarray(wide.sum(axis=1) < max_wide_share * inside.sum(axis=1))


def _room_on_both_sides(
    blocked: npt.NDArray[np.bool_],
    clearance: npt.NDArray[np.floating],
    mid: npt.NDArray[np.float64],
    normal: npt.NDArray[np.float64],
    radius_px: npt.NDArray[np.float64],
    max_depth_px: int,
) -> npt.NDArray[np.bool_]:
    """(G,) bool: straight ahead and behind each gap, within its radius plus ``max_depth_px``, the clearance
    reaches ``radius_px``."""
    h, w = blocked.shape
    reach = math.ceil(float(radius_px.max())) + max_depth_px
    t = np.arange(1, reach + 1, dtype=np.float64)
    ok = np.ones(len(mid), dtype=bool)
    for sign in (1.0, -1.0):
        seen = _free_depth(blocked, mid, sign * normal, reach)
        pts = mid[:, None, :] + sign * t[None, :, None] * normal[:, None, :]
        x = np.clip(np.rint(pts[..., 0]).astype(np.int64), 0, w - 1)
        y = np.clip(np.rint(pts[..., 1]).astype(np.int64), 0, h - 1)
        room = np.where(
            (t[None, :] <= seen[:, None]) & (t[None, :] <= radius_px[:, None] + max_depth_px), clearance[y, x], 0.0
        )
        ok &= room.max(axis=1) >= radius_px
    return ok


def _free_depth(
    blocked: npt.NDArray[np.bool_], points: npt.NDArray[np.float64], direction: npt.NDArray[np.float64], max_px: int
) -> npt.NDArray[np.float64]:
    """(N,) how far, in pixels, each point sees free space along its direction (up to ``max_px``)."""
    h, w = blocked.shape
    t = np.arange(0, max_px + 1, dtype=np.float64)
    # the samples' whole-number columns and rows (the same floats as of (N, T, 2) points), in place, and their flat
    # index in float64 (whole numbers far below 2**53)
    x = np.multiply(t, direction[:, 0, None])
    x += points[:, 0, None]
    np.rint(x, out=x)
    y = np.multiply(t, direction[:, 1, None])
    y += points[:, 1, None]
    np.rint(y, out=y)
    stop = np.ones((len(points), t.size + 1), dtype=bool)  # a stop after the last sample
    inside = stop[:, :-1]
    np.greater_equal(x, 0, out=inside)
    inside &= x < w
    inside &= y >= 0
    inside &= y < h
    y *= w
    y += x
    # off the image (or not a number) a sample is a stop whatever it reads: the index is only kept in the image
    np.logical_not(inside, out=inside)
    inside |= np.take(np.ascontiguousarray(blocked).ravel(), y.astype(np.int64), mode="clip")
    depth: npt.NDArray[np.float64] = np.argmax(stop, axis=1).astype(np.float64) - 1.0
    return depth


def find_doorways(
    space: npt.NDArray[np.bool_],
    *,
    resolution_m: float,
    min_width_m: float = 0.5,
    max_width_m: float = 2.5,
    widening_m: float = 0.3,
    max_depth_m: float = 1.0,
    straightness: float = 0.9,
    wall_run_m: float = 0.5,
    wall_share: float = 0.9,
    max_wall_thickness_m: float = 0.6,
    neck_reach_m: float = 0.5,
    neck_tolerance_m: float = 0.05,
    room_margin_m: float = 0.0,
    corridor_length_m: float = 2.0,
    bump_max_m: float = 0.6,
    flush_tolerance_m: float = 0.1,
    hit: npt.NDArray[np.bool_] | None = None,
    block_max_run_m: float = 1.5,
) -> npt.NDArray[np.float64]:
    """Doorways of a floor: cuts across the narrow passages between walls, independent of any line.

    Every pair of neighbouring pixels whose nearest walls lie on opposite sides (their feature
    points are about as far apart as the two clearances add up to: the medial axis between two
    facing walls or wall ends) proposes the cut between those two wall points. A cut
    ``min_width_m``..``max_width_m`` long is a doorway when it is a neck, it continues a thin
    wall, and behind it on both sides the free space widens and holds a room at least as wide as
    the cut (:func:`widens`); along a corridor, across a bend, or from a wall end across a room it
    is not.

    Parameters
    ----------
    space : (H, W) bool
        Free space with furniture counted free; everything else is wall.
    resolution_m : float
        Metres per pixel.
    wall_run_m, wall_share : float
        A doorway continues a wall: beyond at least one of its ends, ``wall_share`` of the next
        ``wall_run_m`` along the cut is wall (the door's own wall; a cut from a wall end across
        a room to the facing wall leaves that wall at an angle).
    max_wall_thickness_m : float
        ... and that wall is at most this thick across the cut (a cut from the corner of a
        cabinet or block across a corridor continues no wall).
    room_margin_m : float
        On both sides the doorway opens into a room holding a disc of radius half its width
        plus this (:func:`widens`).
    neck_reach_m, neck_tolerance_m : float
        A doorway is a neck: up to ``neck_reach_m`` ahead and behind it (along its normal) the
        clearance does not drop more than ``neck_tolerance_m`` below its own (a cut across a
        corridor that narrows on one side, or across a bend, is no neck).
    straightness : float
        Minimum ratio of the feature points' distance to the sum of the two clearances (1 for
        walls facing each other straight across; a room corner's bisector is about 0.7).
    corridor_length_m : float
        A cut across a corridor, whose space goes on as a band about as wide as the cut for this
        long on both sides, is no doorway (:func:`across_a_corridor`); 0 turns it off.
    bump_max_m, flush_tolerance_m : float
        A cut across a strip that an obstacle against one wall narrows is no doorway (:func:`bumps_a_strip`): on
        both sides, up to ``max_depth_m`` from the cut, the strip's one wall runs on in line with one end of the cut
        (within ``flush_tolerance_m``) and its other wall lies at most ``bump_max_m`` beyond the other end (furniture
        or a bin against a wall, as deep as a wall is thick); 0 turns it off.
    hit, block_max_run_m : (H, W) bool, float
        With ``hit`` (the occupied cells), a cut between a wall running straight past one end (within
        ``flush_tolerance_m``) and a block at the other (thicker than ``max_wall_thickness_m`` over the next
        ``wall_run_m``, ending along the cut within ``block_max_run_m``, hit by the laser) is no doorway
        (:func:`block_beside_a_wall`): a cupboard or table standing out into a room; 0 turns it off.

    Returns
    -------
    (K, 2, 2) float64
        The two wall points (x, y) pixels of each doorway cut.
    """
    if space.all() or not space.any():
        return np.zeros((0, 2, 2))
    rows, cols = np.flatnonzero(space.any(axis=1)), np.flatnonzero(space.any(axis=0))
    r0, c0 = max(int(rows[0]) - 1, 0), max(int(cols[0]) - 1, 0)
    crop = (slice(r0, int(rows[-1]) + 2), slice(c0, int(cols[-1]) + 2))
    return _find_doorways(
        space[crop],
        resolution_m=resolution_m,
        min_width_m=min_width_m,
        max_width_m=max_width_m,
        widening_m=widening_m,
        max_depth_m=max_depth_m,
        straightness=straightness,
        wall_run_m=wall_run_m,
        wall_share=wall_share,
        max_wall_thickness_m=max_wall_thickness_m,
        neck_reach_m=neck_reach_m,
        neck_tolerance_m=neck_tolerance_m,
        room_margin_m=room_margin_m,
        corridor_length_m=corridor_length_m,
        bump_max_m=bump_max_m,
        flush_tolerance_m=flush_tolerance_m,
        hit=None if hit is None or block_max_run_m <= 0 else hit[crop],
        block_max_run_m=block_max_run_m,
    ) + np.array([c0, r0], dtype=np.float64)


def _find_doorways(
    space: npt.NDArray[np.bool_],
    *,
    resolution_m: float,
    min_width_m: float,
    max_width_m: float,
    widening_m: float,
    max_depth_m: float,
    straightness: float,
    wall_run_m: float,
    wall_share: float,
    max_wall_thickness_m: float,
    neck_reach_m: float,
    neck_tolerance_m: float,
    room_margin_m: float,
    corridor_length_m: float,
    bump_max_m: float,
    flush_tolerance_m: float,
    hit: npt.NDArray[np.bool_] | None,
    block_max_run_m: float,
) -> npt.NDArray[np.float64]:
    """:func:`find_doorways` on a crop around the free space (a wall border of at least one pixel)."""
    dist, wall_x, wall_y = _nearest_walls(space, reach_px=math.ceil(max_width_m / resolution_m) + 2)
    lo, hi = min_width_m / resolution_m, max_width_m / resolution_m
    h, w = space.shape
    band = space & (dist >= lo / 2 - 1) & (dist <= hi / 2 + 1)
    cuts: list[npt.NDArray[np.float64]] = []
    for dy, dx in ((0, 1), (1, 0)):
        rows, cols = nonzero_rc(band[: h - dy, : w - dx] & space[dy:, dx:])
        at, next_at = rows * w + cols, (rows + dy) * w + cols + dx
        span_x, span_y = wall_x[at] - wall_x[next_at], wall_y[at] - wall_y[next_at]
        # whole-pixel squared lengths a unit off the bounds cannot pass them: only the others are measured
        span = span_x * span_x + span_y * span_y
        near = np.flatnonzero((span >= lo * lo - 1) & (span <= hi * hi + 1))
        rows, cols, at, next_at = rows[near], cols[near], at[near], next_at[near]
        p = np.stack([wall_x[at], wall_y[at]], axis=1).astype(np.float64)
        q = np.stack([wall_x[next_at], wall_y[next_at]], axis=1).astype(np.float64)
        sep = np.hypot(*(p - q).T)
        clear = dist[rows, cols] + dist[rows + dy, cols + dx]
        ok = (sep >= lo) & (sep <= hi) & (sep >= straightness * clear)
        cuts.append(np.stack([p[ok], q[ok]], axis=1))
    pairs = np.concatenate(cuts)
    if len(pairs) == 0:
        return np.zeros((0, 2, 2))
    swap = (pairs[:, 0, 0] > pairs[:, 1, 0]) | ((pairs[:, 0, 0] == pairs[:, 1, 0]) & (pairs[:, 0, 1] > pairs[:, 1, 1]))
    pairs[swap] = pairs[swap, ::-1]
    # np.unique(axis=0) of whole non-negative pixel coordinates: one sort of a key in the same order
    x0, y0, x1, y1 = pairs.reshape(-1, 4).astype(np.int64).T
    pairs = pairs[np.unique(((x0 * h + y0) * w + x1) * h + y1, return_index=True)[1]]
    walls = ~space
    pairs = pairs[_is_neck(dist, pairs, round(neck_reach_m / resolution_m), neck_tolerance_m / resolution_m)]
    keep = _extends_a_wall(
        walls, pairs, round(wall_run_m / resolution_m), wall_share, round(max_wall_thickness_m / resolution_m)
    )
    pairs = pairs[keep]
    keep = widens(
        walls,
        pairs,
        widening_px=widening_m / resolution_m,
        max_depth_px=max(1, round(max_depth_m / resolution_m)),
        depth_step_px=max(1, round(max_depth_m / resolution_m / 4)),
        clearance=dist,
        room_margin_px=room_margin_m / resolution_m,
        corridor_length_px=round(corridor_length_m / resolution_m),
    )
    pairs = pairs[keep]
    if bump_max_m > 0 and len(pairs):
        pairs = pairs[
            ~bumps_a_strip(
                walls,
                pairs,
                bump_px=bump_max_m / resolution_m,
                tolerance_px=flush_tolerance_m / resolution_m,
                max_depth_px=max(1, round(max_depth_m / resolution_m)),
                depth_step_px=max(1, round(max_depth_m / resolution_m / 4)),
            )
        ]
    if hit is not None and len(pairs):
        pairs = pairs[
            ~block_beside_a_wall(
                walls,
                pairs,
                hit=hit,
                run_px=round(wall_run_m / resolution_m),
                max_thickness_px=round(max_wall_thickness_m / resolution_m),
                max_run_px=round(block_max_run_m / resolution_m),
                tolerance_px=flush_tolerance_m / resolution_m,
                max_depth_px=max(1, round(max_depth_m / resolution_m)),
                depth_step_px=max(1, round(max_depth_m / resolution_m / 4)),
                widening_px=widening_m / resolution_m,
                corridor_length_px=round(corridor_length_m / resolution_m),
            )
        ]
    return pairs


def opens_an_arm(
    blocked: npt.NDArray[np.bool_],
    ends: npt.NDArray[np.float64],
    *,
    min_width_px: float,
    from_px: int,
    to_px: int,
    share: float,
) -> npt.NDArray[np.bool_]:
    """(G,) bool: gaps at least ``min_width_px`` wide across the mouth of an arm of a room, not doorways.

    Just beyond each end of the gap (1 to ``from_px`` - 1 pixels along it) the wall is looked at beside the end, on
    each side along the gap's normal from ``from_px`` to ``to_px``: it runs on that way when at least ``share`` of
    those pixels are ``blocked``.
    At the mouth of an L-shaped room's arm (or across a corridor's bend) one end meets a straight wall side-on,
    which runs on both ways, and the other is a corner, whose wall runs on at least one way: both walls go on beside
    the free space on one side, the arm. A doorway's jambs are the ends of its wall, which runs on along the gap, not
    across it; a partition that stops short of a wall has a free end (its wall runs on neither way), so the gap
    between it and the wall stays a doorway.

    Parameters
    ----------
    blocked : (H, W) bool
        Walls.
    ends : (G, 2, 2) float64
        The two ends (x, y) of each gap, pixels.
    """
    out = np.zeros(len(ends), dtype=bool)
    width, u, normal, _ = _gap_frame(ends)
    wide = np.flatnonzero(width >= min_width_px)
    if wide.size == 0 or to_px < from_px:
        return out
    h, w = blocked.shape
    k = np.arange(1, max(from_px, 2), dtype=np.float64)
    s = np.arange(from_px, to_px + 1, dtype=np.float64)
    runs_on = np.zeros((wide.size, 2, 2), dtype=bool)  # gap, end, side
    for end, outward in ((0, -u[wide]), (1, u[wide])):
        for side, sign in ((0, 1.0), (1, -1.0)):
            pts = (
                ends[wide, end, None, None, :]
                + k[None, :, None, None] * outward[:, None, None, :]
                + sign * s[None, None, :, None] * normal[wide, None, None, :]
            )
            x = np.rint(pts[..., 0]).astype(np.int64)
            y = np.rint(pts[..., 1]).astype(np.int64)
            inside = (x >= 0) & (x < w) & (y >= 0) & (y < h)
            hit: npt.NDArray[np.bool_] = ~inside  # off the image is wall
            hit[inside] = blocked[y[inside], x[inside]]
            runs_on[:, end, side] = hit.reshape(wide.size, -1).mean(axis=1) >= share
    flat: npt.NDArray[np.bool_] = np.all(runs_on, axis=2)  # per gap and end: the wall runs on both ways
    corner: npt.NDArray[np.bool_] = np.any(runs_on, axis=2)  # ... at least one way
    out[wide] = (flat[:, 0] & corner[:, 1]) | (flat[:, 1] & corner[:, 0])
    return out


def off_a_door_jamb(
    ends: npt.NDArray[np.float64],
    space: npt.NDArray[np.bool_],
    hit: npt.NDArray[np.bool_],
    *,
    reach_px: float,
    run_px: int,
    share: float,
    seen_px: int,
    max_cos: float,
) -> npt.NDArray[np.bool_]:
    """(G,) bool: gaps that run from a doorway's jamb into the room behind it, toward nothing the laser hit.

    A gap is such a cut when one of its ends lies within ``reach_px`` of an end of another gap crossing it at an
    angle (the cosine between them at most ``max_cos``) whose wall runs on beyond that end along it (``share`` of the
    next ``run_px`` pixels off ``space``: the end is a jamb of the other gap's wall) while its own does not, and its
    other end has no ``hit`` cell within ``seen_px`` (it ends on the room's unseen inside). A door's jamb is the end
    of the wall the door is in; the free space just behind the door reaches round that jamb into the room, so a cut
    from the jamb at an angle to the door, off its wall, to a shadow of the laser is the room's inside, not a second
    opening.

    Parameters
    ----------
    ends : (G, 2, 2) float64
        The two ends (x, y) of each gap, pixels.
    space, hit : (H, W) bool
        Free space (everything else is wall); cells the laser hit (occupied).
    """
    out = np.zeros(len(ends), dtype=bool)
    if len(ends) < 2:
        return out
    h, w = hit.shape
    x = np.clip(np.rint(ends[..., 0]).astype(np.int64), 0, w - 1)
    y = np.clip(np.rint(ends[..., 1]).astype(np.int64), 0, h - 1)
    seen = np.zeros(ends.shape[:2], dtype=bool)
    for dy in range(-seen_px, seen_px + 1):
        for dx in range(-seen_px, seen_px + 1):
            seen |= hit[np.clip(y + dy, 0, h - 1), np.clip(x + dx, 0, w - 1)]
    _, u, _, _ = _gap_frame(ends)
    k = np.arange(1, run_px + 1, dtype=np.float64)
    runs_on = np.zeros(ends.shape[:2], dtype=bool)  # gap, end: its wall goes on beyond that end along it
    for end, outward in ((0, -u), (1, u)):
        pts = ends[:, end, None, :] + k[None, :, None] * outward[:, None, :]
        px = np.clip(np.rint(pts[..., 0]).astype(np.int64), 0, w - 1)
        py = np.clip(np.rint(pts[..., 1]).astype(np.int64), 0, h - 1)
        runs_on[:, end] = 1.0 - space[py, px].mean(axis=1) >= share
    cand = np.flatnonzero(~seen.all(axis=1))  # a cut toward nothing seen, from a jamb of a wall running on
    jambs = np.flatnonzero(runs_on.any(axis=1))
    if cand.size == 0 or jambs.size == 0:
        return out
    across = np.abs(u[cand] @ u[jambs].T) <= max_cos
    for end in (0, 1):
        near = np.linalg.norm(ends[cand, None, None, end, :] - ends[None, jambs], axis=3) <= reach_px
        jamb = (near & runs_on[None, jambs, :]).any(axis=2) & across
        out[cand] |= jamb.any(axis=1) & ~runs_on[cand, end] & ~seen[cand, 1 - end]
    return out


def bumps_a_strip(
    blocked: npt.NDArray[np.bool_],
    ends: npt.NDArray[np.float64],
    *,
    bump_px: float,
    tolerance_px: float,
    max_depth_px: int,
    depth_step_px: int,
) -> npt.NDArray[np.bool_]:
    """(G,) bool: gaps across a strip that an obstacle against one of its walls narrows, not doorways.

    On each side of a gap, at depths ``depth_step_px, 2 * depth_step_px, ... <= max_depth_px`` along its normal
    (those the free space reaches straight from the gap's middle), the free run through the gap's middle parallel to
    the gap ends within ``tolerance_px`` of one end of the gap and at most ``bump_px`` beyond the other, at every
    depth on both sides: one wall of the strip runs on straight through that end, and the other end is a bump on the
    facing wall (a cupboard, a bin), no thinner strip of wall. A doorway is an opening in a wall: the space behind
    it reaches past both of its ends, or past one by more than a wall is thick.

    Parameters
    ----------
    blocked : (H, W) bool
        Walls.
    ends : (G, 2, 2) float64
        The two ends (x, y) of each gap, pixels.
    """
    if len(ends) == 0:
        return np.zeros(0, dtype=bool)
    width, u, normal, mid = _gap_frame(ends)
    half = width / 2.0
    depths = np.arange(depth_step_px, max_depth_px + 1, depth_step_px, dtype=np.float64)
    reach = math.ceil(float(half.max() + bump_px)) + 2
    # per end: the run never passes that end by more than the tolerance, or the other end by more than a bump
    flush = np.ones((len(ends), 2), dtype=bool)
    bump = np.ones((len(ends), 2), dtype=bool)
    seen = np.zeros(len(ends), dtype=bool)
    for sign in (1.0, -1.0):
        at = _free_depth(blocked, mid, sign * normal, max_depth_px)[:, None] >= depths[None, :]  # (G, D)
        which, step = np.nonzero(at)
        points = mid[which] + sign * depths[step, None] * normal[which]
        seen |= at.any(axis=1)
        for end, direction in ((0, -u[which]), (1, u[which])):
            run = _free_depth(blocked, points, direction, reach)
            flush[:, end] &= np.bincount(which, run > half[which] + tolerance_px, minlength=len(ends)) == 0
            bump[:, end] &= np.bincount(which, run > half[which] + bump_px, minlength=len(ends)) == 0
    out: npt.NDArray[np.bool_] = seen & ((flush[:, 0] & bump[:, 1]) | (flush[:, 1] & bump[:, 0]))
    return out


def block_beside_a_wall(
    blocked: npt.NDArray[np.bool_],
    ends: npt.NDArray[np.float64],
    *,
    hit: npt.NDArray[np.bool_],
    run_px: int,
    max_thickness_px: int,
    max_run_px: int,
    tolerance_px: float,
    max_depth_px: int,
    depth_step_px: int,
    widening_px: float = 0.0,
    corridor_length_px: int = 0,
) -> npt.NDArray[np.bool_]:
    """(G,) bool: gaps between a wall running straight past one end and a block at the other, not doorways.

    At one end the obstacle beyond the gap, along it, is a block: over the next ``run_px`` it is thicker across the
    gap than ``max_thickness_px`` (the median of those samples: a rounded corner is thin only at its tip), it ends
    along the gap within ``max_run_px`` (free space beyond it: furniture standing out into the room, not a wall
    that runs on to the next one), and the laser hit it (a ``hit`` cell on those samples: a mass of unknown space is
    no block). At the other end a wall runs straight past the gap on at least one side: at every depth
    ``depth_step_px, 2 * depth_step_px, ... <= max_depth_px`` along its normal on that side (all reached straight
    from its middle), the free run through its middle parallel to it ends within ``tolerance_px`` of that end. The
    gap is the passage between a room's side wall and a cupboard or table standing out from the facing wall: a
    doorway is an opening in a wall, whose jamb is the end of a wall that runs on. With ``corridor_length_px`` > 0, a
    gap from which a corridor goes on, on either side (:func:`_band_beside`), is a corridor's cross-section or a door
    into it, no passage inside a room: it is left alone.

    Parameters
    ----------
    blocked : (H, W) bool
        Walls (everything but free space).
    ends : (G, 2, 2) float64
        The two ends (x, y) of each gap, pixels.
    hit : (H, W) bool
        Cells the laser hit (occupied).
    """
    if len(ends) == 0:
        return np.zeros(0, dtype=bool)
    width, u, normal, mid = _gap_frame(ends)
    half = width / 2.0
    h, w = hit.shape
    k = np.arange(1, run_px + 1, dtype=np.float64)
    block = np.zeros((len(ends), 2), dtype=bool)
    for end, sign in ((0, -1.0), (1, 1.0)):
        pts = ends[:, end, None, :] + sign * k[None, :, None] * u[:, None, :]
        thickness = _centre_runs(~blocked, pts, np.broadcast_to(normal[:, None, :], pts.shape), max_thickness_px + 1)
        length = _free_depth(~blocked, ends[:, end] + sign * u, sign * u, max_run_px + 1)
        x = np.clip(np.rint(pts[..., 0]).astype(np.int64), 0, w - 1)
        y = np.clip(np.rint(pts[..., 1]).astype(np.int64), 0, h - 1)
        thick = np.median(thickness, axis=1) > max_thickness_px
        block[:, end] = thick & (length < max_run_px) & hit[y, x].any(axis=1)
    if not block.any():
        return np.zeros(len(ends), dtype=bool)
    depths = np.arange(depth_step_px, max_depth_px + 1, depth_step_px, dtype=np.float64)
    reach = math.ceil(float(half.max() + tolerance_px)) + 2
    flush = np.zeros((len(ends), 2), dtype=bool)
    for sign in (1.0, -1.0):
        at = _free_depth(blocked, mid, sign * normal, max_depth_px)[:, None] >= depths[None, :]  # (G, D)
        which, step = np.nonzero(at)
        points = mid[which] + sign * depths[step, None] * normal[which]
        for end, direction in ((0, -u[which]), (1, u[which])):
            run = _free_depth(blocked, points, direction, reach)
            past = np.bincount(which, run > half[which] + tolerance_px, minlength=len(ends)) > 0
            flush[:, end] |= at.all(axis=1) & ~past
    out: npt.NDArray[np.bool_] = (block[:, 0] & flush[:, 1]) | (block[:, 1] & flush[:, 0])
    if corridor_length_px > 0 and out.any():
        out[out] = ~_band_beside(blocked, ends[out], widening_px=widening_px, length_px=corridor_length_px)
    return out


def _band_beside(
    blocked: npt.NDArray[np.bool_],
    ends: npt.NDArray[np.float64],
    *,
    widening_px: float,
    length_px: int,
    max_wide_share: float = 0.5,
    step_px: int = 2,
) -> npt.NDArray[np.bool_]:
    """(G,) bool: on at least one side of the gap the free space goes on straight along its normal for ``length_px``
    as a band about as wide as the gap (wider by ``widening_px`` at fewer than ``max_wide_share`` of the depths, every
    ``step_px``: narrow over most of its length): a corridor, as :func:`across_a_corridor` asks of both sides."""
    width, u, normal, mid = _gap_frame(ends)
    out = np.zeros(len(ends), dtype=bool)
    for sign in (1.0, -1.0):
        long = _free_depth(blocked, mid, sign * normal, length_px) >= length_px
        if long.any():
            out[long] |= _narrow_behind(blocked, width[long] + widening_px, u[long], sign * normal[long], mid[long],
                                        np.full(np.count_nonzero(long), float(length_px)),
                                        max_wide_share=max_wide_share, step_px=step_px)
    return out


def _nearest_walls(
    space: npt.NDArray[np.bool_], *, reach_px: int, tile_px: int = 256, max_share: float = 0.25
) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.int32], npt.NDArray[np.int32]]:
    """Distance to the nearest wall pixel, (H, W) float32 pixels, and the x and y of that wall pixel per
    flat pixel index, (H * W,) int32 each (exact Euclidean feature transform).

    Exact wherever the distance is at most ``reach_px`` (and at least ``reach_px`` elsewhere).
    When free space is a small share of the image (a warehouse floor with a perimeter aisle), the
    transform runs only on tiles of ``tile_px`` holding free space, each widened by ``reach_px``.
    """
    h, w = space.shape
    if space.mean() > max_share:
        tiles = [(0, h, 0, w)]
    else:
        tiles = [
            (r, min(r + tile_px, h), c, min(c + tile_px, w))
            for r in range(0, h, tile_px)
            for c in range(0, w, tile_px)
            if space[r : r + tile_px, c : c + tile_px].any()
        ]
    from scipy import ndimage  # imported when first needed (decompose loads it early)

    if tiles == [(0, h, 0, w)]:
        fy, fx = ndimage.distance_transform_edt(space, return_distances=False, return_indices=True)
    else:
        fy, fx = np.indices((h, w), dtype=np.int32)  # a wall pixel is its own nearest (distance 0)
        for r0, r1, c0, c1 in tiles:
            a0, a1 = max(r0 - reach_px, 0), min(r1 + reach_px, h)
            b0, b1 = max(c0 - reach_px, 0), min(c1 + reach_px, w)
            iy, ix = ndimage.distance_transform_edt(space[a0:a1, b0:b1], return_distances=False, return_indices=True)
            core = (slice(r0 - a0, r1 - a0), slice(c0 - b0, c1 - b0))
            fy[r0:r1, c0:c1] = iy[core] + a0
            fx[r0:r1, c0:c1] = ix[core] + b0
    off_y = fy - np.arange(h, dtype=np.int32)[:, None]
    off_x = fx - np.arange(w, dtype=np.int32)[None, :]
    squared = np.multiply(off_y, off_y, out=off_y)  # the offsets are spent: squared in place
    squared += np.multiply(off_x, off_x, out=off_x)
    # scipy's distance is the float64 square root; rounded to float32 it is the float32 square root of
    # the same whole number when float32 holds that exactly (square roots round once, 53 >= 2 * 24 + 2)
    exact = np.float32 if h * h + w * w < 2**24 else np.float64
    dist = np.sqrt(squared.astype(exact)).astype(np.float32, copy=False)
    return dist, fx.ravel(), fy.ravel()


def _is_neck(
    dist: npt.NDArray[np.floating], cuts: npt.NDArray[np.float64], reach_px: int, tolerance_px: float
) -> npt.NDArray[np.bool_]:
    """(K,) bool: the clearance at each cut's middle is the least along its normal, within ``reach_px``."""
    h, w = dist.shape
    span = cuts[:, 1] - cuts[:, 0]
    u = span / np.maximum(np.linalg.norm(span, axis=1), 1e-9)[:, None]
    normal = np.stack([-u[:, 1], u[:, 0]], axis=1)
    steps = np.arange(-reach_px, reach_px + 1, dtype=np.float64)
    pts = cuts.mean(axis=1)[:, None, :] + steps[None, :, None] * normal[:, None, :]
    x = np.clip(np.rint(pts[..., 0]).astype(np.int64), 0, w - 1)
    y = np.clip(np.rint(pts[..., 1]).astype(np.int64), 0, h - 1)
    clearance = dist[y, x]
    out: npt.NDArray[np.bool_] = clearance.min(axis=1) >= clearance[:, reach_px] - tolerance_px
    return out


def _extends_a_wall(
    walls: npt.NDArray[np.bool_], cuts: npt.NDArray[np.float64], run_px: int, share: float, max_thickness_px: int
) -> npt.NDArray[np.bool_]:
    """(K,) bool: beyond one end of the cut, along it, a thin wall goes on.

    ``share`` of the next ``run_px`` pixels along the cut are wall, and across the cut that wall
    is at most ``max_thickness_px`` thick somewhere (a wall, not a cabinet or a block; a wall
    meeting another one is thick only where they meet).
    """
    if len(cuts) == 0 or run_px < 1:
        return np.ones(len(cuts), dtype=bool)
    h, w = walls.shape
    span = cuts[:, 1] - cuts[:, 0]
    u = span / np.maximum(np.linalg.norm(span, axis=1), 1e-9)[:, None]
    normal = np.stack([-u[:, 1], u[:, 0]], axis=1)
    k = np.arange(1, run_px + 1, dtype=np.float64)
    out = np.zeros(len(cuts), dtype=bool)
    for end, sign in ((0, -1.0), (1, 1.0)):
        pts = cuts[:, end, None, :] + sign * k[None, :, None] * u[:, None, :]
        x = np.clip(np.rint(pts[..., 0]).astype(np.int64), 0, w - 1)
        y = np.clip(np.rint(pts[..., 1]).astype(np.int64), 0, h - 1)
        on_wall = walls[y, x].mean(axis=1) >= share
        along = cuts[:, end, None, :] + sign * np.array([0.2, 0.35, 0.5])[None, :, None] * run_px * u[:, None, :]
        across = np.broadcast_to(normal[:, None, :], along.shape)
        thickness = _centre_runs(~walls, along, across, max_thickness_px + 1).min(axis=1)
        out |= on_wall & (thickness <= max_thickness_px)
    return out


def draw_cuts(cuts: npt.NDArray[np.float64], shape: tuple[int, int]) -> npt.NDArray[np.bool_]:
    """Raster of the cuts (1 px, 4-connected, so they separate 8-connected free space)."""
    canvas = np.zeros(shape, dtype=np.uint8)
    for (x0, y0), (x1, y1) in cuts:
        cv2.line(canvas, (round(x0), round(y0)), (round(x1), round(y1)), 1, 1, cv2.LINE_4)
    return canvas.astype(bool)

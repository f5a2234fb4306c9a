"""The building's layout from its wall lines: a room may end where the map never drew its wall.

As ROSE² reasons (Luperto & Amigoni): the walls seen give a few lines per dominant direction (here the
decomposition's own lines), each extended across the building; a line on which much wall was seen is a
wall of the layout even where its wall is missing. A region that the missing stretches of such lines
cut into several room-like cells (area, width) is split there: rooms that open onto a corridor over an
opening wider than the corridor (no neck, so no doorway) are no longer one region with it.
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np
import numpy.typing as npt
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from services.grid_decomposition.cogency import _line_samples
from services.grid_decomposition.doorways import across_a_corridor
from services.grid_decomposition.segments import fill_from_neighbours, same_value_pieces
from services.grid_decomposition.subdivision import LineGroup, line_endpoints


def layout_openings(
    segments: npt.NDArray[np.int32],
    walls: npt.NDArray[np.bool_],
    groups: Sequence[LineGroup],
    *,
    tolerance_px: int,
    min_seen_px: int,
    min_opening_px: int,
    max_opening_px: int,
    window_px: int,
    min_side_share: float,
) -> tuple[list[npt.NDArray[np.int64]], npt.NDArray[np.int64]]:
    """The missing stretches of the layout's walls inside regions (flat pixel indices of each stretch),
    and the pixels of the layout's lines inside regions on or beside a seen wall (with the stretches they
    close a region's wall: free pixels within the tolerance of a wall would leave a way round a stretch).

    Along every line the seen walls (within ``tolerance_px``) are read as a profile. A line is a wall of
    the layout when at least ``min_seen_px`` of it lies on wall. A stretch is a run of the line inside
    one region (no wall on it), ``min_opening_px``..``max_opening_px`` long, with a wall at both ends
    and, beside it, the wall going on along the line: at least ``min_side_share`` of the
    ``window_px`` beyond one end (or the other) lies on wall, so the stretch is a wall the map did not
    draw, not a line through a room's middle that only crosses its walls.
    """
    h, w = segments.shape
    lines = [line for group in groups for line in group.lines]
    if not lines:
        return [], np.zeros(0, dtype=np.int64)
    xs, ys, of = _line_samples([line_endpoints(line, (h, w)) for line in lines], (h, w))
    group_of = np.repeat(np.arange(len(groups)), [len(g.lines) for g in groups])[of]
    keep = np.ones(xs.size, dtype=bool)
    for g, group in enumerate(groups):
        if group.mask is not None:
            mine = np.flatnonzero(group_of == g)
            keep[mine] = group.mask[ys[mine], xs[mine]]
    xs, ys, of = xs[keep], ys[keep], of[keep]
    k = 2 * tolerance_px + 1
    near = cv2.dilate(walls.astype(np.uint8), cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k))) > 0
    on_wall = near[ys, xs]
    seen = np.bincount(of, weights=on_wall, minlength=len(lines))
    region = segments[ys, xs]
    # runs of one region off the walls, on layout lines, never across two lines' samples
    inside = (region > 0) & ~on_wall & (seen[of] >= min_seen_px)
    start = inside & np.r_[True, (region[1:] != region[:-1]) | (of[1:] != of[:-1]) | ~inside[:-1]]
    first = np.flatnonzero(start)
    run_id = np.cumsum(start) - 1
    length = np.bincount(run_id[inside], minlength=first.size)
    last = first + length - 1
    openings: list[npt.NDArray[np.int64]] = []
    wall_sum = np.r_[0, np.cumsum(on_wall)]
    n = xs.size
    for a, b, size in zip(first, last, length, strict=True):
        if not min_opening_px <= size <= max_opening_px or a == 0 or b + 1 >= n:
            continue
        line = of[a]
        if of[a - 1] != line or of[b + 1] != line or not (on_wall[a - 1] and on_wall[b + 1]):
            continue
        lo, hi = a - window_px, b + 1 + window_px
        if lo < 0 or of[lo] != line or hi > n or of[hi - 1] != line:
            continue
        before = (wall_sum[a] - wall_sum[lo]) / window_px
        after = (wall_sum[hi] - wall_sum[b + 1]) / window_px
        if max(before, after) >= min_side_share:
            openings.append(ys[a : b + 1] * w + xs[a : b + 1])
    beside = (region > 0) & on_wall & (seen[of] >= min_seen_px)
    return openings, ys[beside] * w + xs[beside]


def split_by_layout(
    segments: npt.NDArray[np.int32],
    walls: npt.NDArray[np.bool_],
    groups: Sequence[LineGroup],
    candidates: npt.NDArray[np.bool_],
    *,
    resolution_m: float,
    tolerance_m: float = 0.1,
    min_seen_m: float = 4.0,
    min_opening_m: float = 0.3,
    max_opening_m: float = 8.0,
    window_m: float = 2.0,
    min_side_share: float = 0.5,
    min_room_m2: float = 6.0,
    min_room_width_m: float = 2.0,
    corridor_length_m: float = 2.0,
    widening_m: float = 0.3,
    max_elongation: float = 3.0,
    max_cut_cos: float = 0.5,
) -> npt.NDArray[np.int32]:
    """Split regions along the layout's missing walls (:func:`layout_openings`) into room-like cells.

    A region of ``candidates`` (a flag per segment id) is cut along every missing stretch inside it;
    a cut stays where the cells on both sides are room-like (at least ``min_room_m2`` and a disc
    ``min_room_width_m`` across) and it is not a cut across a corridor (the band goes on as wide on
    both sides, :func:`~services.grid_decomposition.doorways.across_a_corridor`); cells across every
    other cut join again. Segment ids of the pieces are new ids after the largest one.

    Parameters
    ----------
    segments : (H, W) int32
        Segment ids per pixel, 0 = none.
    walls : (H, W) bool
        Walls seen (occupied cells).
    groups : sequence of LineGroup
        The decomposition's lines.
    candidates : (N + 1,) bool
        Segments that may be split (room segments of some size).
    """
    px = 1.0 / resolution_m
    openings, beside = layout_openings(
        np.where(candidates[segments], segments, 0),
        walls,
        groups,
        tolerance_px=max(1, round(tolerance_m * px)),
        min_seen_px=round(min_seen_m * px),
        min_opening_px=round(min_opening_m * px),
        max_opening_px=round(max_opening_m * px),
        window_px=round(window_m * px),
        min_side_share=min_side_share,
    )
    if not openings:
        return segments
    h, w = segments.shape
    ends = np.array(
        [[[o[0] % w, o[0] // w], [o[-1] % w, o[-1] // w]] for o in openings], dtype=np.float64
    )
    cut = np.zeros(h * w, dtype=bool)
    for i, o in enumerate(openings):
        cut[o] = True
    cut_img = cut.reshape(h, w).copy()
    cut_img.ravel()[beside] = True
    seg = np.asarray(segments, dtype=np.int32)
    # a cut across a corridor parts no rooms: the band goes on as wide on both sides, its side walls closed
    # by the layout (the other cuts), each cut tested with itself open
    blocked = (seg == 0) | walls | cut_img
    across = np.zeros(len(openings), dtype=bool)
    for i, o in enumerate(openings if corridor_length_m > 0 else []):
        blocked.ravel()[o] = False
        across[i] = across_a_corridor(
            blocked, ends[i : i + 1], widening_px=widening_m * px, length_px=round(corridor_length_m * px)
        )[0]
        blocked.ravel()[o] = True
    # cells: every region's 4-connected pieces off the cuts
    pieces, n = same_value_pieces(np.where(cut_img | ~candidates[seg], 0, seg))
    cells, n_cells = pieces, n + 1
    # the cells beside each cut (the two it touches most)
    around = cv2.dilate(cells.astype(np.float32), np.ones((3, 3), np.uint8)).astype(np.int64).ravel()
    below = (-cv2.dilate(-np.where(cells > 0, cells, n_cells + 1).astype(np.float32), np.ones((3, 3), np.uint8)))
    below_flat = below.astype(np.int64).ravel()
    pairs: list[tuple[int, int, int]] = []
    for i, o in enumerate(openings):
        a, b = below_flat[o], around[o]
        ok = (a > 0) & (a <= n_cells) & (b > 0) & (a != b)
        if not ok.any():
            continue
        keys, counts = np.unique(np.stack([a[ok], b[ok]], axis=1), axis=0, return_counts=True)
        c0, c1 = keys[int(np.argmax(counts))]
        pairs.append((i, int(c0), int(c1)))
    dist = cv2.distanceTransform((cells > 0).astype(np.uint8), cv2.DIST_L2, 3)
    area = np.bincount(cells.ravel(), minlength=n_cells).astype(np.float64)
    radius = np.zeros(n_cells)
    np.maximum.at(radius, cells.ravel(), dist.ravel())
    room_px, width_px = min_room_m2 * px * px, 0.5 * min_room_width_m * px
    # each cell's first and second moments: a group's principal axis and elongation
    flat = cells.ravel()
    on = flat > 0
    yy, xx = np.divmod(np.flatnonzero(on).astype(np.float64), float(w))
    moments = np.stack(
        [np.bincount(flat[on], weights=v, minlength=n_cells) for v in (xx, yy, xx * xx, yy * yy, xx * yy)], axis=1
    )
    # each cut's direction (unit vector along it)
    along = ends[:, 1] - ends[:, 0]
    along /= np.maximum(np.linalg.norm(along, axis=1, keepdims=True), 1e-9)
    group = np.arange(n_cells)
    while True:  # join cells across the cuts that do not part two rooms, until every cut left does
        group_area = np.bincount(group, weights=area, minlength=n_cells)
        group_radius = np.zeros(n_cells)
        np.maximum.at(group_radius, group, radius)
        roomy = (group_area >= room_px) & (group_radius >= width_px)
        axis, band = _bands(group, moments, group_area, max_elongation)
        # a cut across a band's end (a corridor cut across where a room's side wall continues) parts no rooms
        joins = [
            (group[c0], group[c1]) for i, c0, c1 in pairs
            if group[c0] != group[c1] and (
                across[i] or not (roomy[group[c0]] and roomy[group[c1]])
                or any(band[g] and abs(float(axis[g] @ along[i])) < max_cut_cos for g in (group[c0], group[c1]))
            )
        ]
        if not joins:
            break
        j = np.array(joins)
        graph = coo_matrix((np.ones(len(j)), (j[:, 0], j[:, 1])), shape=(n_cells, n_cells))
        group = connected_components(graph, directed=False)[1][group]
    # a segment keeps its id for its largest room-like group; other room-like groups get new ids, the rest
    # (the cuts, specks cut off) join a neighbour
    cell_seg = np.zeros(n_cells, dtype=np.int64)
    cell_seg[cells.ravel()] = seg.ravel()
    cell_seg[0] = 0
    new_id = np.zeros(n_cells, dtype=np.int64)
    was_split = np.zeros(int(seg.max()) + 1, dtype=bool)
    next_id = int(seg.max()) + 1
    for sid in np.unique(cell_seg[cell_seg > 0]):
        mine = np.flatnonzero(cell_seg == sid)
        rooms = np.unique(group[mine][roomy[group[mine]]])
        if rooms.size < 2:
            continue
        was_split[sid] = True
        biggest = rooms[int(np.argmax(group_area[rooms]))]
        for g in rooms:
            if g != biggest:
                new_id[mine[group[mine] == g]] = next_id
                next_id += 1
        new_id[mine[~roomy[group[mine]]]] = -1
    if not was_split.any():
        return segments
    moved = new_id[cells]
    out = np.where(moved > 0, moved, seg).astype(np.int32)
    holes = ((moved < 0) | cut_img) & was_split[seg]
    out[holes] = 0
    return fill_from_neighbours(out, holes)


def _bands(
    group: npt.NDArray[np.int64], moments: npt.NDArray[np.float64], area: npt.NDArray[np.float64], max_elongation: float
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.bool_]]:
    """Each group's principal axis (unit vector) and whether it is a band (longer than ``max_elongation`` times
    its width, from the ratio of its second moments: a rectangle's is the square of its aspect)."""
    n = area.size
    m = np.stack([np.bincount(group, weights=moments[:, k], minlength=n) for k in range(5)], axis=1)
    a = np.maximum(area, 1.0)
    mx, my = m[:, 0] / a, m[:, 1] / a
    sxx, syy, sxy = m[:, 2] / a - mx * mx, m[:, 3] / a - my * my, m[:, 4] / a - mx * my
    half = 0.5 * (sxx + syy)
    root = np.sqrt(np.maximum(0.25 * (sxx - syy) ** 2 + sxy * sxy, 0.0))
    big, small = half + root, np.maximum(half - root, 1e-9)
    theta = 0.5 * np.arctan2(2.0 * sxy, sxx - syy)
    axis = np.stack([np.cos(theta), np.sin(theta)], axis=1)
    return axis, (area > 0) & (big > max_elongation**2 * small)

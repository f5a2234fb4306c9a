"""A wide border that ends on an obstacle standing free on the floor is no doorway: its two regions are one room."""

from __future__ import annotations

import cv2
import numpy as np
import numpy.typing as npt

from services.grid_decomposition.arrays import label_counts, nonzero_rc
from services.grid_decomposition.openings import join_pairs

_EIGHT = 8
_ELONGATED = 2.0  # an obstacle this many times longer than wide has a line of its own


def _shifted(mask: npt.NDArray[np.bool_], dy: int, dx: int) -> npt.NDArray[np.bool_]:
    """``out[r, c] = mask[r + dy, c + dx]``, False off the image."""
    h, w = mask.shape
    out = np.zeros_like(mask)
    out[max(-dy, 0): h - max(dy, 0), max(-dx, 0): w - max(dx, 0)] = mask[
        max(dy, 0): h - max(-dy, 0), max(dx, 0): w - max(-dx, 0)
    ]
    return out


def _long_pieces(mask: npt.NDArray[np.bool_], min_length_px: float) -> npt.NDArray[np.bool_]:
    """The 8-connected pieces of ``mask`` whose box's diagonal is at least ``min_length_px``."""
    _, labels, stats, _ = cv2.connectedComponentsWithStats(mask.view(np.uint8), connectivity=_EIGHT)
    keep = np.hypot(stats[:, cv2.CC_STAT_WIDTH], stats[:, cv2.CC_STAT_HEIGHT]) >= min_length_px
    keep[0] = False
    out: npt.NDArray[np.bool_] = keep[labels]
    return out


def seen_walls(
    free: npt.NDArray[np.bool_],
    occupied: npt.NDArray[np.bool_],
    wall: npt.NDArray[np.bool_],
    *,
    min_length_px: float,
    near_px: int = 2,
    depth_px: int = 2,
    thickness_px: int = 3,
) -> npt.NDArray[np.bool_]:
    """Walls the laser saw: long runs of hit cells along the map's lines, and long faces of solid obstacle.

    A stripe of unknown between two laser rays lies on the map's lines as much as a wall does; what tells a wall is
    either the laser's hits along it (``wall`` line pixels within ``near_px`` of an ``occupied`` cell), or a face:
    obstacle cells with free space ``depth_px`` deep on one side and obstacle at least ``thickness_px`` thick on
    the other (free space on one side only: a drawn grey wall, a pillar's slanted side, never a ray's one-pixel
    stripe). Each kind kept in 8-connected pieces whose box's diagonal is at least ``min_length_px``.

    Parameters
    ----------
    free, occupied, wall : (H, W) bool
        Free cells, hit cells, and the wall evidence along the map's lines.
    min_length_px : float
        Shortest wall, pixels.
    near_px, depth_px, thickness_px : int
        Pixels.

    Returns
    -------
    (H, W) bool
        The seen walls' cells.
    """
    size = 2 * near_px + 1
    hits = cv2.dilate(occupied.view(np.uint8), np.ones((size, size), np.uint8)).view(bool)
    obstacle = ~free
    face = np.zeros(free.shape, dtype=bool)
    for dy, dx in ((0, 1), (0, -1), (1, 0), (-1, 0)):
        side = obstacle.copy()
        for k in range(1, depth_px + 1):
            side &= _shifted(free, -k * dy, -k * dx)
        for k in range(1, thickness_px):
            side &= _shifted(obstacle, k * dy, k * dx)
        face |= side
    return _long_pieces(wall & hits, min_length_px) | _long_pieces(face, min_length_px)


def _border_pixels(
    seg: npt.NDArray[np.int32], n: int
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.intp], npt.NDArray[np.intp]]:
    """The pixels on both sides of every border between two segments (4-neighbours): pair key, rows, columns."""
    h, w = seg.shape
    keys, rows, cols = [], [], []
    for dy, dx in ((0, 1), (1, 0)):
        p, q = seg[: h - dy, : w - dx], seg[dy:, dx:]
        r, c = nonzero_rc((p != q) & (p > 0) & (q > 0))
        a, b = p[r, c].astype(np.int64), q[r, c].astype(np.int64)
        key = np.minimum(a, b) * n + np.maximum(a, b)
        keys += [key, key]
        rows += [r, r + dy]
        cols += [c, c + dx]
    return np.concatenate(keys), np.concatenate(rows), np.concatenate(cols)


def _axis(
    rows: npt.NDArray[np.intp], cols: npt.NDArray[np.intp]
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64], float]:
    """Centre (row, col), principal direction, the extremes along it of a set of pixels, and how many times longer
    than wide they are (the ratio of the spreads along and across it)."""
    pts = np.stack([rows, cols], axis=1).astype(np.float64)
    centre = pts.mean(axis=0)
    spread, axes = np.linalg.eigh(np.cov((pts - centre).T)) if len(pts) > 1 else (np.zeros(2), np.eye(2))
    direction = axes[:, -1]
    t = (pts - centre) @ direction
    return centre, direction, np.array([t.min(), t.max()]), float(np.sqrt(spread[1] / max(spread[0], 1e-9)))


def join_free_standing_ends(
    segments: npt.NDArray[np.int32],
    free: npt.NDArray[np.bool_],
    occupied: npt.NDArray[np.bool_],
    wall: npt.NDArray[np.bool_],
    *,
    resolution_m: float,
    fixed: npt.NDArray[np.bool_] | None = None,
    min_area_m2: float = 1.5,
    min_border_m: float = 2.0,
    min_piece_m: float = 0.5,
    wall_min_m: float = 1.0,
    on_wall_m: float = 0.15,
    hit_reach_m: float = 0.15,
    standing_off_m: float = 0.25,
    floor_share: float = 0.9,
) -> npt.NDArray[np.int32]:
    """Join two segments whose border is wider than a door and ends on an obstacle standing free on their floor.

    A doorway is a gap between two jambs, and a jamb is a wall's end. Two segments (each at least ``min_area_m2``)
    whose border (its 8-connected pieces at least ``min_piece_m`` long, measured along each piece's principal
    line) is longer than ``min_border_m`` (the widest door) are one room when every end of the border's pieces lies
    either on a seen wall (:func:`seen_walls`, within ``on_wall_m``) or on an obstacle standing free on their
    floor, and at least one on such an obstacle: hit cells within ``hit_reach_m`` of the end (8-connected across
    one-pixel gaps) with no seen wall within ``standing_off_m`` of them, the free space round them (one pixel
    beyond that reach) at least ``floor_share`` the two segments', and no seen wall within ``min_border_m`` along
    their own principal line either way (a piece of wall between two doors lies on its wall's line; a speck no
    more than twice as long as wide has no line of its own: no seen wall within ``min_border_m`` at all). An end near
    no hit and no seen wall (a jamb the laser never saw) keeps the pair apart, and so does an obstacle reaching the
    looked-at window's edge. ``fixed`` (per segment id, warehouse floors) segments never join. Joined, ids 1..M
    (consecutive); else the segments as given.

    Parameters
    ----------
    segments : (H, W) int32
    free, occupied, wall : (H, W) bool
        Free cells, hit cells, the wall evidence along the map's lines.
    resolution_m : float
        Metres per cell.
    """
    seg = np.asarray(segments, dtype=np.int32)
    n = int(seg.max()) + 1
    if n < 3:
        return seg
    min_border_px = min_border_m / resolution_m
    big = label_counts(seg, n)[0] >= min_area_m2 / resolution_m**2
    big[0] = False
    if fixed is not None:
        big &= ~np.asarray(fixed[:n], dtype=bool)
    if np.count_nonzero(big) < 2:
        return seg
    key, rows, cols = _border_pixels(seg, n)
    keep = big[key // n] & big[key % n]
    key, rows, cols = key[keep], rows[keep], cols[keep]
    pair, which, count = np.unique(key, return_inverse=True, return_counts=True)
    # a piece is no longer than its pixels: pairs with fewer border pixels than the widest door are left at once
    candidates = np.flatnonzero(count > min_border_px)
    if candidates.size == 0:
        return seg
    order = np.argsort(which, kind="stable")
    starts = np.concatenate([[0], np.cumsum(count)])
    h, w = seg.shape
    margin = int(np.ceil(min_border_px + wall_min_m / resolution_m))
    first: list[int] = []
    second: list[int] = []
    for k in candidates.tolist():
        at = order[starts[k]: starts[k + 1]]
        a, b = int(pair[k] // n), int(pair[k] % n)
        if _is_one_room(
            seg, free, occupied, wall, a, b, rows[at], cols[at],
            box=(max(int(rows[at].min()) - margin, 0), min(int(rows[at].max()) + margin + 1, h),
                 max(int(cols[at].min()) - margin, 0), min(int(cols[at].max()) + margin + 1, w)),
            min_border_px=min_border_px, min_piece_px=min_piece_m / resolution_m,
            wall_min_px=wall_min_m / resolution_m, on_wall_px=on_wall_m / resolution_m,
            hit_reach_px=max(1, round(hit_reach_m / resolution_m)), standing_off_px=standing_off_m / resolution_m,
            floor_share=floor_share,
        ):
            first.append(a)
            second.append(b)
    if not first:
        return seg
    return join_pairs(seg, np.asarray(first, dtype=np.int64), np.asarray(second, dtype=np.int64))


def _is_one_room(
    seg: npt.NDArray[np.int32],
    free: npt.NDArray[np.bool_],
    occupied: npt.NDArray[np.bool_],
    wall: npt.NDArray[np.bool_],
    a: int,
    b: int,
    rows: npt.NDArray[np.intp],
    cols: npt.NDArray[np.intp],
    *,
    box: tuple[int, int, int, int],
    min_border_px: float,
    min_piece_px: float,
    wall_min_px: float,
    on_wall_px: float,
    hit_reach_px: int,
    standing_off_px: float,
    floor_share: float,
) -> bool:
    """Whether the border of ``a`` and ``b`` (its pixels ``rows``, ``cols``) passes :func:`join_free_standing_ends`,
    everything looked at inside ``box`` (row and column bounds)."""
    r0, r1, c0, c1 = box
    border = np.zeros((r1 - r0, c1 - c0), dtype=np.uint8)
    border[rows - r0, cols - c0] = 1
    n_pieces, pieces = cv2.connectedComponents(border, connectivity=_EIGHT)
    ends = []
    total = 0.0
    pr, pc = nonzero_rc(pieces)
    label = pieces[pr, pc]
    for p in range(1, n_pieces):
        on = label == p
        centre, direction, extremes, _ = _axis(pr[on], pc[on])
        length = float(extremes[1] - extremes[0]) + 1
        if length >= min_piece_px:
            total += length
            ends += [centre + t * direction for t in extremes]
    if total <= min_border_px:
        return False
    crop = (slice(r0, r1), slice(c0, c1))
    free_c, occupied_c = np.ascontiguousarray(free[crop]), np.ascontiguousarray(occupied[crop])
    seg_c = np.ascontiguousarray(seg[crop])
    seen = seen_walls(free_c, occupied_c, np.ascontiguousarray(wall[crop]), min_length_px=wall_min_px)
    distance = np.asarray(cv2.distanceTransform((~seen).view(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE),
                          dtype=np.float32)
    hits = cv2.dilate(occupied_c.view(np.uint8), np.ones((3, 3), np.uint8))
    _, hit_labels, stats, _ = cv2.connectedComponentsWithStats(hits, connectivity=_EIGHT)
    reach = np.hypot(stats[:, cv2.CC_STAT_WIDTH], stats[:, cv2.CC_STAT_HEIGHT])
    height, width = seg_c.shape
    standing = False
    for end in ends:
        y = min(max(round(float(end[0])), 0), height - 1)
        x = min(max(round(float(end[1])), 0), width - 1)
        if distance[y, x] <= on_wall_px:
            continue
        reach_y, reach_x = slice(max(y - hit_reach_px, 0), y + hit_reach_px + 1), slice(
            max(x - hit_reach_px, 0), x + hit_reach_px + 1
        )
        near = hit_labels[reach_y, reach_x]
        touched = np.unique(near[near > 0])
        if touched.size == 0:  # a jamb the laser never saw
            return False
        k = int(touched[np.argmax(reach[touched])])
        left, top = stats[k, cv2.CC_STAT_LEFT], stats[k, cv2.CC_STAT_TOP]
        right, bottom = left + stats[k, cv2.CC_STAT_WIDTH], top + stats[k, cv2.CC_STAT_HEIGHT]
        if left == 0 or top == 0 or right == width or bottom == height:  # beyond the window: not looked at
            return False
        if not _stands_free(
            hit_labels == k, seg_c, free_c, distance, a, b, standing_off_px=standing_off_px,
            ring_px=hit_reach_px + 1, floor_share=floor_share, in_line_px=min_border_px, on_wall_px=on_wall_px,
        ):
            return False
        standing = True
    return standing


def _stands_free(
    obstacle: npt.NDArray[np.bool_],
    seg: npt.NDArray[np.int32],
    free: npt.NDArray[np.bool_],
    distance: npt.NDArray[np.float32],
    a: int,
    b: int,
    *,
    standing_off_px: float,
    ring_px: int,
    floor_share: float,
    in_line_px: float,
    on_wall_px: float,
) -> bool:
    """Whether ``obstacle`` stands free on the floor of ``a`` and ``b``: off every seen wall (``distance`` to them),
    the free space round it theirs, and no seen wall along its own line within ``in_line_px`` (round it, for a
    speck)."""
    r, c = nonzero_rc(obstacle)
    centre, direction, extremes, elongation = _axis(r, c)
    # a speck has no line of its own: any seen wall within that reach may be the one it is a dot of
    if float(distance[r, c].min()) < (standing_off_px if elongation >= _ELONGATED else in_line_px):
        return False
    size = 2 * ring_px + 1
    ring = cv2.dilate(obstacle.view(np.uint8), np.ones((size, size), np.uint8)).view(bool) & ~obstacle & free
    around = seg[ring]
    if around.size == 0 or np.count_nonzero((around == a) | (around == b)) < floor_share * around.size:
        return False
    h, w = seg.shape
    steps = np.arange(1, int(in_line_px) + 1, dtype=np.float64)
    for sign, t in ((-1.0, extremes[0]), (1.0, extremes[1])):
        at = centre[:, None] + direction[:, None] * (t + sign * steps)[None, :]
        yy = np.clip(np.rint(at[0]).astype(np.intp), 0, h - 1)
        xx = np.clip(np.rint(at[1]).astype(np.intp), 0, w - 1)
        if np.any(distance[yy, xx] <= on_wall_px):
            return False
    return True

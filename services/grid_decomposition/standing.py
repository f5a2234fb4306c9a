"""A wide border that ends on an obstacle standing free on the floor is no doorway: its two regions are one room;
nor is a cut along a line across open floor between furniture."""

from __future__ import annotations

import cv2
import numpy as np
import numpy.typing as npt

from services.grid_decomposition.arrays import Components, border_steps, components, nonzero_rc
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
    keys, rows, cols = [], [], []
    for dy, dx, r, c, key in border_steps(seg, n):
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
    joinable: npt.NDArray[np.bool_],
    hit_parts: Components | None = None,
    min_border_m: float = 2.0,
    min_piece_m: float = 0.5,
    wall_min_m: float = 1.0,
    on_wall_m: float = 0.15,
    hit_reach_m: float = 0.15,
    standing_off_m: float = 0.25,
    floor_share: float = 0.9,
) -> npt.NDArray[np.int32]:
    """Join two segments whose border is wider than a door and ends on an obstacle standing free on their floor.

    A doorway is a gap between two jambs, and a jamb is a wall's end. Two ``joinable`` segments (per segment id:
    rooms' regions, off the warehouse floors and large enough) whose border (its 8-connected pieces at least
    ``min_piece_m`` long, measured along each piece's principal line) is longer than ``min_border_m`` (the widest
    door) are one room when every end of the border's pieces lies either on a seen wall (:func:`seen_walls`,
    within ``on_wall_m``) or on an obstacle standing free on their floor, and at least one on such an obstacle: hit
    cells within ``hit_reach_m`` of the end (an 8-connected piece of them) with no seen wall within
    ``standing_off_m`` of them, the free space round them (one pixel beyond that reach) at least ``floor_share``
    the two segments', and no seen wall within ``min_border_m`` along their own principal line either way (a piece
    of wall between two doors lies on its wall's line; a speck no more than twice as long as wide has no line of
    its own: no seen wall within ``min_border_m`` at all). An end near no hit and no seen wall (a jamb the laser
    never saw) keeps the pair apart, and so does an obstacle reaching the looked-at window's edge. Joined, ids 1..M
    (consecutive); else the segments as given.

    Parameters
    ----------
    segments : (H, W) int32
    free, occupied, wall : (H, W) bool
        Free cells, hit cells, the wall evidence along the map's lines.
    resolution_m : float
        Metres per cell.
    joinable : (N,) bool
        Per segment id, at least ``segments.max() + 1`` long.
    hit_parts : Components, optional
        ``components(occupied)``, when already labelled.
    """
    seg = np.asarray(segments, dtype=np.int32)
    n = int(seg.max()) + 1
    big = np.zeros(n, dtype=bool)
    big[1:] = joinable[1:n]
    if np.count_nonzero(big) < 2:
        return seg
    min_border_px = min_border_m / resolution_m
    key, rows, cols = _border_pixels(seg, n)
    keep = big[key // n] & big[key % n]
    key, rows, cols = key[keep], rows[keep], cols[keep]
    pair, which, count = np.unique(key, return_inverse=True, return_counts=True)
    # each 4-neighbour pair of pixels (two of them counted) carries at most a pixel of a piece's length: pairs with
    # fewer than the widest door are left at once
    candidates = np.flatnonzero(count > 2 * min_border_px)
    if candidates.size == 0:
        return seg
    parts = components(occupied) if hit_parts is None else hit_parts
    order = np.argsort(which, kind="stable")
    starts = np.concatenate([[0], np.cumsum(count)])
    first: list[int] = []
    second: list[int] = []
    for k in candidates.tolist():
        at = order[starts[k]: starts[k + 1]]
        a, b = int(pair[k] // n), int(pair[k] % n)
        if _is_one_room(
            seg, free, occupied, wall, parts, a, b, rows[at], cols[at],
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
    parts: Components,
    a: int,
    b: int,
    rows: npt.NDArray[np.intp],
    cols: npt.NDArray[np.intp],
    *,
    min_border_px: float,
    min_piece_px: float,
    wall_min_px: float,
    on_wall_px: float,
    hit_reach_px: int,
    standing_off_px: float,
    floor_share: float,
) -> bool:
    """Whether the border of ``a`` and ``b`` (its pixels ``rows``, ``cols``) passes :func:`join_free_standing_ends`.

    Everything is looked at in windows round the border's ends: an obstacle reaching further than ``min_border_px``
    plus ``wall_min_px`` from its end is no free-standing one; whether the end is on a seen wall is read from the
    seen walls within ``wall_min_px`` of it, and whether its obstacle stands off them from those within that
    reach.
    """
    top, left = int(rows.min()), int(cols.min())
    border = np.zeros((int(rows.max()) - top + 1, int(cols.max()) - left + 1), dtype=np.uint8)
    border[rows - top, cols - left] = 1
    _, pieces, box, _ = cv2.connectedComponentsWithStats(border, connectivity=_EIGHT)
    ends = []
    origin = np.array([top, left])
    total = 0.0
    long = np.flatnonzero(np.hypot(box[:, cv2.CC_STAT_WIDTH], box[:, cv2.CC_STAT_HEIGHT]) >= min_piece_px)
    long = long[long > 0]
    flat = np.unique((rows - top) * border.shape[1] + (cols - left))  # each pixel once
    pr, pc = np.divmod(flat, border.shape[1])
    label = pieces[pr, pc]
    for p in long.tolist():
        on = label == p
        centre, direction, extremes, _ = _axis(pr[on], pc[on])
        length = float(extremes[1] - extremes[0]) + 1
        if length >= min_piece_px:
            total += length
            ends.append(np.rint(centre + extremes[:, None] * direction[None, :]).astype(np.intp) + origin)
    if total <= min_border_px:
        return False
    h, w = seg.shape
    reach = int(np.ceil(min_border_px + wall_min_px))
    objects = []
    for y, x in np.concatenate(ends).tolist():
        window = (slice(max(y - reach, 0), min(y + reach + 1, h)), slice(max(x - reach, 0), min(x + reach + 1, w)))
        obstacle = _standing_obstacle(
            seg, free, parts, a, b, y, x, window, hit_reach_px=hit_reach_px, floor_share=floor_share
        )
        objects.append((y, x, window, obstacle))
    if all(obstacle is None for *_, obstacle in objects):
        return False
    near = int(np.ceil(wall_min_px))
    stands = False
    for y, x, window, obstacle in sorted(objects, key=lambda o: o[3] is not None):  # the ends with none first
        close = (slice(max(y - near, 0), min(y + near + 1, h)), slice(max(x - near, 0), min(x + near + 1, w)))
        if _seen_distance(free, occupied, wall, close, wall_min_px=wall_min_px)[y - close[0].start,
                                                                                x - close[1].start] <= on_wall_px:
            continue
        if obstacle is None or not _off_the_walls(
            obstacle, _seen_distance(free, occupied, wall, window, wall_min_px=wall_min_px),
            standing_off_px=standing_off_px, in_line_px=min_border_px, on_wall_px=on_wall_px,
        ):
            return False  # a jamb: a seen wall's, or one the laser never hit
        stands = True
    return stands


def _seen_distance(
    free: npt.NDArray[np.bool_],
    occupied: npt.NDArray[np.bool_],
    wall: npt.NDArray[np.bool_],
    window: tuple[slice, slice],
    *,
    wall_min_px: float,
) -> npt.NDArray[np.float32]:
    """The distance (pixels) to the seen walls (:func:`seen_walls`) found in ``window``, over the window."""
    seen = seen_walls(
        np.ascontiguousarray(free[window]), np.ascontiguousarray(occupied[window]),
        np.ascontiguousarray(wall[window]), min_length_px=wall_min_px,
    )
    return np.asarray(cv2.distanceTransform((~seen).view(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE),
                      dtype=np.float32)


def _standing_obstacle(
    seg: npt.NDArray[np.int32],
    free: npt.NDArray[np.bool_],
    parts: Components,
    a: int,
    b: int,
    y: int,
    x: int,
    window: tuple[slice, slice],
    *,
    hit_reach_px: int,
    floor_share: float,
) -> npt.NDArray[np.bool_] | None:
    """The obstacle (an 8-connected piece of hit cells, of ``parts``) within ``hit_reach_px`` of the end ``(y, x)``
    that lies inside ``window`` and may stand free on the floor of ``a`` and ``b``: the free space one pixel
    beyond that reach round it at least ``floor_share`` theirs. As a mask over ``window``; None without one."""
    labels = parts.labels
    near = labels[max(y - hit_reach_px, 0): y + hit_reach_px + 1, max(x - hit_reach_px, 0): x + hit_reach_px + 1]
    touched = np.unique(near[near > 0])
    if touched.size == 0:
        return None
    stats = parts.stats
    k = int(touched[np.argmax(np.hypot(stats[touched, cv2.CC_STAT_WIDTH], stats[touched, cv2.CC_STAT_HEIGHT]))])
    left, top = int(stats[k, cv2.CC_STAT_LEFT]), int(stats[k, cv2.CC_STAT_TOP])
    right, bottom = left + int(stats[k, cv2.CC_STAT_WIDTH]), top + int(stats[k, cv2.CC_STAT_HEIGHT])
    rows, cols = window
    if top <= rows.start or left <= cols.start or bottom >= rows.stop or right >= cols.stop:  # not looked at
        return None
    ring_px = hit_reach_px + 1
    box = (slice(max(top - ring_px, 0), bottom + ring_px), slice(max(left - ring_px, 0), right + ring_px))
    obstacle = labels[box] == k
    size = 2 * ring_px + 1
    ring = cv2.dilate(obstacle.view(np.uint8), np.ones((size, size), np.uint8)).view(bool) & ~obstacle & free[box]
    around = seg[box][ring]
    if around.size == 0 or np.count_nonzero((around == a) | (around == b)) < floor_share * around.size:
        return None
    out: npt.NDArray[np.bool_] = labels[window] == k
    return out


def _off_the_walls(
    obstacle: npt.NDArray[np.bool_],
    distance: npt.NDArray[np.float32],
    *,
    standing_off_px: float,
    in_line_px: float,
    on_wall_px: float,
) -> bool:
    """Whether ``obstacle`` stands off every seen wall (``distance`` to them, at least ``standing_off_px``) and no
    seen wall lies along its own line within ``in_line_px`` (round it, for a speck)."""
    r, c = nonzero_rc(obstacle)
    centre, direction, extremes, elongation = _axis(r, c)
    # a speck has no line of its own: any seen wall within that reach may be the one it is a dot of
    if float(distance[r, c].min()) < (standing_off_px if elongation >= _ELONGATED else in_line_px):
        return False
    h, w = distance.shape
    steps = np.arange(1, int(in_line_px) + 1, dtype=np.float64)
    for sign, t in ((-1.0, extremes[0]), (1.0, extremes[1])):
        at = centre[:, None] + direction[:, None] * (t + sign * steps)[None, :]
        yy = np.clip(np.rint(at[0]).astype(np.intp), 0, h - 1)
        xx = np.clip(np.rint(at[1]).astype(np.intp), 0, w - 1)
        if np.any(distance[yy, xx] <= on_wall_px):
            return False
    return True


def join_across_open_lines(
    segments: npt.NDArray[np.int32],
    crossed: npt.NDArray[np.bool_],
    *,
    joinable: npt.NDArray[np.bool_],
    min_border_px: int,
    reach_px: int,
) -> npt.NDArray[np.int32]:
    """Join two ``joinable`` segments whose border runs along a line across open floor between furniture.

    ``crossed`` holds the gaps :func:`~services.grid_decomposition.cogency.wall_evidence` left open as no doors side
    by side: the floor widens behind none of their stretches within the door depth on either side, so the floor
    within that depth of the line is one stretch of open floor, no doorway. A cut the room stage made there anyway
    (along the line, a little beside it) parts nothing: two segments whose border lies within ``reach_px`` (the door
    depth the widening was read over) of such a gap for at least ``min_border_px`` pixel pairs and for at least half
    its length are one region. Ids 1..M (consecutive).
    """
    seg = np.asarray(segments, dtype=np.int32)
    n = int(seg.max()) + 1
    keys, rows, cols = _border_pixels(seg, n)
    if keys.size == 0 or not crossed.any():
        return join_pairs(seg, np.zeros(0, np.int64), np.zeros(0, np.int64))
    k = 2 * reach_px + 1
    rs, cs = nonzero_rc(crossed)
    y0, x0 = max(0, int(rs.min()) - reach_px), max(0, int(cs.min()) - reach_px)
    y1, x1 = int(rs.max()) + reach_px + 1, int(cs.max()) + reach_px + 1
    near = np.zeros(seg.shape, dtype=bool)  # the gaps widened by the reach, in their box only
    near[y0:y1, x0:x1] = cv2.dilate(
        crossed[y0:y1, x0:x1].astype(np.uint8), cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k))
    ) > 0
    key, index = np.unique(keys, return_inverse=True)
    total = np.bincount(index, minlength=key.size)
    on = np.bincount(index, weights=near[rows, cols], minlength=key.size)
    first, second = key // n, key % n
    join = (on >= 2 * min_border_px) & (2 * on >= total) & joinable[first] & joinable[second]
    return join_pairs(seg, first[join], second[join])

"""Joining pieces of one furnished room: no neck between them, and together they are as convex as a room."""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np
import numpy.typing as npt
from scipy import sparse
from scipy.sparse import csgraph

from services.grid_decomposition.arrays import label_boxes, label_max, nonzero_rc
from services.grid_decomposition.segments import renumber, renumber_mapped


def join_room_pieces(
    segments: npt.NDArray[np.int32],
    furniture: npt.NDArray[np.bool_],
    *,
    resolution_m: float,
    furniture_reach_m: float = 1.0,
    fixed: npt.NDArray[np.bool_] | None = None,
    min_saddle_ratio: float = 0.8,
    min_solidity: float = 0.8,
    low_saddle_ratio: float = 0.5,
    min_relative_solidity: float = 0.95,
) -> npt.NDArray[np.int32]:
    """Join touching segments that are pieces of one furnished room rather than rooms joined by a doorway.

    On the clearance map of the floor (free space with ``furniture`` standing on it; distance to
    the nearest wall) a room is a basin whose peak is the middle of its floor. Two rooms joined by
    a doorway meet at a saddle (the middle of the doorway) much lower than the smaller room's
    peak; two pieces of one furnished room, cut apart along a gap between desks, meet at a saddle
    almost as high as the smaller piece's peak (``saddle >= min_saddle_ratio * min(peaks)``: the
    smaller piece has no room of its own behind the border). A wide opening between a small room
    and a corridor is no neck either: there the union has the shape of a T or an L, while two
    pieces of one room fill their convex hull (furniture holes counted in), so the union's
    solidity must reach ``min_solidity``. A furnished room's own outline is often far from convex
    (cupboards and desks against its walls), and a cupboard or desk can narrow it to a neck where it
    was cut: pieces of which one at least is less convex than ``min_solidity``, meeting at a saddle
    of at least ``low_saddle_ratio`` of the smaller peak, also join when their union is at least
    ``min_relative_solidity`` times as convex as the more convex piece (cutting a room in two
    leaves pieces no more convex than the room; a room and a corridor piece make a T or an L, less
    convex than either). Two convex pieces (rooms side by side, both rectangles) still need the
    first test: their union is convex too. Only borders with furniture within
    ``furniture_reach_m`` are joined: the pieces of a bare room were not cut by furniture (a row
    of bare cubicles, each as wide as its opening onto the corridor, stays apart).

    Pairs are joined best solidity first, one join per segment per round, until none is left;
    a joined segment's peak is the higher of its pieces'.

    Parameters
    ----------
    segments : (H, W) int32
        Segment ids 1..N per pixel, 0 = none.
    furniture : (H, W) bool
        Obstacles standing on the floor of the rooms (floor for the clearance).
    resolution_m : float
        Metres per pixel.
    fixed : (N + 1,) bool, optional
        Per segment id: never joined (warehouse floors, road networks).
    low_saddle_ratio, min_relative_solidity : float
        The second test above; ``min_relative_solidity=np.inf`` turns it off.

    Returns
    -------
    (H, W) int32
        Segment ids 1..M (consecutive), 0 where ``segments`` is 0.
    """
    seg = np.asarray(segments, dtype=np.int32)
    n = int(seg.max()) + 1
    if n <= 2:
        return renumber(seg)
    floor = ((seg > 0) | furniture).astype(np.uint8)
    # all that follows reads the floor and what lies near it: the box round the floor and a pixel of no floor
    # round it holds the same clearance (the nearest pixel off the floor is that pixel or nearer), borders and
    # furniture, and the ids keep their order
    rows, cols = np.flatnonzero(floor.any(axis=1)), np.flatnonzero(floor.any(axis=0))
    box = (slice(max(int(rows[0]) - 1, 0), int(rows[-1]) + 2), slice(max(int(cols[0]) - 1, 0), int(cols[-1]) + 2))
    if floor[box].shape != floor.shape:
        out = np.zeros(seg.shape, dtype=np.int32)
        out[box] = join_room_pieces(
            seg[box], furniture[box], resolution_m=resolution_m, furniture_reach_m=furniture_reach_m, fixed=fixed,
            min_saddle_ratio=min_saddle_ratio, min_solidity=min_solidity, low_saddle_ratio=low_saddle_ratio,
            min_relative_solidity=min_relative_solidity,
        )
        return out
    clearance = np.asarray(cv2.distanceTransform(floor, cv2.DIST_L2, 5), dtype=np.float32)
    reach = max(1, round(furniture_reach_m / resolution_m))
    peak = label_max(seg, clearance, n)[0]  # clearance >= 0: off the floor a segment's peak stays 0
    frozen = np.zeros(n, dtype=bool) if fixed is None else np.asarray(fixed[:n], dtype=bool).copy()
    frozen[0] = True
    pairs, saddle, furnished = _saddles(seg, clearance, furniture, reach)
    pieces = _Pieces(seg.copy(), _boxes(seg, n))
    lut = np.arange(n, dtype=np.int32)  # segment id -> the id of the segment it has joined
    while True:
        keep = furnished & ~frozen[pairs[:, 0]] & ~frozen[pairs[:, 1]]
        lower = np.minimum(peak[pairs[:, 0]], peak[pairs[:, 1]])
        high, low = saddle >= min_saddle_ratio * lower, saddle >= low_saddle_ratio * lower
        keep &= high | low
        candidates, high, low = pairs[keep], high[keep], low[keep]
        if candidates.size == 0:
            break
        # a pair that only reaches the second test, of two convex pieces, cannot join: its union is not looked at
        solid = np.zeros(len(candidates))
        for i, (a, b) in enumerate(candidates.tolist()):
            if high[i] or min(pieces.solidity(a, a), pieces.solidity(b, b)) < min_solidity:
                solid[i] = pieces.solidity(a, b)
        joins = high & (solid >= min_solidity)
        # a room cut in two: its union no less convex than its more convex piece (a room and a corridor: a T or
        # L), when a piece is not convex itself (two convex rooms side by side make a convex union too)
        for k in np.flatnonzero(low & ~joins):
            a, b = (int(v) for v in candidates[k])
            sa, sb = sorted((pieces.solidity(a, a), pieces.solidity(b, b)))
            joins[k] = sa < min_solidity and solid[k] >= min_relative_solidity * sb
        order = np.argsort(-solid, kind="stable")
        used = np.zeros(n, dtype=bool)
        for k in order[joins[order]]:
            a, b = (int(v) for v in candidates[k])
            if used[a] or used[b]:
                continue
            used[a] = used[b] = True
            lut[lut == b] = a
            pieces.join(a, b)
            peak[a] = max(peak[a], peak[b])
        if not used.any():
            break
        pieces.known = {ab: s for ab, s in pieces.known.items() if not (used[ab[0]] or used[ab[1]])}
        pairs, saddle, furnished = _merge_pairs(lut[pairs].astype(np.int64), saddle, furnished, n)
    return renumber(pieces.current, copy=False)  # its own copy of the segments


def _saddles(
    seg: npt.NDArray[np.int32], clearance: npt.NDArray[np.float32], furniture: npt.NDArray[np.bool_], reach: int
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.float32], npt.NDArray[np.bool_]]:
    """Touching segment pairs (a < b), the highest clearance along their border, and whether furniture is
    within ``reach`` (the elliptic disc of that radius) of it."""
    n = int(seg.max()) + 1
    w = seg.shape[1]
    keys: list[npt.NDArray[np.int64]] = []
    heights: list[npt.NDArray[np.float32]] = []
    sides: list[npt.NDArray[np.int64]] = []
    for dy, dx, rows, cols in _touching(seg):
        p, q = seg[rows, cols].astype(np.int64), seg[rows + dy, cols + dx].astype(np.int64)
        keys.append(np.minimum(p, q) * n + np.maximum(p, q))
        heights.append(np.minimum(clearance[rows, cols], clearance[rows + dy, cols + dx]))
        sides.append(rows.astype(np.int64) * w + cols)
        sides.append((rows.astype(np.int64) + dy) * w + cols + dx)
    near = _near(furniture, np.concatenate(sides), reach)
    half = sides[0].size, sides[0].size + sides[1].size, sides[0].size + sides[1].size + sides[2].size
    nears = np.concatenate([near[: half[0]] | near[half[0] : half[1]], near[half[1] : half[2]] | near[half[2] :]])
    return _merge_pairs_keys(np.concatenate(keys), np.concatenate(heights), nears, n)


def _touching(seg: npt.NDArray[np.int32]) -> list[tuple[int, int, npt.NDArray[np.intp], npt.NDArray[np.intp]]]:
    """Per step (``dy``, ``dx``) right and down: rows and columns of the pixels whose neighbour that step away is
    in another segment (both ids > 0; raster order), looked for within the box round the segments (there are some)."""
    rows, cols = _segment_box(seg)
    r0, c0 = rows.start, cols.start
    box = seg[rows, cols]
    inside = box > 0
    h, w = box.shape
    found = []
    for dy, dx in ((0, 1), (1, 0)):
        a, b = box[: h - dy, : w - dx], box[dy:, dx:]
        differ = a != b
        differ &= inside[: h - dy, : w - dx]
        differ &= inside[dy:, dx:]
        r, c = nonzero_rc(differ)
        found.append((dy, dx, r + r0, c + c0))
    return found


def _near(furniture: npt.NDArray[np.bool_], pixels: npt.NDArray[np.int64], reach: int) -> npt.NDArray[np.bool_]:
    """Per flat pixel index: furniture within the elliptic disc of radius ``reach`` (``cv2.dilate`` by
    ``cv2.MORPH_ELLIPSE`` read at these pixels), from the furniture counts of the disc's rows."""
    h, w = furniture.shape
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * reach + 1, 2 * reach + 1))
    # the furniture pixels of row y left of column x: table[y + 1, x] - table[y, x] of the summed-area table
    # (whole numbers; OpenCV's table is one pass, a tenth of a row-wise cumsum's time)
    table = cv2.integral(furniture.view(np.uint8), sdepth=cv2.CV_32S if furniture.size < 2**31 else cv2.CV_64F)
    table, stride = table.ravel(), w + 1
    at, inverse = np.unique(pixels, return_inverse=True)
    y, x = np.divmod(at, w)  # y ascending: the pixels whose row y + dy lies in the image are one slice
    out = np.zeros(at.size, dtype=bool)
    ends: dict[int, tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]] = {}  # per half width: the rows' ends
    for dy, row in zip(range(-reach, reach + 1), disc, strict=True):
        half = (int(np.count_nonzero(row)) - 1) // 2
        if half < 0:
            continue
        if half not in ends:  # x - half < w and x + half + 1 > 0: one bound each
            ends[half] = np.maximum(x - half, 0), np.minimum(x + half + 1, w)
        on = slice(int(np.searchsorted(y, -dy)), int(np.searchsorted(y, h - dy)))
        x0, x1 = ends[half][0][on], ends[half][1][on]
        above = (y[on] + dy) * stride  # row y + dy of the table; row y + dy + 1 is a stride further
        below = above + stride
        out[on] |= table[below + x1] - table[above + x1] > table[below + x0] - table[above + x0]
    return out[inverse.ravel()]


def _merge_pairs(
    pairs: npt.NDArray[np.int64], saddle: npt.NDArray[np.float32], furnished: npt.NDArray[np.bool_], n: int
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.float32], npt.NDArray[np.bool_]]:
    """The pairs of :func:`_saddles` after joins (``pairs`` renamed to the joined ids): pairs now one
    segment dropped, the others' borders pooled."""
    apart = pairs[:, 0] != pairs[:, 1]
    p, q = pairs[apart, 0], pairs[apart, 1]
    return _merge_pairs_keys(np.minimum(p, q) * n + np.maximum(p, q), saddle[apart], furnished[apart], n)


def _merge_pairs_keys(
    key: npt.NDArray[np.int64], height: npt.NDArray[np.float32], near: npt.NDArray[np.bool_], n: int
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.float32], npt.NDArray[np.bool_]]:
    codes, inverse = np.unique(key, return_inverse=True)
    top = np.zeros(codes.size, dtype=np.float32)
    np.maximum.at(top, inverse, height)
    furnished = np.bincount(inverse, weights=near, minlength=codes.size) > 0
    return np.stack([codes // n, codes % n], axis=1), top, furnished


def _segment_box(seg: npt.NDArray[np.int32]) -> tuple[slice, slice]:
    """Rows and columns of the box round the segments (there are some)."""
    inside = seg > 0
    rows, cols = np.flatnonzero(inside.any(axis=1)), np.flatnonzero(inside.any(axis=0))
    return slice(int(rows[0]), int(rows[-1]) + 1), slice(int(cols[0]), int(cols[-1]) + 1)


def _boxes(seg: npt.NDArray[np.int32], n: int) -> npt.NDArray[np.int64]:
    """(n, 4) bounding box (row0, col0, row1, col1) of every segment id (zeros where it has no pixel)."""
    boxes = np.zeros((n, 4), dtype=np.int64)
    for i, box in enumerate(label_boxes(seg, n - 1), start=1):  # scipy's find_objects, from the runs
        if box is not None:
            boxes[i] = box[0].start, box[1].start, box[0].stop, box[1].stop
    return boxes


@dataclass
class _Pieces:
    """The segments of :func:`join_room_pieces` while they join: their ids per pixel (``lut[seg]``), boxes
    (:func:`_boxes`), convex hulls (image coordinates, found when first asked for) and the solidities known."""

    current: npt.NDArray[np.int32]
    boxes: npt.NDArray[np.int64]
    hulls: dict[int, npt.NDArray[np.int32]] = field(default_factory=dict)
    known: dict[tuple[int, int], float] = field(default_factory=dict)

    def hull(self, a: int) -> npt.NDArray[np.int32]:
        """Convex hull of segment ``a`` (the hull of its outlines is the hull of its pixels)."""
        if a not in self.hulls:
            r0, c0, r1, c1 = (int(v) for v in self.boxes[a])
            piece = (self.current[r0:r1, c0:c1] == a).view(np.uint8)
            outlines, _ = cv2.findContours(piece, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE, offset=(c0, r0))
            self.hulls[a] = np.asarray(cv2.convexHull(np.concatenate(outlines)), dtype=np.int32)
        return self.hulls[a]

    def solidity(self, a: int, b: int) -> float:
        """Area of segments ``a`` and ``b`` together, holes filled, over the area of their convex hull."""
        if (a, b) in self.known:
            return self.known[a, b]
        r0, c0 = np.minimum(self.boxes[a, :2], self.boxes[b, :2])
        r1, c1 = np.maximum(self.boxes[a, 2:], self.boxes[b, 2:])
        crop = self.current[r0:r1, c0:c1]
        union = (crop == a).view(np.uint8) if a == b else ((crop == a) | (crop == b)).view(np.uint8)
        # holes filled: every pixel but the background reached from round the box
        padded = cv2.copyMakeBorder(union, 1, 1, 1, 1, cv2.BORDER_CONSTANT, value=0)
        filled = padded.size - cv2.floodFill(padded, None, (0, 0), 2)[0]
        # the hull of the union is the hull of the pieces' hulls
        hull = self.hull(a) if a == b else cv2.convexHull(np.concatenate([self.hull(a), self.hull(b)]))
        # pixel centres span the hull: half a pixel all round is still the union's area
        hull_area = cv2.contourArea(hull) + 0.5 * cv2.arcLength(hull, True) + 1.0
        self.known[a, b] = float(filled / hull_area)
        return self.known[a, b]

    def join(self, a: int, b: int) -> None:
        """Segment ``b`` joins ``a``."""
        r0, c0, r1, c1 = (int(v) for v in self.boxes[b])
        box = self.current[r0:r1, c0:c1]
        box[box == b] = a
        self.boxes[a, :2] = np.minimum(self.boxes[a, :2], self.boxes[b, :2])
        self.boxes[a, 2:] = np.maximum(self.boxes[a, 2:], self.boxes[b, 2:])
        if a in self.hulls and b in self.hulls:
            self.hulls[a] = np.asarray(cv2.convexHull(np.concatenate([self.hulls[a], self.hulls[b]])), dtype=np.int32)
        else:
            self.hulls.pop(a, None)
        self.hulls.pop(b, None)


def join_furnished_groups(
    segments: npt.NDArray[np.int32],
    furniture: npt.NDArray[np.bool_],
    *,
    doors: npt.NDArray[np.bool_] | None = None,
    reach_px: int = 2,
    wall_reach_px: float = 10.0,
    fixed: npt.NDArray[np.bool_] | None = None,
    min_solidity: float = 0.8,
) -> npt.NDArray[np.int32]:
    """Join the pieces of an open-plan room that only furniture separates, when together they are room-shaped.

    Desk clusters standing free in an open-plan office end the room stage's cuts (a doorway cut or
    neck from a cluster to the wall, a line along a cluster's edge) and cut the office into pieces
    that no pair test joins: two pieces wrapped round a cluster are not convex together, only the
    whole office is. A border between two pieces is *furniture-made* when every run of it (a
    connected stretch of border pixels: one cut, one line) comes within ``reach_px`` of
    ``furniture`` and none lies on ``doors`` (doorways between two walls, whatever stands beside
    them), and what stands between the two pieces is furniture rather than wall: the line of
    obstacle pixels as near to one piece as to the other (their Voronoi border inside the
    obstacles) is at least as long through ``furniture`` as through walls within ``wall_reach_px``
    of both pieces (a partition between two rooms; the outside beyond an outer wall is farther).
    Pieces linked so form a group, and a group becomes one segment when it is shaped like one
    room: its floor with the furniture it touches fills at least ``min_solidity`` of its convex
    hull. A group that also takes in a corridor through furniture at its door is an L or a T, and
    a corridor ring round a block of rooms has the block in its hull (no hole is filled that is
    not furniture): they stay in their pieces.

    Parameters
    ----------
    segments : (H, W) int32
        Segment ids 1..N per pixel, 0 = none.
    furniture : (H, W) bool
        Obstacles standing free on the floor: furniture, desk clusters (off the segments).
    doors : (H, W) bool, optional
        Doorways between walls (a border run on one is never furniture-made).
    fixed : (N + 1,) bool, optional
        Per segment id: never joined (warehouse floors, road networks).

    Returns
    -------
    (H, W) int32
        Segment ids 1..M (consecutive), 0 where ``segments`` is 0.
    """
    seg = np.asarray(segments, dtype=np.int32)
    n = int(seg.max()) + 1
    if n <= 2 or not furniture.any():
        return renumber(seg)
    h, w = seg.shape
    keys: list[npt.NDArray[np.int64]] = []
    sides: list[npt.NDArray[np.int64]] = []
    for dy, dx, rows, cols in _touching(seg):
        p, q = seg[rows, cols].astype(np.int64), seg[rows + dy, cols + dx].astype(np.int64)
        key = np.minimum(p, q) * n + np.maximum(p, q)
        keys += [key, key]
        sides += [rows.astype(np.int64) * w + cols, (rows.astype(np.int64) + dy) * w + cols + dx]
    key, pixel = np.concatenate(keys), np.concatenate(sides)
    if key.size == 0:
        return renumber(seg)
    codes, pair = np.unique(key, return_inverse=True)
    pair = pair.ravel()
    size = 2 * reach_px + 1
    standing_bytes = np.ascontiguousarray(furniture, dtype=bool).view(np.uint8)  # OpenCV reads the flags as 0/1
    near = np.asarray(cv2.dilate(standing_bytes, np.ones((size, size), np.uint8))).view(bool).ravel()
    run, n_runs = _runs(pixel, pair, h, w)
    made = np.zeros(n_runs, dtype=bool)
    made[run[near[pixel]]] = True
    if doors is not None:  # a doorway between two walls stays one, whatever stands beside it
        made[run[doors.ravel()[pixel]]] = False
    linked = np.bincount(pair, weights=~made[run], minlength=codes.size) == 0
    frozen = np.zeros(n, dtype=bool) if fixed is None else np.asarray(fixed[:n], dtype=bool).copy()
    frozen[0] = True
    a, b = codes // n, codes % n
    linked &= ~frozen[a] & ~frozen[b]
    if not linked.any():  # no separator looked at
        return renumber(seg)
    through_wall, through_furniture = _separators(seg, furniture, codes, n, wall_reach_px)
    linked &= through_wall <= through_furniture
    if not linked.any():
        return renumber(seg)
    graph = sparse.coo_matrix((np.ones(int(linked.sum())), (a[linked], b[linked])), shape=(n, n))
    _, group = csgraph.connected_components(graph, directed=False)
    members = np.bincount(group, minlength=n)
    if not (members >= 2).any():  # no group to look at: the furniture is not labelled
        return renumber(seg)
    lut = np.arange(n, dtype=np.int32)
    # the furniture's pieces, labelled in the box round it and a pixel more (the same pieces; only which pixels
    # share a piece is read, not its number)
    rows, cols = np.flatnonzero(standing_bytes.any(axis=1)), np.flatnonzero(standing_bytes.any(axis=0))
    box = (slice(max(int(rows[0]) - 1, 0), int(rows[-1]) + 2), slice(max(int(cols[0]) - 1, 0), int(cols[-1]) + 2))
    standing = np.zeros((h, w), dtype=np.int32)
    standing[box] = cv2.connectedComponents(standing_bytes[box], connectivity=8)[1]
    boxes = _boxes(seg, n)
    for g in np.flatnonzero(members >= 2).tolist():
        ids = np.flatnonzero(group == g)
        if _group_solidity(seg, ids, boxes, standing, n) >= min_solidity:
            lut[ids] = ids[0]
    return renumber_mapped(lut, seg)


def _separators(
    seg: npt.NDArray[np.int32], furniture: npt.NDArray[np.bool_], codes: npt.NDArray[np.int64], n: int, wall_px: float
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Per pair ``codes`` (``a * n + b``): pixels of their Voronoi border inside the obstacles (neighbouring
    obstacle pixels nearest to ``a`` and to ``b``) on walls within ``wall_px`` of both, and on ``furniture``."""
    # only the box round the segments and the furniture holds such pixels (a wall beyond it is farther)
    margin = int(np.ceil(wall_px)) + 2
    present = (seg > 0) | furniture
    rows, cols = np.flatnonzero(present.any(axis=1)), np.flatnonzero(present.any(axis=0))
    box = (
        slice(max(int(rows[0]) - margin, 0), int(rows[-1]) + 1 + margin),
        slice(max(int(cols[0]) - margin, 0), int(cols[-1]) + 1 + margin),
    )
    seg, furniture = seg[box], furniture[box]
    blocked = (seg == 0).astype(np.uint8)
    dist, label = cv2.distanceTransformWithLabels(blocked, cv2.DIST_L2, 5, labelType=cv2.DIST_LABEL_PIXEL)
    owners = seg[seg > 0]  # per label (pixel of a segment): its segment, > 0
    index = np.asarray(label, dtype=np.int32)
    index -= 1
    nearest = np.take(owners, index)  # a segment's own pixels too: they are left out by ``on``
    on = blocked.view(bool)
    h, w = seg.shape
    wall = np.zeros(codes.size)
    furn = np.zeros(codes.size)
    for dy, dx in ((0, 1), (1, 0)):
        a, b = nearest[: h - dy, : w - dx], nearest[dy:, dx:]
        both = on[: h - dy, : w - dx] & on[dy:, dx:] & (a != b)
        rows, cols = nonzero_rc(both)
        p, q = a[rows, cols].astype(np.int64), b[rows, cols].astype(np.int64)
        key = np.minimum(p, q) * n + np.maximum(p, q)
        at = np.minimum(np.searchsorted(codes, key), codes.size - 1)
        known = codes[at] == key
        d = np.maximum(dist[rows, cols], dist[rows + dy, cols + dx])
        f = furniture[rows, cols] | furniture[rows + dy, cols + dx]
        np.add.at(furn, at[known & f], 1.0)
        np.add.at(wall, at[known & ~f & (d <= wall_px)], 1.0)
    return wall, furn


def _runs(
    pixel: npt.NDArray[np.int64], pair: npt.NDArray[np.int64], h: int, w: int
) -> tuple[npt.NDArray[np.int64], int]:
    """Per border pixel entry (flat ``pixel``, ``pair`` index): its run, the 8-connected stretch of border
    pixels of the same pair it lies on; and the number of runs."""
    code = pair * (h * w) + pixel
    unique, entry = np.unique(code, return_inverse=True)
    entry = entry.ravel()
    at_pixel, at_pair = unique % (h * w), unique // (h * w)
    row, col = np.divmod(at_pixel, w)
    starts, ends = [], []
    for dy, dx in ((0, 1), (1, 0), (1, 1), (1, -1)):
        inside = (row + dy < h) & (col + dx >= 0) & (col + dx < w)
        other = at_pair * (h * w) + at_pixel + dy * w + dx
        at = np.minimum(np.searchsorted(unique, other), unique.size - 1)
        found = np.flatnonzero(inside & (unique[at] == other))
        starts.append(found)
        ends.append(at[found])
    i, j = np.concatenate(starts), np.concatenate(ends)
    graph = sparse.coo_matrix((np.ones(i.size), (i, j)), shape=(unique.size, unique.size))
    n_runs, run = csgraph.connected_components(graph, directed=False)
    return run[entry], int(n_runs)


def _group_solidity(
    seg: npt.NDArray[np.int32],
    ids: npt.NDArray[np.int64],
    boxes: npt.NDArray[np.int64],
    standing: npt.NDArray[np.int32],
    n: int,
) -> float:
    """Area of the segments ``ids`` with the furniture pieces (``standing`` ids) touching them over the
    area of their convex hull."""
    member = np.zeros(n, dtype=bool)
    member[ids] = True
    r0, c0 = (max(int(v) - 1, 0) for v in boxes[ids, :2].min(axis=0))
    r1, c1 = (int(v) + 1 for v in boxes[ids, 2:].max(axis=0))
    union = member[seg[r0:r1, c0:c1]]
    crop = standing[r0:r1, c0:c1]
    touching = np.unique(crop[cv2.dilate(union.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)])
    union |= np.isin(crop, touching[touching > 0])
    outlines, _ = cv2.findContours(union.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    hull = cv2.convexHull(np.concatenate(outlines))
    hull_area = cv2.contourArea(hull) + 0.5 * cv2.arcLength(hull, True) + 1.0
    return float(np.count_nonzero(union) / hull_area)

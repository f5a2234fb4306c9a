"""Borders between regions read as openings: regions parted by a cut that is no doorway join again."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import numpy.typing as npt
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from services.grid_decomposition.arrays import border_steps, label_counts, lookup, near_at, nonzero_rc
from services.grid_decomposition.segments import renumber


class Openings(NamedTuple):
    """Borders between two segments that are one straight cut.

    Attributes
    ----------
    first, second : (K,) int64
        The two segment ids (``first < second``).
    ends : (K, 2, 2) float64
        The cut's two ends, (x, y) pixels, on the border's principal line.
    width_px : (K,) float64
        Distance between the ends.
    """

    first: npt.NDArray[np.int64]
    second: npt.NDArray[np.int64]
    ends: npt.NDArray[np.float64]
    width_px: npt.NDArray[np.float64]


def straight_openings(
    segments: npt.NDArray[np.int32], obstacle: npt.NDArray[np.bool_], *, max_spread_px: float = 1.5
) -> Openings:
    """The borders between two segments on free pixels that are one straight cut.

    A border is the 4-neighbour pixel pairs of two segments, both pixels free (not ``obstacle``: regions take in
    the furniture and the walls stuffed with it, whose borders are no opening), read at the pairs' midpoints. It is
    straight when its points lie within ``max_spread_px`` of their principal line (root mean square): a cut or a
    line across an opening, not the long crooked border of two regions side by side.
    """
    seg = np.asarray(segments, dtype=np.int32)
    n = int(seg.max()) + 1
    keys: list[npt.NDArray[np.int64]] = []
    xs: list[npt.NDArray[np.float64]] = []
    ys: list[npt.NDArray[np.float64]] = []
    for dy, dx, r, c, key in border_steps(seg, n, ~obstacle):
        keys.append(key)
        xs.append(c.astype(np.float64) + dx / 2)
        ys.append(r.astype(np.float64) + dy / 2)
    key = np.concatenate(keys)
    x, y = np.concatenate(xs), np.concatenate(ys)
    pair, which = np.unique(key, return_inverse=True)
    count = np.bincount(which, minlength=pair.size).astype(np.float64)
    mx = np.bincount(which, x, minlength=pair.size) / np.maximum(count, 1)
    my = np.bincount(which, y, minlength=pair.size) / np.maximum(count, 1)
    dx_, dy_ = x - mx[which], y - my[which]
    sxx, syy, sxy = (
        np.bincount(which, d, minlength=pair.size) / np.maximum(count, 1) for d in (dx_ * dx_, dy_ * dy_, dx_ * dy_)
    )
    angle = 0.5 * np.arctan2(2 * sxy, sxx - syy)  # the border's principal direction
    cos, sin = np.cos(angle), np.sin(angle)
    along = dx_ * cos[which] + dy_ * sin[which]
    spread = np.sqrt(np.bincount(which, (dy_ * cos[which] - dx_ * sin[which]) ** 2, minlength=pair.size)
                     / np.maximum(count, 1))
    t0 = np.full(pair.size, np.inf)
    t1 = np.full(pair.size, -np.inf)
    np.minimum.at(t0, which, along)
    np.maximum.at(t1, which, along)
    k = np.flatnonzero(spread <= max_spread_px)
    ends = np.stack(
        [np.stack([mx[k] + t * cos[k], my[k] + t * sin[k]], axis=1) for t in (t0[k], t1[k])], axis=1
    ).reshape(k.size, 2, 2)
    return Openings(pair[k] // n, pair[k] % n, ends, t1[k] - t0[k])


def join_pairs(
    segments: npt.NDArray[np.int32], first: npt.NDArray[np.int64], second: npt.NDArray[np.int64]
) -> npt.NDArray[np.int32]:
    """Segments with each pair ``(first[i], second[i])`` (and what it links to) one segment; ids 1..M in order."""
    seg = np.asarray(segments, dtype=np.int32)
    if first.size == 0:
        return renumber(seg)
    n = int(seg.max()) + 1
    _, group = connected_components(coo_matrix((np.ones(first.size), (first, second)), shape=(n, n)), directed=False)
    present = label_counts(seg, n)[0] > 0
    present[0] = False
    _, dense = np.unique(group[present], return_inverse=True)
    lut = np.zeros(n, dtype=np.int32)
    lut[present] = dense + 1
    return lookup(lut, seg)


def join_unseen_openings(
    segments: npt.NDArray[np.int32],
    obstacle: npt.NDArray[np.bool_],
    occupied: npt.NDArray[np.bool_],
    *,
    resolution_m: float,
    fixed: npt.NDArray[np.bool_] | None = None,
    max_width_m: float = 2.5,
    unseen_m: float = 0.75,
    max_spread_px: float = 1.5,
) -> npt.NDArray[np.int32]:
    """Join two segments parted by a straight cut that ends on nothing the laser saw at either end.

    A doorway is an opening in a wall, and the laser sees a wall where it hits it: occupied cells at the jambs, or
    within a grey (unknown) wall a few pixels off the floor. A cut (a closed gap along a line, a free-space cut,
    a neck) at most ``max_width_m`` long (:func:`straight_openings`) with no ``occupied`` cell within ``unseen_m``
    of either end runs from unknown space to unknown space: across a strip of laser rays between the shadows of
    the rays and the unexplored edge of the map. It parts nothing the map shows, so its two sides are one region.
    ``fixed`` (per segment id, warehouse floors) segments never join. Ids 1..M (consecutive).
    """
    seg = np.asarray(segments, dtype=np.int32)
    n = int(seg.max()) + 1
    if n < 3 or (fixed is not None and np.count_nonzero(~fixed[1:n]) < 2):  # no pair may join (a rack hall)
        return renumber(seg)
    cuts = straight_openings(seg, obstacle, max_spread_px=max_spread_px)
    keep = cuts.width_px * resolution_m <= max_width_m
    if fixed is not None:
        keep &= ~fixed[cuts.first] & ~fixed[cuts.second]
    if not keep.any():
        return renumber(seg)
    h, w = seg.shape
    x = np.clip(np.rint(cuts.ends[..., 0]).astype(np.int64), 0, w - 1)
    y = np.clip(np.rint(cuts.ends[..., 1]).astype(np.int64), 0, h - 1)
    # the chamfer distance to the occupied cells above unseen_m, read at the ends only (no whole-image transform)
    seen = near_at(occupied, y.ravel(), x.ravel(), unseen_m / resolution_m, 5).reshape(y.shape)
    keep &= ~seen.any(axis=1)
    return join_pairs(seg, cuts.first[keep], cuts.second[keep])


def join_unseen_passages(
    segments: npt.NDArray[np.int32],
    obstacle: npt.NDArray[np.bool_],
    occupied: npt.NDArray[np.bool_],
    *,
    resolution_m: float,
    fixed: npt.NDArray[np.bool_] | None = None,
    max_area_m2: float = 3.0,
    min_border_m: float = 0.5,
    seen_min_m: float = 0.5,
    max_spread_px: float = 1.5,
) -> npt.NDArray[np.int32]:
    """Join a short piece of corridor between two cuts to both its sides when the laser hit no wall beside it.

    A piece smaller than ``max_area_m2`` that borders exactly two other segments, each along a straight cut at least
    ``min_border_m`` long (:func:`straight_openings`), lies between two doorways, each a gap between jambs. A jamb
    the laser saw is occupied cells at the floor's edge; where the cells touching the piece (8-neighbours) are
    occupied along less than ``seen_min_m`` in all, its walls are the grey (unknown) fringe of walls seen from afar
    and its cuts end on bumps of that fringe: they part nothing seen, so the piece and both its sides are one
    region. ``fixed`` (per segment id, warehouse floors) segments never join. Ids 1..M (consecutive).
    """
    seg = np.asarray(segments, dtype=np.int32)
    n = int(seg.max()) + 1
    if n < 4:  # a piece and two sides
        return renumber(seg)
    area = label_counts(seg, n)[0]
    piece = (area > 0) & (area < max_area_m2 / resolution_m**2)
    piece[0] = False
    if fixed is not None:
        piece &= ~np.asarray(fixed[:n], dtype=bool)
    if not piece.any():
        return renumber(seg)
    # the pieces' pixels (few): their neighbours and the occupied cells beside them are looked up from these alone
    h, w = seg.shape
    r, c = nonzero_rc(lookup(piece, seg))
    own = seg[r, c].astype(np.int64)
    keys = []  # each piece's 4-neighbour segments
    for dy, dx in ((0, 1), (1, 0), (0, -1), (-1, 0)):
        rr, cc = r + dy, c + dx
        ok = (rr >= 0) & (rr < h) & (cc >= 0) & (cc < w)
        other = seg[rr[ok], cc[ok]].astype(np.int64)
        diff = (other != own[ok]) & (other > 0)
        keys.append(own[ok][diff] * n + other[diff])
    pair = np.unique(np.concatenate(keys))
    piece &= np.bincount(pair // n, minlength=n) == 2
    if not piece.any():
        return renumber(seg)
    cuts = straight_openings(seg, obstacle, max_spread_px=max_spread_px)
    long = cuts.width_px * resolution_m >= min_border_m
    ends = np.concatenate([cuts.first[long], cuts.second[long]])
    piece &= np.bincount(ends, minlength=n) == 2  # both its borders are long straight cuts
    first, second = cuts.first[long], cuts.second[long]
    if fixed is not None:  # a piece beside a warehouse floor stays
        held = np.asarray(fixed[:n], dtype=bool)
        piece[first[held[second]]] = False
        piece[second[held[first]]] = False
    if not piece.any():
        return renumber(seg)
    # the occupied cells touching each piece (8-neighbours of its pixels), each counted once per piece
    on = piece[own]
    r, c, own = r[on], c[on], own[on]
    touching = []
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            rr, cc = np.clip(r + dy, 0, h - 1), np.clip(c + dx, 0, w - 1)
            hit = occupied[rr, cc]
            touching.append((rr[hit].astype(np.int64) * w + cc[hit]) * n + own[hit])
    seen = np.bincount(np.unique(np.concatenate(touching)) % n, minlength=n)
    piece &= seen * resolution_m < seen_min_m
    take = piece[first] | piece[second]
    return join_pairs(seg, first[take], second[take])

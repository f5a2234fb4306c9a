"""From per-face segment ids to a clean per-pixel segmentation of free space."""

from __future__ import annotations

from typing import TypeVar

import cv2
import numpy as np
import numpy.typing as npt
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from services.grid_decomposition.arrays import (
    components_stats,
    distinct,
    label_boxes,
    label_counts,
    label_max,
    lookup,
    unique_inverse,
    value_runs,
)

_Id = TypeVar("_Id", np.int32, np.uint8)


def fill_from_neighbours(
    segments: npt.NDArray[np.int32],
    target: npt.NDArray[np.bool_],
    *,
    max_iterations: int = 200,
    overwrite: bool = False,
) -> npt.NDArray[np.int32]:
    """Give unlabelled (0) ``target`` pixels the id of a labelled 8-neighbour, growing outwards.

    Each step, every hole next to a labelled pixel takes the largest id among its labelled
    8-neighbours (a grey dilation restricted to the holes). Only the front moves: the work is
    proportional to the pixels filled, not to the image (a few streak pixels on a 9 Mpx hall).
    With ``overwrite`` a C-contiguous int32 ``segments`` may be filled in place and returned (an
    image the caller drew for this: no whole-image copy); else the result is a new array.
    """
    return _fill(np.asarray(segments), target, max_iterations, np.int32, overwrite)


def fill_bytes_from_neighbours(
    labels: npt.NDArray[np.uint8],
    target: npt.NDArray[np.bool_],
    *,
    max_iterations: int = 200,
    overwrite: bool = False,
) -> npt.NDArray[np.uint8]:
    """:func:`fill_from_neighbours` of ids below 256, worked and returned in uint8 (a quarter of the memory)."""
    return _fill(np.asarray(labels, dtype=np.uint8), target, max_iterations, np.uint8, overwrite)


def _working(segments: npt.NDArray[np.integer], dtype: type[_Id], overwrite: bool) -> npt.NDArray[_Id]:
    """``segments`` itself when it may be overwritten and is a writable C-contiguous image of ``dtype``, else a copy
    (the fill writes through flat views)."""
    if overwrite and segments.dtype == dtype and segments.flags.c_contiguous and segments.flags.writeable:
        return segments  # type: ignore[return-value]  # checked: of dtype
    return np.array(segments, dtype=dtype, order="C")  # C-ordered: a column-ordered image's flat view would be a copy


def _fill(
    segments: npt.NDArray[np.integer],
    target: npt.NDArray[np.bool_],
    max_iterations: int,
    dtype: type[_Id],
    overwrite: bool,
) -> npt.NDArray[_Id]:
    hole = target & (segments == 0)
    rows = np.flatnonzero(hole.any(axis=1))
    if rows.size == 0:
        return _working(segments, dtype, overwrite)
    cols = np.flatnonzero(hole.any(axis=0))
    # the holes' bounding box and one pixel around it: every labelled pixel next to a hole
    height, width = segments.shape
    r0, r1 = max(int(rows[0]) - 1, 0), min(int(rows[-1]) + 2, height)
    c0, c1 = max(int(cols[0]) - 1, 0), min(int(cols[-1]) + 2, width)
    framed_size = (r1 - r0 + 2) * (c1 - c0 + 2)
    if min(rows[0], cols[0]) >= 2 and rows[-1] < height - 2 and cols[-1] < width - 2 and 2 * framed_size >= hole.size:
        # holes two pixels or more inside the image, their box most of it: the copy returned is the working image
        # (the front is a pixel or more inside it, so its neighbours' flat indices never leave it or wrap a row)
        out = _working(segments, dtype, overwrite)
        _grow(out, hole, width, framed_size, int(out[r0:r1, c0:c1].max()), max_iterations)
        return out
    # the box framed by zeros is the working copy (the image's own copy only when the box is not all of it)
    lab: npt.NDArray[_Id] = np.asarray(cv2.copyMakeBorder(
        segments[r0:r1, c0:c1].astype(dtype, copy=False), 1, 1, 1, 1, cv2.BORDER_CONSTANT, value=0
    ), dtype=dtype)
    open_ = cv2.copyMakeBorder(hole[r0:r1, c0:c1].view(np.uint8), 1, 1, 1, 1, cv2.BORDER_CONSTANT, value=0).view(bool)
    _grow(lab, open_, c1 - c0 + 2, framed_size, int(lab.max()), max_iterations)
    if (r1 - r0, c1 - c0) == (height, width):
        return np.ascontiguousarray(lab[1:-1, 1:-1])
    out = _working(segments, dtype, overwrite)
    out[r0:r1, c0:c1] = lab[1:-1, 1:-1]
    return out


def _grow(
    lab: npt.NDArray[np.integer], open_: npt.NDArray[np.bool_], stride: int, framed_size: int, top: int, steps: int
) -> None:
    """:func:`fill_from_neighbours` in place on ``lab``, whose holes are ``open_`` (taken as they fill): images
    ``stride`` wide in which every neighbour of a pixel next to a hole lies (a frame of zeros, or a margin);
    ``framed_size`` is the framed box's pixels and ``top`` the largest id in it (they choose the first step)."""
    lab_flat, open_flat = lab.ravel(), open_.ravel()
    offsets = np.array([-stride - 1, -stride, -stride + 1, -1, 1, stride - 1, stride, stride + 1], dtype=np.int64)
    if steps > 0 and np.count_nonzero(open_) * 32 >= framed_size and top < 2**24:
        # many holes (the lines through a map): the first step at once, as a grey dilation of the
        # box (ids below 2**8 in uint8, below 2**16 in uint16, below 2**24 exact in float32)
        dtype = np.uint8 if top < 2**8 else np.uint16 if top < 2**16 else np.float32
        grown = cv2.dilate(lab.astype(dtype, copy=False), np.ones((3, 3), np.uint8))
        front = np.flatnonzero(open_ & (grown > 0))
        lab_flat[front] = grown.ravel()[front].astype(lab.dtype, copy=False)
        open_flat[front] = False
        steps -= 1
        # the holes left touch no pixel labelled before: only those just filled next to them move on
        left = np.flatnonzero(open_flat) if steps > 0 else front[:0]
        if left.size < front.size:
            filled_now = np.zeros(lab_flat.size, dtype=bool)
            filled_now[front] = True
            around = (left[:, None] + offsets).ravel()  # in the image: a hole's neighbours are
            front = around[filled_now[around]]
            filled_now[:] = False
            front = distinct(front, filled_now)
    else:
        near_hole = cv2.dilate(open_.view(np.uint8), np.ones((3, 3), np.uint8)).view(bool)
        near_hole &= lab > 0
        front = np.flatnonzero(near_hole)
    seen = np.zeros(lab_flat.size, dtype=bool)
    for _ in range(steps):
        if front.size == 0:
            break
        # every offset at once: a hole takes the largest id of its front neighbours (a hole is never on the front,
        # so the ids read are the step's own)
        cand = (front[:, None] + offsets).ravel()
        ok = open_flat[cand]
        cand = cand[ok]
        np.maximum.at(lab_flat, cand, np.repeat(lab_flat[front], offsets.size)[ok])
        # the next front: each filled pixel once (the order of a front does not matter)
        front = distinct(cand, seen)
        open_flat[front] = False


def segment_image(
    face_image: npt.NDArray[np.int32],
    face_segment: npt.NDArray[np.int64],
    free: npt.NDArray[np.bool_],
    *,
    min_area_px: int,
) -> npt.NDArray[np.int32]:
    """Per-pixel segments of free space from a segment id per face.

    Line pixels take a neighbouring face's segment; every segment is split into its 4-connected
    pieces; pieces smaller than ``min_area_px`` are absorbed by their neighbours (an enclosed one
    stays a segment of its own, unless under half of ``min_area_px``: specks of mapping noise).

    Parameters
    ----------
    face_image : (H, W) int32
        Face id per pixel, 0 on lines.
    face_segment : (F + 1,) int64
        Segment id per face (0 = none).
    free : (H, W) bool
    min_area_px : int

    Returns
    -------
    (H, W) int32
        Segment ids 1..N (consecutive), 0 off free space.
    """
    seg = lookup(face_segment.astype(np.int32), face_image)  # ids are far below 2**31
    np.multiply(seg, free, out=seg)  # 0 off free space, in place
    seg = fill_from_neighbours(seg, free & (face_image == 0), max_iterations=3, overwrite=True)  # its own
    piece_of_run, length, n_pieces, owner, area = _piece_runs(seg)
    # ids in the order of their segment, then of their first pixel (cv2 numbers pieces in scan order)
    order = np.lexsort((np.arange(n_pieces + 1), owner))
    big = (area >= min_area_px) & (owner > 0)
    lut = np.zeros(n_pieces + 1, dtype=np.int32)
    kept = order[big[order]]
    lut[kept] = np.arange(1, kept.size + 1, dtype=np.int32)
    next_id = kept.size + 1
    # the lookups per run, then spread over the run's pixels: far fewer runs than pixels
    out = np.repeat(lut[piece_of_run], length).reshape(seg.shape)
    small = np.repeat(((owner > 0) & ~big)[piece_of_run], length).reshape(seg.shape)
    if small.any():
        out = fill_from_neighbours(out, small, overwrite=True)  # its own
        alone = small & (out == 0)
        if alone.any():
            _n, pieces, stats = components_stats(alone.astype(np.uint8), 4)
            keep = stats[:, cv2.CC_STAT_AREA] >= min_area_px // 2
            keep[0] = False
            ids = np.where(keep, np.cumsum(keep) + next_id - 1, 0)
            out[alone] = ids[pieces[alone]]  # out is fill_from_neighbours' own copy
    return out


def same_value_pieces(seg: npt.NDArray[np.int32]) -> tuple[npt.NDArray[np.int32], int]:
    """The 4-connected pieces of equal non-zero value of ``seg``, numbered 1..N in scan order, 0 elsewhere.

    From the runs of equal values along the rows (a label image of large regions has far fewer
    runs than pixels): a run joins the runs of the same value above it that share a column, the
    joined runs are labelled as a graph, and pieces are numbered by their first pixel in raster
    order, as OpenCV numbers the components of an image.
    """
    piece_of_run, length, n, _, _ = _piece_runs(seg)
    return np.repeat(piece_of_run, length).reshape(seg.shape), n


def _piece_runs(
    seg: npt.NDArray[np.int32],
) -> tuple[npt.NDArray[np.int32], npt.NDArray[np.int64], int, npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """:func:`same_value_pieces` by runs: the piece of each run of equal values along the rows (raster order)
    and the run's length, the number of pieces, each piece's value and pixel count (index 0: the zero pixels)."""
    w = seg.shape[1]
    flat = np.ascontiguousarray(seg, dtype=np.int32).ravel()
    start = np.empty(flat.size, dtype=bool)
    start[0] = True
    np.not_equal(flat[1:], flat[:-1], out=start[1:])
    start[::w] = True
    first = np.flatnonzero(start)  # run starts in raster order; a run never crosses a row end
    n_runs = first.size
    length = np.diff(np.append(first, flat.size))
    value = flat[first]
    on = np.flatnonzero(value > 0)
    below = on[first[on] >= w]
    # the runs of the row above over the first and the last column of each run
    lo = np.searchsorted(first, first[below] - w, side="right") - 1
    hi = np.searchsorted(first, first[below] + length[below] - 1 - w, side="right") - 1
    span = hi - lo + 1
    src = np.repeat(below, span)
    dst = np.repeat(lo, span) + np.arange(int(span.sum())) - np.repeat(np.cumsum(span) - span, span)
    same = value[dst] == value[src]
    graph = coo_matrix((np.ones(int(same.sum()), dtype=np.int8), (src[same], dst[same])), shape=(n_runs, n_runs))
    _, comp = connected_components(graph, directed=False)
    # pieces numbered by their first run
    ids, first_run = np.unique(comp[on], return_index=True)
    rank = np.zeros(int(comp.max()) + 1, dtype=np.int32)
    rank[ids[np.argsort(first_run)]] = np.arange(1, ids.size + 1, dtype=np.int32)
    piece_of_run = np.zeros(n_runs, dtype=np.int32)
    piece_of_run[on] = rank[comp[on]]
    owner = np.zeros(ids.size + 1, dtype=np.int64)
    owner[piece_of_run] = value  # a piece's runs share its value; piece 0's are 0
    area = np.bincount(piece_of_run, weights=length, minlength=ids.size + 1).astype(np.int64)
    return piece_of_run, length, int(ids.size), owner, area


def merge_small_segments(
    segments: npt.NDArray[np.int32],
    *,
    min_area_px: int,
    fixed: npt.NDArray[np.bool_] | None = None,
    absorb: npt.NDArray[np.bool_] | None = None,
    lone_dropped: npt.NDArray[np.bool_] | None = None,
) -> npt.NDArray[np.int32]:
    """Merge every segment smaller than ``min_area_px`` into the neighbour it shares the longest border with.

    Smallest first; a merged segment's borders add up, so a chain of slivers ends in the room
    they line. Segments without a neighbour (an enclosed closet) stay, unless ``lone_dropped``.

    Parameters
    ----------
    segments : (H, W) int32
        Segment ids 1..N (consecutive) per pixel, 0 = none.
    min_area_px : int
    fixed : (N + 1,) bool, optional
        Per segment id: never merged away (it may still absorb small neighbours).
    absorb : (N + 1,) bool, optional
        Per segment id: merged like a small one whatever its area.
    lone_dropped : (N + 1,) bool, optional
        Per segment id: no segment (0) when it is to be merged but has no neighbour.

    Returns
    -------
    (H, W) int32
        Segment ids 1..M (consecutive), 0 where ``segments`` is 0 and on dropped segments.
    """
    seg = np.asarray(segments, dtype=np.int32)
    n = int(seg.max()) + 1
    area = label_counts(seg, n)[0]
    must = np.zeros(n, dtype=bool) if absorb is None else absorb[:n].copy()
    small = ((area < min_area_px) | must) & (area > 0)
    small[0] = False
    if fixed is not None:
        small &= ~fixed[:n]
    if not small.any():
        return _relabel(seg, np.arange(n), area > 0)
    pairs, border, _ = border_closure(seg, None)
    neighbours: list[dict[int, int]] = [{} for _ in range(n)]
    for (p, q), c in zip(pairs.tolist(), border.tolist(), strict=True):
        neighbours[p][q] = c
        neighbours[q][p] = c
    parent = np.arange(n)
    dropped = np.zeros(n, dtype=bool)  # with the pieces merged into them before
    for s in sorted(np.flatnonzero(small).tolist(), key=lambda i: area[i]):
        if (area[s] >= min_area_px and not must[s]) or not neighbours[s]:
            if not neighbours[s] and lone_dropped is not None and lone_dropped[s]:
                dropped[s] = True
            continue
        _absorb(s, max(neighbours[s], key=lambda k: neighbours[s][k]), parent, area, neighbours)
    root = _roots(parent)
    return _relabel(seg, root, (area > 0) & ~dropped[root])


def join_small_regions(
    segments: npt.NDArray[np.int32],
    *,
    min_area_px: int,
    apart: npt.NDArray[np.bool_] | None = None,
) -> npt.NDArray[np.int32]:
    """``segments`` with no region under ``min_area_px`` left: each joins the neighbour it shares the longest
    border with (smallest first, borders adding up as in :func:`merge_small_segments`); one with no neighbour
    left is no region (its cells 0, loose as specks are).

    Regions mostly (over half) on ``apart`` (places found from racks: a bin is a region however little of its floor
    was seen) are neither joined nor given a small region: floor is never storage. Returns ``segments`` itself when
    no region is too small, else ids 1..M in the order of the old ids.
    """
    seg = np.asarray(segments, dtype=np.int32)
    n = int(seg.max(initial=0)) + 1
    area, on_apart = label_counts(seg, n, apart)
    held = 2 * on_apart > area
    small = (area > 0) & (area < min_area_px) & ~held
    small[0] = False
    if not small.any():
        return seg
    pairs, border, _ = border_closure(seg, None)
    neighbours: list[dict[int, int]] = [{} for _ in range(n)]
    for (p, q), c in zip(pairs.tolist(), border.tolist(), strict=True):
        if not (held[p] or held[q]):
            neighbours[p][q] = c
            neighbours[q][p] = c
    parent = np.arange(n)
    dropped = np.zeros(n, dtype=bool)
    area = area.copy()
    for s in sorted(np.flatnonzero(small).tolist(), key=lambda i: area[i]):
        if area[s] >= min_area_px:  # it took smaller ones in
            continue
        if not neighbours[s]:
            dropped[s] = True
            continue
        _absorb(s, max(neighbours[s], key=lambda k: neighbours[s][k]), parent, area, neighbours)
    root = _roots(parent)
    return renumber_mapped(np.where(dropped[root], 0, root).astype(np.int32), seg)


def merge_passages(
    segments: npt.NDArray[np.int32],
    *,
    max_area_px: int,
    max_width_px: float,
    min_border_px: int,
    min_border_share: float = 1 / 3,
    fixed: npt.NDArray[np.bool_] | None = None,
) -> npt.NDArray[np.int32]:
    """Merge every strip between segments into the one it shares the longest border with.

    A strip is a piece smaller than ``max_area_px`` and nowhere wider than ``max_width_px`` (the widest disc inside
    it) that borders at least two other segments over ``min_border_px`` each and whose borders with other segments
    make up at least ``min_border_share`` of its outline: the floor left between two cuts across a room (a line and a
    free-space cut side by side, the two lines of one doorway), its long sides on the cuts, too narrow for a room.
    A piece of a corridor between two cuts has its long sides on walls, and a small room behind a door borders one
    segment only: both stay, and so does a strip once the pieces merged into it leave it bordering one segment.
    Smallest first; borders add up as in :func:`merge_small_segments`. ``fixed`` (per segment id) pieces stay, and a
    strip bordering a fixed one (a warehouse floor) too. Ids 1..M (consecutive).
    """
    seg = np.asarray(segments, dtype=np.int32)
    n = int(seg.max()) + 1
    area = label_counts(seg, n)[0]
    still = np.zeros(n, dtype=bool) if fixed is None else np.asarray(fixed[:n], dtype=bool).copy()
    still[0] = True
    candidate = (area > 0) & (area < max_area_px) & ~still
    if not candidate.any():
        return _relabel(seg, np.arange(n), area > 0)
    # their widths, within the box round them and a pixel more: a segment's widest disc lies in its own box
    at = lookup(candidate, seg)
    rows, cols = np.flatnonzero(at.any(axis=1)), np.flatnonzero(at.any(axis=0))
    h, w = seg.shape
    r0, r1 = max(int(rows[0]) - 1, 0), min(int(rows[-1]) + 2, h)
    c0, c1 = max(int(cols[0]) - 1, 0), min(int(cols[-1]) + 2, w)
    box = seg[r0:r1, c0:c1]
    inner = box > 0  # the pixels with the same segment on all four sides: the widest disc from the rest
    inner[1:] &= box[1:] == box[:-1]
    inner[:-1] &= box[:-1] == box[1:]
    inner[:, 1:] &= box[:, 1:] == box[:, :-1]
    inner[:, :-1] &= box[:, :-1] == box[:, 1:]
    inner[[0, -1]] = False  # the image's edge, or a pixel beside the segments looked at
    inner[:, [0, -1]] = False
    depth = np.asarray(cv2.distanceTransform(inner.view(np.uint8), cv2.DIST_L2, 5), dtype=np.float32)
    width = 2 * label_max(box, depth, n)[0] + 1
    candidate &= width <= max_width_px
    if not candidate.any():
        return _relabel(seg, np.arange(n), area > 0)
    a, b, shut_px = _differing_pairs(seg, None)  # the borders' pixel pairs, and the outlines' (with 0)
    # 4-neighbour pixel pairs of another id (0 too), the image's edge
    outline = np.bincount(a, minlength=n) + np.bincount(b, minlength=n)
    ok = (a > 0) & (b > 0)
    pairs, border, _ = _pair_borders(a[ok], b[ok], shut_px[ok], n)
    for edge in (seg[0], seg[-1], seg[:, 0], seg[:, -1]):
        outline += np.bincount(edge, minlength=n)
    shared = np.bincount(pairs.ravel(), weights=np.repeat(border, 2), minlength=n)
    candidate &= shared >= min_border_share * outline
    neighbours: list[dict[int, int]] = [{} for _ in range(n)]
    for (p, q), c in zip(pairs.tolist(), border.tolist(), strict=True):
        neighbours[p][q] = c
        neighbours[q][p] = c
    parent = np.arange(n)
    while True:
        between = [
            s
            for s in np.flatnonzero(candidate).tolist()
            if sum(c >= min_border_px for c in neighbours[s].values()) >= 2 and not any(still[k] for k in neighbours[s])
        ]
        if not between:
            break
        s = min(between, key=lambda i: area[i])
        t = max(neighbours[s], key=lambda k: neighbours[s][k])
        _absorb(s, t, parent, area, neighbours)
        candidate[s] = False
        candidate[t] &= area[t] < max_area_px
    return _relabel(seg, _roots(parent), area > 0)


def _absorb(
    s: int,
    t: int,
    parent: npt.NDArray[np.int64],
    area: npt.NDArray[np.int64],
    neighbours: list[dict[int, int]],
) -> None:
    """Segment ``s`` joins segment ``t``: its area and its borders (pixel counts by neighbour) become ``t``'s."""
    parent[s] = t
    area[t] += area[s]
    for k, c in neighbours[s].items():
        del neighbours[k][s]
        if k != t:
            neighbours[t][k] = neighbours[t].get(k, 0) + c
            neighbours[k][t] = neighbours[k].get(t, 0) + c
    neighbours[s] = {}


def _roots(parent: npt.NDArray[np.int64]) -> npt.NDArray[np.int64]:
    """The segment each segment finally joined, following ``parent`` to its end."""
    root = parent.copy()
    while True:
        nxt = root[root]
        if np.array_equal(nxt, root):
            return root
        root = nxt


def _relabel(
    seg: npt.NDArray[np.int32], group: npt.NDArray[np.int64], present: npt.NDArray[np.bool_]
) -> npt.NDArray[np.int32]:
    """Segments relabelled by ``group`` (per id), the groups of the ``present`` ids numbered 1..M in order."""
    n = int(seg.max()) + 1
    ids = np.flatnonzero(present[:n])
    ids = ids[ids > 0]
    _, dense = np.unique(group[ids], return_inverse=True)
    lut = np.zeros(n, dtype=np.int32)
    lut[ids] = dense + 1
    return _apply(lut, seg)


def _apply(lut: npt.NDArray[np.int32], seg: npt.NDArray[np.int32]) -> npt.NDArray[np.int32]:
    """``lut[seg]``; a copy of ``seg`` when ``lut`` changes no id (most calls on a warehouse)."""
    if np.array_equal(lut, np.arange(lut.size)):
        return np.array(seg, dtype=np.int32, copy=True)
    return lookup(lut, seg)


def renumber(seg: npt.NDArray[np.int32], *, copy: bool = True) -> npt.NDArray[np.int32]:
    """Ids 1..N in the order of the old ids, 0 kept; ``seg`` itself when no id changes and ``copy`` is false."""
    if seg.size == 0:
        return np.array(seg, dtype=np.int32, copy=True)
    runs = value_runs(seg)
    present = np.bincount(runs[0]) > 0
    present[0] = False
    lut = np.where(present, np.cumsum(present), 0).astype(np.int32)
    if np.array_equal(lut, np.arange(lut.size)):
        return np.array(seg, dtype=np.int32, copy=True) if copy else np.asarray(seg, dtype=np.int32)
    return lookup(lut, seg, runs)


def renumber_mapped(lut: npt.NDArray[np.int32], seg: npt.NDArray[np.int32]) -> npt.NDArray[np.int32]:
    """``renumber(np.take(lut, seg))`` from the runs of ``seg``: the ids ``lut`` gives the runs, renumbered, spread
    once (no image of the mapped ids in between)."""
    if seg.size == 0:
        return np.take(lut, seg).astype(np.int32)
    value, length = value_runs(seg)
    mapped = lut[value]
    present = np.bincount(mapped) > 0
    present[0] = False
    new = np.where(present, np.cumsum(present), 0).astype(np.int32)
    return np.repeat(new[mapped], length).reshape(seg.shape)


def split_along(segments: npt.NDArray[np.int32], barrier: npt.NDArray[np.bool_]) -> npt.NDArray[np.int32]:
    """Split every segment into the 8-connected pieces it falls into once ``barrier`` pixels are taken out.

    Barrier pixels then rejoin a neighbouring piece of their segment.

    Parameters
    ----------
    segments : (H, W) int32
        Segment ids 1..N (consecutive) per pixel, 0 = none.
    barrier : (H, W) bool
        Cuts (4-connected lines separate 8-connected pieces).

    Returns
    -------
    (H, W) int32
        Segment ids 1..N (consecutive), 0 where ``segments`` is 0.
    """
    seg = np.asarray(segments, dtype=np.int32)
    cut = np.where(barrier, 0, seg)
    out = seg.copy()
    next_id = int(seg.max()) + 1
    touched = np.zeros(next_id, dtype=bool)
    touched[seg[barrier]] = True
    touched[0] = False
    for sid, box in enumerate(label_boxes(seg), start=1):  # a segment's box is its own pixels'
        if box is None or not touched[sid]:
            continue
        n, pieces = cv2.connectedComponents((cut[box] == sid).astype(np.uint8), connectivity=8)
        view = out[box]
        view[(seg[box] == sid) & barrier[box]] = 0
        more = pieces >= 2  # piece 1 keeps the segment's id, piece k >= 2 gets the next id in turn
        view[more] = pieces[more] + (next_id - 2)
        next_id += max(n - 2, 0)
    return fill_from_neighbours(out, barrier & (seg > 0), overwrite=True)  # out is this function's own copy


def border_closure(
    segments: npt.NDArray[np.int32], closed: npt.NDArray[np.bool_] | None
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Touching segment pairs, the length of their border and how much of it is closed.

    A border pixel pair (4-neighbours of two segments) is closed when either pixel is on ``closed``
    (``None``: nothing is).

    Returns
    -------
    pairs : (K, 2) int64
        Segment ids ``a < b``.
    total, shut : (K,) int64
        Border pixel pairs, and those closed.
    """
    seg = np.ascontiguousarray(segments)
    n = int(seg.max()) + 1
    a, b, shut_px = _differing_pairs(seg, closed)
    ok = (a > 0) & (b > 0)
    a, b, shut_px = a[ok], b[ok], shut_px[ok]
    return _pair_borders(a, b, shut_px, n)


def _differing_pairs(
    segments: npt.NDArray[np.int32], closed: npt.NDArray[np.bool_] | None
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], npt.NDArray[np.bool_]]:
    """The ids of every pair of 4-neighbour pixels with different ids (0 too), rows then columns in raster order,
    and whether either pixel is on ``closed`` (``None``: nothing is)."""
    seg = np.ascontiguousarray(segments)
    h, w = seg.shape
    flat = seg.ravel()
    shut_flat = None if closed is None else np.ascontiguousarray(closed, dtype=bool).ravel()
    firsts: list[npt.NDArray[np.int64]] = []
    seconds: list[npt.NDArray[np.int64]] = []
    shuts: list[npt.NDArray[np.bool_]] = []
    for dy, dx in ((0, 1), (1, 0)):
        if h - dy == 0 or w - dx == 0:
            continue
        # flat indices of the pairs' first pixels (raster order), read with 1-D gathers
        k = np.flatnonzero(seg[: h - dy, : w - dx] != seg[dy:, dx:])
        first = k + k // (w - dx) * dx
        second = first + dy * w + dx
        firsts.append(flat[first].astype(np.int64))
        seconds.append(flat[second].astype(np.int64))
        shuts.append(np.zeros(k.size, dtype=bool) if shut_flat is None else shut_flat[first] | shut_flat[second])
    if not firsts:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros(0, dtype=bool)
    return np.concatenate(firsts), np.concatenate(seconds), np.concatenate(shuts)


def _pair_borders(
    a: npt.NDArray[np.int64], b: npt.NDArray[np.int64], shut_px: npt.NDArray[np.bool_], n: int
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """:func:`border_closure` of the border pixel pairs' ids ``a``, ``b`` (both > 0, different) and closed flags."""
    if a.size == 0:
        return np.zeros((0, 2), dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    codes, inverse = unique_inverse(np.minimum(a, b) * n + np.maximum(a, b))
    total = np.bincount(inverse, minlength=len(codes)).astype(np.int64)
    shut = np.bincount(inverse, weights=shut_px, minlength=len(codes)).astype(np.int64)
    return np.stack([codes // n, codes % n], axis=1), total, shut


def merge_open_segments(
    segments: npt.NDArray[np.int32],
    closed: npt.NDArray[np.bool_],
    *,
    max_closed_share: float = 0.5,
    fixed: npt.NDArray[np.bool_] | None = None,
) -> npt.NDArray[np.int32]:
    """Join touching segments whose shared border is mostly open (cogency between segments).

    A border pixel pair is closed when either pixel is on ``closed`` (wall evidence, a closed
    doorway, a cut). Two segments touching along a border of which at most
    ``max_closed_share`` is closed are one region, as faces joined by a connected link are;
    this also joins faces that no line edge links (across texture-region borders).

    Parameters
    ----------
    segments : (H, W) int32
        Segment ids 1..N (consecutive) per pixel, 0 = none.
    closed : (H, W) bool
    fixed : (N + 1,) bool, optional
        Per segment id: never joined.

    Returns
    -------
    (H, W) int32
        Segment ids 1..M (consecutive), 0 where ``segments`` is 0.
    """
    seg = np.asarray(segments, dtype=np.int32)
    n = int(seg.max()) + 1
    present = label_counts(seg, n)[0] > 0
    if fixed is not None and fixed[:n][present].all():  # no segment may join (a rack hall's floors)
        return _relabel(seg, np.arange(n), present)
    pairs, total, shut = border_closure(seg, closed)
    join = shut <= max_closed_share * total
    if fixed is not None:
        join &= ~fixed[pairs[:, 0]] & ~fixed[pairs[:, 1]]
    pairs = pairs[join]
    m = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    _, comp = connected_components(m, directed=False)
    return _relabel(seg, comp, present)

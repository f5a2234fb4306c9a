"""Exact array primitives the decomposition calls on whole grids, faster than their numpy forms.

numpy's ``unique`` hashes when asked for the values alone, which is many times slower than a sort
on millions of distinct integers; with an inverse it sorts. Ids of pixels are small non-negative
integers: a count per id finds them in one pass.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any, TypeVar

import cv2
import numpy as np
import numpy.typing as npt

_DENSE_PER_VALUE = 4  # a count per id while the ids' range is at most this many times the values
_SPARSE_MASK = 32  # label_counts counts a mask's pixels one by one when at most this share of the image (1 / 32)
_Value = TypeVar("_Value", bound=np.generic)


def distinct(values: npt.NDArray[np.int64], scratch: npt.NDArray[np.bool_]) -> npt.NDArray[np.int64]:
    """The sorted distinct values of ``values`` (indices into ``scratch``), as ``np.unique`` gives them.

    Many values (a front of millions of pixels) are marked in ``scratch`` (all False, and left so)
    and read back in one pass; a few are sorted.
    """
    if values.size * 16 >= scratch.size:
        scratch[values] = True
        out = np.flatnonzero(scratch)
        scratch[out] = False
        return out
    return _sorted_distinct(np.sort(values))


def _sorted_distinct(ordered: npt.NDArray[np.int64]) -> npt.NDArray[np.int64]:
    keep = np.ones(ordered.size, dtype=bool)
    keep[1:] = ordered[1:] != ordered[:-1]
    return ordered[keep]


def unique_inverse(keys: npt.NDArray[np.integer]) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """``np.unique(keys, return_inverse=True)`` of non-negative integer ``keys`` (1-D), values as int64.

    Keys in a range not much larger than their number are counted, not sorted.
    """
    flat = np.asarray(keys).ravel()
    if flat.size == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    top = int(flat.max())
    if top >= _DENSE_PER_VALUE * flat.size + 1024:
        values, inverse = np.unique(flat, return_inverse=True)
        return values.astype(np.int64), inverse.ravel().astype(np.int64)
    present = np.bincount(flat, minlength=top + 1) > 0
    rank = np.cumsum(present) - 1
    return np.flatnonzero(present), rank[flat]


def _runs(flat: npt.NDArray[np.integer], row_length: int = 0) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.intp]]:
    """First index and length of each run of equal values of a flat image in raster order; with ``row_length``,
    runs also end at the end of each row of that length."""
    start = np.empty(flat.size, dtype=bool)
    start[:1] = True
    np.not_equal(flat[1:], flat[:-1], out=start[1:])
    if row_length:
        start[::row_length] = True
    first = np.flatnonzero(start)
    return first, np.diff(np.append(first, flat.size))


def nonzero_rc(array: npt.NDArray[np.generic]) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.intp]]:
    """``np.nonzero`` of a 2-D array: the rows and columns of its non-zero entries, in raster order.

    From the flat indices (one pass over the array, then a division of the entries found): numpy's 2-D
    ``nonzero`` walks a multi-index, 3-10 times slower on an image.
    """
    width = array.shape[1]
    if width == 0:
        rows, cols = np.nonzero(array)
        return rows, cols
    rows, cols = np.divmod(np.flatnonzero(array), width)
    return rows, cols


def border_steps(
    segments: npt.NDArray[np.int32], n: int, allowed: npt.NDArray[np.bool_] | None = None
) -> list[tuple[int, int, npt.NDArray[np.intp], npt.NDArray[np.intp], npt.NDArray[np.int64]]]:
    """The borders between segments, per step (``dy``, ``dx``) right and down: rows and columns of the pixels whose
    neighbour that step away is in another segment (both ids > 0, both pixels ``allowed`` when given; raster order)
    and each pair's key ``min(a, b) * n + max(a, b)`` (``n`` above every id)."""
    h, w = segments.shape
    found = []
    for dy, dx in ((0, 1), (1, 0)):
        p, q = segments[: h - dy, : w - dx], segments[dy:, dx:]
        differ = (p != q) & (p > 0) & (q > 0)
        if allowed is not None:
            differ &= allowed[: h - dy, : w - dx] & allowed[dy:, dx:]
        r, c = nonzero_rc(differ)
        a, b = p[r, c].astype(np.int64), q[r, c].astype(np.int64)
        found.append((dy, dx, r, c, np.minimum(a, b) * n + np.maximum(a, b)))
    return found


def label_sums(
    labels: npt.NDArray[np.integer], n: int
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Pixel count, sum of columns and sum of rows of every label ``0..n - 1`` of a label image.

    The same as ``np.bincount(labels.ravel(), weights, n)`` with a column or row index per pixel,
    from the runs of equal labels along the rows: a label image of large regions has far fewer
    runs than pixels. The sums are whole numbers, exact in float64 in any order.

    Parameters
    ----------
    labels : (H, W) non-negative integer
    n : int
        At least ``labels.max() + 1``.

    Returns
    -------
    count : (n,) int64
    sum_col, sum_row : (n,) float64
    """
    w = labels.shape[1]
    flat = np.ascontiguousarray(labels).ravel()
    if flat.size == 0:
        return np.zeros(n, dtype=np.int64), np.zeros(n), np.zeros(n)
    first, length = _runs(flat, w)
    label = flat[first]
    row = first // w
    col = first - row * w
    count = np.bincount(label, weights=length, minlength=n).astype(np.int64)
    sum_col = np.bincount(label, weights=length * col + length * (length - 1) // 2, minlength=n)
    sum_row = np.bincount(label, weights=length * row, minlength=n)
    return count, sum_col.astype(np.float64), sum_row.astype(np.float64)


def label_counts(
    labels: npt.NDArray[np.integer], n: int, mask: npt.NDArray[np.bool_] | None = None
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Pixels of every label ``0..n - 1`` of a label image, and of them those inside ``mask``.

    ``np.bincount(labels.ravel(), minlength=n)`` and ``np.bincount(labels[mask], minlength=n)``
    from the runs of equal (label, mask) pairs in raster order, as :func:`label_sums` counts:
    3-4 times faster on segment images.

    Parameters
    ----------
    labels : (H, W) non-negative integer
    n : int
        At least ``labels.max() + 1``.
    mask : (H, W) bool, optional

    Returns
    -------
    count, inside : (n,) int64
        ``inside`` is all zeros without a mask.
    """
    flat = np.ascontiguousarray(labels).ravel()
    if flat.size == 0:
        return np.zeros(n, dtype=np.int64), np.zeros(n, dtype=np.int64)
    m = None if mask is None else np.ascontiguousarray(mask, dtype=bool).ravel()
    if m is not None and np.count_nonzero(m) * _SPARSE_MASK <= flat.size:
        # a sparse mask (a few warehouse-floor or ray pixels on an office map): its pixels counted by their labels
        # (whole numbers, the same counts), the labels' own runs alone, without the mask's run ends
        inside = np.bincount(flat[np.flatnonzero(m)], minlength=n).astype(np.int64)
        return label_counts(labels, n)[0], inside
    start = np.empty(flat.size, dtype=bool)
    start[0] = True
    np.not_equal(flat[1:], flat[:-1], out=start[1:])
    if m is not None:
        start[1:] |= m[1:] != m[:-1]
    first = np.flatnonzero(start)
    length = np.diff(np.append(first, flat.size))
    label = flat[first]
    count = np.bincount(label, weights=length, minlength=n).astype(np.int64)
    if m is None:
        return count, np.zeros(n, dtype=np.int64)
    on = m[first]
    inside = np.bincount(label[on], weights=length[on], minlength=n).astype(np.int64)
    return count, inside


class MaskCounts:
    """:func:`label_counts` of one mask over the label images of several steps: a sparse mask's pixels found once.

    ``counts(labels)`` is ``label_counts(labels, int(labels.max()) + 1, mask)``; ``inside(labels)`` is its second
    array alone, without counting every label's pixels (a sparse mask: the labels at its pixels counted, whole
    numbers, the same counts).
    """

    def __init__(self, mask: npt.NDArray[np.bool_]) -> None:
        self.mask = mask
        sparse = np.count_nonzero(mask) * _SPARSE_MASK <= mask.size
        self.at = np.flatnonzero(mask) if sparse else None  # the sparse mask's flat indices

    def counts(self, labels: npt.NDArray[np.integer]) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
        """Pixels of every label ``0..labels.max()``, and of them those inside the mask."""
        n = int(labels.max()) + 1
        if self.at is None:
            return label_counts(labels, n, self.mask)
        return label_counts(labels, n)[0], self._inside(labels, n)

    def inside(self, labels: npt.NDArray[np.integer]) -> npt.NDArray[np.int64]:
        """Pixels of every label ``0..labels.max()`` inside the mask."""
        n = int(labels.max()) + 1
        return label_counts(labels, n, self.mask)[1] if self.at is None else self._inside(labels, n)

    def _inside(self, labels: npt.NDArray[np.integer], n: int) -> npt.NDArray[np.int64]:
        assert self.at is not None
        return np.bincount(np.ascontiguousarray(labels).ravel()[self.at], minlength=n).astype(np.int64)


def label_max(
    labels: npt.NDArray[np.integer], values: npt.NDArray[np.floating], n: int
) -> tuple[npt.NDArray[np.floating], npt.NDArray[np.int64]]:
    """Largest value (at least 0) and pixel count of every label ``0..n - 1`` of a label image.

    ``np.maximum.at(zeros, labels.ravel(), values.ravel())`` and ``np.bincount(labels.ravel(), minlength=n)``
    from the runs of equal labels in raster order: the maximum of each run (``np.maximum.reduceat``), then of
    the runs of each label. A maximum is exact in any order.
    """
    flat = np.ascontiguousarray(labels).ravel()
    out = np.zeros(n, dtype=values.dtype)
    if flat.size == 0:
        return out, np.zeros(n, dtype=np.int64)
    first, length = _runs(flat)
    label = flat[first]
    np.maximum.at(out, label, np.maximum.reduceat(np.ascontiguousarray(values).ravel(), first))
    count = np.bincount(label, weights=length, minlength=n).astype(np.int64)
    return out, count


def value_runs(image: npt.NDArray[np.integer]) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Value and length of each run of equal values of a non-empty image in raster order (runs cross rows)."""
    flat = np.ascontiguousarray(image).ravel()
    first, length = _runs(flat)
    return flat[first].astype(np.int64, copy=False), length


def lookup(
    lut: npt.NDArray[_Value],
    image: npt.NDArray[np.integer],
    runs: tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]] | None = None,
) -> npt.NDArray[_Value]:
    """``lut[image]`` (non-negative ids), looked up once per run of equal ids and spread over the run's pixels.

    A label image has far fewer runs than pixels: on a 9 Mpx hall this is many times faster than the
    gather of every pixel. ``runs`` is :func:`value_runs` of ``image``, when known.
    """
    if image.size == 0:
        return np.zeros(image.shape, dtype=lut.dtype)
    value, length = value_runs(image) if runs is None else runs
    return np.repeat(lut[value], length).reshape(image.shape)


def label_boxes(labels: npt.NDArray[np.integer], max_label: int = 0) -> list[tuple[slice, slice] | None]:
    """``scipy.ndimage.find_objects(labels, max_label)`` of a 2-D label image (non-negative ids), from its runs.

    The rows and columns each label spans, from the runs of equal labels along the rows: a label image of
    large regions has far fewer runs than pixels. ``None`` for an id without a pixel; ``max_label`` 0: up to
    the largest id.
    """
    h, w = labels.shape
    if labels.size == 0:
        return [None] * max_label
    flat = np.ascontiguousarray(labels).ravel()
    first, length = _runs(flat, w)
    label = flat[first].astype(np.intp)
    n = (int(label.max(initial=0)) if max_label <= 0 else max_label) + 1
    keep = (label > 0) & (label < n)
    first, length, label = first[keep], length[keep], label[keep]
    row = first // w
    col = first - row * w
    r0, c0 = np.full(n, h, dtype=np.int64), np.full(n, w, dtype=np.int64)
    r1, c1 = np.full(n, -1, dtype=np.int64), np.full(n, -1, dtype=np.int64)
    np.minimum.at(r0, label, row)
    np.maximum.at(r1, label, row)
    np.minimum.at(c0, label, col)
    np.maximum.at(c1, label, col + length - 1)
    return [
        (slice(a, b + 1), slice(c, d + 1)) if b >= 0 else None
        for a, b, c, d in zip(r0[1:].tolist(), r1[1:].tolist(), c0[1:].tolist(), c1[1:].tolist(), strict=True)
    ]


def components_stats(
    mask: npt.NDArray[np.bool_] | npt.NDArray[np.uint8] | cv2.typing.MatLike, connectivity: int
) -> tuple[int, npt.NDArray[np.int32], npt.NDArray[np.int32]]:
    """``cv2.connectedComponentsWithStats(mask, connectivity=connectivity)`` without the centroids, 3-5 times faster.

    The labels are ``cv2.connectedComponents``' (the same labelling, without OpenCV's per-pixel statistics);
    the left, top, width, height and area of every label, the background's included, come from the runs of
    equal labels along the rows (whole numbers, exact in any order). Label 0 without a pixel gets OpenCV's
    values for it, ``(-1, 2**31 - 1, 0, 0, 0)``.

    Returns
    -------
    n : int
        Labels, the background's included.
    labels : (H, W) int32
    stats : (n, 5) int32
        ``cv2.CC_STAT_LEFT``, ``TOP``, ``WIDTH``, ``HEIGHT``, ``AREA`` per label.
    """
    n, labels, stats, _ = components_stats_runs(mask, connectivity)
    return n, labels, stats


def components_stats_runs(
    mask: npt.NDArray[np.bool_] | npt.NDArray[np.uint8] | cv2.typing.MatLike, connectivity: int
) -> tuple[int, npt.NDArray[np.int32], npt.NDArray[np.int32], tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]]:
    """:func:`components_stats` and the runs of equal labels along the rows it counted them from (label, length)."""
    image = np.asarray(mask)
    bytes_ = np.asarray(image.view(np.uint8) if image.dtype == np.bool_ else image, dtype=np.uint8)
    n, found = cv2.connectedComponents(bytes_, connectivity=connectivity, ltype=cv2.CV_32S)
    labels = np.asarray(found, dtype=np.int32)
    h, w = labels.shape
    flat = labels.ravel()
    first, length = _runs(flat, w)
    label = flat[first].astype(np.intp)
    row = first // w
    col = first - row * w
    left, top = np.full(n, w, dtype=np.int64), np.full(n, h, dtype=np.int64)
    right, bottom = np.full(n, -1, dtype=np.int64), np.full(n, -1, dtype=np.int64)
    np.minimum.at(left, label, col)
    np.maximum.at(right, label, col + length - 1)
    np.minimum.at(top, label, row)
    np.maximum.at(bottom, label, row)
    stats = np.empty((n, 5), dtype=np.int32)
    stats[:, cv2.CC_STAT_LEFT] = left
    stats[:, cv2.CC_STAT_TOP] = top
    stats[:, cv2.CC_STAT_WIDTH] = right - left + 1
    stats[:, cv2.CC_STAT_HEIGHT] = bottom - top + 1
    stats[:, cv2.CC_STAT_AREA] = np.bincount(label, weights=length, minlength=n)
    empty = stats[:, cv2.CC_STAT_AREA] == 0
    stats[empty] = (-1, np.iinfo(np.int32).max, 0, 0, 0)
    return n, labels, stats, (label.astype(np.int64, copy=False), length.astype(np.int64, copy=False))


@dataclass(frozen=True)
class Components:
    """The 8-connected components of a mask, as ``cv2.connectedComponentsWithStats`` gives them."""

    labels: npt.NDArray[np.int32]  # (H, W) component id per pixel, 0 off the mask
    stats: npt.NDArray[np.int32]  # (N + 1, 5) left, top, width, height, area per id
    # the runs of equal ids along the rows (id, length; raster order): ``lookup(table, labels, runs)`` spreads a
    # per-id table over the image without reading the labels again
    runs: tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]

    def spread(self, table: npt.NDArray[_Value]) -> npt.NDArray[_Value]:
        """``table[labels]`` (one entry per id), from the runs."""
        return lookup(table, self.labels, self.runs)


def components(mask: npt.NDArray[np.bool_]) -> Components:
    """:class:`Components` of ``mask``, labelled once for every step that reads them.

    The obstacles for the furniture, the line search's structure and the free-standing obstacles; the
    occupied cells for the shelf dashes and the floor objects.
    """
    _n, labels, stats, runs = components_stats_runs(mask, 8)
    return Components(labels, stats, runs)


@functools.lru_cache(maxsize=32, typed=True)
def _chamfer_ball(radius_px: float, mask_size: int) -> npt.NDArray[np.uint8]:
    """The offsets whose ``cv2.distanceTransform(..., cv2.DIST_L2, mask_size)`` distance is at most ``radius_px``.

    Measured by the transform itself from one zero pixel, compared as the caller compares (typed cache: an
    int, a float and a numpy float radius compare differently with the float32 distances).
    """
    reach = int(radius_px) + 2  # each step of the chamfer masks is at least 0.955 px
    image = np.ones((2 * reach + 1, 2 * reach + 1), dtype=np.uint8)
    image[reach, reach] = 0
    inside = cv2.distanceTransform(image, cv2.DIST_L2, mask_size) <= radius_px
    r = reach - int(np.flatnonzero(inside.any(axis=1))[0])
    return np.ascontiguousarray(inside[reach - r : reach + r + 1, reach - r : reach + r + 1], dtype=np.uint8)


def near(mask: npt.NDArray[np.bool_], radius_px: float, mask_size: int = 3) -> npt.NDArray[np.bool_]:
    """``cv2.distanceTransform((~mask).astype(np.uint8), cv2.DIST_L2, mask_size) <= radius_px``, by one dilation.

    The chamfer transform's distance of a pixel is the least over the mask's pixels of one propagation from
    each, and its float sums do not depend on where the pixel lies: so it is the dilation of ``mask`` by the
    transform's own ball. A dilation by a small ball is a few times faster than the transform.
    """
    flags = np.ascontiguousarray(mask, dtype=bool).view(np.uint8)  # 0/1 bytes, no copy: the dilation is 0/1 too
    return np.asarray(cv2.dilate(flags, _chamfer_ball(radius_px, mask_size))).view(bool)


def near_at(
    mask: npt.NDArray[np.bool_],
    rows: npt.NDArray[np.integer],
    cols: npt.NDArray[np.integer],
    radius_px: float,
    mask_size: int = 3,
) -> npt.NDArray[np.bool_]:
    """:func:`near` read at the pixels ``(rows, cols)`` of the image only: whether a pixel of ``mask`` lies in the
    transform's ball round each (offsets off the image hold none, as the transform has no pixel there).

    A whole-image transform read at a few pixels costs a pass over every pixel; this looks at the ball round each.
    """
    ball = _chamfer_ball(radius_px, mask_size)  # square, the pixel at its middle
    r = ball.shape[0] // 2
    ball_rows, ball_cols = nonzero_rc(ball)
    h, w = mask.shape
    at_r = np.asarray(rows, dtype=np.intp)[:, None] + (ball_rows - r)[None, :]
    at_c = np.asarray(cols, dtype=np.intp)[:, None] + (ball_cols - r)[None, :]
    on = (at_r >= 0) & (at_r < h) & (at_c >= 0) & (at_c < w)
    hit = np.zeros(at_r.shape, dtype=bool)
    hit[on] = mask[at_r[on], at_c[on]]
    out: npt.NDArray[np.bool_] = np.any(hit, axis=1)
    return out


@functools.lru_cache(maxsize=32, typed=True)
def _short_of_ball(
    scale: float | np.floating[Any], limit: float | np.floating[Any], mask_size: int
) -> npt.NDArray[np.uint8]:
    """The offsets whose ``cv2.distanceTransform(..., cv2.DIST_L2, mask_size)`` distance ``d`` has not
    ``d * scale >= limit``, measured by the transform itself from one zero pixel and compared as the caller compares
    (typed cache: a Python and a numpy float scale compare differently with the float32 distances)."""
    reach = max(int(limit / scale / 0.95), 0) + 2  # each step of the chamfer masks is at least 0.955 px
    image = np.ones((2 * reach + 1, 2 * reach + 1), dtype=np.uint8)
    image[reach, reach] = 0
    inside = ~(cv2.distanceTransform(image, cv2.DIST_L2, mask_size) * scale >= limit)
    if not inside.any():  # even the pixel itself reaches the limit: an empty ball
        return np.zeros((1, 1), dtype=np.uint8)
    r = reach - int(np.flatnonzero(inside.any(axis=1))[0])
    return np.ascontiguousarray(inside[reach - r : reach + r + 1, reach - r : reach + r + 1], dtype=np.uint8)


def short_of(
    mask: npt.NDArray[np.bool_], scale: float | np.floating[Any], limit: float | np.floating[Any], mask_size: int = 5
) -> npt.NDArray[np.bool_]:
    """``~(cv2.distanceTransform((~mask).astype(np.uint8), cv2.DIST_L2, mask_size) * scale >= limit)`` for
    ``scale > 0``, by one dilation (as :func:`near`): the pixels whose distance to ``mask``, scaled, falls short of
    ``limit``. ``d * scale`` rises with ``d``, so the least distance falls short when some mask pixel's does."""
    ball = _short_of_ball(scale, limit, mask_size)
    if not ball.any():
        return np.zeros(mask.shape, dtype=bool)
    return np.asarray(cv2.dilate(np.ascontiguousarray(mask, dtype=bool).view(np.uint8), ball)).view(bool)

"""Array primitives: the same answers as the numpy forms they replace."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from scipy import ndimage

from services.grid_decomposition.arrays import (
    MaskCounts,
    border_steps,
    components,
    components_stats,
    components_stats_runs,
    distinct,
    label_boxes,
    label_counts,
    label_max,
    label_sums,
    lookup,
    near,
    near_at,
    nonzero_rc,
    short_of,
    unique_inverse,
    value_runs,
)


@pytest.mark.parametrize("seed", range(6))
def test_distinct_gives_numpys_unique(seed: int) -> None:
    rng = np.random.default_rng(seed)
    size = int(rng.integers(1, 5000))
    values = rng.integers(0, size, int(rng.integers(0, 3 * size))).astype(np.int64)
    scratch = np.zeros(size, dtype=bool)
    assert np.array_equal(distinct(values, scratch), np.unique(values))
    assert not scratch.any()


@pytest.mark.parametrize("spread", [3, 1000, 10**9])
def test_unique_inverse_gives_numpys_unique_with_inverse(spread: int) -> None:
    keys = np.random.default_rng(spread).integers(0, spread, 2000)
    values, inverse = unique_inverse(keys)
    expected, expected_inverse = np.unique(keys, return_inverse=True)
    assert np.array_equal(values, expected)
    assert np.array_equal(inverse, expected_inverse)
    assert np.array_equal(values[inverse], keys)


@pytest.mark.parametrize("shape", [(1, 1), (1, 9), (7, 1), (40, 33)])
def test_label_sums_are_the_weighted_counts_per_label(shape: tuple[int, int]) -> None:
    rng = np.random.default_rng(shape[1])
    labels = np.repeat(rng.integers(0, 6, (shape[0], shape[1] // 3 + 1)), 3, axis=1)[:, : shape[1]].astype(np.int32)
    h, w = shape
    count, sum_col, sum_row = label_sums(labels, 8)
    flat = labels.ravel()
    assert np.array_equal(count, np.bincount(flat, minlength=8))
    assert np.array_equal(sum_col, np.bincount(flat, np.tile(np.arange(w, dtype=np.float64), h), 8))
    assert np.array_equal(sum_row, np.bincount(flat, np.repeat(np.arange(h, dtype=np.float64), w), 8))


@pytest.mark.parametrize("shape", [(0, 5), (1, 1), (1, 9), (7, 1), (40, 33)])
def test_label_counts_are_the_pixel_counts_per_label_in_and_out_of_a_mask(shape: tuple[int, int]) -> None:
    rng = np.random.default_rng(shape[1])
    labels = np.repeat(rng.integers(0, 6, (shape[0], shape[1] // 3 + 1)), 3, axis=1)[:, : shape[1]].astype(np.int32)
    for density in (0.4, 0.01, 0.0):  # dense and sparse masks (counted by runs, or pixel by pixel), and none
        mask = rng.random(shape) < density
        count, inside = label_counts(labels, 8, mask)
        assert np.array_equal(count, np.bincount(labels.ravel(), minlength=8))
        assert np.array_equal(inside, np.bincount(labels[mask], minlength=8))
        assert count.dtype == inside.dtype == np.int64
    alone, nothing = label_counts(labels, 8)
    assert np.array_equal(alone, count)
    assert not nothing.any()


@pytest.mark.parametrize("density", [0.4, 0.01, 0.0])
def test_mask_counts_are_the_label_counts_of_each_label_image(density: float) -> None:
    """One mask (dense, sparse, empty) over label images whose largest label differs: the counts of each image."""
    rng = np.random.default_rng(round(density * 100))
    mask = rng.random((50, 70)) < density
    counts = MaskCounts(mask)
    for top in (1, 9, 3):
        labels = rng.integers(0, top + 1, mask.shape).astype(np.int32)
        count, inside = counts.counts(labels)
        assert np.array_equal(count, np.bincount(labels.ravel(), minlength=top + 1))
        assert np.array_equal(inside, np.bincount(labels[mask], minlength=top + 1))
        assert np.array_equal(counts.inside(labels), inside)
        assert count.dtype == inside.dtype == counts.inside(labels).dtype == np.int64


@pytest.mark.parametrize("mask_size", [3, 5])
@pytest.mark.parametrize("radius", [0, 1, 2.5, 5, 10.000000000000002, 13.7])
def test_near_is_the_distance_transform_within_a_radius(mask_size: int, radius: float) -> None:
    """Sparse and dense masks, pixels at every image border, and a mask without any pixel."""
    rng = np.random.default_rng(mask_size * 100 + round(radius * 10))
    for density in (0.0, 0.002, 0.05, 0.6):
        mask = rng.random((int(rng.integers(3, 90)), int(rng.integers(3, 90)))) < density
        expected = cv2.distanceTransform((~mask).astype(np.uint8), cv2.DIST_L2, mask_size) <= radius
        assert np.array_equal(near(mask, radius, mask_size), expected)


@pytest.mark.parametrize("mask_size", [3, 5])
@pytest.mark.parametrize("radius", [0, 1, 2.5, 10.000000000000002, 15.000000000000002])
def test_near_at_reads_the_distance_transform_at_the_points(mask_size: int, radius: float) -> None:
    """Points anywhere (corners and borders too, some repeated), sparse and dense masks, none, and no point."""
    rng = np.random.default_rng(mask_size * 100 + round(radius * 10))
    for density in (0.0, 0.002, 0.05, 0.6):
        h, w = (int(v) for v in rng.integers(1, 90, 2))
        mask = rng.random((h, w)) < density
        rows = np.r_[rng.integers(0, h, 60), 0, h - 1, 0, h - 1]
        cols = np.r_[rng.integers(0, w, 60), 0, 0, w - 1, w - 1]
        expected = cv2.distanceTransform((~mask).astype(np.uint8), cv2.DIST_L2, mask_size) <= radius
        assert np.array_equal(near_at(mask, rows, cols, radius, mask_size), expected[rows, cols])
        assert near_at(mask, rows[:0], cols[:0], radius, mask_size).shape == (0,)


@pytest.mark.parametrize("seed", range(4))
def test_label_max_gives_numpys_maximum_at_and_bincount(seed: int) -> None:
    rng = np.random.default_rng(seed)
    h, w = (int(v) for v in rng.integers(1, 60, 2))
    labels = np.repeat(rng.integers(0, 12, (h, (w + 3) // 4)), 4, axis=1)[:, :w].astype(np.int32)  # runs
    values = (rng.random((h, w)) * 50).astype(np.float32)
    expected = np.zeros(15, dtype=np.float32)
    np.maximum.at(expected, labels.ravel(), values.ravel())
    largest, count = label_max(labels, values, 15)
    assert largest.dtype == np.float32 and np.array_equal(largest, expected)
    assert np.array_equal(count, np.bincount(labels.ravel(), minlength=15))


@pytest.mark.parametrize("connectivity", [4, 8])
@pytest.mark.parametrize("seed", range(4))
def test_components_stats_are_opencvs_labels_and_stats(connectivity: int, seed: int) -> None:
    """Sparse, blobby and full masks as bool and as 0/255 bytes; the background's stats too (also when empty)."""
    rng = np.random.default_rng(seed)
    for density in (0.0, 0.03, 0.5, 1.0):
        mask = rng.random((int(rng.integers(1, 70)), int(rng.integers(1, 70)))) < density
        mask = cv2.dilate(mask.astype(np.uint8), np.ones((2, 2), np.uint8)).astype(bool) if seed % 2 else mask
        for image in (mask, mask.astype(np.uint8) * 255):
            n, labels, stats, _ = cv2.connectedComponentsWithStats(image.astype(np.uint8), connectivity=connectivity)
            got_n, got_labels, got_stats = components_stats(image, connectivity)
            assert got_n == n
            assert got_labels.dtype == np.int32 and np.array_equal(got_labels, labels)
            assert got_stats.dtype == np.int32 and np.array_equal(got_stats, stats)


@pytest.mark.parametrize("connectivity", [4, 8])
@pytest.mark.parametrize("seed", range(4))
def test_components_runs_spread_a_table_as_the_gather_of_every_pixel(connectivity: int, seed: int) -> None:
    """The runs the statistics came from cover the labels in raster order; a table spread by them is the gather."""
    rng = np.random.default_rng(seed)
    for density in (0.0, 0.03, 0.5, 1.0):
        mask = rng.random((int(rng.integers(1, 70)), int(rng.integers(1, 70)))) < density
        n, labels, stats, (label, length) = components_stats_runs(mask, connectivity)
        assert (n, labels.tolist(), stats.tolist()) == tuple(
            v.tolist() if isinstance(v, np.ndarray) else v for v in components_stats(mask, connectivity)
        )
        assert np.array_equal(np.repeat(label, length), labels.ravel())
        table = rng.random(n) < 0.5
        assert np.array_equal(lookup(table, labels, (label, length)), table[labels])
        if connectivity == 8:
            parts = components(mask)
            assert np.array_equal(parts.spread(table), table[parts.labels])


@pytest.mark.parametrize("seed", range(4))
def test_lookup_by_runs_is_the_gather_of_every_pixel(seed: int) -> None:
    rng = np.random.default_rng(seed)
    h, w = (int(v) for v in rng.integers(1, 50, 2))
    image = np.repeat(rng.integers(0, 9, (h, (w + 4) // 5)), 5, axis=1)[:, :w].astype(np.int32)  # runs
    lut = rng.integers(0, 1000, 9).astype(np.int32)
    got = lookup(lut, image)
    assert got.dtype == np.int32 and got.shape == image.shape and np.array_equal(got, lut[image])
    value, length = value_runs(image)
    assert int(length.sum()) == image.size and np.array_equal(np.repeat(value, length), image.ravel())
    assert np.all(value[1:] != value[:-1])
    flags = rng.random(9) < 0.5
    assert np.array_equal(lookup(flags, image), flags[image])


@pytest.mark.parametrize("seed", range(6))
def test_label_boxes_are_scipys_find_objects(seed: int) -> None:
    """Missing ids give None, ``max_label`` cuts the list or pads it with None."""
    rng = np.random.default_rng(seed)
    h, w = (int(v) for v in rng.integers(1, 40, 2))
    labels = np.repeat(rng.integers(0, int(rng.integers(1, 12)), (h, w)), 1 + seed % 3, axis=1).astype(np.int32)
    assert label_boxes(labels) == ndimage.find_objects(labels)
    for max_label in (1, 3, 20):
        assert label_boxes(labels, max_label) == ndimage.find_objects(labels, max_label=max_label)


@pytest.mark.parametrize("seed", range(4))
def test_nonzero_rc_is_numpys_nonzero_of_an_image(seed: int) -> None:
    rng = np.random.default_rng(seed)
    image = rng.integers(0, 3, (int(rng.integers(1, 60)), int(rng.integers(1, 80)))) * (rng.random() < 0.9)
    for array in (image, image > 1, image[::2, 1::3], (image > 0)[:, ::-1], np.zeros((5, 0), dtype=bool)):
        rows, cols = nonzero_rc(array)
        expected_rows, expected_cols = np.nonzero(array)
        assert rows.dtype == expected_rows.dtype and cols.dtype == expected_cols.dtype
        assert np.array_equal(rows, expected_rows) and np.array_equal(cols, expected_cols)


@pytest.mark.parametrize("seed", range(4))
def test_short_of_is_the_scaled_distance_transform_compared(seed: int) -> None:
    """Masks sparse to full, scales and limits as Python, float64 and float32 numbers (each compares in its own
    precision), limits at or below zero (nothing falls short), the map border."""
    rng = np.random.default_rng(seed)
    for density in (0.0, 0.002, 0.05, 0.5, 1.0):
        mask = rng.random((int(rng.integers(1, 90)), int(rng.integers(1, 90)))) < density
        distance = cv2.distanceTransform((~mask).astype(np.uint8), cv2.DIST_L2, 5)
        for scale, limit in ((0.05, 0.3), (np.float64(0.05), 0.3), (np.float32(0.05), np.float32(0.3)),
                             (0.1, float(rng.uniform(0.0, 1.5))), (0.05, 0.0), (0.05, -1.0)):
            got = short_of(mask, scale, limit)
            assert got.dtype == np.bool_ and np.array_equal(got, ~(distance * scale >= limit))


def test_border_steps_finds_every_neighbour_pair_of_two_segments() -> None:
    """Every 4-neighbour pair of pixels in two different segments (background 0 never counts), keyed by the pair;
    with ``allowed``, only pairs whose two pixels are allowed."""
    rng = np.random.default_rng(0)
    seg = rng.integers(0, 4, (30, 40)).astype(np.int32)
    allowed = rng.random(seg.shape) < 0.7
    for mask in (None, allowed):
        expected = set()
        for r in range(seg.shape[0]):
            for c in range(seg.shape[1]):
                for dy, dx in ((0, 1), (1, 0)):
                    if r + dy < seg.shape[0] and c + dx < seg.shape[1]:
                        a, b = int(seg[r, c]), int(seg[r + dy, c + dx])
                        ok = mask is None or (mask[r, c] and mask[r + dy, c + dx])
                        if a and b and a != b and ok:
                            expected.add((dy, dx, r, c, min(a, b) * 4 + max(a, b)))
        got = {
            (dy, dx, int(r), int(c), int(k))
            for dy, dx, rows, cols, keys in border_steps(seg, 4, mask)
            for r, c, k in zip(rows, cols, keys, strict=True)
        }
        assert got == expected

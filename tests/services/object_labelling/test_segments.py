from __future__ import annotations

import numpy as np
import pytest

from services.object_labelling import RangeHeightScan, boundaries, range_height_scan, segments
from tests.services.object_labelling.synthetic import Box, render_depth, true_plane, vga_intrinsics

PLANE = true_plane(1.0, 0.25)


def _scan_of(ranges: list[float], heights: list[float]) -> RangeHeightScan:
    r, h = np.array(ranges), np.array(heights)
    n = r.size
    bearings = np.linspace(0.5, -0.5, n)
    index = np.arange(n)
    return RangeHeightScan(bearings, r, h, r * np.cos(bearings), r * np.sin(bearings), index, index, index, index)


def test_boundaries_sit_at_the_first_cone_after_each_step() -> None:
    inf = float("inf")
    ranges = [inf] * 10 + [2.0] * 8 + [3.0] * 8 + [inf] * 10
    heights = [0.0] * 10 + [1.0] * 16 + [0.0] * 10
    assert boundaries(_scan_of(ranges, heights)).tolist() == [10, 18, 26]


def test_boundaries_ignore_steps_below_the_threshold() -> None:
    ranges = [2.0] * 10 + [2.05] * 10
    assert boundaries(_scan_of(ranges, [1.0] * 20), min_step_m=0.09).size == 0


@pytest.mark.parametrize("seed", range(4))
def test_segments_measure_separated_boxes(seed: int) -> None:
    rng = np.random.default_rng(seed)
    intrinsics = vga_intrinsics()
    boxes: list[Box] = []
    # three thin boxes side by side with gaps (thin, so that no side face adds to the visible width)
    for y in (0.9, 0.0, -0.9):
        width, height = rng.uniform(0.35, 0.6), rng.uniform(0.15, 1.0)
        boxes.append((rng.uniform(2.4, 3.7), y + rng.uniform(-0.05, 0.05), 0.1, width, height))
    depth = render_depth(intrinsics, boxes, noise_m=0.005, seed=seed)
    found = segments(range_height_scan(depth, intrinsics, PLANE))
    assert len(found) == 3
    for segment, (x, _, dx, width, height) in zip(sorted(found, key=lambda s: -s.bearing_rad), boxes, strict=True):
        assert segment.range_m == pytest.approx(x - dx / 2, abs=0.1)
        assert segment.height_m == pytest.approx(height, abs=0.05)
        assert segment.width_m == pytest.approx(width, abs=0.12)
        row_min, col_min, row_max, col_max = segment.box
        assert 0 <= row_min <= row_max < intrinsics.height and 0 <= col_min <= col_max < intrinsics.width

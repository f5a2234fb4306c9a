from __future__ import annotations

import math

import numpy as np
import pytest

from services.object_labelling import MissingCones, ObjectLabellingError, range_height_scan
from tests.services.object_labelling.synthetic import render_depth, true_plane, vga_intrinsics

PLANE = true_plane(1.0, 0.25)


def test_scan_of_an_empty_floor_sees_no_obstacle() -> None:
    intrinsics = vga_intrinsics()
    scan = range_height_scan(render_depth(intrinsics, [], noise_m=0.005), intrinsics, PLANE)
    assert np.isinf(scan.ranges_m).all()
    assert (scan.heights_m == 0).all()


def test_scan_puts_a_box_at_its_range_bearing_and_height() -> None:
    intrinsics = vga_intrinsics()
    # a 0.6 m wide, 1.2 m high box whose front face is 2.8 m ahead, centred 0.3 m to the left
    scan = range_height_scan(render_depth(intrinsics, [(3.0, 0.3, 0.4, 0.6, 1.2)]), intrinsics, PLANE)
    hit = np.isfinite(scan.ranges_m)
    bearings = scan.bearings_rad[hit]
    assert bearings.min() == pytest.approx(math.atan2(0.0, 2.8), abs=0.02)
    assert bearings.max() == pytest.approx(math.atan2(0.6, 2.8), abs=0.02)
    front = scan.ranges_m[hit] * np.cos(bearings)
    np.testing.assert_allclose(front, 2.8, atol=0.02)
    assert scan.heights_m[hit].max() == pytest.approx(1.2, abs=0.03)
    assert (scan.col_min[hit] >= 0).all() and (scan.row_max[hit] < intrinsics.height).all()


def test_cones_are_ordered_from_the_left_image_edge() -> None:
    intrinsics = vga_intrinsics()
    scan = range_height_scan(render_depth(intrinsics, [(3.0, 0.0, 0.4, 0.6, 1.2)]), intrinsics, PLANE)
    assert (np.diff(scan.bearings_rad) < 0).all()
    hit = np.flatnonzero(np.isfinite(scan.ranges_m))
    assert (np.diff(scan.col_min[hit]) >= 0).all()


def test_cones_without_depth_are_excluded_or_interpolated() -> None:
    intrinsics = vga_intrinsics()
    depth = render_depth(intrinsics, [(3.0, 0.0, 0.4, 2.0, 1.2)])
    depth[:, 316:324] = 0  # a sensor hole across the box
    excluded = range_height_scan(depth, intrinsics, PLANE, missing=MissingCones.EXCLUDE)
    filled = range_height_scan(depth, intrinsics, PLANE, missing=MissingCones.GAUSSIAN)
    holes = np.isnan(excluded.ranges_m)
    assert holes.any()
    np.testing.assert_allclose(filled.ranges_m[holes], 2.8, atol=0.05)
    np.testing.assert_array_equal(filled.ranges_m[~holes], excluded.ranges_m[~holes])


def test_scan_rejects_corrupt_depth() -> None:
    intrinsics = vga_intrinsics()
    with pytest.raises(ObjectLabellingError, match="no depth"):
        range_height_scan(np.zeros((480, 640), np.uint16), intrinsics, PLANE)
    with pytest.raises(ObjectLabellingError, match="camera model"):
        range_height_scan(np.ones((240, 320), np.uint16), intrinsics, PLANE)
    with pytest.raises(ObjectLabellingError, match="uint16"):
        range_height_scan(np.ones((480, 640), np.float32), intrinsics, PLANE)

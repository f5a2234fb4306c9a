from __future__ import annotations

import numpy as np
import pytest

from services.object_labelling import ObjectLabellingError, check_ground_plane, depth_to_points, fit_ground_plane
from tests.services.object_labelling.synthetic import render_depth, true_plane, vga_intrinsics


@pytest.mark.parametrize(("height_m", "pitch_rad"), [(1.0, 0.25), (0.6, 0.1), (1.5, 0.45)])
def test_fit_ground_plane_recovers_the_floor_under_noise_and_clutter(height_m: float, pitch_rad: float) -> None:
    intrinsics = vga_intrinsics()
    boxes = [(3.0, 0.5, 0.8, 1.2, 0.6), (2.5, -0.8, 0.4, 0.4, 1.8)]
    depth = render_depth(intrinsics, boxes, camera_height_m=height_m, pitch_rad=pitch_rad, noise_m=0.005, seed=1)
    plane = fit_ground_plane(depth_to_points(depth, intrinsics)[0])
    truth = true_plane(height_m, pitch_rad)
    assert np.dot(plane.normal, truth.normal) > np.cos(0.01)
    assert plane.offset == pytest.approx(height_m, abs=0.01)


def test_fit_ground_plane_never_takes_a_wall_for_the_floor() -> None:
    intrinsics = vga_intrinsics()
    wall = [(2.0, 0.0, 0.2, 10.0, 3.0)]  # a wall filling most of the view, 1.9 m ahead
    depth = render_depth(intrinsics, wall, pitch_rad=0.3)
    plane = fit_ground_plane(depth_to_points(depth, intrinsics)[0], min_inliers=100)
    assert np.dot(plane.normal, true_plane(1.0, 0.3).normal) > np.cos(0.02)


def test_check_ground_plane_flags_a_moved_camera() -> None:
    intrinsics = vga_intrinsics()
    plane = true_plane(1.0, 0.25)
    same = depth_to_points(render_depth(intrinsics, [], pitch_rad=0.25), intrinsics)[0]
    moved = depth_to_points(render_depth(intrinsics, [], pitch_rad=0.40), intrinsics)[0]
    assert check_ground_plane(same, plane).valid
    check = check_ground_plane(moved, plane)
    assert not check.valid
    assert check.inliers < check_ground_plane(same, plane).inliers


def test_fit_ground_plane_rejects_too_few_points() -> None:
    with pytest.raises(ObjectLabellingError, match="points"):
        fit_ground_plane(np.zeros((2, 3)))

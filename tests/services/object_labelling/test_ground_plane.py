from __future__ import annotations

import numpy as np
import pytest

from services.object_labelling import (
    ObjectLabellingError,
    check_ground_plane,
    depth_to_points,
    fit_ground_plane,
    subsample,
)
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


def _checked_points(depth: np.ndarray) -> np.ndarray:
    """Every 4th pixel, as the labeller checks (checked with min_inliers=300)."""
    return depth_to_points(*subsample(depth, vga_intrinsics(), step=4))[0]


@pytest.mark.parametrize(("height_m", "pitch_rad"), [(1.0, 0.40), (1.0, 0.10), (1.3, 0.25), (0.8, 0.25)])
def test_check_ground_plane_flags_a_moved_camera(height_m: float, pitch_rad: float) -> None:
    intrinsics = vga_intrinsics()
    plane = true_plane(1.0, 0.25)
    boxes = [(3.0, 0.5, 0.8, 1.2, 0.6)]
    same = _checked_points(render_depth(intrinsics, boxes, pitch_rad=0.25, noise_m=0.005))
    moved = _checked_points(render_depth(intrinsics, boxes, camera_height_m=height_m, pitch_rad=pitch_rad,
                                         noise_m=0.005))
    assert check_ground_plane(same, plane, min_inliers=300).verified
    check = check_ground_plane(moved, plane, min_inliers=300)
    assert not check.valid and not check.verified


def test_a_view_without_floor_does_not_contradict_the_plane() -> None:
    rack_face = [(1.2, 0.0, 0.2, 10.0, 3.0)]  # a rack face 1.1 m ahead hides the floor
    points = _checked_points(render_depth(vga_intrinsics(), rack_face, pitch_rad=0.25, noise_m=0.005))
    check = check_ground_plane(points, true_plane(1.0, 0.25), min_inliers=300)
    assert check.valid and not check.verified


def test_fit_ground_plane_rejects_too_few_points() -> None:
    with pytest.raises(ObjectLabellingError, match="points"):
        fit_ground_plane(np.zeros((2, 3)))

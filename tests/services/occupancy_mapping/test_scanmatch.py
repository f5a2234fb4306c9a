"""Scan-to-map matching: drift correction on simulated rooms, and the cases where it must keep still."""

from __future__ import annotations

import math

import numpy as np
import pytest

from services.occupancy_mapping import (
    OccupancyGrid,
    OccupancyMappingError,
    ScanArrays,
    ScanMatcher,
    likelihood_field,
    match_scan,
    sharpness,
)
from services.occupancy_mapping.scanmatch import border_cells, compose_poses, invert_pose
from shared.transforms import Pose2D
from tests.services.occupancy_mapping.simulate import room_ranges

RES_M = 0.05
HALF_ROOM_M = 4.0
ANGLES = np.linspace(-math.pi, math.pi, 720, endpoint=False)


def _true_pose(i: int, n: int) -> Pose2D:
    """A loop through the room, turning as it goes."""
    s = i / n
    return Pose2D(2.0 * math.cos(math.tau * s), 1.5 * math.sin(math.tau * s), math.tau * s + 1.0)


def _scan(pose: Pose2D, rng: np.random.Generator, i: int) -> ScanArrays:
    ranges = room_ranges(pose.x_m, pose.y_m, pose.yaw_rad, ANGLES, half_size_m=HALF_ROOM_M)
    ranges = ranges + rng.normal(0.0, 0.01, ANGLES.size)
    ranges[rng.random(ANGLES.size) < 0.05] = np.nan
    return ScanArrays(ranges, ANGLES, 0.05, 30.0, "laser", i)


def _map(matcher: ScanMatcher | None, *, drift: Pose2D, n: int = 160, seed: int = 3) -> OccupancyGrid:
    """Drive the loop with odometry drifting linearly to ``drift`` (applied as ``drift * true``)."""
    rng = np.random.default_rng(seed)
    grid = OccupancyGrid(resolution_m=RES_M)
    for i in range(n):
        true = _true_pose(i, n)
        f = i / n
        odom = compose_poses(Pose2D(f * drift.x_m, f * drift.y_m, f * drift.yaw_rad), true)
        scan = _scan(true, rng, i)
        pose = odom if matcher is None else matcher(grid, odom, scan)
        grid.integrate(pose, scan.ranges, scan.angles, range_min_m=0.05, range_max_m=30.0, max_range_m=30.0)
    return grid


def _wall_offsets_cells(grid: OccupancyGrid) -> np.ndarray:
    """Distance of each occupied cell centre to the nearest true wall, cells."""
    rows, cols = np.nonzero(grid.occupancy() > 65)
    x = grid.origin_x_m + (cols + 0.5) * RES_M
    y = grid.origin_y_m + (rows + 0.5) * RES_M
    return np.asarray(np.minimum(np.abs(np.abs(x) - HALF_ROOM_M), np.abs(np.abs(y) - HALF_ROOM_M)) / RES_M)


def _room_field() -> tuple[np.ndarray, tuple[float, float]]:
    """Likelihood field of the room walls with the zero border a 0.3 m search needs, and its origin."""
    border = border_cells(0.3, RES_M)
    half = round(HALF_ROOM_M / RES_M)
    size = 2 * (half + border)
    occupied = np.zeros((size, size), bool)
    lo, hi = border, border + 2 * half - 1
    occupied[lo : hi + 1, [lo, hi]] = True
    occupied[[lo, hi], lo : hi + 1] = True
    field = likelihood_field(occupied, sigma_cells=1.5)
    origin = -(half + border) * RES_M
    return field, (origin, origin)


def _points(pose: Pose2D) -> np.ndarray:
    r = room_ranges(pose.x_m, pose.y_m, pose.yaw_rad, ANGLES[::4], half_size_m=HALF_ROOM_M - RES_M / 2)
    return np.stack([r * np.cos(ANGLES[::4]), r * np.sin(ANGLES[::4])], axis=1)


def test_pose_composition_round_trips() -> None:
    a, b = Pose2D(1.0, -2.0, 0.7), Pose2D(-0.3, 0.4, -2.9)
    back = compose_poses(invert_pose(a), compose_poses(a, b))
    assert back == pytest.approx(b)


def test_likelihood_field_is_one_on_walls_and_falls_with_distance() -> None:
    occupied = np.zeros((9, 9), bool)
    occupied[4, 4] = True
    field = likelihood_field(occupied, sigma_cells=1.5)
    assert field[4, 4] == pytest.approx(1.0)
    row = field[4, 4:]
    assert np.all(np.diff(row) < 0)
    assert field.dtype == np.float32
    assert not likelihood_field(np.zeros((3, 3), bool), sigma_cells=1.0).any()


def test_likelihood_field_rejects_bad_sigma() -> None:
    with pytest.raises(OccupancyMappingError, match="sigma_cells"):
        likelihood_field(np.ones((3, 3), bool), sigma_cells=0.0)


def test_match_scan_recovers_a_pose_error_inside_the_window() -> None:
    field, origin = _room_field()
    true = Pose2D(0.4, -0.7, 0.3)
    prior = Pose2D(true.x_m + 0.17, true.y_m - 0.11, true.yaw_rad + math.radians(2.5))
    result = match_scan(
        field,
        field_origin_m=origin,
        resolution_m=RES_M,
        prior=prior,
        points_m=_points(true),
        window_m=0.3,
        window_rad=math.radians(5.0),
    )
    assert math.hypot(result.pose.x_m - true.x_m, result.pose.y_m - true.y_m) < RES_M
    assert abs(result.pose.yaw_rad - true.yaw_rad) < math.radians(0.5)
    assert result.score > result.prior_score


def test_match_scan_rejects_empty_points_and_windows() -> None:
    field, origin = _room_field()
    with pytest.raises(OccupancyMappingError, match="points_m"):
        match_scan(
            field,
            field_origin_m=origin,
            resolution_m=RES_M,
            prior=Pose2D(0, 0, 0),
            points_m=np.zeros((0, 2)),
            window_m=0.3,
            window_rad=0.1,
        )
    with pytest.raises(OccupancyMappingError, match="window_m"):
        match_scan(
            field,
            field_origin_m=origin,
            resolution_m=RES_M,
            prior=Pose2D(0, 0, 0),
            points_m=np.ones((3, 2)),
            window_m=0.0,
            window_rad=0.1,
        )


def test_matching_keeps_walls_within_a_cell_when_odometry_drifts() -> None:
    drift = Pose2D(0.35, -0.25, math.radians(6.0))
    matcher = ScanMatcher()
    matched = _map(matcher, drift=drift)
    smeared = _map(None, drift=drift)
    near_matched = np.mean(_wall_offsets_cells(matched) <= 1.5)  # on the true wall cell or its neighbour
    near_smeared = np.mean(_wall_offsets_cells(smeared) <= 1.5)
    assert near_matched > 0.95
    assert near_smeared < near_matched - 0.2
    assert sharpness(matched.occupancy()) > sharpness(smeared.occupancy()) + 0.1
    # walls stay thin: about one cell of wall per cell of perimeter, where the drifted map is a band
    perimeter_cells = 8 * HALF_ROOM_M / RES_M
    assert np.count_nonzero(matched.occupancy() > 65) < 2.0 * perimeter_cells
    assert np.count_nonzero(smeared.occupancy() > 65) > np.count_nonzero(matched.occupancy() > 65)
    # the drift estimate takes odometry back to the true frame
    expected = invert_pose(drift)
    got = matcher.drift("laser")
    assert math.hypot(got.x_m - expected.x_m, got.y_m - expected.y_m) < 0.1
    assert abs(got.yaw_rad - expected.yaw_rad) < math.radians(1.0)


def test_matching_never_moves_a_right_prediction() -> None:
    rng = np.random.default_rng(11)
    grid = OccupancyGrid(resolution_m=RES_M)
    matcher = ScanMatcher(warmup_scans=5)
    n = 80
    for i in range(n):
        true = _true_pose(i, n)
        scan = _scan(true, rng, i)
        assert matcher(grid, true, scan) == true
        grid.integrate(true, scan.ranges, scan.angles, range_min_m=0.05, range_max_m=30.0, max_range_m=30.0)
    assert matcher.drift("laser") == Pose2D(0.0, 0.0, 0.0)
    assert matcher.counts["match_corrected"] == 0
    assert matcher.counts["match_kept_prior"] > 0


@pytest.mark.parametrize(
    "ranges",
    [
        np.full(ANGLES.size, np.nan),
        np.full(ANGLES.size, np.inf),
        np.full(ANGLES.size, 0.01),  # all below range_min
        np.where(np.arange(ANGLES.size) % 60 == 0, 2.0, np.nan),  # too few returns
    ],
    ids=["nan", "inf", "too-short", "few-returns"],
)
def test_degenerate_scans_leave_the_pose_unchanged(ranges: np.ndarray) -> None:
    rng = np.random.default_rng(5)
    grid = OccupancyGrid(resolution_m=RES_M)
    for i in range(6):
        pose = _true_pose(i, 40)
        scan = _scan(pose, rng, i)
        grid.integrate(pose, scan.ranges, scan.angles, range_min_m=0.05, range_max_m=30.0, max_range_m=30.0)
    matcher = ScanMatcher(warmup_scans=0)
    predicted = Pose2D(0.31, -0.2, 0.5)
    assert matcher(grid, predicted, ScanArrays(ranges, ANGLES, 0.05, 30.0, "laser", 99)) == predicted
    assert matcher.drift("laser") == Pose2D(0.0, 0.0, 0.0)


def test_each_sensor_frame_keeps_its_own_drift() -> None:
    matcher = ScanMatcher()
    _map(matcher, drift=Pose2D(0.3, 0.0, 0.0))
    assert matcher.drift("laser").x_m < -0.1
    assert matcher.drift("robot2/laser") == Pose2D(0.0, 0.0, 0.0)


def test_scan_matcher_rejects_bad_settings() -> None:
    with pytest.raises(OccupancyMappingError, match="window_rad"):
        ScanMatcher(window_rad=4.0)
    with pytest.raises(OccupancyMappingError, match="sigma_cells"):
        ScanMatcher(sigma_cells=-1.0)
    with pytest.raises(OccupancyMappingError, match="min_returns"):
        ScanMatcher(min_returns=0)

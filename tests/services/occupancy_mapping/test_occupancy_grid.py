"""The growing log-odds occupancy grid."""

from __future__ import annotations

import math

import numpy as np
import pytest

from services.occupancy_mapping import OccupancyGrid, OccupancyMappingError, RayCasting
from shared.transforms import Pose2D
from tests.services.occupancy_mapping.simulate import room_ranges

RES = 0.05
ANGLES = np.linspace(-math.pi, math.pi, 720, endpoint=False)
LIMITS = {"range_min_m": 0.1, "range_max_m": 12.0, "max_range_m": 12.0}


def _cell(grid: OccupancyGrid, x: float, y: float) -> tuple[int, int]:
    return int((y - grid.origin_y_m) // grid.resolution_m), int((x - grid.origin_x_m) // grid.resolution_m)


def _scan_room(grid: OccupancyGrid, poses: list[Pose2D], **room: float) -> None:
    for pose in poses:
        ranges = room_ranges(pose.x_m, pose.y_m, pose.yaw_rad, ANGLES, **room)
        assert grid.integrate(pose, ranges, ANGLES, **LIMITS) == ANGLES.size


@pytest.fixture
def room_poses() -> list[Pose2D]:
    rng = np.random.default_rng(7)
    xy = rng.uniform(-2.0, 2.0, (6, 2))
    yaw = rng.uniform(-math.pi, math.pi, 6)
    return [Pose2D(float(x), float(y), float(t)) for (x, y), t in zip(xy, yaw, strict=True)]


@pytest.mark.parametrize("method", list(RayCasting))
def test_square_room_walls_occupied_interior_free_outside_unknown(
    method: RayCasting, room_poses: list[Pose2D]
) -> None:
    grid = OccupancyGrid(resolution_m=RES, ray_casting=method)
    _scan_room(grid, room_poses, half_size_m=3.02)
    occ = grid.occupancy()
    # every wall cell along the four walls is occupied within one cell
    for t in np.arange(-2.9, 2.9, 0.1):
        for x, y in ((3.02, t), (-3.02, t), (t, 3.02), (t, -3.02)):
            r, c = _cell(grid, x, y)
            assert occ[r - 1 : r + 2, c - 1 : c + 2].max() > 65, (x, y)
    r0, c0 = _cell(grid, -2.8, -2.8)
    r1, c1 = _cell(grid, 2.8, 2.8)
    interior = occ[r0:r1, c0:c1]
    assert np.all((interior >= 0) & (interior < 25))
    ro, co = _cell(grid, 3.4, 0.0)
    assert np.all(occ[ro:, co:] == -1)


def test_polygon_and_sampled_casting_agree(room_poses: list[Pose2D]) -> None:
    grids = [OccupancyGrid(resolution_m=RES, ray_casting=m) for m in RayCasting]
    for grid in grids:
        _scan_room(grid, room_poses)
    a, b = (g.occupancy() for g in grids)
    assert a.shape == b.shape
    assert np.mean(a == b) > 0.99


def test_grid_grows_in_chunks_and_keeps_old_cells(room_poses: list[Pose2D]) -> None:
    grid = OccupancyGrid(resolution_m=RES, chunk_m=8.0)
    _scan_room(grid, room_poses)
    before = grid.occupancy()
    origin = (grid.origin_x_m, grid.origin_y_m)
    assert before.shape == (160, 160)
    # a second room far to the east and south
    _scan_room(grid, [Pose2D(20.0, -9.0, 0.0)], centre_x_m=20.0, centre_y_m=-9.0, half_size_m=3.02)
    after = grid.occupancy()
    assert after.shape[0] % 160 == 0 and after.shape[1] % 160 == 0
    assert after.shape[1] > before.shape[1] and after.shape[0] > before.shape[0]
    dc = round((origin[0] - grid.origin_x_m) / RES)
    dr = round((origin[1] - grid.origin_y_m) / RES)
    np.testing.assert_array_equal(after[dr : dr + 160, dc : dc + 160], before)
    r, c = _cell(grid, 23.02, -9.0 + 0.51)
    assert after[r, c] > 65


def test_no_return_beams_clear_but_never_mark_occupied() -> None:
    grid = OccupancyGrid(resolution_m=RES)
    angles = np.linspace(-0.2, 0.2, 41)
    ranges = np.full(angles.size, np.inf)
    ranges[::2] = 12.0  # at range_max: no return either
    used = grid.integrate(
        Pose2D(0, 0, 0),
        ranges,
        angles,
        range_min_m=0.1,
        range_max_m=12.0,
        max_range_m=30.0,
        no_return_clear_m=3.0,
    )
    occ = grid.occupancy()
    assert used == angles.size
    assert occ.max() < 50
    r, c = _cell(grid, 2.5, 0.0)
    assert 0 <= occ[r, c] < 50
    r, c = _cell(grid, 3.5, 0.0)
    assert occ[r, c] == -1


def test_nan_negative_and_short_beams_are_skipped() -> None:
    grid = OccupancyGrid(resolution_m=RES)
    ranges = np.array([np.nan, -1.0, 0.05, -np.inf, 2.0])
    angles = np.linspace(-0.1, 0.1, 5)
    assert grid.integrate(Pose2D(0, 0, 0), ranges, angles, **LIMITS) == 1
    r, c = _cell(grid, 2.0 * math.cos(0.1), 2.0 * math.sin(0.1))
    assert grid.occupancy()[r - 1 : r + 2, c - 1 : c + 2].max() > 65


def test_all_invalid_scan_changes_nothing() -> None:
    grid = OccupancyGrid(resolution_m=RES)
    assert grid.integrate(Pose2D(0, 0, 0), [np.nan, np.nan], [0.0, 0.1], **LIMITS) == 0
    assert np.all(grid.occupancy() == -1)


@pytest.mark.parametrize(
    ("ranges", "angles", "pose", "match"),
    [
        ([1.0, 2.0], [0.0], Pose2D(0, 0, 0), "2 ranges but 1 angles"),
        ([1.0], [0.0], Pose2D(math.nan, 0, 0), "pose must be finite"),
        ([1.0], [math.inf], Pose2D(0, 0, 0), "angles must be finite"),
    ],
)
def test_integrate_rejects_bad_input(
    ranges: list[float], angles: list[float], pose: Pose2D, match: str
) -> None:
    with pytest.raises(OccupancyMappingError, match=match):
        OccupancyGrid(resolution_m=RES).integrate(pose, ranges, angles, **LIMITS)


def test_integrate_rejects_bad_range_limits() -> None:
    with pytest.raises(OccupancyMappingError, match="range_min_m < range_max_m"):
        OccupancyGrid(resolution_m=RES).integrate(
            Pose2D(0, 0, 0), [1.0], [0.0], range_min_m=5.0, range_max_m=1.0, max_range_m=10.0
        )


def test_constructor_rejects_nonsense() -> None:
    with pytest.raises(OccupancyMappingError, match="resolution_m"):
        OccupancyGrid(resolution_m=0.0)
    with pytest.raises(OccupancyMappingError, match="miss_logodds < 0 < hit_logodds"):
        OccupancyGrid(resolution_m=RES, hit_logodds=-1.0)


def test_layer_round_trip_resumes_the_same_map(room_poses: list[Pose2D]) -> None:
    grid = OccupancyGrid(resolution_m=RES)
    _scan_room(grid, room_poses)
    layer = grid.to_layer("occupancy")
    assert layer.data.dtype == np.int8
    resumed = OccupancyGrid.from_occupancy(
        layer.data, resolution_m=layer.resolution_m, origin_x_m=layer.origin_x_m, origin_y_m=layer.origin_y_m
    )
    np.testing.assert_array_equal(resumed.occupancy(), layer.data)
    assert (resumed.origin_x_m, resumed.origin_y_m) == (grid.origin_x_m, grid.origin_y_m)
    _scan_room(resumed, room_poses[:1])
    assert resumed.occupancy().shape == layer.data.shape


def test_from_occupancy_rejects_bad_layers() -> None:
    with pytest.raises(OccupancyMappingError, match=r"-1\.\.100"):
        OccupancyGrid.from_occupancy(
            np.full((2, 2), 120, np.int16), resolution_m=RES, origin_x_m=0, origin_y_m=0
        )
    with pytest.raises(OccupancyMappingError, match="whole number"):
        OccupancyGrid.from_occupancy(
            np.zeros((2, 2), np.int8), resolution_m=RES, origin_x_m=0.01, origin_y_m=0
        )

"""Portals, point location, straight legs and grid search on small literal grids."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from atlas.navigation import Frame, find_portals
from atlas.navigation.grid import free_cells, grid_path, nearest_cell, segment_clear
from shared.store import GridLayer

FRAME = Frame(0.5, -1.0, 2.0, (6, 8))
"""6 x 8 cells of 0.5 m from (-1, 2)."""


def _two_rooms() -> np.ndarray:
    """Region 1 on the left four columns, region 2 on the right four, region 3 in the top-right corner."""
    seg = np.zeros((6, 8), dtype=np.uint16)
    seg[:, :4] = 1
    seg[:, 4:] = 2
    seg[4:, 6:] = 3
    return seg


def test_portal_lies_in_the_middle_of_the_shared_boundary() -> None:
    portals = find_portals(_two_rooms(), FRAME)
    assert set(portals) == {(1, 2), (2, 3)}
    between = portals[(1, 2)]
    assert between.x_m == pytest.approx(-1.0 + 4 * 0.5)  # the line between columns 3 and 4
    assert 2.0 <= between.y_m <= 5.0
    assert between.width_m == pytest.approx(6 * 0.5)


def test_portal_of_a_bent_boundary_is_on_the_boundary() -> None:
    portals = find_portals(_two_rooms(), FRAME)
    bent = portals[(2, 3)]  # an L: below region 3 and left of it
    on_vertical = bent.x_m == pytest.approx(-1.0 + 6 * 0.5) and bent.y_m >= 2.0 + 4 * 0.5
    on_horizontal = bent.y_m == pytest.approx(2.0 + 4 * 0.5) and bent.x_m >= -1.0 + 6 * 0.5
    assert on_vertical or on_horizontal
    assert bent.width_m == pytest.approx((2 + 2) * 0.5)


def test_no_portals_where_regions_do_not_touch() -> None:
    seg = np.zeros((4, 5), dtype=np.uint16)
    seg[:, :2], seg[:, 3:] = 1, 2
    assert find_portals(seg, Frame(0.1, 0.0, 0.0, (4, 5))) == {}


def test_nearest_cell_prefers_the_cell_under_the_point_then_the_closest_within_tolerance() -> None:
    mask = np.zeros((6, 8), dtype=bool)
    mask[:, 5:] = True
    assert nearest_cell(mask, FRAME, 2.1, 3.1, tolerance_m=1.0) == (2, 6)
    assert nearest_cell(mask, FRAME, 1.3, 3.1, tolerance_m=1.0) == (2, 5)
    assert nearest_cell(mask, FRAME, -0.9, 3.1, tolerance_m=1.0) is None
    assert nearest_cell(mask, FRAME, 50.0, 50.0, tolerance_m=1.0) is None


def test_a_straight_leg_is_clear_only_on_mask_cells() -> None:
    mask = np.ones((6, 8), dtype=bool)
    mask[1:, 3] = False  # a wall with a gap in the lowest row
    assert not segment_clear(mask, FRAME, (-0.75, 4.0), (2.75, 4.0))
    assert segment_clear(mask, FRAME, (-0.75, 2.25), (2.75, 2.25))
    assert not segment_clear(mask, FRAME, (-0.75, 2.25), (9.0, 2.25))  # leaves the grid


def test_grid_path_goes_round_a_wall_through_its_gap() -> None:
    mask = np.ones((6, 8), dtype=bool)
    mask[1:, 3] = False
    a, b = (-0.75, 4.25), (2.75, 4.25)
    path = grid_path(mask, FRAME, a, b)
    assert path is not None
    assert path[0] == a and path[-1] == b
    assert all(segment_clear(mask, FRAME, p, q) for p, q in itertools.pairwise(path))
    assert min(y for _, y in path) < 2.5  # through the gap in the lowest row
    assert sum(math.dist(p, q) for p, q in itertools.pairwise(path)) > math.dist(a, b)


def test_grid_path_is_none_without_a_way_through() -> None:
    mask = np.ones((6, 8), dtype=bool)
    mask[:, 3] = False
    assert grid_path(mask, FRAME, (-0.75, 4.25), (2.75, 4.25)) is None


def test_free_cells_resample_an_occupancy_layer_with_another_extent() -> None:
    occupancy = GridLayer("occupancy", np.array([[0, 100], [-1, 20]], dtype=np.int8), 1.0, -1.0, 2.0)
    free = free_cells(occupancy, FRAME)
    assert free[0, 0] and free[0, 1]  # inside the free cell (-1..0, 2..3)
    assert not free[0, 2]  # occupied cell
    assert not free[2, 0]  # unknown cell
    assert free[2, 2]  # 20 % is free
    assert not free[:, 4:].any() and not free[4:, :].any()  # outside the occupancy layer

"""Change between two occupancy grids, as the decomposition worker measures it."""

from __future__ import annotations

import numpy as np
import pytest

from services.grid_decomposition import DecompositionError, changed_fraction, occupancy_classes
from services.grid_decomposition.change import unchanged_cells
from shared.store import GridLayer
from tests.services.grid_decomposition.warehouse import synthetic_warehouse

RES_M = 0.1


def _layer(data: np.ndarray, *, origin_xy_m: tuple[float, float] = (0.0, 0.0), resolution_m: float = RES_M
           ) -> GridLayer:
    return GridLayer("occupancy", data.astype(np.int8), resolution_m, *origin_xy_m)


def _room(seed: int, shape: tuple[int, int] = (30, 40)) -> np.ndarray:
    rng = np.random.default_rng(seed)
    occ = rng.choice(np.array([-1, 0, 50, 100], dtype=np.int8), size=shape, p=[0.2, 0.6, 0.05, 0.15])
    return occ


def test_occupancy_classes_use_the_decomposition_thresholds() -> None:
    occ = np.array([[-1, 0, 24, 25, 65, 66, 100]], dtype=np.int8)
    assert occupancy_classes(occ).tolist() == [[0, 1, 1, 2, 2, 3, 3]]


def test_occupancy_classes_reject_a_float_grid() -> None:
    with pytest.raises(DecompositionError, match="2-D integer grid"):
        occupancy_classes(np.zeros((3, 3)))  # type: ignore[arg-type]


def test_changed_fraction_of_an_unchanged_grid_is_zero() -> None:
    occ = _room(0)
    assert changed_fraction(_layer(occ), _layer(occ.copy())) == 0.0


def test_changed_fraction_measures_structural_change_against_the_obstacles() -> None:
    occ = np.zeros((10, 10), dtype=np.int8)
    occ[:, 9] = 100  # a wall of 10 cells
    after = occ.copy()
    after[0, 5] = 100  # free -> occupied
    after[1, 5] = 10  # free -> free: same class
    after[2, 9] = 50  # occupied -> uncertain
    assert changed_fraction(_layer(occ), _layer(after)) == pytest.approx(2 / 11)


def test_changed_fraction_measures_exploration_against_the_known_cells() -> None:
    occ = np.zeros((10, 10), dtype=np.int8)
    occ[:, :5] = -1
    occ[:, 9] = 100
    after = occ.copy()
    after[0:3, 4] = 0  # unknown -> free
    after[0, 3] = 100  # unknown -> occupied: explored, no structural change of known cells
    assert changed_fraction(_layer(occ), _layer(after)) == pytest.approx(4 / 54)


def test_changed_fraction_notices_a_different_rack_layout() -> None:
    before = synthetic_warehouse(0, resolution_m=RES_M).occupancy
    after = synthetic_warehouse(1, resolution_m=RES_M).occupancy
    assert changed_fraction(_layer(before), _layer(after)) > 0.2


def test_changed_fraction_of_a_grid_grown_by_unknown_cells_is_zero() -> None:
    occ = _room(1)
    grown = np.full((occ.shape[0] + 7, occ.shape[1] + 5), -1, dtype=np.int8)
    grown[3 : 3 + occ.shape[0], 4 : 4 + occ.shape[1]] = occ
    origin = (2.0 - 4 * RES_M, -1.0 - 3 * RES_M)
    assert changed_fraction(_layer(occ, origin_xy_m=(2.0, -1.0)), _layer(grown, origin_xy_m=origin)) == 0.0


def test_changed_fraction_counts_newly_known_cells_of_a_grown_grid() -> None:
    occ = np.zeros((10, 10), dtype=np.int8)
    grown = np.zeros((10, 15), dtype=np.int8)
    assert changed_fraction(_layer(occ), _layer(grown)) == pytest.approx(50 / 150)


def test_changed_fraction_of_grids_that_do_not_overlap_is_one() -> None:
    occ = _room(2)
    far = (occ.shape[1] * RES_M * 3, 0.0)
    assert changed_fraction(_layer(occ), _layer(occ, origin_xy_m=far)) == 1.0


def test_changed_fraction_is_one_for_grids_not_aligned_cell_by_cell() -> None:
    occ = _room(3)
    assert changed_fraction(_layer(occ), _layer(occ, origin_xy_m=(RES_M / 2, 0.0))) == 1.0
    assert changed_fraction(_layer(occ), _layer(occ, resolution_m=2 * RES_M)) == 1.0


def test_changed_fraction_of_unknown_grids_is_zero() -> None:
    unknown = np.full((5, 5), -1, dtype=np.int8)
    assert changed_fraction(_layer(unknown), _layer(unknown, origin_xy_m=(3.0, 3.0))) == 0.0


@pytest.mark.parametrize("seed", range(5))
def test_changed_fraction_is_symmetric_and_within_unit_interval(seed: int) -> None:
    rng = np.random.default_rng(seed)
    a, b = _room(seed, (20, 25)), _room(seed + 100, (18, 30))
    shift = rng.integers(-10, 10, size=2) * RES_M
    la, lb = _layer(a), _layer(b, origin_xy_m=(float(shift[0]), float(shift[1])))
    forward = changed_fraction(la, lb)
    assert 0.0 < forward <= 1.0
    assert changed_fraction(lb, la) == pytest.approx(forward)


def test_unchanged_cells_leave_out_changes_their_margin_and_cells_the_old_grid_did_not_hold() -> None:
    before = np.zeros((8, 8), dtype=np.int8)
    after = before.copy()
    after[4, 4] = 100  # a new obstacle
    after[0, 0] = 10  # still free: the same class
    covered = np.ones((8, 8), dtype=bool)
    covered[:, 7] = False  # the grid grew by a column
    same = unchanged_cells(before, after, resolution_m=0.1, covered=covered, margin_m=0.1)
    expected = np.ones((8, 8), dtype=bool)
    expected[3:6, 3:6] = False
    expected[:, 6:] = False
    assert np.array_equal(same, expected)
    with pytest.raises(DecompositionError, match="shape"):
        unchanged_cells(before, after[:, :4], resolution_m=0.1)


def test_a_map_drawn_again_a_cell_over_is_unchanged_within_the_jitter_but_a_new_wall_is_not() -> None:
    before = np.zeros((12, 12), dtype=np.int8)
    before[:, 5] = 100  # a wall
    after = np.roll(before, 1, axis=1)  # drawn again one cell to the right
    after[9:, 1] = 100  # and a wall that was not there
    assert not unchanged_cells(before, after, resolution_m=0.1, margin_m=0.0)[:, 5:7].any()
    same = unchanged_cells(before, after, resolution_m=0.1, margin_m=0.0, jitter_m=0.1)
    expected = np.ones((12, 12), dtype=bool)
    expected[9:, 1] = False
    assert np.array_equal(same, expected)
    with pytest.raises(DecompositionError, match="jitter_m"):
        unchanged_cells(before, after, resolution_m=0.1, jitter_m=-0.1)

"""Degenerate input to every stage of the pipeline: a clear error or an empty answer, never a crash."""

import numpy as np
import pytest

from services.pillar_mapping import (
    BearingOnlyMapper,
    LandmarkMap,
    PillarMappingError,
    detect_pillars,
    fit_landmark_map,
    fit_layout,
)
from services.pillar_mapping.synthetic import default_camera


@pytest.mark.parametrize("grey", [0, 128, 255])
def test_a_blank_frame_has_no_uprights(grey: int) -> None:
    camera = default_camera(size_px=240)
    assert detect_pillars(np.full((240, 240, 3), grey, dtype=np.uint8), camera).bearings_rad.size == 0


def test_bearings_with_nan_are_refused_and_an_empty_frame_is_fine() -> None:
    mapper = BearingOnlyMapper()
    with pytest.raises(PillarMappingError, match="finite"):
        mapper.observe((0.0, 0.0, 0.0), [0.1, np.nan], [0.01, 0.01])
    report = mapper.observe((0.0, 0.0, 0.0), [], [])
    assert report.matched == report.initialised == 0


def _table(xy: np.ndarray) -> np.ndarray:
    return np.column_stack([xy, np.tile([1e-4, 0.0, 1e-4], (len(xy), 1))])


@pytest.mark.parametrize(
    "xy",
    [
        np.zeros((0, 2)),  # no uprights
        np.array([[0.0, 0.0], [2.7, 0.0], [5.4, 0.0]]),  # fewer than a row
        np.zeros((40, 2)),  # all in one place
        np.column_stack([np.arange(40) * 0.01, np.zeros(40)]),  # closer together than any bay
        np.column_stack([np.arange(30) * 2.7, np.arange(30) * 1e-9]),  # one row, nothing to pair it with
    ],
)
def test_layouts_of_degenerate_maps_have_no_bins(xy: np.ndarray) -> None:
    layout = fit_layout(_table(xy))
    assert layout.bins == []
    assert len(layout.rows) + len(layout.outliers) <= max(len(xy), 1)


def test_an_empty_or_non_finite_live_map_gives_no_bins() -> None:
    empty = LandmarkMap(np.zeros((0, 2)), np.zeros((0, 2, 2)), np.zeros(0, dtype=np.int64))
    assert fit_landmark_map(empty).bins == []
    covs = np.tile(np.eye(2) * 1e-4, (5, 1, 1))
    covs[2] = np.nan
    nan_cov = LandmarkMap(np.column_stack([np.arange(5) * 2.7, np.zeros(5)]), covs, np.full(5, 9, dtype=np.int64))
    assert fit_landmark_map(nan_cov).bins == []


@pytest.mark.parametrize("bad", [np.inf, np.nan])
def test_a_landmark_table_with_non_finite_values_is_refused(bad: float) -> None:
    table = _table(np.column_stack([np.arange(10) * 2.7, np.zeros(10)]))
    table[3, 4] = bad
    with pytest.raises(PillarMappingError, match="non-finite"):
        fit_layout(table)

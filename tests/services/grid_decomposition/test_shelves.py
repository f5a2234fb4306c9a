"""Racks a lidar sees only as rows of dashes (their upright frames) are storage, the gaps between them aisles."""

from __future__ import annotations

import numpy as np

from services.grid_decomposition import decompose
from services.grid_decomposition.arrays import components
from services.grid_decomposition.shelves import find_shelf_banks
from shared.vocabulary import PlaceLabel
from tests.services.grid_decomposition.test_rooms import RES, _furnish, _office_row

_X0, _PITCH, _DASH, _N = 60, 36, 18, 6  # px: first rack, rack pitch 1.8 m, frames 0.9 m deep
_ROWS = (60, 100, 140)  # frame rows 2 m apart: racks 4 m long


def _rack_bank() -> np.ndarray:
    """14 x 11 m hall at 5 cm: six racks seen as three rows of 0.9 m dashes (their frames), 1.8 m apart."""
    occ = np.full((220, 280), -1, dtype=np.int8)
    occ[2:218, 2:278] = 100
    occ[5:215, 5:275] = 0
    for y in _ROWS:
        for k in range(_N):
            x = _X0 + k * _PITCH
            occ[y : y + 2, x : x + _DASH] = 100
    return occ


def test_a_bank_of_racks_seen_as_dashes_is_storage_with_aisles_between() -> None:
    occ = _rack_bank()
    d = decompose(occ, resolution_m=RES)
    mid = _X0 + _DASH // 2
    rack = d.labels[_ROWS[0] + 5 : _ROWS[-1] - 3, mid - 4 : mid + 5]
    aisle = d.labels[_ROWS[0] + 5 : _ROWS[-1] - 3, mid + 14 : mid + 23]
    assert (rack == PlaceLabel.STORAGE.value).mean() > 0.9
    assert (aisle == PlaceLabel.CORRIDOR.value).mean() > 0.9
    assert (d.labels[180:210, 20:260] != PlaceLabel.STORAGE.value).all()  # the floor beside the bank is no rack


def test_the_occupied_cells_labelled_once_find_the_same_banks() -> None:
    occ = _rack_bank()
    banks = find_shelf_banks(occ == 100, occ == 0, resolution_m=RES)
    shared = find_shelf_banks(occ == 100, occ == 0, resolution_m=RES, labelled=components(occ == 100))
    assert banks.storage.any()
    for own, given in zip(banks, shared, strict=True):
        assert np.array_equal(own, given)


def test_one_row_of_dashes_or_unaligned_rows_are_no_racks() -> None:
    occ = _rack_bank()
    occ[_ROWS[1] : _ROWS[1] + 2] = np.where(occ[_ROWS[1] : _ROWS[1] + 2] == 100, 0, occ[_ROWS[1] : _ROWS[1] + 2])
    occ[_ROWS[2] : _ROWS[2] + 2] = np.where(occ[_ROWS[2] : _ROWS[2] + 2] == 100, 0, occ[_ROWS[2] : _ROWS[2] + 2])
    banks = find_shelf_banks(occ == 100, occ == 0, resolution_m=RES)
    assert not banks.storage.any() and not banks.aisle.any()
    shifted = _rack_bank()
    shifted[_ROWS[1] : _ROWS[1] + 2] = np.roll(shifted[_ROWS[1] : _ROWS[1] + 2], _PITCH // 2, axis=1)
    shifted[_ROWS[2] : _ROWS[2] + 2] = 0
    banks = find_shelf_banks(shifted == 100, shifted == 0, resolution_m=RES)
    assert not banks.storage.any()


def test_a_furnished_office_has_no_racks_and_no_storage() -> None:
    occ = _furnish(_office_row())
    banks = find_shelf_banks(occ == 100, occ == 0, resolution_m=RES)
    assert not banks.storage.any() and not banks.aisle.any() and not banks.outline.any()
    assert not (decompose(occ, resolution_m=RES).labels == PlaceLabel.STORAGE.value).any()

"""Cleaning a real SLAM map before decomposing it."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from services.grid_decomposition import decompose
from services.grid_decomposition.cleaning import clean_occupancy

RES = 0.05


def _room() -> npt.NDArray[np.int8]:
    """A 6 m x 4 m walled room in unknown space (0.1 m walls), GridLayer order."""
    occ = np.full((120, 160), -1, dtype=np.int8)
    occ[20:100, 20:140] = 100
    occ[22:98, 22:138] = 0
    return occ


def test_a_speck_in_the_room_becomes_free() -> None:
    occ = _room()
    occ[60, 80] = 100
    cleaned, what = clean_occupancy(occ, resolution_m=RES)
    assert cleaned[60, 80] == 0 and what.specks[60, 80]


def test_a_blob_on_the_wall_is_no_speck() -> None:
    occ = _room()
    occ[22, 80] = 100  # on the wall's inner face
    cleaned, _ = clean_occupancy(occ, resolution_m=RES)
    assert cleaned[22, 80] == 100


def test_a_laser_streak_outside_the_building_is_removed() -> None:
    occ = _room()
    occ[60, 138:140] = 0  # a gap in the wall (glass) ...
    occ[60, 140:159] = 0  # ... and the ray beyond it, 1 px wide in unknown space
    cleaned, what = clean_occupancy(occ, resolution_m=RES)
    assert np.all(cleaned[60, 150:159] == -1) and what.streaks[60, 150:159].all()
    assert np.all(cleaned[30:90, 30:130] == 0)  # the room's floor stays


def test_an_isolated_free_speck_in_unknown_space_is_removed() -> None:
    occ = _room()
    occ[5:8, 5:8] = 0
    cleaned, _ = clean_occupancy(occ, resolution_m=RES)
    assert np.all(cleaned[5:8, 5:8] == -1)


def test_grey_fringe_at_a_wall_becomes_wall_and_clear_floor_stays() -> None:
    occ = _room()
    occ[22:98, 22:24] = 12  # half-seen cells along the left wall
    occ[50:52, 80:82] = 12  # the same grey alone in the middle of the room
    cleaned, what = clean_occupancy(occ, resolution_m=RES)
    assert np.all(cleaned[22:98, 22:24] == 100) and what.fringe[22:98, 22:24].all()
    assert np.all(cleaned[50:52, 80:82] == 12)


def test_trinary_map_of_clean_rooms_is_unchanged() -> None:
    occ = _room()
    cleaned, _ = clean_occupancy(occ, resolution_m=RES)
    assert np.array_equal(cleaned, occ)


def test_decomposition_labels_no_fringe_and_no_streak() -> None:
    occ = _room()
    occ[22:98, 22:24] = 12
    occ[60, 138:140] = 0
    occ[60, 140:159] = 0
    result = decompose(occ, resolution_m=RES)
    assert not result.segments[22:98, 22:24].any()
    assert not result.segments[60, 150:159].any()
    assert result.segments[60, 80] > 0

"""Rack halls drawn the ways other maps draw racks: exact truth on free cells, each style as described."""

from __future__ import annotations

import numpy as np
import pytest

from services.simulator.rackmaps import PlaceTruth, RackStyle, rack_hall_map


@pytest.mark.parametrize("style", list(RackStyle))
def test_truth_covers_exactly_the_free_cells(style: RackStyle) -> None:
    hall = rack_hall_map(3, style=style, rotation_rad=0.3, n_double_rows=2, bays_per_section=4)
    free = hall.occupancy == 0
    assert ((hall.truth > 0) == free).all()
    assert set(np.unique(hall.truth[free])) <= {p.value for p in PlaceTruth if p.value}
    assert set(np.unique(hall.occupancy)) <= {-1, 0, 100}


def test_the_same_seed_draws_the_same_hall() -> None:
    a = rack_hall_map(5, style=RackStyle.MIXED)
    b = rack_hall_map(5, style=RackStyle.MIXED)
    assert (a.occupancy == b.occupancy).all() and (a.truth == b.truth).all()


def test_a_solid_rack_is_an_occupied_rectangle_and_has_no_free_storage() -> None:
    hall = rack_hall_map(0, style=RackStyle.SOLID, n_double_rows=2, bays_per_section=4)
    assert not (hall.truth == PlaceTruth.STORAGE.value).any()
    r0, c0 = np.floor(hall.racks_px[0].min(axis=0)[::-1]).astype(int) + 1
    r1, c1 = np.ceil(hall.racks_px[0].max(axis=0)[::-1]).astype(int) - 1
    assert (hall.occupancy[r0:r1, c0:c1] == 100).all()


def test_at_pallet_height_loaded_bays_hide_what_is_behind_and_empty_bays_are_open() -> None:
    hall = rack_hall_map(1, style=RackStyle.PALLET_HEIGHT, n_double_rows=2, bays_per_section=6)
    inside = hall.cells > 0  # bay footprints (free cells only)
    storage = np.zeros(hall.occupancy.shape, dtype=bool)
    for rack in hall.racks_px:
        r0, c0 = np.floor(rack.min(axis=0)[::-1]).astype(int)
        r1, c1 = np.ceil(rack.max(axis=0)[::-1]).astype(int)
        storage[r0:r1, c0:c1] = True
    assert (hall.occupancy[storage] == -1).mean() > 0.2  # unknown behind pallet faces
    assert inside.sum() > 0.1 * storage.sum()  # empty bays seen through


def test_missing_uprights_are_not_drawn() -> None:
    full = rack_hall_map(2, style=RackStyle.UPRIGHTS, missing=0.0)
    some = rack_hall_map(2, style=RackStyle.UPRIGHTS, missing=0.3)
    ratio = (some.occupancy == 100).sum() / (full.occupancy == 100).sum()
    assert ratio < 1.0


def test_a_depot_is_open_floor_with_pallets_on_it() -> None:
    hall = rack_hall_map(4, style=RackStyle.DEPOT)
    free = hall.occupancy == 0
    assert (hall.truth[free] == PlaceTruth.OPEN_AREA.value).all()
    assert len(hall.pallets_px) >= 6 and len(hall.racks_px) == 0 and not hall.junctions.any()


def test_turning_keeps_the_hall() -> None:
    straight = rack_hall_map(6, style=RackStyle.UPRIGHTS)
    turned = rack_hall_map(6, style=RackStyle.UPRIGHTS, rotation_rad=0.5)
    a, b = (straight.truth > 0).sum(), (turned.truth > 0).sum()
    assert abs(a - b) < 0.01 * a
    assert len(straight.junctions_px) == len(turned.junctions_px)

import numpy as np
import pytest
from scipy.spatial import cKDTree

from services.pillar_mapping import PillarMappingError, fit_layout, rack_profile
from services.pillar_mapping.synthetic import merge_layouts, noisy_landmarks, rack_region


def test_each_floor_cell_becomes_one_bin_per_level_of_the_site_profile() -> None:
    layout = rack_region(aisles=2, bays=6)
    landmarks, _ = noisy_landmarks(layout, np.random.default_rng(0), missing_fraction=0.0)

    bins = fit_layout(landmarks, profiles=[rack_profile([0.0, 1.5, 3.0, 4.5])]).bins

    assert len(bins) == 4 * len(layout.bin_centres)
    by_cell: dict[str, list[tuple[int | None, float | None]]] = {}
    for b in bins:
        cell, level = b.id.rsplit("-", 1)
        assert b.level is not None and level == f"{b.level + 1:02d}"
        by_cell.setdefault(cell, []).append((b.level, b.z_m))
    assert all(sorted(v) == [(0, 0.0), (1, 1.5), (2, 3.0), (3, 4.5)] for v in by_cell.values())


def test_without_a_profile_levels_are_unknown_and_ids_have_none() -> None:
    landmarks, _ = noisy_landmarks(rack_region(aisles=1, bays=4), np.random.default_rng(0), missing_fraction=0.0)

    bins = fit_layout(landmarks).bins

    assert bins and all(b.level is None and b.z_m is None and b.id.count("-") == 1 for b in bins)


def test_a_profile_with_an_area_applies_only_to_the_racks_inside_it() -> None:
    layout = merge_layouts(rack_region(aisles=1, bays=4), rack_region(origin_xy_m=(30.0, 0.0), aisles=1, bays=4))
    landmarks, _ = noisy_landmarks(layout, np.random.default_rng(1), missing_fraction=0.0)
    east = rack_profile([0.0, 2.0], area=[[25.0, -5.0], [50.0, -5.0], [50.0, 20.0], [25.0, 20.0]])
    default = rack_profile([0.0, 1.2, 2.4])

    bins = fit_layout(landmarks, profiles=[east, default]).bins

    assert {b.z_m for b in bins if b.centre[0] > 25} == {0.0, 2.0}
    assert {b.z_m for b in bins if b.centre[0] < 25} == {0.0, 1.2, 2.4}


def test_bin_ids_with_levels_survive_a_rebuild_with_other_noise() -> None:
    layout = rack_region(aisles=3, bays=10, cross_aisle_every=5, cross_aisle_width_m=3.0)
    profile = rack_profile([0.0, 1.6, 3.2])
    ids = []
    for seed in (1, 2):
        landmarks, _ = noisy_landmarks(layout, np.random.default_rng(seed))
        bins = fit_layout(landmarks, profiles=[profile]).bins
        cell = cKDTree(layout.bin_centres)
        ids.append({(int(cell.query(b.centre)[1]), b.level): b.id for b in bins})
    shared = ids[0].keys() & ids[1].keys()
    assert len(shared) >= 0.99 * 3 * len(layout.bin_centres)
    assert all(ids[0][k] == ids[1][k] for k in shared)


@pytest.mark.parametrize(
    ("levels", "area", "message"),
    [
        ([], None, "increasing"),
        ([0.0, 1.5, 1.5], None, "increasing"),
        ([-0.5, 1.0], None, ">= 0"),
        ([0.0, float("nan")], None, "finite"),
        ([0.0, 1.5], [[0.0, 0.0], [1.0, 0.0]], "at least 3"),
    ],
)
def test_rack_profile_rejects_nonsense(levels: list[float], area: list[list[float]] | None, message: str) -> None:
    with pytest.raises(PillarMappingError, match=message):
        rack_profile(levels, area)

import numpy as np
import pytest
from scipy.spatial import cKDTree

from services.pillar_mapping import fit_layout, fit_rack_rows
from services.pillar_mapping.synthetic import HallLayout, merge_layouts, noisy_landmarks, rack_region


def _exact_rows(layout: HallLayout, landmarks: np.ndarray) -> tuple[int, int]:
    """(true rows matched upright for upright within 10 cm by a fitted row, true rows)."""
    rows = fit_rack_rows(landmarks)
    found = 0
    for r in range(len(layout.row_n)):
        truth = layout.uprights[layout.row_of == r]
        for row in rows:
            ordered = row.uprights if np.hypot(*(row.uprights[0] - truth[0])) < 0.5 else row.uprights[::-1]
            if row.n == len(truth) and np.all(np.hypot(*(ordered - truth).T) <= 0.1):
                found += 1
                break
    return found, len(layout.row_n)


@pytest.mark.parametrize("seed", range(3))
def test_a_cross_aisle_about_one_bay_wide_cuts_every_row_in_two(seed: int) -> None:
    # the demo warehouse: 3.0 m between the uprights either side of the cross aisle, bays 2.7 m
    layout = rack_region(aisles=3, bays=10, bay_pitch_m=2.7, cross_aisle_every=5, cross_aisle_width_m=3.0)
    landmarks, _ = noisy_landmarks(layout, np.random.default_rng(seed), sigma_m=0.03, missing_fraction=0.1)

    found, total = _exact_rows(layout, landmarks)

    assert found == total


@pytest.mark.parametrize("width_m", [3.0, 2 * 2.7, 2.9])
def test_no_bin_is_made_in_a_cross_aisle(width_m: float) -> None:
    # 5.4 m is exactly two bays: the rows either side share one lattice and only an empty slot tells
    layout = rack_region(aisles=3, bays=12, bay_pitch_m=2.7, cross_aisle_every=6, cross_aisle_width_m=width_m)
    landmarks, _ = noisy_landmarks(layout, np.random.default_rng(4), sigma_m=0.03, missing_fraction=0.1)

    centres = np.array([b.centre for b in fit_layout(landmarks).bins])

    to_truth, _ = cKDTree(layout.bin_centres).query(centres)
    to_found, _ = cKDTree(centres).query(layout.bin_centres)
    assert np.all(to_truth <= 0.1), f"bins {centres[to_truth > 0.1].round(2).tolist()} are in no rack"
    assert np.all(to_found <= 0.1)


def test_bays_count_on_across_a_cross_aisle_and_aisles_keep_their_number() -> None:
    layout = rack_region(aisles=2, bays=8, cross_aisle_every=4, cross_aisle_width_m=3.0)
    landmarks, _ = noisy_landmarks(layout, np.random.default_rng(0), missing_fraction=0.0)

    bins = fit_layout(landmarks).bins

    assert sorted({b.aisle for b in bins}) == [1, 2]
    for aisle in (1, 2):
        for parity in (1, 0):
            bays = sorted(b.bay for b in bins if b.aisle == aisle and b.bay % 2 == parity)
            assert bays == list(range(2 - parity, 17, 2)), (aisle, bays)


def test_one_displaced_landmark_does_not_cut_its_row() -> None:
    layout = rack_region(aisles=2, bays=12)
    landmarks, _ = noisy_landmarks(layout, np.random.default_rng(1), sigma_m=0.01, missing_fraction=0.0)
    landmarks[5, 0] += 0.2  # one upright mapped 20 cm off along its row, ten times its stated std

    rows = fit_rack_rows(landmarks)

    assert sorted(r.n for r in rows) == [13] * len(layout.row_n)


@pytest.mark.parametrize("seed", range(4))
def test_a_region_at_another_angle_and_pitch_is_fitted_row_for_row(seed: int) -> None:
    layout = merge_layouts(
        rack_region(aisles=3, bays=14),
        rack_region(origin_xy_m=(55.0, 0.0), theta_rad=np.deg2rad(30), aisles=2, bays=9, bay_pitch_m=3.6),
    )
    landmarks, _ = noisy_landmarks(layout, np.random.default_rng(seed), sigma_m=0.03, missing_fraction=0.1)

    found, total = _exact_rows(layout, landmarks)

    assert found == total


@pytest.mark.parametrize("seed", range(2))
def test_a_small_region_at_another_angle_beside_a_big_one_is_fitted_row_for_row(seed: int) -> None:
    # the big region's lattice diagonals outnumber the small one's rows in the whole map's orientations
    layout = merge_layouts(
        rack_region(aisles=10, bays=24),
        rack_region(origin_xy_m=(80.0, 5.0), theta_rad=np.deg2rad(30), aisles=1, bays=8, bay_pitch_m=3.6),
    )
    landmarks, _ = noisy_landmarks(layout, np.random.default_rng(seed), sigma_m=0.03, missing_fraction=0.1)

    found, total = _exact_rows(layout, landmarks)

    assert found == total

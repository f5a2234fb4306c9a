import numpy as np
import numpy.typing as npt
import pytest
from scipy.spatial import cKDTree

from services.pillar_mapping import PillarMappingError, RackRow, fit_layout, fit_rack_rows
from services.pillar_mapping.synthetic import HallLayout, merge_layouts, noisy_landmarks, rack_region


def _rows_match(rows: list[RackRow], layout: HallLayout) -> bool:
    found = {(r.n, round(r.d_m, 2)) for r in rows}
    truth = {(int(n), round(float(d), 2)) for n, d in zip(layout.row_n, layout.row_d, strict=True)}
    return found == truth and len(rows) == len(layout.row_n)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_fit_rack_rows_finds_every_row_with_its_count_and_spacing(seed: int) -> None:
    rng = np.random.default_rng(seed)
    layout = rack_region(aisles=4, bays=14, theta_rad=rng.uniform(-1.5, 1.5))
    landmarks, _ = noisy_landmarks(layout, rng, sigma_m=0.03, missing_fraction=0.1)
    rows = fit_rack_rows(landmarks)
    assert _rows_match(rows, layout)


def test_fit_layout_fills_in_unseen_uprights_and_finds_the_bins() -> None:
    rng = np.random.default_rng(5)
    layout = merge_layouts(
        rack_region(aisles=3, bays=12),
        rack_region(origin_xy_m=(60.0, 5.0), theta_rad=np.deg2rad(35), aisles=2, bays=8, bay_pitch_m=3.6),
    )
    landmarks, kept = noisy_landmarks(layout, rng)
    result = fit_layout(landmarks)
    modelled = np.concatenate([r.uprights for r in result.rows])
    distance, _ = cKDTree(modelled).query(layout.uprights[~kept])
    assert np.all(distance <= 0.1)
    centres = np.array([b.centre for b in result.bins])
    to_truth, _ = cKDTree(layout.bin_centres).query(centres)
    to_found, _ = cKDTree(centres).query(layout.bin_centres)
    assert np.mean(to_found <= 0.1) >= 0.99
    assert np.all(to_truth <= 0.1)
    ids = [b.id for b in result.bins]
    assert len(set(ids)) == len(ids)


def test_bin_ids_survive_a_rebuild_with_other_noise() -> None:
    layout = rack_region(aisles=3, bays=10)
    ids = []
    for seed in (1, 2):
        landmarks, _ = noisy_landmarks(layout, np.random.default_rng(seed))
        bins = fit_layout(landmarks).bins
        tree = cKDTree(layout.bin_centres)
        ids.append({int(tree.query(b.centre)[1]): b.id for b in bins})
    shared = ids[0].keys() & ids[1].keys()
    assert len(shared) >= 0.99 * len(layout.bin_centres)
    assert all(ids[0][k] == ids[1][k] for k in shared)


def test_access_pose_faces_the_opening_from_the_aisle() -> None:
    layout = rack_region(aisles=2, bays=6)
    landmarks, _ = noisy_landmarks(layout, np.random.default_rng(0), missing_fraction=0.0)
    for b in fit_layout(landmarks).bins:
        x, y, yaw = b.access_pose
        ahead = np.array([x, y]) + 0.5 * np.array([np.cos(yaw), np.sin(yaw)])
        assert np.hypot(*(ahead - b.centre)) < np.hypot(x - b.centre[0], y - b.centre[1])
        aisle_y = layout.aisles[:, 0, 1]
        assert np.min(np.abs(aisle_y - y)) < 1.0


def test_fit_rack_rows_gives_nothing_for_no_or_unstructured_landmarks() -> None:
    rng = np.random.default_rng(0)
    assert fit_rack_rows(np.zeros((0, 5))) == []
    collinear = np.column_stack(
        [rng.uniform(0, 60, 40), np.zeros(40), np.full(40, 1e-3), np.zeros(40), np.full(40, 1e-3)]
    )
    assert fit_rack_rows(collinear) == []
    scattered = np.column_stack([rng.uniform(0, 60, (300, 2)), np.tile([1e-3, 0, 1e-3], (300, 1))])
    assert fit_layout(scattered).bins == []


def test_a_single_row_is_fitted_but_gets_no_bins() -> None:
    row = np.column_stack([np.arange(12) * 2.7, np.full(12, 4.0), np.full(12, 1e-4), np.zeros(12), np.full(12, 1e-4)])
    result = fit_layout(row)
    assert [(r.n, round(r.d_m, 3)) for r in result.rows] == [(12, 2.7)]
    assert result.bins == []


@pytest.mark.parametrize(
    ("table", "message"),
    [
        (np.array([[np.nan, 0.0, 1.0, 0.0, 1.0]]), "non-finite"),
        (np.zeros((3, 4)), r"\(N, 5\)"),
        (np.array([[0.0, 0.0, -1.0, 0.0, -1.0]] * 5), "positive semi-definite"),
    ],
)
def test_fit_rack_rows_rejects_malformed_tables(table: npt.NDArray[np.float64], message: str) -> None:
    with pytest.raises(PillarMappingError, match=message):
        fit_rack_rows(table)

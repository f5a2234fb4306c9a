import numpy as np
import pytest

from services.pillar_mapping.join import join_rows
from services.pillar_mapping.rowmodel import fit_model, validated_landmarks
from services.pillar_mapping.synthetic import noisy_landmarks, rack_region

PITCH = (1.5, 4.5)
U = np.array([1.0, 0.0])


def _table(xy: np.ndarray) -> np.ndarray:
    return validated_landmarks(np.column_stack([xy, np.full((len(xy), 3), [1e-4, 0.0, 1e-4])]))


def _row_of(slots: list[int], *, d: float = 2.7, y: float = 0.0, shift: float = 0.0) -> np.ndarray:
    return np.array([[shift + k * d, y] for k in slots])


def test_join_rows_merges_two_pieces_of_one_row_and_pulls_its_leftovers() -> None:
    table = _table(np.vstack([_row_of(list(range(8))), _row_of(list(range(12, 21))), _row_of([8, 10])]))
    pieces = [fit_model(table, np.arange(8), U, 0, PITCH), fit_model(table, np.arange(8, 17), U, 0, PITCH)]
    joined = join_rows(table, pieces, PITCH)
    assert len(joined) == 1
    (row,) = joined
    assert row.n == 21
    assert row.d == pytest.approx(2.7, abs=0.005)
    assert sorted(row.members.tolist()) == list(range(len(table)))


def test_join_rows_keeps_apart_pieces_off_each_others_lattice() -> None:
    # two segments of one rack line broken by a cross aisle that is not a whole number of bays
    table = _table(np.vstack([_row_of(list(range(6))), _row_of(list(range(7, 13)), shift=0.3)]))
    pieces = [fit_model(table, np.arange(6), U, 0, PITCH), fit_model(table, np.arange(6, 12), U, 0, PITCH)]
    joined = join_rows(table, pieces, PITCH)
    assert sorted(r.n for r in joined) == [6, 6]


def test_join_rows_pulls_nothing_from_a_parallel_row() -> None:
    table = _table(np.vstack([_row_of(list(range(10))), _row_of([10, 11], y=1.1)]))
    joined = join_rows(table, [fit_model(table, np.arange(10), U, 0, PITCH)], PITCH)
    assert joined[0].n == 10
    assert sorted(joined[0].members.tolist()) == list(range(10))


def test_join_rows_does_not_bridge_a_long_empty_stretch() -> None:
    table = _table(np.vstack([_row_of(list(range(6))), _row_of(list(range(14, 20)))]))
    pieces = [fit_model(table, np.arange(6), U, 0, PITCH), fit_model(table, np.arange(6, 12), U, 0, PITCH)]
    assert len(join_rows(table, pieces, PITCH, max_gap_m=10.0)) == 2


@pytest.mark.parametrize("seed", range(3))
def test_join_rows_gives_each_landmark_to_at_most_one_row_of_its_own(seed: int) -> None:
    layout = rack_region(aisles=3, bays=12)
    landmarks, _ = noisy_landmarks(layout, np.random.default_rng(seed), sigma_m=0.03, missing_fraction=0.2)
    table = validated_landmarks(landmarks)
    gaps = np.hypot(*(table[:, None, :2] - layout.uprights[None]).transpose(2, 0, 1))
    truth = layout.row_of[np.argmin(gaps, axis=1)]
    rows = []
    for r in range(len(layout.row_n)):
        mine = np.flatnonzero(truth == r)
        rows.append(fit_model(table, mine[: max(4, mine.size // 2)], U, 0, PITCH))
    joined = join_rows(table, rows, PITCH)
    members = np.concatenate([r.members for r in joined])
    assert np.unique(members).size == members.size
    assert all(np.unique(truth[r.members]).size == 1 for r in joined)
    assert members.size == len(table)

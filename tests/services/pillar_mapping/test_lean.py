"""The rack-row fit's own DBSCAN and peak finder give scikit-learn's and scipy's answers exactly."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import find_peaks as scipy_find_peaks
from sklearn.cluster import DBSCAN

from services.pillar_mapping.lean import dbscan, find_peaks


@pytest.mark.parametrize("seed", range(6))
def test_dbscan_labels_as_scikit_learn(seed: int) -> None:
    rng = np.random.default_rng(seed)
    centres = rng.uniform(0.0, 3.0, (8, 3))
    points = np.vstack([centres[rng.integers(0, 8, 400)] + rng.normal(0.0, 0.05, (400, 3)),
                        rng.uniform(0.0, 3.0, (100, 3))])
    rng.shuffle(points)

    for eps, min_samples in ((0.08, 4), (0.15, 6), (0.05, 2)):
        expected = DBSCAN(eps=eps, min_samples=min_samples).fit_predict(points)
        np.testing.assert_array_equal(dbscan(points, eps=eps, min_samples=min_samples), expected)


def test_dbscan_of_nothing_and_of_lone_points_is_noise() -> None:
    assert dbscan(np.zeros((0, 3)), eps=0.1, min_samples=4).size == 0
    np.testing.assert_array_equal(dbscan([[0.0, 0.0], [5.0, 5.0]], eps=0.1, min_samples=2), [-1, -1])


@pytest.mark.parametrize("seed", range(6))
def test_find_peaks_as_scipy(seed: int) -> None:
    rng = np.random.default_rng(seed)
    signal = np.round(rng.normal(0.0, 1.0, 300).cumsum(), 1)  # rounding makes plateaus and ties
    signal[100:110] = signal.max() + 1.0  # a wide plateau
    signal[-5:] = signal.max() + 2.0  # a plateau at the end is no peak

    for distance in (1, 2, 6, 25):
        expected, _ = scipy_find_peaks(signal, distance=distance)
        np.testing.assert_array_equal(find_peaks(signal, distance=distance), expected)

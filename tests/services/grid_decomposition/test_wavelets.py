"""find_peaks_ricker: scipy's CWT peak detection with a vectorised noise floor, same peaks."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter1d
from scipy.signal import find_peaks_cwt
from scipy.signal._peak_finding import _boolrelextrema, _cwt, _identify_ridge_lines, _ricker

from services.grid_decomposition.wavelets import _ridge_lines, find_peaks_ricker


@pytest.mark.parametrize("seed", range(12))
def test_find_peaks_ricker_finds_the_peaks_scipy_finds(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = int(rng.integers(5, 2500))
    signal = np.zeros(n)
    k = int(rng.integers(1, max(2, n // 10)))
    signal[rng.integers(0, n, k)] = rng.uniform(0.1, 50.0, k)
    if seed % 3 == 0:  # a periodic pattern, like rack uprights
        signal[:: int(rng.integers(3, 60))] += 10.0
    smooth = gaussian_filter1d(signal, 1.0) + 1e-3 * signal.max()
    widths = np.arange(1, int(rng.integers(2, 21)) + 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        expected = np.asarray(find_peaks_cwt(smooth, widths), dtype=np.int64)
    assert np.array_equal(find_peaks_ricker(smooth, widths), expected)


def test_find_peaks_ricker_finds_a_wall_on_a_clear_radiogram() -> None:
    signal = np.exp(-0.5 * ((np.arange(400) - 150.0) / 2.0) ** 2) + 1e-3
    assert 150 in find_peaks_ricker(signal, np.arange(1, 21))


@pytest.mark.parametrize("seed", range(8))
def test_ridges_are_scipys_also_where_two_maxima_of_a_row_join_one_ridge(seed: int) -> None:
    """Length and first (row, column) of every ridge, in scipy's order; wide distances join several maxima of
    a row to one ridge (its rows repeat: scipy's argsort decides which comes first)."""
    rng = np.random.default_rng(seed)
    signal = np.round(np.convolve(rng.random(int(rng.integers(50, 1500))) ** 4, np.ones(3), "same"), 1)
    widths = np.arange(1, int(rng.integers(4, 25)))
    cwt = _cwt(signal, _ricker, widths)
    for scale in (0.25, 2.0):
        distances = (widths * scale).astype(np.float64)
        expected = [(len(r), int(r[0]), int(c[0])) for r, c in _identify_ridge_lines(cwt, distances, 1)]
        assert _ridge_lines(_boolrelextrema(cwt, np.greater, axis=1, order=1), distances, 1) == expected

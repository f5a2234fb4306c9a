"""Continuous-wavelet (Ricker) peak detection, as scipy's ``find_peaks_cwt`` with a vectorised noise floor."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt
from numpy.lib.stride_tricks import sliding_window_view


def _window_percentile(row: npt.NDArray[np.float64], window: int, percent: float) -> npt.NDArray[np.float64]:
    """``percent`` percentile (linear interpolation) of ``row`` over a window around every point.

    The window of point ``i`` is ``row[max(i - h, 0) : min(i + h + odd, n)]`` with ``h, odd =
    divmod(window, 2)``, cut at the ends, exactly as scipy's ridge filter takes it.
    """
    n = row.size
    half, odd = divmod(window, 2)
    starts = np.maximum(np.arange(n) - half, 0)
    ends = np.minimum(np.arange(n) + half + odd, n)
    out = np.empty(n)
    full = (ends - starts) == window
    if window >= 1 and full.any():
        idx = percent / 100.0 * (window - 1)
        lo = math.floor(idx)
        hi = min(lo + 1, window - 1)
        views = sliding_window_view(row, window)[starts[full]]
        part = np.partition(views, [lo, hi], axis=1)
        out[full] = part[:, lo] + (part[:, hi] - part[:, lo]) * (idx % 1)
    for i in np.flatnonzero(~full):
        values = np.sort(row[starts[i] : ends[i]])
        idx = percent / 100.0 * (values.size - 1)
        lo = math.floor(idx)
        out[i] = values[lo] if idx % 1 == 0 else values[lo] + (values[lo + 1] - values[lo]) * (idx % 1)
    return out


def find_peaks_ricker(
    signal: npt.NDArray[np.float64],
    widths: npt.NDArray[np.int64],
    *,
    min_snr: float = 1.0,
    noise_percent: float = 10.0,
) -> npt.NDArray[np.int64]:
    """Peak indices of a 1-D signal by Ricker-wavelet CWT ridge lines (Du et al. 2006).

    Same result as ``scipy.signal.find_peaks_cwt(signal, widths)`` with its defaults (ridges
    followed from the widest wavelet down, kept when at least a quarter of the widths long and
    with a signal-to-noise ratio of at least ``min_snr`` at the narrowest wavelet, the noise being
    the ``noise_percent`` percentile of the narrowest response over a window of a twentieth of the
    signal), with the noise floor computed for all points at once.

    Parameters
    ----------
    signal : (N,) float64
    widths : (K,) int64
        Wavelet widths, samples, ascending.

    Returns
    -------
    (P,) int64
        Sorted peak indices.
    """
    # scipy's ridge tracking is reused as is; only its per-point noise loop (a Python loop of one
    # scoreatpercentile per signal point, most of find_peaks_cwt's time on long radiograms) is
    # replaced. scipy.signal is imported when first needed (decompose loads it early).
    from scipy.signal._peak_finding import _boolrelextrema, _cwt, _ricker

    widths = np.atleast_1d(np.asarray(widths))
    cwt = _cwt(np.asarray(signal, dtype=np.float64), _ricker, widths)
    ridges = _ridge_lines(_boolrelextrema(cwt, np.greater, axis=1, order=1), widths / 4.0, math.ceil(widths[0]))
    if not ridges:
        return np.zeros(0, dtype=np.int64)
    noise = _window_percentile(cwt[0], math.ceil(cwt.shape[1] / 20), noise_percent)
    min_length = math.ceil(cwt.shape[0] / 4)
    peaks = []
    with np.errstate(divide="ignore", invalid="ignore"):
        for length, row, col in ridges:
            if length < min_length:
                continue
            snr = abs(cwt[row, col] / noise[col])
            if not snr < min_snr:
                peaks.append(col)
    return np.sort(np.asarray(peaks, dtype=np.int64))


def _ridge_lines(
    maxima: npt.NDArray[np.bool_], max_distances: npt.NDArray[np.float64], gap_thresh: int
) -> list[tuple[int, int, int]]:
    """Length and first (row, column) of each ridge scipy's ``_identify_ridge_lines`` finds, in its order.

    ``maxima``: the relative maxima of each row of the CWT. The same ridges, built the same way row by
    row from the widest wavelet down: each maximum joins the ridge whose last column is nearest (the first
    such ridge, within the row's distance) or starts a new one, and a ridge ends after more than
    ``gap_thresh`` rows without a maximum. The distances of a row's maxima to the ridges are found at once
    instead of one maximum at a time. scipy returns each ridge's rows and columns scattered by the
    ``argsort`` of its rows; its first entry is that of the ridge's last row when no row repeats (rows are
    added in falling order), and is found by the same ``argsort`` when one does.
    """
    has_max = np.flatnonzero(maxima.any(axis=1))
    if has_max.size == 0:
        return []
    start_row = int(has_max[-1])
    # a ridge: its rows, its columns, the rows since it last grew
    ridges: list[list[Any]] = [[[start_row], [col], 0] for col in np.flatnonzero(maxima[start_row]).tolist()]
    ended: list[list[Any]] = []
    for row in range(start_row - 1, -1, -1):
        cols = np.flatnonzero(maxima[row])
        for ridge in ridges:
            ridge[2] += 1
        if ridges and cols.size:
            diffs = np.abs(cols[:, None] - np.array([ridge[1][-1] for ridge in ridges])[None, :])
            closest = np.argmin(diffs, axis=1)
            joins = (diffs[np.arange(cols.size), closest] <= max_distances[row]).tolist()
            closest_list = closest.tolist()
        else:
            joins, closest_list = [False] * cols.size, [0] * cols.size
        for col, join, k in zip(cols.tolist(), joins, closest_list, strict=True):
            if join:  # a ridge started in this row is no candidate: it is not among the distances
                ridge = ridges[k]
                ridge[1].append(col)
                ridge[0].append(row)
                ridge[2] = 0
            else:
                ridges.append([[row], [col], 0])
        for i in range(len(ridges) - 1, -1, -1):
            if ridges[i][2] > gap_thresh:
                ended.append(ridges.pop(i))
    out = []
    for rows_of, cols_of, _ in ended + ridges:
        if len(set(rows_of)) == len(rows_of):
            out.append((len(rows_of), rows_of[-1], cols_of[-1]))
        else:
            order = np.argsort(rows_of)
            first = int(np.flatnonzero(order == 0)[0])  # scipy's rows[order] = rows_of puts this entry first
            out.append((len(rows_of), rows_of[first], cols_of[first]))
    return out

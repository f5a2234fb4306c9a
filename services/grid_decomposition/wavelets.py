"""Continuous-wavelet (Ricker) peak detection, as scipy's ``find_peaks_cwt`` with a vectorised noise floor."""

from __future__ import annotations

import math

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
    from scipy.signal._peak_finding import _cwt, _identify_ridge_lines, _ricker

    widths = np.atleast_1d(np.asarray(widths))
    cwt = _cwt(np.asarray(signal, dtype=np.float64), _ricker, widths)
    ridges = _identify_ridge_lines(cwt, widths / 4.0, math.ceil(widths[0]))
    if not ridges:
        return np.zeros(0, dtype=np.int64)
    noise = _window_percentile(cwt[0], math.ceil(cwt.shape[1] / 20), noise_percent)
    min_length = math.ceil(cwt.shape[0] / 4)
    peaks = []
    with np.errstate(divide="ignore", invalid="ignore"):
        for rows, cols in ridges:
            if len(rows) < min_length:
                continue
            snr = abs(cwt[rows[0], cols[0]] / noise[cols[0]])
            if not snr < min_snr:
                peaks.append(int(cols[0]))
    return np.sort(np.asarray(peaks, dtype=np.int64))

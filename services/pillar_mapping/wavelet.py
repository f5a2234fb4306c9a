"""Peak detection on a circular signal by a continuous wavelet transform with a derivative-of-Gaussian."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import numpy.typing as npt
from scipy.signal import find_peaks

FloatArray = npt.NDArray[np.float64]


class WaveletPeaks(NamedTuple):
    """Peaks of a circular signal: positions in (fractional) samples, best scale in samples, SNR."""

    positions: FloatArray
    scales: FloatArray
    snr: FloatArray


def dog_transform(signal: FloatArray, scales: FloatArray) -> FloatArray:
    """Circular correlation of ``signal`` with ``-(x / s) exp(-x^2 / 2 s^2)`` at each scale ``s``.

    A pair of opposite steps ``+A`` at ``c - h`` and ``-A`` at ``c + h`` gives a maximum of
    ``2 A exp(-1/2)`` at ``c`` for ``s = h``, whatever ``h``.

    Parameters
    ----------
    signal : ndarray of float64, shape (N,)
        Circular signal, one value per sample.
    scales : ndarray of float64, shape (S,)
        Wavelet scales, samples.

    Returns
    -------
    ndarray of float64, shape (S, N)
    """
    n = signal.size
    x = np.fft.fftfreq(n, 1.0 / n)[None, :]
    s = scales[:, None]
    wavelets = -(x / s) * np.exp(-0.5 * (x / s) ** 2)
    spectrum = np.fft.fft(signal)[None, :] * np.conj(np.fft.fft(wavelets, axis=1))
    return np.real(np.fft.ifft(spectrum, axis=1))


def dog_peaks(
    signal: FloatArray,
    scales: FloatArray,
    *,
    min_snr: float = 6.0,
    min_separation: int = 2,
) -> WaveletPeaks:
    """Positions of opposite-edge pairs in a circular signal, found across wavelet scales.

    The response at each scale is divided by the noise it would give on white noise of the
    signal's robust spread (MAD of the signal), so scales compete fairly; peaks of the
    best-scale SNR above ``min_snr`` are kept and refined by a parabola through three samples.

    Parameters
    ----------
    signal : ndarray of float64, shape (N,)
    scales : ndarray of float64, shape (S,)
        Wavelet scales, samples.
    min_snr : float
        Least signal-to-noise ratio of a peak.
    min_separation : int
        Least distance between peaks, samples.
    """
    n = signal.size
    response = dog_transform(signal, scales)
    noise = 1.4826 * float(np.median(np.abs(signal - np.median(signal))))
    floor = 1e-3 * float(np.max(np.abs(signal))) if signal.size else 0.0
    noise = max(noise, floor, np.finfo(np.float64).tiny)
    x = np.arange(-4 * scales.max(), 4 * scales.max() + 1)
    norms = np.sqrt(
        np.sum((x[None, :] / scales[:, None]) ** 2 * np.exp(-((x[None, :] / scales[:, None]) ** 2)), axis=1)
    )
    snr_all = response / (noise * norms[:, None])
    best = np.argmax(snr_all, axis=0)
    snr = snr_all[best, np.arange(n)]
    pad = 2 * min_separation + 1
    wrapped = np.concatenate([snr[-pad:], snr, snr[:pad]])
    found, _ = find_peaks(wrapped, height=min_snr, distance=min_separation)
    found = found[(found >= pad) & (found < n + pad)] - pad
    left, mid, right = snr[(found - 1) % n], snr[found], snr[(found + 1) % n]
    curvature = left - 2 * mid + right
    offset = np.where(curvature < 0, 0.5 * (left - right) / np.where(curvature < 0, curvature, -1.0), 0.0)
    positions = (found + np.clip(offset, -0.5, 0.5)) % n
    return WaveletPeaks(positions.astype(np.float64), scales[best[found]].astype(np.float64), mid.astype(np.float64))

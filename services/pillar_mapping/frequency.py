"""Number and spacing of landmarks along a row from the Fourier transform of its 1-D projection (paper A, 2.2)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


class Periodicity(NamedTuple):
    """A row's spacing ``d_m``, the coherence of its landmarks at that spacing (1 = perfectly regular)."""

    d_m: float
    coherence: float


def projection_spectrum(along_m: FloatArray, sigma_m: FloatArray, frequencies: FloatArray) -> FloatArray:
    """|Fourier transform| of the sum of 1-D Gaussians at ``along_m`` with std ``sigma_m``, per landmark.

    The signal of equation 5 of the paper, transformed in closed form: each Gaussian
    contributes ``exp(-2 pi i f mu) exp(-2 pi^2 sigma^2 f^2)``.

    Parameters
    ----------
    along_m, sigma_m : ndarray of float64, shape (K,)
        Landmark positions along the row and their standard deviations, metres.
    frequencies : ndarray of float64, shape (F,)
        Cycles per metre.

    Returns
    -------
    ndarray of float64, shape (F,)
        Magnitude divided by K, in [0, 1].
    """
    phase = np.exp(-2j * np.pi * frequencies[:, None] * along_m[None, :])
    damping = np.exp(-2 * np.pi**2 * frequencies[:, None] ** 2 * sigma_m[None, :] ** 2)
    return np.asarray(np.abs((phase * damping).sum(axis=1)) / max(along_m.size, 1))


def dominant_spacing(
    along_m: FloatArray,
    sigma_m: FloatArray,
    *,
    min_spacing_m: float,
    max_spacing_m: float,
    harmonic_ratio: float = 0.85,
    samples: int = 160,
) -> Periodicity:
    """The spacing whose frequency dominates the row's projection spectrum.

    Frequencies from ``1 / max_spacing_m`` to ``1 / min_spacing_m`` are scanned; of the
    spectral peaks within ``harmonic_ratio`` of the highest the lowest frequency wins, so a
    multiple of the true frequency (as tall for regular rows) is not taken; the winner is
    refined on a fine grid around it.
    """
    freqs = np.linspace(1.0 / max_spacing_m, 1.0 / min_spacing_m, samples)
    spectrum = projection_spectrum(along_m, sigma_m, freqs)
    interior = (spectrum[1:-1] >= spectrum[:-2]) & (spectrum[1:-1] >= spectrum[2:])
    peaks = np.flatnonzero(interior) + 1
    if spectrum[0] >= spectrum[1]:
        peaks = np.concatenate([[0], peaks])
    if spectrum[-1] >= spectrum[-2]:
        peaks = np.concatenate([peaks, [samples - 1]])
    strong = peaks[spectrum[peaks] >= harmonic_ratio * spectrum.max()]
    best = int(strong.min())
    step = freqs[1] - freqs[0]
    fine = np.linspace(freqs[best] - step, freqs[best] + step, 33)
    fine_spectrum = projection_spectrum(along_m, sigma_m, fine)
    top = int(np.argmax(fine_spectrum))
    return Periodicity(float(1.0 / fine[top]), float(fine_spectrum[top]))

"""Radiograms along dominant orientations and the lines their wavelet peaks give."""

from __future__ import annotations

import bisect
import math
import warnings
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from services.grid_decomposition.orientations import Gradients
from services.grid_decomposition.wavelets import find_peaks_ricker


class Radiogram(NamedTuple):
    """Projection of oriented edge pixels onto the normal of a direction.

    ``signal[i]`` counts edge pixels (weighted by gradient magnitude) whose signed distance
    ``-sin(angle) * col + cos(angle) * row`` rounds to ``start_px + i``.
    """

    angle_rad: float
    start_px: int
    signal: npt.NDArray[np.float64]


class Line(NamedTuple):
    """A decomposition line ``-sin(angle) * x + cos(angle) * y = offset`` in pixel units.

    ``support_m`` is the peak amplitude (edge length lined up on it, metres), ``width_m`` the peak
    width at half height; ``coarse`` marks lines kept in the coarse decomposition.
    """

    angle_rad: float
    offset_px: float
    support_m: float
    width_m: float
    coarse: bool


def radiogram(
    gradients: Gradients,
    angle_rad: float,
    *,
    max_gradient_tilt_rad: float = math.radians(60.0),
    mask: npt.NDArray[np.bool_] | None = None,
) -> Radiogram:
    """Radiogram of an obstacle mask along ``angle_rad`` with gradient-orientation filtering.

    Edge pixels whose gradient is tilted more than ``max_gradient_tilt_rad`` from the normal of
    the projection direction are rejected (they belong to lines of other orientations); small
    blobs such as rack uprights, whose gradients fan out, still vote.

    Parameters
    ----------
    gradients : Gradients
        From :func:`oriented_gradients` of the occupied (and optionally unknown) pixels.
    angle_rad : float
        Line direction, radians, x = column, y = row.
    mask : (H, W) bool, optional
        Only edge pixels inside it vote (a texture region).
    """
    # (v % pi) by its cases, the same floats as numpy's remainder (fmod, then + pi below 0): directions and
    # angles lie in [-pi/2, pi/2), so v in (-pi/2, 3pi/2), and v - pi above pi is exact (Sterbenz)
    folded = gradients.direction - angle_rad + math.pi / 2  # v, folded in place (each case read from v)
    low, high = folded < 0, folded >= math.pi
    np.add(folded, math.pi, out=folded, where=low)
    np.subtract(folded, math.pi, out=folded, where=high)
    keep = np.abs(folded - math.pi / 2) <= max_gradient_tilt_rad
    if mask is not None:
        keep &= mask[gradients.rows, gradients.cols]
    h, w = gradients.shape
    corners = np.array([[0, 0], [0, w], [h, 0], [h, w]], dtype=np.float64)
    s_corner = -math.sin(angle_rad) * corners[:, 1] + math.cos(angle_rad) * corners[:, 0]
    start = math.floor(s_corner.min())
    size = math.ceil(s_corner.max()) - start + 1
    # every edge pixel, a rejected one with weight 0 (its bin lies in range; adding 0.0 changes no sum): no gathers
    s = -math.sin(angle_rad) * gradients.cols + math.cos(angle_rad) * gradients.rows
    weights = np.where(keep, gradients.magnitude, 0.0)
    signal = np.bincount(np.rint(s - start).astype(np.int64), weights=weights, minlength=size)
    return Radiogram(angle_rad, start, signal[:size].astype(np.float64))


def line_offsets(
    gram: Radiogram,
    *,
    resolution_m: float,
    wavelet_widths_px: tuple[int, int] = (1, 20),
    fine_min_support_m: float = 0.3,
    coarse_min_support_m: float = 0.8,
    coarse_max_width_m: float = 0.6,
    min_line_gap_m: float = 0.25,
) -> list[Line]:
    """Lines from the Ricker-wavelet (CWT) peaks of a radiogram, with a coarse/fine flag.

    Peaks are found by continuous-wavelet peak detection (Du et al., scipy ``find_peaks_cwt``)
    over widths ``wavelet_widths_px`` (the paper's sigma in [1, 20]), joined by the local maxima
    whose width lies in that range (scipy's ridge tracking drops interior peaks of strictly
    periodic radiograms such as rack uprights). A peak's amplitude (edge
    length on the line, metres; Sobel magnitude of a straight step is about 2 per pixel on each
    of its two sides) and width set the resolution: the fine set keeps peaks with at least
    ``fine_min_support_m``; the coarse set also requires ``coarse_min_support_m`` and a width at
    most ``coarse_max_width_m`` (diffuse clutter gives wide, low peaks). Of peaks closer than
    ``min_line_gap_m`` only the best supported is kept.
    """
    from scipy.ndimage import gaussian_filter1d  # imported when first needed (decompose loads it early)
    from scipy.signal import find_peaks, peak_widths

    signal = gram.signal
    if signal.size < 3 or not np.any(signal > 0):
        return []
    smooth = gaussian_filter1d(signal, 1.0)
    lo, hi = wavelet_widths_px
    # a tiny floor keeps the SNR test of find_peaks_cwt defined where the radiogram is flat zero
    floor = 1e-3 * float(smooth.max())
    with np.errstate(divide="ignore", invalid="ignore"):
        cwt_peaks = find_peaks_ricker(smooth + floor, np.arange(lo, hi + 1))
    # find_peaks_cwt loses ridges of strictly periodic patterns (evenly spaced walls or uprights);
    # local maxima whose width lies in the wavelet range are added
    plain, _ = find_peaks(smooth, width=(lo, 2 * hi), prominence=floor * 10)
    peaks = np.union1d(cwt_peaks, plain.astype(np.int64))
    if peaks.size == 0:
        return []
    # snap each ridge maximum to the local maximum of the signal within +-2 px
    windows = np.clip(peaks[:, None] + np.arange(-2, 3)[None, :], 0, signal.size - 1)
    peaks = np.unique(windows[np.arange(peaks.size), np.argmax(smooth[windows], axis=1)])
    with warnings.catch_warnings():  # plateau peaks have zero prominence and width; fine here
        warnings.filterwarnings("ignore", message="some peaks have")
        widths = peak_widths(smooth, peaks, rel_height=0.5)[0]
    lines: list[Line] = []
    for p, wd in zip(peaks, widths, strict=True):
        half = max(2, math.ceil(wd))
        support = float(signal[max(0, p - half) : p + half + 1].sum()) / 8.0 * resolution_m
        if support < fine_min_support_m:
            continue
        # sub-pixel centre of mass within the peak
        lo_i, hi_i = max(0, p - half), min(signal.size, p + half + 1)
        weights = signal[lo_i:hi_i]
        centre = float(np.dot(np.arange(lo_i, hi_i), weights) / weights.sum()) if weights.sum() > 0 else p
        width_m = float(wd) * resolution_m
        coarse = support >= coarse_min_support_m and width_m <= coarse_max_width_m
        lines.append(Line(gram.angle_rad, gram.start_px + centre, support, width_m, coarse))
    return _merge_close(lines, min_gap_px=max(2.0, min_line_gap_m / resolution_m))


def _merge_close(lines: list[Line], *, min_gap_px: float) -> list[Line]:
    """Of lines closer than ``min_gap_px``, keep the best supported.

    Best supported first, a line is kept when the kept offsets next to its own (a sorted list) are
    at least ``min_gap_px`` away: then all are.
    """
    kept: list[Line] = []
    offsets: list[float] = []  # of the kept lines, ascending
    for line in sorted(lines, key=lambda ln: -ln.support_m):
        at = bisect.bisect_left(offsets, line.offset_px)
        neighbours = offsets[max(at - 1, 0) : at + 1]
        if all(abs(line.offset_px - k) >= min_gap_px for k in neighbours):
            kept.append(line)
            offsets.insert(at, line.offset_px)
    return sorted(kept, key=lambda ln: ln.offset_px)

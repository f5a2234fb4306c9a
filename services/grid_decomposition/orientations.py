"""Dominant orientations of an occupancy map: weighted HOG, Gaussian-mixture smoothing, CWT peaks."""

from __future__ import annotations

import math
from typing import NamedTuple

import cv2
import numpy as np
import numpy.typing as npt

from services.grid_decomposition.errors import DecompositionError
from services.grid_decomposition.wavelets import find_peaks_ricker

_BINS = 180


class Gradients(NamedTuple):
    """Oriented gradients of the edge pixels of an obstacle mask.

    ``rows``/``cols`` locate the pixels with a non-negligible gradient, ``magnitude`` is the Sobel
    magnitude of the lightly blurred mask there, and ``direction`` the direction of the line the
    gradient is normal to, radians in [-pi/2, pi/2) (x = column, y = row).
    """

    shape: tuple[int, int]
    rows: npt.NDArray[np.int64]
    cols: npt.NDArray[np.int64]
    magnitude: npt.NDArray[np.float64]
    direction: npt.NDArray[np.float64]


# the blur (9 taps, sigma 1) and the Sobel (3 taps) read 4 + 1 rows either side of an output row
_STRIP_MARGIN_PX = 5
_STRIP_PX = 1 << 18  # pixels of a strip: its three float32 buffers stay in cache and are reused for the next


def oriented_gradients(obstacle: npt.NDArray[np.bool_]) -> Gradients:
    """Gradients of a (H, W) bool obstacle mask at its edge pixels (see :class:`Gradients`).

    Computed in strips of rows, each with the rows its filters read around it (the image's own border rows
    at its top and bottom): every filtered pixel reads the same pixels as in one pass over the whole image
    (OpenCV filters a row at a time, the full width), but three buffers of a strip are reused instead of three
    fresh whole-image float32 arrays (37 MB each on a 250 m hall, each page faulted in: most of the time).
    """
    mask = np.asarray(obstacle, dtype=bool)
    if mask.ndim != 2 or mask.size == 0:
        raise DecompositionError(f"obstacle mask must be a non-empty 2-D array, got shape {mask.shape}")
    height, width = mask.shape
    step = max(1, _STRIP_PX // width)
    spare, image, gy = (np.empty((min(height, step) + 2 * _STRIP_MARGIN_PX, width), np.float32) for _ in range(3))
    near_parts, gx_parts, gy_parts = [], [], []
    for r0 in range(0, height, step):
        r1 = min(r0 + step, height)
        a0, a1 = max(r0 - _STRIP_MARGIN_PX, 0), min(r1 + _STRIP_MARGIN_PX, height)
        src, blurred, dy = spare[: a1 - a0], image[: a1 - a0], gy[: a1 - a0]
        np.copyto(src, mask[a0:a1])
        cv2.GaussianBlur(src, (0, 0), 1.0, dst=blurred)
        # each buffer written again once read for the last time
        dx = cv2.Sobel(blurred, cv2.CV_32F, 1, 0, dst=src, ksize=3)
        cv2.Sobel(blurred, cv2.CV_32F, 0, 1, dst=dy, ksize=3)
        inner = slice(r0 - a0, r1 - a0)
        # cartToPolar (magnitude and angle) only near the edges: cv2.magnitude, which may differ from
        # cartToPolar's in the last bit, picks the pixels with a margin, cartToPolar's own magnitude decides
        near = np.flatnonzero(cv2.magnitude(dx, dy, magnitude=blurred)[inner] > 0.05 * (1 - 1e-5))
        near_parts.append(near + r0 * width)  # flat indices of the image, in raster order
        gx_parts.append(dx[inner].ravel()[near])
        gy_parts.append(dy[inner].ravel()[near])
    near = np.concatenate(near_parts)
    magnitude, phase = (
        # one call over all the picked pixels, as before (its vector loop and tail see the same elements)
        (a.ravel() for a in cv2.cartToPolar(np.concatenate(gx_parts), np.concatenate(gy_parts)))
        if near.size
        else (np.zeros(0, np.float32), np.zeros(0, np.float32))  # no edge (OpenCV gives None)
    )
    keep = magnitude > 0.05
    at, magnitude, phase = near[keep], magnitude[keep], phase[keep]
    rows, cols = np.divmod(at, width)
    direction = phase.astype(np.float64)  # then (phase + pi/2 + pi/2) % pi - pi/2, step by step in place
    direction += math.pi / 2
    direction += math.pi / 2
    direction %= math.pi
    direction -= math.pi / 2
    return Gradients(
        (int(height), int(width)),
        rows.astype(np.int64, copy=False),  # flat indices divided: int64 already
        cols.astype(np.int64, copy=False),
        magnitude.astype(np.float64),
        direction,
    )


def _gmm_smooth(hist: npt.NDArray[np.float64], max_components: int) -> npt.NDArray[np.float64]:
    """The histogram modelled by a 1-D Gaussian mixture chosen by BIC (circular, via a shift)."""
    shift = int(np.argmin(np.convolve(np.r_[hist, hist[:4]], np.ones(5), "valid")[:_BINS]))
    rolled = np.roll(hist, -shift)
    counts = np.rint(rolled / rolled.sum() * 1500).astype(np.int64)
    samples = np.repeat(np.arange(_BINS, dtype=np.float64), counts)
    samples = samples + np.tile(np.linspace(-0.45, 0.45, 7), samples.size // 7 + 1)[: samples.size]
    x = samples.reshape(-1, 1)
    best: _Mixture | None = None
    best_bic = math.inf
    for k in range(1, max_components + 1):
        gmm = _fit_mixture(x, k)
        bic = -2 * float(np.mean(_score_samples(gmm, x))) * x.shape[0] + (3 * k - 1) * math.log(x.shape[0])
        if bic < best_bic:
            best, best_bic = gmm, bic
    assert best is not None
    grid = np.arange(_BINS, dtype=np.float64).reshape(-1, 1)
    density = np.exp(_score_samples(best, grid))
    return np.roll(density, shift)


class _Mixture(NamedTuple):
    """A fitted 1-D Gaussian mixture: (K,) weights, (K, 1) means, (K, 1, 1) Cholesky factors of the precisions."""

    weights: npt.NDArray[np.float64]
    means: npt.NDArray[np.float64]
    precisions_chol: npt.NDArray[np.float64]


_REG_COVAR = 0.5
_TOL = 1e-3
_MAX_ITER = 100


def _fit_mixture(x: npt.NDArray[np.float64], k: int) -> _Mixture:
    """``GaussianMixture(k, random_state=0, reg_covar=0.5, init_params="k-means++", n_init=1).fit(x)``.

    scikit-learn's EM for one feature and full covariances, step for step and with the same
    numpy expressions (so the same floating-point results), without its validation and array-API
    dispatch, which cost many times the arithmetic on 1,500 samples; the start is scikit-learn's
    k-means++ seeding (:func:`_kmeans_plusplus`).
    """
    n = x.shape[0]
    resp = np.zeros((n, k), dtype=x.dtype)
    resp[_kmeans_plusplus(x, k), np.arange(k)] = 1
    weights, means, prec_chol = _m_step(x, resp)
    weights /= n
    lower_bound = -np.inf
    for _ in range(_MAX_ITER):
        previous = lower_bound
        log_norm, log_resp = _e_step(_Mixture(weights, means, prec_chol), x)
        lower_bound = float(np.mean(log_norm))
        weights, means, prec_chol = _m_step(x, np.exp(log_resp))
        weights /= np.sum(weights)
        if abs(lower_bound - previous) < _TOL:
            break
    return _Mixture(weights, means, prec_chol)


def _squared_distances(
    centres: npt.NDArray[np.float64], x: npt.NDArray[np.float64], x_norms: npt.NDArray[np.float64]
) -> npt.NDArray[np.float64]:
    """scikit-learn's ``_euclidean_distances(centres, x, Y_norm_squared=x_norms, squared=True)`` of float64 arrays."""
    distances: npt.NDArray[np.float64] = -2 * (centres @ x.T)
    distances += np.einsum("ij,ij->i", centres, centres)[:, None]
    distances += x_norms.reshape(1, -1)
    np.maximum(distances, np.asarray(0, dtype=distances.dtype), out=distances)
    return distances


def _kmeans_plusplus(x: npt.NDArray[np.float64], k: int) -> npt.NDArray[np.int64]:
    """Indices of the ``k`` seeds of scikit-learn's ``_kmeans_plusplus(x, k, row_norms(x, squared=True),
    np.ones(n), np.random.RandomState(0))`` for a dense float64 ``x``: its steps with the same numpy expressions
    (the same random draws and floats), so the line search needs no scikit-learn (whose import, with the
    clustering modules, is a long step of a fresh process's start; the place categories still load it)."""
    n = x.shape[0]
    weight = np.ones(n, dtype=x.dtype)
    x_norms = np.einsum("ij,ij->i", x, x)
    random_state = np.random.RandomState(0)
    n_local_trials = 2 + int(np.log(k))
    indices = np.full(k, -1, dtype=int)
    indices[0] = random_state.choice(n, p=weight / weight.sum())
    closest_dist_sq = _squared_distances(x[indices[0]][np.newaxis], x, x_norms)
    current_pot = closest_dist_sq @ weight
    for c in range(1, k):
        rand_vals = random_state.uniform(size=n_local_trials) * current_pot
        candidate_ids = np.searchsorted(np.cumsum(weight * closest_dist_sq), rand_vals)
        np.clip(candidate_ids, None, closest_dist_sq.size - 1, out=candidate_ids)
        distance_to_candidates = _squared_distances(x[candidate_ids], x, x_norms)
        np.minimum(closest_dist_sq, distance_to_candidates, out=distance_to_candidates)
        candidates_pot = distance_to_candidates @ weight.reshape(-1, 1)
        best = np.argmin(candidates_pot)
        current_pot = candidates_pot[best]
        closest_dist_sq = distance_to_candidates[best]
        indices[c] = candidate_ids[best]
    return indices


def _m_step(
    x: npt.NDArray[np.float64], resp: npt.NDArray[np.float64]
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Weights (unnormalised), means and precision Cholesky factors from responsibilities."""
    nk = np.sum(resp, axis=0) + 10 * np.finfo(resp.dtype).eps
    means = (resp.T @ x) / nk[:, np.newaxis]
    prec_chol = np.empty((means.shape[0], 1, 1), dtype=x.dtype)
    for c in range(means.shape[0]):
        diff = x - means[c, :]
        covariance = ((resp[:, c] * diff.T) @ diff) / nk[c]
        covariance.flat[::2] += _REG_COVAR
        # Cholesky factor and its inverse of a 1 x 1 matrix: a square root and a division
        prec_chol[c, :, :] = (1.0 / np.sqrt(covariance)).T
    return nk, means, prec_chol


def _weighted_log_prob(gmm: _Mixture, x: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """scikit-learn's per component ``np.sum(np.square(x @ P - mean @ P), axis=1)`` for one feature, all at once.

    With 1 x 1 factors each product is one multiplication and each sum one term, so the broadcast
    ``(x * p - mean * p) ** 2`` is the same floats.
    """
    log_det = np.sum(np.log(np.reshape(gmm.precisions_chol, (gmm.means.shape[0], -1))[:, ::2]), axis=1)
    p = gmm.precisions_chol[:, 0, 0]
    log_prob = np.square(x * p - gmm.means[:, 0] * p)
    out: npt.NDArray[np.float64] = -0.5 * (math.log(2 * math.pi) + log_prob) + log_det + np.log(gmm.weights)
    return out


def _e_step(gmm: _Mixture, x: npt.NDArray[np.float64]) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    weighted = _weighted_log_prob(gmm, x)
    log_norm = _logsumexp(weighted)
    with np.errstate(under="ignore"):
        log_resp = weighted - log_norm[:, np.newaxis]
    return log_norm, log_resp


def _score_samples(gmm: _Mixture, x: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    return _logsumexp(_weighted_log_prob(gmm, x))


def _columns(array: npt.NDArray[np.float64], op: np.ufunc) -> npt.NDArray[np.float64]:
    """``op.reduce(array, axis=1, keepdims=True)`` of a C-ordered (N, K) array, as numpy orders it.

    numpy reduces a short last axis one column after the other, ``op(op(a0, a1), a2) ...``: so do
    column operations, without numpy's per-row inner loops over K < 8 values.
    """
    out = array[:, 0].copy()
    for j in range(1, array.shape[1]):
        op(out, array[:, j], out=out)
    return out[:, np.newaxis]


def _logsumexp(array: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Log of the sum of exponentials along axis 1, as scikit-learn computes it (the same floats)."""
    array_max = _columns(array, np.maximum)
    index_max = array == array_max
    m = _columns(index_max.astype(array.dtype), np.add)
    shift = np.where(np.isfinite(array_max), array_max, 0)
    # scikit-learn sets the maxima to -inf before the exponentials: their exp(-inf) is the 0 written after
    exp = np.exp(array - shift)
    exp[index_max] = 0.0
    s = _columns(exp, np.add)
    s = np.where(s == 0, s, s / m)
    out: npt.NDArray[np.float64] = np.squeeze(np.log1p(s) + np.log(m) + array_max, axis=1)
    return out


def _sharpness(angle_rad: float, rows: npt.NDArray[np.float64], cols: npt.NDArray[np.float64]) -> float:
    """Sum of squares of the points' projection across lines of ``angle_rad`` (1 px bins): high when they line up."""
    s = -math.sin(angle_rad) * cols
    s += math.cos(angle_rad) * rows
    s -= s.min()
    whole = s.astype(np.int64)  # s >= 0: truncation is the floor
    part = s - whole
    # each point split linearly between its two bins: no rounding luck at tiny angles (a point's share of the
    # next bin is the count of its own bin one bin on: the same sums added in the same order)
    size = int(whole.max()) + 2
    hist = np.bincount(whole, 1.0 - part, size)
    hist[1:] += np.bincount(whole, part, size - 1)
    return float(np.dot(hist, hist))


def _refine(
    angle_rad: float,
    rows: npt.NDArray[np.float64],
    cols: npt.NDArray[np.float64],
    span_rad: float,
    *,
    max_moves: int = 4,
) -> float:
    """The angle near ``angle_rad`` whose projection of the points is sharpest (max sum of squares).

    Searched over ``angle_rad +- span_rad`` in 30 steps; when the sharpest angle is at an end of
    that span (the smoothed histogram peak can sit a few degrees off a family of long walls), the
    search moves on from there, at most ``max_moves`` times; then it is refined to a tenth of a step.
    """
    def sharpest(centre: float, steps: npt.NDArray[np.float64]) -> tuple[float, bool]:
        scores = np.array([_sharpness(a, rows, cols) for a in centre + steps])
        best = int(np.argmax(scores))
        return float(centre + steps[best]), 0 < best < steps.size - 1

    centre = angle_rad
    coarse = np.linspace(-span_rad, span_rad, 31)
    for _ in range(max_moves + 1):
        centre, inside = sharpest(centre, coarse)
        if inside:
            break
    # then to a tenth of the coarse step: over a 250 m wall 0.1 degree is 9 px
    centre, _ = sharpest(centre, np.linspace(-coarse[1] + coarse[0], coarse[1] - coarse[0], 21))
    return (centre + math.pi / 2) % math.pi - math.pi / 2


def dominant_orientations(
    gradients: Gradients,
    *,
    max_orientations: int = 6,
    min_peak_ratio: float = 0.12,
    min_separation_rad: float = math.radians(10.0),
    square_tolerance_rad: float = math.radians(3.0),
) -> npt.NDArray[np.float64]:
    """Directions of the straight structure in a map, any number at any angles.

    A histogram of gradient orientations weighted by gradient magnitude (1 degree bins) is modelled
    by a Gaussian mixture (number of components by BIC), which merges spikes into the orientation
    they flank; peaks of the smooth curve are found by continuous-wavelet (Ricker) peak detection and
    kept when at least ``min_peak_ratio`` of the highest. Each is then refined to the angle whose
    projection of the edge pixels is sharpest, so long walls stay on one line.

    Parameters
    ----------
    gradients : Gradients
        From :func:`oriented_gradients` of the obstacle mask (occupied, or occupied and unknown).
    max_orientations : int
        Upper bound on mixture components (and so on orientations).
    min_peak_ratio : float
        Peaks lower than this fraction of the highest peak are noise.
    min_separation_rad : float
        Peaks closer than this (radians) are one orientation.
    square_tolerance_rad : float
        An orientation within this of square to a stronger one is made square to it: walls are
        built at right angles, and the weaker family's edges are the ones a fan of laser rays or
        speckle pulls off (``map_with_clutter``'s walls, at 0 and 90 degrees, gave 0 and 88: its
        vertical lines drifted off the walls they were found on within a few metres).

    Returns
    -------
    (K,) float64
        Line directions in radians, [-pi/2, pi/2), x = column and y = row, strongest first.
    """
    if gradients.magnitude.size == 0:
        return np.zeros(0)
    strong = gradients.magnitude > 0.25 * gradients.magnitude.max()
    direction = gradients.direction[strong]
    bins = np.floor((direction + math.pi / 2) / math.pi * _BINS).astype(np.int64) % _BINS
    hist = np.bincount(bins, weights=gradients.magnitude[strong], minlength=_BINS).astype(np.float64)
    smooth = _gmm_smooth(hist, max_orientations)
    tripled = np.r_[smooth, smooth, smooth]
    with np.errstate(divide="ignore", invalid="ignore"):
        found = find_peaks_ricker(tripled, np.arange(1, 8))
    # each ridge maximum snapped to the highest smoothed bin within +-3 (the ridge can sit a bin
    # off a sharp peak, and its height decides whether the orientation is kept)
    ridges = [int(p) for p in found if _BINS <= p < 2 * _BINS]
    peaks = sorted({(p - 3 + int(np.argmax(tripled[p - 3 : p + 4]))) % _BINS for p in ridges})
    if not peaks:
        peaks = [int(np.argmax(smooth))]
    heights = smooth[peaks]
    keep = [p for p, h in zip(peaks, heights, strict=True) if h >= min_peak_ratio * heights.max()]
    keep.sort(key=lambda p: -smooth[p])
    rows, cols = gradients.rows[strong], gradients.cols[strong]
    if rows.size > 60000:
        pick = np.random.default_rng(0).choice(rows.size, 60000, replace=False)
        rows, cols = rows[pick], cols[pick]
    angles: list[float] = []
    for p in keep:
        a = _refine(
            (p + 0.5) / _BINS * math.pi - math.pi / 2,
            rows.astype(np.float64),
            cols.astype(np.float64),
            math.radians(2.0),
        )
        if all(abs((a - b + math.pi / 2) % math.pi - math.pi / 2) >= min_separation_rad for b in angles):
            angles.append(a)
    # the sharpest direction of a nearly square pair sets the other
    sharpness = [_sharpness(a, rows.astype(np.float64), cols.astype(np.float64)) for a in angles]
    anchors: list[float] = []
    for i in sorted(range(len(angles)), key=lambda i: -sharpness[i]):
        square = [b for b in anchors if abs((angles[i] - b) % math.pi - math.pi / 2) < square_tolerance_rad]
        if square:
            angles[i] = square[0] % math.pi - math.pi / 2  # square to it, in [-pi/2, pi/2)
        else:
            anchors.append(angles[i])
    return np.asarray(angles, dtype=np.float64)

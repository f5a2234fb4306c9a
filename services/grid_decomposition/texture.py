"""Region segmentation of maps with several patterns: Gabor filter bank, PCA and k-means (paper C)."""

from __future__ import annotations

import math

import cv2
import numpy as np
import numpy.typing as npt

from services.grid_decomposition.arrays import components_stats
from services.grid_decomposition.errors import DecompositionError
from services.grid_decomposition.places import CLUSTERING, one_thread


def gabor_features(
    obstacle: npt.NDArray[np.bool_],
    *,
    resolution_m: float,
    wavelengths_m: tuple[float, ...] = (0.8, 1.6, 3.2, 6.4, 12.8),
    n_orientations: int = 8,
    pixels_per_wavelength: float = 4.0,
) -> npt.NDArray[np.float32]:
    """Local energy of a Gabor filter bank (5 frequencies x 8 orientations by default).

    Each wavelength is filtered on a copy averaged down to ``pixels_per_wavelength`` pixels a
    wavelength (an image pyramid: long wavelengths cost no more than short ones), and its energy
    is brought back to the input grid.

    Returns
    -------
    (H, W, len(wavelengths_m) * n_orientations) float32
        Magnitude of each complex Gabor response, smoothed over about two wavelengths.
    """
    image = obstacle.astype(np.float32)
    h, w = image.shape
    channels: list[npt.NDArray[np.float32]] = []
    for wavelength_m in wavelengths_m:
        scale = min(1.0, pixels_per_wavelength * resolution_m / wavelength_m)
        size_wh = (max(4, round(w * scale)), max(4, round(h * scale)))
        level = image if scale == 1.0 else cv2.resize(image, size_wh, interpolation=cv2.INTER_AREA)
        lam = wavelength_m / (resolution_m * w / level.shape[1])
        sigma = 0.56 * lam
        size = int(2 * math.ceil(2.5 * sigma) + 1)
        for k in range(n_orientations):
            theta = math.pi * k / n_orientations
            real = cv2.getGaborKernel((size, size), sigma, theta, lam, 0.5, 0.0, cv2.CV_32F)
            imag = cv2.getGaborKernel((size, size), sigma, theta, lam, 0.5, math.pi / 2, cv2.CV_32F)
            real -= real.mean()
            energy = cv2.magnitude(cv2.filter2D(level, -1, real), cv2.filter2D(level, -1, imag))
            energy = cv2.GaussianBlur(energy, (0, 0), 2.0 * lam)
            if level.shape != image.shape:
                energy = cv2.resize(energy, (w, h), interpolation=cv2.INTER_LINEAR)
            channels.append(np.asarray(energy, dtype=np.float32))
    return np.stack(channels, axis=-1)


def segment_texture_regions(
    obstacle: npt.NDArray[np.bool_],
    known: npt.NDArray[np.bool_],
    *,
    resolution_m: float,
    n_regions: int,
    working_resolution_m: float = 0.2,
    n_components: int = 4,
    seed: int = 0,
) -> npt.NDArray[np.int32]:
    """Split a map into ``n_regions`` texture regions (Gabor bank, PCA, k-means; after Bigun).

    Computed on a copy resampled to ``working_resolution_m``; labels are cleaned by a median
    filter, unknown space takes the label of the nearest known pixel, and each region keeps only
    its largest connected parts (smaller islands join the surrounding region).

    Parameters
    ----------
    obstacle, known : (H, W) bool
        Occupied pixels and known (free or occupied) pixels.
    resolution_m : float
        Map resolution, metres per pixel.
    n_regions : int
        Number of regions (k of k-means), >= 1.

    Returns
    -------
    (H, W) int32
        Region id per pixel, 0..n_regions-1.
    """
    if n_regions < 1:
        raise DecompositionError(f"n_regions must be >= 1, got {n_regions}")
    h, w = obstacle.shape
    if n_regions == 1:
        return np.zeros((h, w), dtype=np.int32)
    scale = min(1.0, resolution_m / working_resolution_m)
    size = (max(8, round(w * scale)), max(8, round(h * scale)))
    small = cv2.resize(obstacle.astype(np.float32), size, interpolation=cv2.INTER_AREA) > 0.05
    small_known = cv2.resize(known.astype(np.float32), size, interpolation=cv2.INTER_AREA) > 0.5
    res = resolution_m * w / size[0]
    feats = gabor_features(small, resolution_m=res)
    samples = feats[small_known]
    if samples.shape[0] < n_regions:
        return np.zeros((h, w), dtype=np.int32)
    from sklearn.cluster import KMeans  # scikit-learn is imported when first needed
    from sklearn.decomposition import PCA

    with CLUSTERING, one_thread():
        logs = np.log1p(samples)
        reduced = PCA(min(n_components, logs.shape[1]), random_state=seed).fit_transform(logs)
        labels = KMeans(n_regions, n_init=4, random_state=seed).fit_predict(reduced)
    grid = np.zeros(small.shape, dtype=np.uint8)
    grid[small_known] = labels.astype(np.uint8) + 1
    _, nearest = _nearest(grid > 0)
    grid = grid[nearest[0], nearest[1]]
    grid = cv2.medianBlur(grid, 5)
    grid = _drop_islands(grid, n_regions, min_fraction=0.02)
    full = cv2.resize(grid, (w, h), interpolation=cv2.INTER_NEAREST)
    return (full.astype(np.int32) - 1).clip(0, n_regions - 1)


def _nearest(mask: npt.NDArray[np.bool_]) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.int64]]:
    from scipy.ndimage import distance_transform_edt  # imported when first needed (decompose loads it early)

    dist, idx = distance_transform_edt(~mask, return_indices=True)
    return dist, idx


def _drop_islands(grid: npt.NDArray[np.uint8], n_regions: int, *, min_fraction: float) -> npt.NDArray[np.uint8]:
    """Relabel connected patches smaller than ``min_fraction`` of the image by their surroundings."""
    out = grid.copy()
    keep = np.zeros(grid.shape, dtype=bool)
    for label in range(1, n_regions + 1):
        _, parts, stats = components_stats((grid == label).astype(np.uint8), 4)
        big = np.flatnonzero(stats[:, cv2.CC_STAT_AREA] >= min_fraction * grid.size)
        keep |= np.isin(parts, big[big > 0])
    if keep.any():
        _, nearest = _nearest(keep)
        out = grid[nearest[0], nearest[1]]
    return out

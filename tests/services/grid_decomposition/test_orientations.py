"""Dominant orientations from the weighted HOG, GMM and CWT peaks."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from services.grid_decomposition import dominant_orientations, orientations, oriented_gradients
from services.grid_decomposition.orientations import _gmm_smooth, _kmeans_plusplus, _sharpness


def _angle_error(a: float, b: float) -> float:
    return abs((a - b + math.pi / 2) % math.pi - math.pi / 2)


def test_dominant_orientations_of_axis_aligned_rooms_are_horizontal_and_vertical() -> None:
    occ = np.zeros((200, 300), dtype=bool)
    occ[[10, 100, 190], 10:290] = True
    occ[10:190, [10, 150, 290]] = True
    angles = dominant_orientations(oriented_gradients(occ))
    assert len(angles) == 2
    assert min(_angle_error(a, 0.0) for a in angles) < math.radians(1)
    assert min(_angle_error(a, math.pi / 2) for a in angles) < math.radians(1)


def test_a_family_pulled_two_degrees_off_square_is_made_square_to_the_sharper_one() -> None:
    # long straight walls across, and short walls up that lean 2 degrees (as speckle and ray fans
    # pull a real map's weaker family): the lines up must stay on the walls, square to the others
    occ = np.zeros((300, 400), dtype=np.uint8)
    for y in (20, 150, 280):
        cv2.line(occ, (10, y), (390, y), 1, 1)
    lean = math.tan(math.radians(2.0)) * 120
    for x in range(40, 380, 40):
        cv2.line(occ, (x, 30), (round(x + lean), 150), 1, 1)
    angles = dominant_orientations(oriented_gradients(occ.astype(bool)))
    assert len(angles) == 2
    assert min(_angle_error(a, 0.0) for a in angles) < math.radians(0.5)
    assert _angle_error(angles[0] - angles[1], math.pi / 2) < 1e-9


def test_dominant_orientations_follow_a_rotated_building() -> None:
    occ = np.zeros((400, 400), dtype=np.uint8)
    box = cv2.boxPoints(((200.0, 200.0), (250.0, 150.0), 30.0)).astype(np.int32)
    cv2.polylines(occ, [box], True, 1, 2)
    angles = dominant_orientations(oriented_gradients(occ.astype(bool)))
    assert len(angles) == 2
    assert min(_angle_error(a, math.radians(30)) for a in angles) < math.radians(1.5)
    assert min(_angle_error(a, math.radians(120)) for a in angles) < math.radians(1.5)


def test_dominant_orientations_of_a_map_without_edges_is_empty() -> None:
    assert dominant_orientations(oriented_gradients(np.zeros((20, 20), dtype=bool))).size == 0


def _whole_image_gradients(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Rows, columns, magnitudes and phases of the edge pixels, filtered in one pass over the whole image."""
    image = cv2.GaussianBlur(mask.astype(np.float32), (0, 0), 1.0)
    gx = cv2.Sobel(image, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(image, cv2.CV_32F, 0, 1, ksize=3)
    near = np.flatnonzero(cv2.magnitude(gx, gy) > 0.05 * (1 - 1e-5))
    if near.size == 0:
        return near, near, np.zeros(0), np.zeros(0)
    magnitude, phase = (a.ravel() for a in cv2.cartToPolar(gx.ravel()[near], gy.ravel()[near]))
    keep = magnitude > 0.05
    rows, cols = np.divmod(near[keep], mask.shape[1])
    return rows, cols, magnitude[keep].astype(np.float64), phase[keep].astype(np.float64)


@pytest.mark.parametrize("seed", range(3))
def test_gradients_in_strips_are_those_of_one_pass_over_the_whole_image(
    seed: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Strips of one row up to the whole image, edges on the strips' borders and on the image's, random masks."""
    rng = np.random.default_rng(seed)
    for _ in range(40):
        height, width = (int(n) for n in rng.integers(1, 120, 2))
        mask = rng.random((height, width)) < rng.uniform(0.0, 0.6)
        if rng.random() < 0.5:  # blocks: long straight edges
            mask = np.kron(mask[: height // 5 + 1, : width // 5 + 1], np.ones((5, 5), bool))[:height, :width]
        monkeypatch.setattr(orientations, "_STRIP_PX", int(rng.integers(1, 3 * height * width + 2)))
        got = oriented_gradients(mask)
        rows, cols, magnitude, phase = _whole_image_gradients(mask)
        assert np.array_equal(got.rows, rows) and np.array_equal(got.cols, cols)
        assert np.array_equal(got.magnitude, magnitude)
        assert np.array_equal(got.direction, (phase + math.pi / 2 + math.pi / 2) % math.pi - math.pi / 2)


def _sklearn_smooth(hist: np.ndarray, max_components: int) -> np.ndarray:
    """The histogram's mixture density as scikit-learn's GaussianMixture fits it (the reference)."""
    from sklearn.mixture import GaussianMixture

    shift = int(np.argmin(np.convolve(np.r_[hist, hist[:4]], np.ones(5), "valid")[:180]))
    rolled = np.roll(hist, -shift)
    counts = np.rint(rolled / rolled.sum() * 1500).astype(np.int64)
    samples = np.repeat(np.arange(180, dtype=np.float64), counts)
    samples = samples + np.tile(np.linspace(-0.45, 0.45, 7), samples.size // 7 + 1)[: samples.size]
    x = samples.reshape(-1, 1)
    fits = [
        GaussianMixture(k, random_state=0, reg_covar=0.5, init_params="k-means++", n_init=1).fit(x)
        for k in range(1, max_components + 1)
    ]
    best = min(fits, key=lambda g: float(g.bic(x)))
    return np.roll(np.exp(best.score_samples(np.arange(180, dtype=np.float64).reshape(-1, 1))), shift)


@pytest.mark.parametrize("seed", range(3))
def test_orientation_histogram_mixture_is_scikit_learns(seed: int) -> None:
    rng = np.random.default_rng(seed)
    bins = np.arange(180)
    hist = rng.uniform(0.0, 2.0, 180)
    for centre in rng.integers(0, 180, 1 + seed):
        hist += rng.uniform(10, 100) * np.exp(-0.5 * ((bins - centre) / rng.uniform(0.5, 5.0)) ** 2)
    assert np.array_equal(_gmm_smooth(hist, 4), _sklearn_smooth(hist, 4))


@pytest.mark.parametrize("seed", range(4))
def test_kmeans_plusplus_seeds_are_scikit_learns(seed: int) -> None:
    """The seeds the line search draws without scikit-learn are the ones scikit-learn draws (ties and repeats too)."""
    from sklearn.cluster._kmeans import _kmeans_plusplus as sklearn_seeds
    from sklearn.utils.extmath import row_norms

    rng = np.random.default_rng(seed)
    for n, k in ((1500, 1), (1500, 2), (1400, 4), (7, 7), (300, 6)):
        values = rng.normal(90, 40, n) if seed % 2 else np.repeat(rng.uniform(0, 180, 5), n // 5 + 1)[:n]
        x = (values + np.tile(np.linspace(-0.45, 0.45, 7), n // 7 + 1)[:n]).reshape(-1, 1)
        _, want = sklearn_seeds(x, k, row_norms(x, squared=True), np.ones(n), np.random.RandomState(0))
        assert np.array_equal(_kmeans_plusplus(x, k), want)


@pytest.mark.parametrize("seed", range(4))
def test_sharpness_is_the_sum_of_squares_of_the_linearly_split_histogram(seed: int) -> None:
    """Bit for bit the two-histogram form (floor, a point's weight to its bin and the next), at any angle."""
    rng = np.random.default_rng(seed)
    for angle in (0.0, math.pi / 2, math.pi / 4, 1e-9, float(rng.uniform(-math.pi, math.pi))):
        n = int(rng.integers(1, 3000))
        rows, cols = rng.integers(0, 2000, n).astype(np.float64), rng.integers(0, 2000, n).astype(np.float64)
        s = -math.sin(angle) * cols + math.cos(angle) * rows
        s -= s.min()
        whole = np.floor(s).astype(np.int64)
        part = s - whole
        size = int(whole.max()) + 2
        hist = np.bincount(whole, 1.0 - part, size) + np.bincount(whole + 1, part, size)
        assert _sharpness(angle, rows, cols) == float(np.dot(hist, hist))

"""Map-quality figures: how sharp a map is, and how well its walls agree with a reference map."""

from __future__ import annotations

import math
from typing import NamedTuple

import cv2
import numpy as np
import numpy.typing as npt

from services.occupancy_mapping.errors import OccupancyMappingError
from shared.store.records import GridLayer
from shared.transforms import Pose2D

OCCUPIED_PERCENT = 65
FREE_PERCENT = 25


class WallAgreement(NamedTuple):
    """Result of :func:`wall_agreement`.

    ``fraction`` of the reference's occupied cells within tolerance of one of ours, after mapping
    ours into the reference frame with ``ours_to_reference`` (``p_ref = R(yaw) p_ours + (x, y)``);
    ``fraction_in_view`` counts only the reference cells that fall within tolerance of a cell our
    map has observed (known), i.e. the part of the reference our data could have seen;
    ``precision`` is the other direction: the fraction of our occupied cells within tolerance of
    a reference wall (low when we invent or misplace walls, or see things the reference lacks).
    """

    fraction: float
    ours_to_reference: Pose2D
    reference_cells: int
    fraction_in_view: float
    precision: float


def _check(occupancy: npt.NDArray[np.int8], what: str) -> npt.NDArray[np.int8]:
    occ = np.asarray(occupancy)
    if occ.ndim != 2 or 0 in occ.shape:
        raise OccupancyMappingError(f"{what} must be a non-empty 2-D array, got shape {occ.shape}")
    return occ


def sharpness(occupancy: npt.NDArray[np.int8]) -> float:
    """Mean, over occupied cells, of 1 / (cells to the nearest free cell), in [0, 1]; higher is sharper.

    A crisp map has walls one or two cells thick with free space on the observed side, so an
    occupied cell is typically 1 cell (chessboard distance) from free space and the figure is
    near 1. Pose error or blur spread walls into bands of occupied and uncertain cells, pushing
    occupied cells away from free space, and the figure drops smoothly (about 0.5 for a 3-cell
    band). Occupied is > 65 %, free < 25 % (map_saver's thresholds). 0.0 for a map with no walls.
    """
    occ = _check(occupancy, "occupancy")
    known = occ >= 0
    occupied = known & (occ > OCCUPIED_PERCENT)
    free = known & (occ < FREE_PERCENT)
    if not occupied.any() or not free.any():
        return 0.0
    distance = cv2.distanceTransform((~free).astype(np.uint8), cv2.DIST_C, 3)
    return float(np.mean(1.0 / distance[occupied]))


def _occupied_points(layer: GridLayer) -> npt.NDArray[np.float64]:
    """World (x, y) of the centres of a layer's occupied cells, (n, 2)."""
    rows, cols = np.nonzero(np.asarray(layer.data) > OCCUPIED_PERCENT)
    return np.stack(
        [
            layer.origin_x_m + (cols + 0.5) * layer.resolution_m,
            layer.origin_y_m + (rows + 0.5) * layer.resolution_m,
        ],
        axis=1,
    )


def _rotate(points: npt.NDArray[np.float64], yaw_rad: float) -> npt.NDArray[np.float64]:
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    rotated: npt.NDArray[np.float64] = points @ np.array([[c, s], [-s, c]])
    return rotated


def _score_shifts(
    ref_pts: npt.NDArray[np.float64],
    near_ours: npt.NDArray[np.float32],
    lo: npt.NDArray[np.float64],
    cell_m: float,
) -> tuple[float, npt.NDArray[np.float64]]:
    """Best shift of ``ref_pts`` (rotated into our frame) onto the ``near_ours`` mask, by FFT correlation."""
    idx = np.floor((ref_pts - ref_pts.min(axis=0)) / cell_m).astype(np.intp)
    ref_img = np.zeros((idx[:, 1].max() + 1, idx[:, 0].max() + 1), np.float32)
    np.add.at(ref_img, (idx[:, 1], idx[:, 0]), 1.0)
    h = near_ours.shape[0] + ref_img.shape[0]
    w = near_ours.shape[1] + ref_img.shape[1]
    fa = np.fft.rfft2(near_ours, (h, w))
    fb = np.fft.rfft2(ref_img[::-1, ::-1], (h, w))
    corr = np.fft.irfft2(fa * fb, (h, w))
    r, c = np.unravel_index(int(np.argmax(corr)), corr.shape)
    # corr[r, c] counts ref cells at (row, col) landing on near_ours[row + r - (H_ref - 1), ...]
    shift_cells = np.array([c - (ref_img.shape[1] - 1), r - (ref_img.shape[0] - 1)], dtype=np.float64)
    ref_to_ours = lo + shift_cells * cell_m - ref_pts.min(axis=0)
    return float(corr[r, c]), ref_to_ours


def _within(
    ref_in_ours: npt.NDArray[np.float64],
    distance_m: npt.NDArray[np.float32],
    lo: npt.NDArray[np.float64],
    cell_m: float,
    tolerance_m: float,
) -> npt.NDArray[np.bool_]:
    idx = np.floor((ref_in_ours - lo) / cell_m).astype(np.intp)
    inside = (
        (idx[:, 0] >= 0)
        & (idx[:, 1] >= 0)
        & (idx[:, 0] < distance_m.shape[1])
        & (idx[:, 1] < distance_m.shape[0])
    )
    hits = np.zeros(len(idx), bool)
    hits[inside] = distance_m[idx[inside, 1], idx[inside, 0]] <= tolerance_m
    return hits


def wall_agreement(
    ours: GridLayer,
    reference: GridLayer,
    *,
    tolerance_m: float = 0.1,
    coarse_step_rad: float = math.radians(2.0),
    search_cell_m: float = 0.1,
) -> WallAgreement:
    """Register ``ours`` onto ``reference`` rigidly, then score wall agreement.

    The registration maximises the number of reference wall cells within ``tolerance_m`` of our
    walls: for each rotation on a ``coarse_step_rad`` grid, the best translation comes from an FFT
    cross-correlation of the rotated reference walls with our dilated walls at ``search_cell_m``;
    the best rotation is then refined in tenth steps. The score uses an exact distance transform
    at our resolution. Our map may cover only part of the reference, which caps the figure.

    Parameters
    ----------
    ours, reference : GridLayer
        Occupancy layers (int8, -1 unknown, 0..100), each in its own frame.
    tolerance_m : float
        How far a reference wall cell may be from one of ours and still agree, metres.
    coarse_step_rad : float
        Rotation search step, radians.
    search_cell_m : float
        Cell size of the translation search, metres.
    """
    if not (tolerance_m > 0 and coarse_step_rad > 0 and search_cell_m > 0):
        raise OccupancyMappingError("tolerance_m, coarse_step_rad and search_cell_m must be positive")
    _check(ours.data, "our map")
    _check(reference.data, "reference map")
    ours_pts, ref_pts = _occupied_points(ours), _occupied_points(reference)
    if len(ours_pts) == 0 or len(ref_pts) == 0:
        raise OccupancyMappingError("both maps need occupied cells to be compared")
    lo = ours_pts.min(axis=0) - 2 * search_cell_m
    idx = np.floor((ours_pts - lo) / search_cell_m).astype(np.intp)
    ours_img = np.zeros((idx[:, 1].max() + 3, idx[:, 0].max() + 3), np.uint8)
    ours_img[idx[:, 1], idx[:, 0]] = 1
    radius = max(1, math.ceil(tolerance_m / search_cell_m))
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))
    near = cv2.dilate(ours_img, kernel).astype(np.float32)

    def best_at(yaw: float) -> tuple[float, npt.NDArray[np.float64]]:
        return _score_shifts(_rotate(ref_pts, yaw), near, lo, search_cell_m)

    coarse = [(yaw, *best_at(yaw)) for yaw in np.arange(-math.pi, math.pi, coarse_step_rad)]
    yaw0 = max(coarse, key=lambda item: item[1])[0]
    fine = [(yaw, *best_at(yaw)) for yaw in yaw0 + np.linspace(-coarse_step_rad, coarse_step_rad, 21)]
    # exact scoring at our resolution for the best few candidates, with a local shift search
    fine_res = ours.resolution_m
    lo_f = ours_pts.min(axis=0) - 1.0
    idx_f = np.floor((ours_pts - lo_f) / fine_res).astype(np.intp)
    walls = np.ones(
        (idx_f[:, 1].max() + int(2.0 / fine_res), idx_f[:, 0].max() + int(2.0 / fine_res)), np.uint8
    )
    walls[idx_f[:, 1], idx_f[:, 0]] = 0
    distance = (cv2.distanceTransform(walls, cv2.DIST_L2, 5) * fine_res).astype(np.float32)
    best = (-1.0, 0.0, np.zeros(2))
    for yaw, _, shift in sorted(fine, key=lambda item: -item[1])[:5]:
        rotated = _rotate(ref_pts, yaw)
        for dx in np.arange(-search_cell_m, search_cell_m + 1e-9, fine_res / 2):
            for dy in np.arange(-search_cell_m, search_cell_m + 1e-9, fine_res / 2):
                t = shift + np.array([dx, dy])
                score = float(_within(rotated + t, distance, lo_f, fine_res, tolerance_m).mean())
                if score > best[0]:
                    best = (score, float(yaw), t)
    score, yaw, t = best
    known_rows, known_cols = np.nonzero(np.asarray(ours.data) >= 0)
    known_pts = np.stack(
        [ours.origin_x_m + (known_cols + 0.5) * fine_res, ours.origin_y_m + (known_rows + 0.5) * fine_res],
        axis=1,
    )
    unknown = np.ones_like(walls)
    k_idx = np.floor((known_pts - lo_f) / fine_res).astype(np.intp)
    keep = (k_idx[:, 0] < unknown.shape[1]) & (k_idx[:, 1] < unknown.shape[0]) & (k_idx >= 0).all(axis=1)
    unknown[k_idx[keep, 1], k_idx[keep, 0]] = 0
    to_known = (cv2.distanceTransform(unknown, cv2.DIST_L2, 5) * fine_res).astype(np.float32)
    ref_in_ours = _rotate(ref_pts, yaw) + t
    agree = _within(ref_in_ours, distance, lo_f, fine_res, tolerance_m)
    in_view = _within(ref_in_ours, to_known, lo_f, fine_res, tolerance_m)
    in_view_fraction = float(agree[in_view].mean()) if in_view.any() else 0.0
    # p_ours = R(yaw) p_ref + t, so p_ref = R(-yaw) p_ours - R(-yaw) t
    back = -_rotate(t[None, :], -yaw)[0]
    ours_in_ref = _rotate(ours_pts, -yaw) + back
    ref_lo = ref_pts.min(axis=0) - 1.0
    ref_idx = np.floor((ref_pts - ref_lo) / reference.resolution_m).astype(np.intp)
    ref_free = np.ones((ref_idx[:, 1].max() + int(2.0 / reference.resolution_m),
                        ref_idx[:, 0].max() + int(2.0 / reference.resolution_m)), np.uint8)
    ref_free[ref_idx[:, 1], ref_idx[:, 0]] = 0
    to_ref_wall = (cv2.distanceTransform(ref_free, cv2.DIST_L2, 5) * reference.resolution_m).astype(np.float32)
    precision = float(_within(ours_in_ref, to_ref_wall, ref_lo, reference.resolution_m, tolerance_m).mean())
    return WallAgreement(score, Pose2D(float(back[0]), float(back[1]), -yaw), len(ref_pts), in_view_fraction,
                         precision)

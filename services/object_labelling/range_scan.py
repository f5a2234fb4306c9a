"""Range and height scan: a top-down 1-D contour of the obstacles in a depth image.

Non-ground points are projected onto the floor plane and binned into measurement cones across
the camera's horizontal field of view. Per cone the contour keeps the closest point (range,
bearing) and the height of the obstacle there (the highest point within a short depth band
behind the closest one), plus the image rows and columns that point set covers, for ROIs.
"""

from __future__ import annotations

import enum
import math
from typing import NamedTuple

import numpy as np
import numpy.typing as npt
from scipy.ndimage import gaussian_filter1d

from services.object_labelling.camera import CameraIntrinsics, depth_to_points, subsample
from services.object_labelling.errors import ObjectLabellingError
from services.object_labelling.ground_plane import GroundPlane

FloatArray = npt.NDArray[np.float64]
MAX_RANGE_M = 6.0
"""Default horizontal range limit of the scan, metres (a 5 m depth camera sees 5.7 m at its image border)."""


class MissingCones(enum.Enum):
    """What to do with cones that got no depth at all (sensor holes)."""

    EXCLUDE = "exclude"
    GAUSSIAN = "gaussian"


class RangeHeightScan(NamedTuple):
    """Per-cone contour, cone 0 at the left image edge; all arrays have shape (n_cones,).

    ``ranges_m`` is the horizontal distance of the closest obstacle point (``inf`` for a cone
    that saw only floor or far points, ``NaN`` for a cone with no depth at all); ``heights_m`` the
    obstacle height there (0 for free, NaN for missing); ``bearings_rad`` the cone centres
    (left positive); ``forward_m``/``left_m`` the closest point on the floor plane; ``col_min``
    ... ``row_max`` the image pixels the obstacle covers in that cone (-1 where none).
    """

    bearings_rad: FloatArray
    ranges_m: FloatArray
    heights_m: FloatArray
    forward_m: FloatArray
    left_m: FloatArray
    col_min: npt.NDArray[np.intp]
    col_max: npt.NDArray[np.intp]
    row_min: npt.NDArray[np.intp]
    row_max: npt.NDArray[np.intp]


def floor_axes(plane: GroundPlane) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Up, forward and left unit vectors (3,) of the floor frame, in the camera's optical frame.

    Forward is the optical axis projected onto the plane, left = up x forward; the scan's ranges
    and bearings are measured in this frame from the camera's foot point on the floor.
    """
    normal = np.asarray(plane.normal)
    forward = np.array([0.0, 0.0, 1.0]) - normal[2] * normal
    if np.linalg.norm(forward) < 1e-6:
        raise ObjectLabellingError("camera looks straight at the floor: no forward direction on the plane")
    forward /= np.linalg.norm(forward)
    return normal, forward, np.cross(normal, forward)  # left = up x forward


def _gaussian_fill(values: FloatArray, missing: npt.NDArray[np.bool_], sigma: float) -> FloatArray:
    """Fill ``missing`` entries by normalised Gaussian convolution of the others (stays NaN if none near)."""
    known = ~missing
    filled_values = np.where(known, values, 0.0)
    num = gaussian_filter1d(filled_values, sigma, mode="nearest")
    den = gaussian_filter1d(known.astype(np.float64), sigma, mode="nearest")
    out = values.copy()
    with np.errstate(invalid="ignore", divide="ignore"):
        estimate = num / den
    reachable = missing & (den > 0.05)
    out[reachable] = estimate[reachable]
    return out


def range_height_scan(
    depth_mm: npt.NDArray[np.uint16],
    intrinsics: CameraIntrinsics,
    plane: GroundPlane,
    *,
    n_cones: int = 160,
    max_range_m: float = MAX_RANGE_M,
    ground_tolerance_m: float = 0.05,
    max_height_m: float = 3.0,
    depth_band_m: float = 0.3,
    pixel_step: int = 2,
    missing: MissingCones = MissingCones.EXCLUDE,
    fill_sigma_cones: float = 1.5,
) -> RangeHeightScan:
    """Top-down range and height scan of the obstacles in one depth image.

    Parameters
    ----------
    depth_mm
        (height, width) uint16 depth in millimetres (16UC1), 0 = no return.
    intrinsics
        Camera model of the depth image.
    plane
        The taught-in ground plane in the camera's optical frame.
    n_cones
        Measurement cones across the horizontal field of view (each
        ``intrinsics.horizontal_fov_rad / n_cones`` wide).
    max_range_m
        Obstacles farther than this (horizontal distance) are ignored.
    ground_tolerance_m, max_height_m
        Points lower than ``ground_tolerance_m`` count as floor, higher than ``max_height_m``
        as ceiling; neither is an obstacle.
    depth_band_m
        A cone's height is the highest obstacle point within this distance behind its closest one.
    pixel_step
        Use every ``pixel_step``-th row and column of the depth image (speed).
    missing
        Cones without any depth: leave as NaN (``EXCLUDE``) or interpolate from neighbours with a
        Gaussian kernel of ``fill_sigma_cones`` (``GAUSSIAN``).
    """
    if n_cones < 3 or pixel_step < 1 or max_range_m <= 0 or depth_band_m < 0:
        raise ObjectLabellingError(
            f"bad scan parameters n_cones={n_cones}, pixel_step={pixel_step}, "
            f"max_range_m={max_range_m}, depth_band_m={depth_band_m}"
        )
    sub, sub_intrinsics = subsample(depth_mm, intrinsics, step=pixel_step)
    if not sub.any():
        raise ObjectLabellingError(f"depth image has no depth on its every-{pixel_step}th-pixel grid")
    points, pixels = depth_to_points(sub, sub_intrinsics, max_depth_m=max_range_m * 2.0 + max_height_m)
    pixels = pixels * pixel_step
    normal, forward_axis, left_axis = floor_axes(plane)
    heights = points @ normal + plane.offset
    forward, left = points @ forward_axis, points @ left_axis
    ranges = np.hypot(forward, left)
    bearings = np.arctan2(left, forward)
    left_edge = math.atan(intrinsics.cx / intrinsics.fx)
    cone_width = intrinsics.horizontal_fov_rad / n_cones
    cones = np.clip(((left_edge - bearings) / cone_width).astype(np.intp), 0, n_cones - 1)
    seen = np.bincount(cones, minlength=n_cones) > 0

    obstacle = np.flatnonzero((heights > ground_tolerance_m) & (heights < max_height_m) & (ranges < max_range_m))
    o_cone, o_range = cones[obstacle], ranges[obstacle]
    closest = np.full(n_cones, np.inf)
    np.minimum.at(closest, o_cone, o_range)
    in_band = o_range <= closest[o_cone] + depth_band_m
    band, b_cone = obstacle[in_band], o_cone[in_band]
    b_pix = pixels[band]
    height = np.zeros(n_cones)
    np.maximum.at(height, b_cone, heights[band])
    big = np.iinfo(np.intp).max
    row_min, col_min = np.full(n_cones, big), np.full(n_cones, big)
    row_max, col_max = np.full(n_cones, -1), np.full(n_cones, -1)
    np.minimum.at(row_min, b_cone, b_pix[:, 0])
    np.minimum.at(col_min, b_cone, b_pix[:, 1])
    np.maximum.at(row_max, b_cone, b_pix[:, 0])
    np.maximum.at(col_max, b_cone, b_pix[:, 1])
    row_min[row_min == big], col_min[col_min == big] = -1, -1

    # the closest point itself (the first one of a cone reaching its minimum), for widths on the floor plane
    at_min = np.flatnonzero(o_range == closest[o_cone])
    hit_cones, first = np.unique(o_cone[at_min], return_index=True)
    nearest = obstacle[at_min[first]]
    fwd, lft = np.full(n_cones, np.nan), np.full(n_cones, np.nan)
    fwd[hit_cones], lft[hit_cones] = forward[nearest], left[nearest]

    closest[~seen], height[~seen] = np.nan, np.nan
    if missing is MissingCones.GAUSSIAN and (~seen).any() and seen.any():
        filled = _gaussian_fill(np.minimum(closest, max_range_m), ~seen, fill_sigma_cones)
        closest = np.where(filled >= max_range_m, np.inf, filled)
        height = _gaussian_fill(height, ~seen, fill_sigma_cones)
    centres = left_edge - (np.arange(n_cones) + 0.5) * cone_width
    return RangeHeightScan(
        np.asarray(centres, np.float64), closest, height, fwd, lft, col_min, col_max, row_min, row_max
    )

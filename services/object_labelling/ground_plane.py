"""Ground plane: RANSAC fit at teach-in, then a cheap per-frame validity check.

The camera is fixed on the vehicle, so the floor plane in the camera frame is constant. It is
estimated once (teach-in) and kept; each frame then counts the points that still lie on it. Too
few is not proof of a moved camera by itself (a camera facing a rack close by sees no floor), so
the plane is only *contradicted* when something is seen through the floor or another floor-like
plane is in view; then the camera was moved or knocked and the plane must be taught in again.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from services.object_labelling.errors import ObjectLabellingError

DEFAULT_UP = (0.0, -1.0, 0.0)  # optical frame: y points down


class GroundPlane(NamedTuple):
    """Plane ``normal . p + offset = 0`` with a unit ``normal`` pointing up (into free space).

    ``height_m(points)`` is then the signed height above the floor, and ``offset`` is the camera's
    own height above it (metres).
    """

    normal: tuple[float, float, float]
    offset: float

    def height_m(self, points: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Signed height above the plane of (n, 3) points, metres."""
        return np.asarray(points @ np.asarray(self.normal) + self.offset, dtype=np.float64)


class GroundCheck(NamedTuple):
    """Result of :func:`check_ground_plane`.

    ``inliers``: points on the taught-in plane; ``verified``: enough of them to confirm it;
    ``valid``: the frame does not contradict the plane (verified, or no floor in view at all).
    """

    inliers: int
    valid: bool
    verified: bool


def _plane_through(p: npt.NDArray[np.float64]) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Normals (m, 3) and offsets (m,) of planes through point triples p (m, 3, 3); degenerate -> norm 0."""
    normals = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    norms = np.linalg.norm(normals, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        normals = normals / norms[:, None]
    return normals, -np.einsum("ij,ij->i", normals, p[:, 0])


def fit_ground_plane(
    points: npt.NDArray[np.float64],
    *,
    inlier_tolerance_m: float = 0.03,
    iterations: int = 200,
    up: tuple[float, float, float] = DEFAULT_UP,
    max_tilt_rad: float = 0.5,
    min_inliers: int = 500,
    seed: int = 0,
) -> GroundPlane:
    """RANSAC plane fit for the floor, refined by least squares on the inliers.

    Parameters
    ----------
    points
        (n, 3) float64 optical-frame points (metres) of a teach-in view showing mostly floor.
    inlier_tolerance_m
        Distance from the plane within which a point counts as floor.
    iterations
        RANSAC hypotheses (all evaluated at once, vectorised).
    up
        Rough up direction in the camera frame; hypotheses whose normal deviates from it by more
        than ``max_tilt_rad`` are ignored, so walls and rack faces are never taken for the floor.
    min_inliers
        Fewer inliers than this for the best plane raises :class:`ObjectLabellingError`.
    seed
        Seed of the hypothesis sampling.
    """
    if points.ndim != 2 or points.shape[1] != 3 or points.shape[0] < 3:
        raise ObjectLabellingError(f"need (n >= 3, 3) points for a plane fit, got shape {points.shape}")
    up_vec = np.asarray(up, dtype=np.float64)
    up_vec = up_vec / np.linalg.norm(up_vec)
    rng = np.random.default_rng(seed)
    sample = points[rng.choice(points.shape[0], min(points.shape[0], 5000), replace=False)]
    normals, offsets = _plane_through(points[rng.integers(0, points.shape[0], (iterations, 3))])
    flip = np.where(normals @ up_vec < 0, -1.0, 1.0)
    normals, offsets = normals * flip[:, None], offsets * flip
    usable = np.isfinite(normals).all(axis=1) & (normals @ up_vec >= np.cos(max_tilt_rad))
    if not usable.any():
        raise ObjectLabellingError(f"no plane within {max_tilt_rad:.2f} rad of the up direction {up}")
    normals, offsets = normals[usable], offsets[usable]
    counts = (np.abs(sample @ normals.T + offsets) <= inlier_tolerance_m).sum(axis=0)
    best = int(np.argmax(counts))
    inliers = points[np.abs(points @ normals[best] + offsets[best]) <= inlier_tolerance_m]
    if inliers.shape[0] < min_inliers:
        raise ObjectLabellingError(
            f"best ground plane has {inliers.shape[0]} inliers, fewer than the {min_inliers} required"
        )
    centroid = inliers.mean(axis=0)
    normal = np.linalg.svd(inliers - centroid, full_matrices=False)[2][2]
    if normal @ up_vec < 0:
        normal = -normal
    return GroundPlane((float(normal[0]), float(normal[1]), float(normal[2])), float(-normal @ centroid))


def check_ground_plane(
    points: npt.NDArray[np.float64],
    plane: GroundPlane,
    *,
    inlier_tolerance_m: float = 0.03,
    min_inliers: int = 500,
    below_m: float = 0.15,
    search_height_m: float = 0.5,
    min_spread_m: float = 0.25,
) -> GroundCheck:
    """Check a frame's points against the taught-in ``plane``.

    The plane is *contradicted* (``valid`` False) when at least ``min_inliers`` points lie more
    than ``below_m`` below it (nothing is seen through a floor: the camera was raised or tilted
    up). Otherwise it is *verified* when at least ``min_inliers`` points lie within
    ``inlier_tolerance_m`` of it. If not, it is contradicted when the points lower than
    ``search_height_m`` hold another floor-like plane (within 0.5 rad of the plane's up direction)
    with three times ``min_inliers`` points spread at least ``min_spread_m`` (standard deviation)
    in its second direction too: the floor is in view, elsewhere (camera lowered or tilted down).
    With neither, the view simply shows no floor, and the frame stays valid.

    ``min_inliers`` is an absolute count: scale it with the number of points checked (the
    labeller checks every 4th pixel of a 640 x 480 frame, 19,200 points, with 300).
    """
    if points.ndim != 2 or points.shape[1] != 3:
        raise ObjectLabellingError(f"points must be (n, 3), got shape {points.shape}")
    heights = plane.height_m(points)
    inliers = int(np.count_nonzero(np.abs(heights) <= inlier_tolerance_m))
    if np.count_nonzero(heights < -below_m) >= min_inliers:
        return GroundCheck(inliers, False, False)
    if inliers >= min_inliers:
        return GroundCheck(inliers, True, True)
    low = points[heights < search_height_m]
    if low.shape[0] >= 3 * min_inliers:
        try:
            other = fit_ground_plane(low, inlier_tolerance_m=inlier_tolerance_m, up=plane.normal,
                                     min_inliers=3 * min_inliers)
        except ObjectLabellingError:
            other = None  # no floor in view
        if other is not None:
            on = low[np.abs(other.height_m(low)) <= inlier_tolerance_m]
            # a floor spreads in two directions; a level plane cutting a wall leaves only a thin strip
            spread = np.linalg.svd(on - on.mean(axis=0), compute_uv=False)[1] / np.sqrt(on.shape[0])
            if spread >= min_spread_m:
                return GroundCheck(inliers, False, False)
    return GroundCheck(inliers, True, False)

"""Landmark position from bearings taken at several known sensor poses."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from services.pillar_mapping.errors import PillarMappingError

FloatArray = npt.NDArray[np.float64]


class Triangulation(NamedTuple):
    """A triangulated point: ``mean`` (2,) metres, ``cov`` (2, 2) m^2, ``residuals_rad`` (K,), ``parallax_rad``."""

    mean: FloatArray
    cov: FloatArray
    residuals_rad: FloatArray
    parallax_rad: float


def wrap(angle: npt.ArrayLike) -> FloatArray:
    """Angles wrapped to [-pi, pi)."""
    return np.asarray((np.asarray(angle, dtype=np.float64) + np.pi) % (2 * np.pi) - np.pi)


def triangulate_bearings(
    origins: FloatArray, bearings_rad: FloatArray, sigmas_rad: FloatArray, *, iterations: int = 8
) -> Triangulation:
    """Weighted least-squares intersection of bearing rays, refined by Gauss-Newton on bearing residuals.

    Parameters
    ----------
    origins : ndarray of float64, shape (K, 2)
        Sensor positions in the map frame, metres.
    bearings_rad : ndarray of float64, shape (K,)
        Ray directions in the map frame, radians.
    sigmas_rad : ndarray of float64, shape (K,)
        Their standard deviations, radians.

    Returns
    -------
    Triangulation
        The covariance is the inverse Gauss-Newton information; ``parallax_rad`` is the widest
        angle between two rays as seen from the point.

    Raises
    ------
    PillarMappingError
        With fewer than two rays or rays that are (nearly) parallel.
    """
    if origins.shape[0] < 2:
        raise PillarMappingError(f"need at least two bearings to triangulate, got {origins.shape[0]}")
    normals = np.stack([-np.sin(bearings_rad), np.cos(bearings_rad)], axis=1)
    a = normals.T @ normals
    if np.linalg.cond(a) > 1e8:
        raise PillarMappingError("bearing rays are parallel: no parallax to triangulate")
    point = np.linalg.solve(a, normals.T @ np.sum(normals * origins, axis=1))
    weights = 1.0 / sigmas_rad**2
    info = np.eye(2)
    for _ in range(iterations):
        delta = point[None, :] - origins
        q = np.maximum(np.sum(delta**2, axis=1), 1e-12)
        residual = wrap(bearings_rad - np.arctan2(delta[:, 1], delta[:, 0]))
        jac = np.stack([-delta[:, 1] / q, delta[:, 0] / q], axis=1)
        info = (jac * weights[:, None]).T @ jac
        if np.linalg.cond(info) > 1e12:
            raise PillarMappingError("bearing rays are parallel: no parallax to triangulate")
        step = np.linalg.solve(info, (jac * weights[:, None]).T @ residual)
        point = point + step
        if float(np.hypot(*step)) < 1e-7:
            break
    delta = point[None, :] - origins
    seen = np.arctan2(delta[:, 1], delta[:, 0])
    spread = wrap(seen - seen[0])
    cov: FloatArray = np.asarray(np.linalg.inv(info), dtype=np.float64)
    return Triangulation(point, cov, wrap(bearings_rad - seen), float(spread.max() - spread.min()))

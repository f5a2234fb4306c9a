"""Vectorised planar rigid transforms on (x, y, yaw) rows, metres and radians."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


def wrap_angle(angle_rad: npt.ArrayLike) -> FloatArray:
    """Angles wrapped into [-pi, pi)."""
    a = np.asarray(angle_rad, dtype=np.float64)
    return np.asarray((a + np.pi) % (2.0 * np.pi) - np.pi)


def compose(a: npt.ArrayLike, b: npt.ArrayLike) -> FloatArray:
    """``a * b`` row-wise for (..., 3) poses: ``b`` expressed in ``a``'s frame, mapped to ``a``'s parent."""
    pa, pb = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    c, s = np.cos(pa[..., 2]), np.sin(pa[..., 2])
    x = pa[..., 0] + c * pb[..., 0] - s * pb[..., 1]
    y = pa[..., 1] + s * pb[..., 0] + c * pb[..., 1]
    return np.stack([x, y, wrap_angle(pa[..., 2] + pb[..., 2])], axis=-1)


def inverse(a: npt.ArrayLike) -> FloatArray:
    """Inverse of (..., 3) poses."""
    p = np.asarray(a, dtype=np.float64)
    c, s = np.cos(p[..., 2]), np.sin(p[..., 2])
    x = -(c * p[..., 0] + s * p[..., 1])
    y = s * p[..., 0] - c * p[..., 1]
    return np.stack([x, y, wrap_angle(-p[..., 2])], axis=-1)


def between(a: npt.ArrayLike, b: npt.ArrayLike) -> FloatArray:
    """``a^-1 * b``: pose ``b`` in the frame of pose ``a``."""
    return compose(inverse(a), b)


def transform_points(pose: npt.ArrayLike, points_xy: npt.ArrayLike) -> FloatArray:
    """Points (n, 2) from a frame at ``pose`` (3,) into its parent frame, (n, 2) float64 metres."""
    p = np.asarray(pose, dtype=np.float64)
    pts = np.asarray(points_xy, dtype=np.float64).reshape(-1, 2)
    c, s = np.cos(p[2]), np.sin(p[2])
    return np.asarray(pts @ np.array([[c, s], [-s, c]]) + p[:2], dtype=np.float64)

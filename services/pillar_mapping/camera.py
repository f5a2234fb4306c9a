"""Equidistant (Kannala-Brandt) fisheye calibration as carried by sensor_msgs/CameraInfo."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any, NamedTuple, TypeAlias

import numpy as np
import numpy.typing as npt
import yaml
from rosbags.typesys.stores.ros2_jazzy import sensor_msgs__msg__CameraInfo as CameraInfo

from services.pillar_mapping.errors import PillarMappingError

FloatArray = npt.NDArray[np.float64]

_MODELS = frozenset({"equidistant", "fisheye", "kannala_brandt"})

CameraInfoLike: TypeAlias = CameraInfo | Mapping[str, Any]
"""A sensor_msgs/CameraInfo, or the same fields (or the camera_calibration YAML layout) as a mapping."""


class FisheyeCamera(NamedTuple):
    """An equidistant fisheye: ``r = f * theta_d``, ``theta_d = theta (1 + k1 theta^2 + ... + k4 theta^8)``.

    ``k`` is the 3x3 intrinsic matrix (pixels), ``d`` the four coefficients k1..k4 as in
    ``cv2.fisheye``; ``fov_rad`` is the full field of view, beyond which pixels are ignored.
    """

    k: FloatArray
    d: FloatArray
    width: int
    height: int
    fov_rad: float = float(np.deg2rad(185.0))

    @property
    def principal_point(self) -> tuple[float, float]:
        """(cx, cy) in pixels: the vanishing point of vertical lines for a downward camera."""
        return float(self.k[0, 2]), float(self.k[1, 2])


def _field(info: CameraInfoLike, *names: str) -> Any:
    for name in names:
        if isinstance(info, Mapping):
            if name in info:
                return info[name]
        elif hasattr(info, name):
            return getattr(info, name)
    raise PillarMappingError(f"camera info has none of the fields {names}")


def _data(value: Any) -> FloatArray:
    if isinstance(value, Mapping):
        value = value.get("data")
    try:
        return np.asarray(value, dtype=np.float64).ravel()
    except (TypeError, ValueError) as err:
        raise PillarMappingError(f"camera info array {value!r} is not numeric") from err


def camera_from_info(info: CameraInfoLike, *, fov_rad: float = float(np.deg2rad(185.0))) -> FisheyeCamera:
    """A :class:`FisheyeCamera` from a CameraInfo message or its YAML/dict form.

    Accepts a sensor_msgs/CameraInfo (attributes ``k``, ``d``, ``width``, ``height``,
    ``distortion_model``), the same as a mapping, or the camera_calibration YAML layout
    (``camera_matrix.data``, ``distortion_coefficients.data``, ``image_width``, ``image_height``).

    Raises
    ------
    PillarMappingError
        If the model is not equidistant, K is singular or D does not have four coefficients.
    """
    model = str(_field(info, "distortion_model")).strip().lower()
    if model not in _MODELS:
        raise PillarMappingError(
            f"distortion model {model!r} is not equidistant fisheye; expected one of {sorted(_MODELS)}"
        )
    k = _data(_field(info, "k", "K", "camera_matrix"))
    d = _data(_field(info, "d", "D", "distortion_coefficients"))
    width = int(_field(info, "width", "image_width"))
    height = int(_field(info, "height", "image_height"))
    if k.size != 9 or not np.all(np.isfinite(k)):
        raise PillarMappingError(f"camera matrix must hold 9 finite numbers, got {k.tolist()}")
    k = k.reshape(3, 3)
    if k[0, 0] <= 0 or k[1, 1] <= 0:
        raise PillarMappingError(f"focal lengths must be positive, got fx={k[0, 0]}, fy={k[1, 1]}")
    if d.size == 0:
        d = np.zeros(4)
    if d.size != 4 or not np.all(np.isfinite(d)):
        raise PillarMappingError(f"equidistant model needs 4 finite coefficients k1..k4, got {d.tolist()}")
    if width <= 0 or height <= 0:
        raise PillarMappingError(f"image size {width}x{height} must be positive")
    if not 0 < fov_rad < 2 * np.pi:
        raise PillarMappingError(f"field of view {fov_rad} rad must lie in (0, 2 pi)")
    return FisheyeCamera(k, d, width, height, float(fov_rad))


def read_camera_info_yaml(path: Path) -> FisheyeCamera:
    """:func:`camera_from_info` of a camera_calibration YAML file."""
    try:
        info = yaml.safe_load(Path(path).read_text())
    except (OSError, yaml.YAMLError) as err:
        raise PillarMappingError(f"cannot read camera info {path}: {err}") from err
    if not isinstance(info, Mapping):
        raise PillarMappingError(f"camera info {path} is not a YAML mapping")
    return camera_from_info(info)


def _undistort_theta(theta_d: FloatArray, d: FloatArray) -> FloatArray:
    """Invert ``theta_d = theta (1 + k1 theta^2 + ...)`` by Newton's method (radians)."""
    theta = theta_d.copy()
    for _ in range(12):
        t2 = theta * theta
        poly = 1 + t2 * (d[0] + t2 * (d[1] + t2 * (d[2] + t2 * d[3])))
        dpoly = 1 + t2 * (3 * d[0] + t2 * (5 * d[1] + t2 * (7 * d[2] + t2 * 9 * d[3])))
        theta = theta - (theta * poly - theta_d) / np.where(np.abs(dpoly) < 1e-9, 1e-9, dpoly)
    return theta


def pixel_angles(camera: FisheyeCamera, u: npt.ArrayLike, v: npt.ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Polar angles of pixels' viewing rays in the optical frame.

    Parameters
    ----------
    camera : FisheyeCamera
    u, v : array_like
        Pixel coordinates (column, row), any matching shape.

    Returns
    -------
    theta : ndarray of float64
        Angle from the optical axis, radians.
    azimuth : ndarray of float64
        ``atan2(y, x)`` of the ray in the optical frame (x right, y down), radians in (-pi, pi].
    """
    k = camera.k
    xn = (np.asarray(u, dtype=np.float64) - k[0, 2]) / k[0, 0]
    yn = (np.asarray(v, dtype=np.float64) - k[1, 2]) / k[1, 1]
    xn = xn - k[0, 1] / k[1, 1] * yn
    theta = _undistort_theta(np.hypot(xn, yn), camera.d)
    return theta, np.arctan2(yn, xn)


def pixel_rays(camera: FisheyeCamera, u: npt.ArrayLike, v: npt.ArrayLike) -> FloatArray:
    """Unit viewing rays (..., 3) in the optical frame (x right, y down, z along the axis)."""
    theta, azimuth = pixel_angles(camera, u, v)
    s = np.sin(theta)
    return np.stack([s * np.cos(azimuth), s * np.sin(azimuth), np.cos(theta)], axis=-1)


def project_angles(camera: FisheyeCamera, theta: npt.ArrayLike, azimuth: npt.ArrayLike) -> FloatArray:
    """Pixels (..., 2) as (u, v) of rays at polar angle ``theta`` and ``azimuth`` (radians)."""
    t = np.asarray(theta, dtype=np.float64)
    a = np.asarray(azimuth, dtype=np.float64)
    t2 = t * t
    d = camera.d
    theta_d = t * (1 + t2 * (d[0] + t2 * (d[1] + t2 * (d[2] + t2 * d[3]))))
    xd, yd = theta_d * np.cos(a), theta_d * np.sin(a)
    k = camera.k
    return np.stack([k[0, 0] * xd + k[0, 1] * yd + k[0, 2], k[1, 1] * yd + k[1, 2]], axis=-1)

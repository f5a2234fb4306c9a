"""Bearings to rack uprights in one downward-looking fisheye image (paper A, section 3)."""

from __future__ import annotations

import logging
from pathlib import Path
from typing import NamedTuple

import cv2
import numpy as np
import numpy.typing as npt

from services.pillar_mapping.camera import (
    CameraInfoLike,
    FisheyeCamera,
    camera_from_info,
    project_angles,
    read_camera_info_yaml,
)
from services.pillar_mapping.errors import PillarMappingError
from services.pillar_mapping.paint import DEFAULT_PAINT, PaintModel, paint_likelihood
from services.pillar_mapping.wavelet import WaveletPeaks, dog_peaks

logger = logging.getLogger(__name__)

FloatArray = npt.NDArray[np.float64]


class BearingSignal(NamedTuple):
    """Per-bearing sums over the sampling circles, shape (bins,) float64 each.

    ``gradient`` is the tangential paint gradient (a positive then a negative peak per
    upright); ``paint`` the paint likelihood itself.
    """

    gradient: FloatArray
    paint: FloatArray


class PillarDetections(NamedTuple):
    """Uprights seen in one image, in the camera's optical frame.

    ``bearings_rad`` is the azimuth ``atan2(y, x)`` around the optical axis (x right, y down in
    the image), in [-pi, pi); ``sigmas_rad`` its standard deviation; ``strengths`` the wavelet
    signal-to-noise ratio. All arrays have shape (K,), float64, sorted by bearing.
    """

    bearings_rad: FloatArray
    sigmas_rad: FloatArray
    strengths: FloatArray


def _as_camera(camera_info: CameraInfoLike | FisheyeCamera) -> FisheyeCamera:
    return camera_info if isinstance(camera_info, FisheyeCamera) else camera_from_info(camera_info)


def bearing_signal(
    image_bgr: npt.NDArray[np.uint8],
    camera: FisheyeCamera,
    *,
    paint: PaintModel = DEFAULT_PAINT,
    bins: int = 1440,
    circles: int = 32,
    min_theta_rad: float = float(np.deg2rad(20.0)),
    gradient_tolerance_rad: float = float(np.deg2rad(30.0)),
) -> BearingSignal:
    """Tangential paint gradient accumulated over concentric circles, as a signal over bearing.

    Vertical uprights under a downward camera are radial bars towards the principal point, so
    their edges have gradients perpendicular to the radial lines. The paint likelihood's
    gradient is kept only within ``gradient_tolerance_rad`` of that direction, sampled on
    ``circles`` circles between ``min_theta_rad`` from the axis and the edge of the field of
    view, and summed per bearing: an upright gives a positive then a negative peak.

    Returns
    -------
    BearingSignal
        Signals at bearings ``-pi + (i + 0.5) * 2 pi / bins``.
    """
    likelihood = cv2.GaussianBlur(paint_likelihood(image_bgr, paint), (0, 0), 1.0)
    gx = cv2.Sobel(likelihood, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(likelihood, cv2.CV_32F, 0, 1, ksize=3)
    azimuth = -np.pi + (np.arange(bins) + 0.5) * (2 * np.pi / bins)
    theta = np.linspace(min_theta_rad, 0.5 * camera.fov_rad, circles)
    uv = project_angles(camera, theta[:, None], azimuth[None, :]).astype(np.float32)
    sample = {
        name: cv2.remap(img, uv[..., 0], uv[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        for name, img in (("gx", gx), ("gy", gy), ("paint", likelihood))
    }
    fx, fy = camera.k[0, 0], camera.k[1, 1]
    tx, ty = -fx * np.sin(azimuth), fy * np.cos(azimuth)
    norm = np.hypot(tx, ty)
    tx, ty = tx / norm, ty / norm
    gxs, gys = sample["gx"].astype(np.float64), sample["gy"].astype(np.float64)
    tangential = gxs * tx + gys * ty
    radial = gxs * ty - gys * tx
    keep = np.abs(radial) <= np.tan(gradient_tolerance_rad) * np.abs(tangential)
    return BearingSignal(
        np.asarray(np.sum(np.where(keep, tangential, 0.0), axis=0), dtype=np.float64),
        np.asarray(np.sum(sample["paint"], axis=0), dtype=np.float64),
    )


def _painted(peaks: WaveletPeaks, paint: FloatArray, *, min_centre_fraction: float) -> WaveletPeaks:
    """The peaks whose centre bin carries paint, not the gap between two uprights."""
    n = paint.size
    centre = np.rint(peaks.positions).astype(np.int64) % n
    keep = np.ones(centre.size, dtype=bool)
    for i, (c, s) in enumerate(zip(centre, peaks.scales, strict=True)):
        reach = int(np.ceil(s))
        window = paint[np.arange(c - reach, c + reach + 1) % n]
        keep[i] = paint[c] >= min_centre_fraction * window.max()
    return WaveletPeaks(peaks.positions[keep], peaks.scales[keep], peaks.snr[keep])


def detect_pillars(
    image_bgr: npt.NDArray[np.uint8],
    camera_info: CameraInfoLike | FisheyeCamera,
    *,
    paint: PaintModel = DEFAULT_PAINT,
    bins: int = 1440,
    circles: int = 32,
    min_theta_rad: float = float(np.deg2rad(20.0)),
    gradient_tolerance_rad: float = float(np.deg2rad(30.0)),
    min_width_rad: float = float(np.deg2rad(0.4)),
    max_width_rad: float = float(np.deg2rad(16.0)),
    min_snr: float = 8.0,
    min_centre_fraction: float = 0.6,
) -> PillarDetections:
    """Bearings, with standard deviations, to the painted uprights seen in a downward fisheye image.

    The paint is found by colour indexing, its oriented gradient accumulated over bearing by
    :func:`bearing_signal`, and each upright's pair of opposite edges found by a continuous
    wavelet transform with a first-derivative-of-Gaussian wavelet whose scales span half-widths
    from ``min_width_rad / 2`` to ``max_width_rad / 2``.

    Parameters
    ----------
    image_bgr : ndarray of uint8, shape (H, W, 3)
        The image, BGR.
    camera_info : FisheyeCamera or CameraInfo-like
        Equidistant fisheye calibration (see :func:`~services.pillar_mapping.camera.camera_from_info`).
    paint : PaintModel
        Colour of the uprights.
    bins : int
        Bearing resolution of the signal, samples per turn.
    min_snr : float
        Least wavelet signal-to-noise ratio of a detection.
    min_centre_fraction : float
        Least paint at a detection's centre relative to the most paint within its matched
        width; rejects the wavelet's response between two close uprights.

    Returns
    -------
    PillarDetections
        Bearings in the optical frame; sigmas grow with the matched width and fall with SNR.
    """
    camera = _as_camera(camera_info)
    if image_bgr.shape[:2] != (camera.height, camera.width):
        raise PillarMappingError(
            f"image is {image_bgr.shape[1]}x{image_bgr.shape[0]} but the calibration is for "
            f"{camera.width}x{camera.height}"
        )
    if bins < 64 or circles < 1:
        raise PillarMappingError(f"need at least 64 bins and 1 circle, got {bins} and {circles}")
    if not 0 < min_width_rad < max_width_rad:
        raise PillarMappingError(f"width range [{min_width_rad}, {max_width_rad}] rad is empty")
    signal = bearing_signal(
        image_bgr,
        camera,
        paint=paint,
        bins=bins,
        circles=circles,
        min_theta_rad=min_theta_rad,
        gradient_tolerance_rad=gradient_tolerance_rad,
    )
    step = 2 * np.pi / bins
    scales = np.geomspace(max(0.5 * min_width_rad / step, 0.7), 0.5 * max_width_rad / step, 14)
    peaks = dog_peaks(signal.gradient, scales, min_snr=min_snr)
    peaks = _painted(peaks, signal.paint, min_centre_fraction=min_centre_fraction)
    bearings = -np.pi + (peaks.positions + 0.5) * step
    sigmas = np.hypot(step / np.sqrt(12.0), 2.0 * peaks.scales * step / peaks.snr)
    order = np.argsort(bearings)
    logger.debug("detected %d uprights", order.size)
    return PillarDetections(bearings[order], sigmas[order], peaks.snr[order])


def detect_pillars_file(image_path: Path, camera_info_path: Path) -> PillarDetections:
    """:func:`detect_pillars` on an image file with a camera_calibration YAML (for ``aisle pillars detect``)."""
    image = cv2.imread(str(image_path), cv2.IMREAD_COLOR)
    if image is None:
        raise PillarMappingError(f"cannot read image {image_path}")
    return detect_pillars(np.asarray(image, dtype=np.uint8), read_camera_info_yaml(camera_info_path))

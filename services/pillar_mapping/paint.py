"""Colour indexing of upright paint: a hue-saturation histogram back-projected onto an image."""

from __future__ import annotations

from typing import NamedTuple

import cv2
import numpy as np
import numpy.typing as npt

from services.pillar_mapping.errors import PillarMappingError


class PaintModel(NamedTuple):
    """The uprights' paint colour in HSV: hue in degrees on [0, 360), saturation and value on [0, 1].

    The default is the common blue of pallet-rack uprights (beams are usually orange).
    """

    hue_deg: float = 210.0
    hue_tolerance_deg: float = 20.0
    min_saturation: float = 0.35
    min_value: float = 0.15


DEFAULT_PAINT = PaintModel()


def _histogram(paint: PaintModel) -> npt.NDArray[np.float32]:
    """The (180, 256) hue-saturation model histogram in OpenCV units, values in [0, 1]."""
    hue = (np.arange(180, dtype=np.float64) + 0.5) * 2.0
    diff = np.abs((hue - paint.hue_deg + 180.0) % 360.0 - 180.0)
    hue_weight = np.exp(-0.5 * (diff / paint.hue_tolerance_deg) ** 2)
    sat = (np.arange(256) + 0.5) / 256.0
    sat_weight = np.clip((sat - paint.min_saturation) / 0.1 + 0.5, 0.0, 1.0)
    return np.outer(hue_weight, sat_weight).astype(np.float32)


def paint_likelihood(image_bgr: npt.NDArray[np.uint8], paint: PaintModel = DEFAULT_PAINT) -> npt.NDArray[np.float32]:
    """How much each pixel looks like upright paint.

    Parameters
    ----------
    image_bgr : ndarray of uint8, shape (H, W, 3)
        8-bit BGR image.
    paint : PaintModel
        The paint colour.

    Returns
    -------
    ndarray of float32, shape (H, W)
        Back-projected likelihood in [0, 1]; pixels darker than ``min_value`` are 0.
    """
    if image_bgr.ndim != 3 or image_bgr.shape[2] != 3 or image_bgr.dtype != np.uint8:
        raise PillarMappingError(f"image must be 8-bit BGR of shape (H, W, 3), got {image_bgr.dtype} {image_bgr.shape}")
    if not 0 < paint.hue_tolerance_deg <= 180:
        raise PillarMappingError(f"hue tolerance {paint.hue_tolerance_deg} deg must lie in (0, 180]")
    hsv = cv2.cvtColor(image_bgr, cv2.COLOR_BGR2HSV)
    likelihood = cv2.calcBackProject([hsv], [0, 1], _histogram(paint), [0, 180, 0, 256], scale=1.0)
    out: npt.NDArray[np.float32] = np.asarray(likelihood, dtype=np.float32)
    out[hsv[..., 2] < paint.min_value * 255.0] = 0.0
    return out

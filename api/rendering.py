"""Grid layers as greyscale images for people to look at."""

from __future__ import annotations

import io
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt

UNKNOWN_GREY = 205
"""Grey of unknown occupancy cells, as map_server's map_saver writes them."""
FREE_PERCENT = 25
OCCUPIED_PERCENT = 65
"""map_saver's default thresholds: at or below FREE_PERCENT is free, at or above OCCUPIED_PERCENT occupied."""


class RenderError(ValueError):
    """A layer whose values cannot be shown as an image."""


def layer_image(data: npt.NDArray[Any]) -> npt.NDArray[np.uint8]:
    """A greyscale image of a grid layer, north up.

    Parameters
    ----------
    data : (rows, cols) array
        Layer values, row 0 the lowest y. ``int8`` is read as occupancy (nav_msgs/OccupancyGrid):
        -1 unknown (grey 205); as map_saver thresholds them, 0..25 free (white) and 65..100
        occupied (black), the undecided band shaded linearly in between; values outside -1..100
        are shown as unknown. Other numeric dtypes are scaled min-max to
        0..255 over their finite values; non-finite cells are black.

    Returns
    -------
    (rows, cols) uint8 array
        Row 0 is the top of the image, i.e. the highest y.

    Examples
    --------
    >>> layer_image(np.array([[0], [100], [-1]], dtype=np.int8))[:, 0].tolist()
    [205, 0, 255]
    >>> layer_image(np.array([[45]], dtype=np.int8)).tolist()
    [[128]]
    """
    if data.ndim != 2:
        raise RenderError(f"only 2-D layers can be rendered, not shape {data.shape}")
    grey = _occupancy_grey(data) if data.dtype == np.int8 else _scaled_grey(data)
    return np.ascontiguousarray(grey[::-1])


def _occupancy_grey(data: npt.NDArray[np.int8]) -> npt.NDArray[np.uint8]:
    grey = np.full(data.shape, UNKNOWN_GREY, dtype=np.uint8)
    known = (data >= 0) & (data <= 100)
    band = (data[known].astype(np.float64) - FREE_PERCENT) / (OCCUPIED_PERCENT - FREE_PERCENT)
    grey[known] = np.round(255.0 * (1.0 - np.clip(band, 0.0, 1.0))).astype(np.uint8)
    return grey


def _scaled_grey(data: npt.NDArray[Any]) -> npt.NDArray[np.uint8]:
    if data.dtype.kind not in "biuf":
        raise RenderError(f"layers of dtype {data.dtype.name} cannot be rendered; fetch their values instead")
    values = data.astype(np.float64)
    finite = np.isfinite(values)
    grey = np.zeros(data.shape, dtype=np.uint8)
    if finite.any():
        low, high = values[finite].min(), values[finite].max()
        if high > low:
            grey[finite] = np.round((values[finite] - low) / (high - low) * 255.0).astype(np.uint8)
    return grey


def encode_png(image: npt.NDArray[np.uint8]) -> bytes:
    """PNG file bytes of a greyscale uint8 image."""
    ok, buffer = cv2.imencode(".png", image)
    if not ok:
        raise RenderError(f"PNG encoding failed for an image of shape {image.shape}")
    return bytes(buffer.tobytes())


def encode_npy(data: npt.NDArray[Any]) -> bytes:
    """``.npy`` file bytes of a layer's values (no pickled objects)."""
    buffer = io.BytesIO()
    np.save(buffer, data, allow_pickle=False)
    return buffer.getvalue()

"""Grid layers as images for people to look at: greyscale, or colour with a legend for label layers."""

from __future__ import annotations

import io
from collections.abc import Mapping, Sequence
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt

UNKNOWN_GREY = 205
"""Grey of unknown occupancy cells, as map_server's map_saver writes them."""
FREE_PERCENT = 25
OCCUPIED_PERCENT = 65
"""map_saver's default thresholds: at or below FREE_PERCENT is free, at or above OCCUPIED_PERCENT occupied."""
SEMANTIC_LABELS = "semantic_labels"
LABEL_ENCODINGS = frozenset({SEMANTIC_LABELS, "place_labels"})
"""Layer encodings (``meta['encoding']``) drawn as classes in colour with a legend."""
"""``meta["encoding"]`` of label layers: integer codes, ``meta["classes"][code]`` naming each and an optional
``meta["colours"][code]`` giving its ``[r, g, b]``; code 0 means "no label"."""
DEFAULT_LABEL_COLOURS = (
    (31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40), (148, 103, 189),
    (140, 86, 75), (227, 119, 194), (127, 127, 127), (188, 189, 34), (23, 190, 207),
)
"""Colours of codes 1, 2, ... (cycled) when a label layer names none; code 0 is white."""
_LEGEND_ROW_PX = 18
_LEGEND_FONT_SCALE = 0.42


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


def render_layer(data: npt.NDArray[Any], meta: Mapping[str, Any]) -> npt.NDArray[np.uint8]:
    """The image shown for a layer: :func:`label_image` for label layers (semantic classes, place labels),
    else :func:`layer_image`."""
    encoding = meta.get("encoding")
    if encoding not in LABEL_ENCODINGS:
        return layer_image(data)
    names = meta.get("classes")
    if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
        raise RenderError(f"a {encoding} layer needs meta['classes'], a list of class names by code")
    return label_image(data, class_names=names, colours=meta.get("colours"))


def label_image(data: npt.NDArray[Any], *, class_names: Sequence[str], colours: object = None
                ) -> npt.NDArray[np.uint8]:
    """An RGB image of a label layer, north up, with a legend of the classes present to its right.

    Parameters
    ----------
    data : (rows, cols) integer array
        Class codes, row 0 the lowest y; code 0 is "no label" and is left out of the legend.
    class_names : sequence of str
        Name of each code; every code in ``data`` needs one.
    colours : sequence of [r, g, b], optional
        Colour of each code (0..255); default white for 0 and :data:`DEFAULT_LABEL_COLOURS` for the rest.

    Returns
    -------
    (max(rows, legend height), cols + legend width, 3) uint8 array
        RGB; the map fills the top-left ``rows x cols`` pixels, one pixel a cell, white below it.

    Examples
    --------
    >>> label_image(np.array([[0, 1]], np.uint8), class_names=["none", "wall"])[0, :2].tolist()
    [[255, 255, 255], [31, 119, 180]]
    """
    if data.ndim != 2:
        raise RenderError(f"only 2-D layers can be rendered, not shape {data.shape}")
    if data.dtype.kind not in "iu":
        raise RenderError(f"label layers hold integer codes, not {data.dtype.name}")
    if data.min() < 0 or data.max() >= len(class_names):
        raise RenderError(f"label codes {data.min()}..{data.max()} are not all named by the "
                          f"{len(class_names)} classes in the layer's meta")
    colour_of = palette(len(class_names), colours)
    image = colour_of[data[::-1].astype(np.intp)]
    present = [int(code) for code in np.unique(data) if code != 0]
    width = max((cv2.getTextSize(class_names[c], cv2.FONT_HERSHEY_SIMPLEX, _LEGEND_FONT_SCALE, 1)[0][0]
                 for c in present), default=0) + 28
    height = max(image.shape[0], _LEGEND_ROW_PX * len(present) + 4)
    canvas = np.full((height, image.shape[1] + width, 3), 255, dtype=np.uint8)
    canvas[: image.shape[0], : image.shape[1]] = image
    left = image.shape[1]
    for i, code in enumerate(present):
        top = 2 + i * _LEGEND_ROW_PX
        colour = tuple(int(v) for v in colour_of[code])
        cv2.rectangle(canvas, (left + 4, top + 2), (left + 16, top + 14), colour, thickness=-1)
        cv2.putText(canvas, class_names[code], (left + 22, top + 13), cv2.FONT_HERSHEY_SIMPLEX, _LEGEND_FONT_SCALE,
                    (0, 0, 0), 1, cv2.LINE_AA)
    return canvas


def palette(n: int, colours: object) -> npt.NDArray[np.uint8]:
    """The (n, 3) uint8 RGB colour of each of ``n`` label codes: ``colours`` (a layer's ``meta["colours"]``), or
    white for 0 and :data:`DEFAULT_LABEL_COLOURS` for the rest when it is None."""
    if colours is None:
        default = [(255, 255, 255)] + [DEFAULT_LABEL_COLOURS[i % len(DEFAULT_LABEL_COLOURS)] for i in range(n - 1)]
        return np.array(default[:n], dtype=np.uint8).reshape(n, 3)
    table = np.asarray(colours, dtype=object)
    if table.shape != (n, 3) or not all(isinstance(v, int) and 0 <= v <= 255 for v in table.ravel()):
        raise RenderError(f"meta['colours'] must give [r, g, b] (0..255) for each of the {n} classes")
    return table.astype(np.uint8)


def encode_png(image: npt.NDArray[np.uint8]) -> bytes:
    """PNG file bytes of a greyscale (rows, cols), RGB (rows, cols, 3) or RGBA (rows, cols, 4) uint8 image."""
    bgr: npt.NDArray[Any] = image
    if image.ndim == 3:
        bgr = cv2.cvtColor(image, cv2.COLOR_RGBA2BGRA if image.shape[2] == 4 else cv2.COLOR_RGB2BGR)
    ok, buffer = cv2.imencode(".png", bgr)
    if not ok:
        raise RenderError(f"PNG encoding failed for an image of shape {image.shape}")
    return bytes(buffer.tobytes())


def encode_npy(data: npt.NDArray[Any]) -> bytes:
    """``.npy`` file bytes of a layer's values (no pickled objects)."""
    buffer = io.BytesIO()
    np.save(buffer, data, allow_pickle=False)
    return buffer.getvalue()

"""Grid layers as transparent overlays for a map viewer: RGBA, north up, one pixel a cell, no legend."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import numpy.typing as npt

from atlas.render.layers import LABEL_ENCODINGS, RenderError, layer_image, palette

OVERLAY_ALPHA = 200
"""Opacity (0..255) of labelled cells whose labels are certain (and of every drawn cell of other layers)."""


def overlay_image(data: npt.NDArray[Any], meta: Mapping[str, Any], *,
                  certainty: npt.NDArray[np.floating[Any]] | None = None) -> npt.NDArray[np.uint8]:
    """An RGBA image of a layer to lay over others: what carries no information is transparent.

    Parameters
    ----------
    data : (rows, cols) array
        Layer values, row 0 the lowest y.
    meta : mapping
        The layer's meta. Label layers (``encoding`` in :data:`atlas.render.layers.LABEL_ENCODINGS`) are drawn in
        their classes' colours with code 0 transparent; occupancy (int8) as map_saver greys with unknown cells
        transparent; other layers as min-max greys.
    certainty : (rows, cols) float array, optional
        How sure each cell's label is, 0..1 (e.g. 1 - normalised entropy); it scales the opacity, and cells
        outside 0..1 (no data) are transparent.

    Returns
    -------
    (rows, cols, 4) uint8 array
        RGBA, row 0 the highest y.

    Examples
    --------
    >>> overlay_image(np.array([[-1, 0]], np.int8), {"encoding": "occupancy"})[0, :, 3].tolist()
    [0, 200]
    """
    if data.ndim != 2:
        raise RenderError(f"only 2-D layers can be rendered, not shape {data.shape}")
    if certainty is not None and certainty.shape != data.shape:
        raise RenderError(f"the certainty layer's shape {certainty.shape} differs from the layer's {data.shape}")
    rgba = np.zeros((*data.shape, 4), dtype=np.uint8)
    if meta.get("encoding") in LABEL_ENCODINGS:
        names = meta.get("classes")
        if not isinstance(names, list) or data.dtype.kind not in "iu" or data.min() < 0 or data.max() >= len(names):
            raise RenderError("a label layer needs integer codes named by meta['classes']")
        rgba[..., :3] = palette(len(names), meta.get("colours"))[data.astype(np.intp)]
        rgba[..., 3] = np.where(data > 0, OVERLAY_ALPHA, 0)
    else:
        grey = layer_image(data)[::-1]
        rgba[..., :3] = grey[..., None]
        rgba[..., 3] = OVERLAY_ALPHA
        if data.dtype == np.int8:
            rgba[..., 3] = np.where((data >= 0) & (data <= 100), OVERLAY_ALPHA, 0)
    if certainty is not None:
        known = np.isfinite(certainty) & (certainty >= 0) & (certainty <= 1)
        scale = np.where(known, np.nan_to_num(certainty), 0.0)
        rgba[..., 3] = np.round(rgba[..., 3] * scale).astype(np.uint8)
    return np.ascontiguousarray(rgba[::-1])

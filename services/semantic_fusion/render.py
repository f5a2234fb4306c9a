"""Label layers as colour images with a legend, for the API to serve as PNG."""

from __future__ import annotations

import cv2
import numpy as np
import numpy.typing as npt

from services.semantic_fusion.classes import CLASS_COLOURS
from services.semantic_fusion.errors import SemanticFusionError
from shared.vocabulary import SemanticClass

_ROW_PX = 18
_LEGEND_WIDTH_PX = 110


def render_labels(labels: npt.ArrayLike, *, scale: int = 1, legend: bool = True) -> npt.NDArray[np.uint8]:
    """An RGB image (H', W', 3) uint8 of a label layer, north (highest row) up.

    Parameters
    ----------
    labels : (H, W) array_like of uint8
        :class:`SemanticClass` codes, GridLayer order (row 0 = lowest y).
    scale : int
        Pixels per cell edge (nearest-neighbour enlargement).
    legend : bool
        Append a legend column naming the class of each colour present in ``labels``.

    Raises
    ------
    SemanticFusionError
        Not a 2-D integer array, codes outside :class:`SemanticClass`, or ``scale < 1``.
    """
    grid = np.asarray(labels)
    if grid.ndim != 2 or 0 in grid.shape or not np.issubdtype(grid.dtype, np.integer):
        raise SemanticFusionError(f"labels must be a non-empty 2-D integer array, got {grid.dtype} {grid.shape}")
    if grid.min() < 0 or grid.max() > max(SemanticClass):
        raise SemanticFusionError(f"label codes must be in 0..{int(max(SemanticClass))}")
    if scale < 1:
        raise SemanticFusionError(f"scale must be >= 1, got {scale}")
    palette = np.array([CLASS_COLOURS[c] for c in SemanticClass], dtype=np.uint8)
    image = palette[grid[::-1]]
    if scale > 1:
        image = np.repeat(np.repeat(image, scale, axis=0), scale, axis=1)
    if not legend:
        return np.ascontiguousarray(image)
    present = [c for c in SemanticClass if c is not SemanticClass.NONE and np.any(grid == c)]
    height = max(image.shape[0], _ROW_PX * len(present) + 4)
    panel = np.full((height, _LEGEND_WIDTH_PX, 3), 255, dtype=np.uint8)
    for i, cls in enumerate(present):
        top = 2 + i * _ROW_PX
        cv2.rectangle(panel, (4, top + 2), (16, top + 14), CLASS_COLOURS[cls], thickness=-1)
        cv2.putText(panel, cls.name.lower(), (22, top + 13), cv2.FONT_HERSHEY_SIMPLEX, 0.42, (0, 0, 0), 1,
                    cv2.LINE_AA)
    canvas = np.full((height, image.shape[1], 3), 255, dtype=np.uint8)
    canvas[: image.shape[0]] = image
    return np.concatenate([canvas, panel], axis=1)

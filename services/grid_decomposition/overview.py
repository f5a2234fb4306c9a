"""A picture of a decomposition a person can check at a glance."""

from __future__ import annotations

import cv2
import numpy as np
import numpy.typing as npt

from services.grid_decomposition.pipeline import Decomposition
from services.grid_decomposition.semantics import Label

LABEL_COLOURS: dict[Label, tuple[int, int, int]] = {
    Label.NONE: (40, 40, 40),
    Label.CORRIDOR: (120, 200, 120),
    Label.JUNCTION: (70, 110, 230),
    Label.STORAGE: (240, 170, 60),
    Label.ROOM: (190, 160, 230),
    Label.OPEN_AREA: (150, 220, 230),
    Label.UNIDENTIFIED: (200, 200, 200),
}


def overview_image(decomposition: Decomposition, *, max_side_px: int = 2000) -> npt.NDArray[np.uint8]:
    """RGB image (top row = highest y): label colours, region borders, walls in red, lines faint.

    Returns
    -------
    (H', W', 3) uint8
        At most ``max_side_px`` on its longer side.
    """
    lut = np.zeros((256, 3), dtype=np.uint8)
    for label, colour in LABEL_COLOURS.items():
        lut[label.value] = colour
    rgb = lut[decomposition.labels].copy()
    seg = decomposition.segments
    border = np.zeros(seg.shape, dtype=bool)
    border[:, 1:] |= seg[:, 1:] != seg[:, :-1]
    border[1:, :] |= seg[1:, :] != seg[:-1, :]
    border &= seg > 0
    rgb[decomposition.subdivision.line_image & (decomposition.labels > 0)] //= 2
    rgb[border] = (20, 20, 20)
    sub, cog = decomposition.subdivision, decomposition.cogency
    wall_px = np.zeros(seg.size, dtype=bool)
    for e in np.flatnonzero(cog.cogent):
        wall_px[sub.edge_pixels[sub.edge_starts[e] : sub.edge_starts[e + 1]]] = True
    rgb.reshape(-1, 3)[wall_px] = (230, 30, 30)
    image = np.ascontiguousarray(rgb[::-1])
    h, w = image.shape[:2]
    scale = min(1.0, max_side_px / max(h, w))
    if scale < 1.0:
        size = (max(1, round(w * scale)), max(1, round(h * scale)))
        image = np.asarray(cv2.resize(image, size, interpolation=cv2.INTER_AREA), dtype=np.uint8)
    return image

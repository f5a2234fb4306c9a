"""Pixel boxes of an image: overlap and padded crops (the labeller's ROIs and the training crops alike)."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

ROI_PAD_FRACTION = 0.1
"""Crops (training boxes and the labeller's ROIs alike) get this share of their size as margin on each side."""


def box_iou(a: npt.NDArray[np.int64], b: npt.NDArray[np.int64]) -> npt.NDArray[np.float64]:
    """Intersection over union (n, m) of inclusive pixel boxes a (n, 4) and b (m, 4), (row0, col0, row1, col1)."""
    a, b = a.reshape(-1, 4)[:, None, :], b.reshape(-1, 4)[None, :, :]
    rows = np.clip(np.minimum(a[..., 2], b[..., 2]) - np.maximum(a[..., 0], b[..., 0]) + 1, 0, None)
    cols = np.clip(np.minimum(a[..., 3], b[..., 3]) - np.maximum(a[..., 1], b[..., 1]) + 1, 0, None)
    inter = rows * cols

    def area(box: npt.NDArray[np.int64]) -> npt.NDArray[np.int64]:
        return (box[..., 2] - box[..., 0] + 1) * (box[..., 3] - box[..., 1] + 1)

    return np.asarray(inter / (area(a) + area(b) - inter), dtype=np.float64)


def crop_box(image: npt.NDArray[np.uint8], box: tuple[int, int, int, int], *, pad_fraction: float
             ) -> npt.NDArray[np.uint8]:
    """The inclusive pixel box (row0, col0, row1, col1) of ``image``, padded by ``pad_fraction`` of its size."""
    r0, c0, r1, c1 = box
    pr, pc = int(pad_fraction * (r1 - r0 + 1)), int(pad_fraction * (c1 - c0 + 1))
    height, width = image.shape[:2]
    return image[max(r0 - pr, 0) : min(r1 + pr + 1, height), max(c0 - pc, 0) : min(c1 + pc + 1, width)]

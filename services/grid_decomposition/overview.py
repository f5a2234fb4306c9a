"""A picture of a decomposition a person can check at a glance: places in colour, walls, doors, a legend."""

from __future__ import annotations

import math

import cv2
import numpy as np
import numpy.typing as npt

from services.grid_decomposition.pipeline import Decomposition
from shared.vocabulary import PlaceLabel

LABEL_COLOURS: dict[PlaceLabel, tuple[int, int, int]] = {
    PlaceLabel.NONE: (40, 40, 40),
    PlaceLabel.CORRIDOR: (120, 200, 120),
    PlaceLabel.JUNCTION: (70, 110, 230),
    PlaceLabel.STORAGE: (240, 170, 60),
    PlaceLabel.ROOM: (190, 160, 230),
    PlaceLabel.OPEN_AREA: (150, 220, 230),
    PlaceLabel.UNIDENTIFIED: (200, 200, 200),
}
WALL_COLOUR = (230, 30, 30)
RACK_COLOUR = (150, 80, 10)
DOOR_COLOUR = (230, 0, 230)
BORDER_COLOUR = (20, 20, 20)
_FONT = cv2.FONT_HERSHEY_SIMPLEX
_ROW_PX = 26


def overview_image(
    decomposition: Decomposition, *, max_side_px: int = 2000, min_side_px: int = 1000, margin_m: float | None = 2.0
) -> npt.NDArray[np.uint8]:
    """RGB image (top row = highest y): label colours, region borders, walls, doors, rack rows, lines, legend.

    Walls are red, doors magenta, rack rows (:func:`~services.grid_decomposition.racks.find_racks`) brown
    outlines, decomposition lines faint.

    The map is scaled to at most ``max_side_px`` on its longer side (small maps are enlarged by an
    integer factor, nearest neighbour, to about ``min_side_px``); the legend to its right names every
    colour with its share of the free space, the line styles, the region count and a scale bar.
    The picture shows the labelled part of the map and ``margin_m`` around it (a robot's map is
    often a small building in a large unknown canvas); ``None`` shows the whole map.

    Returns
    -------
    (H', W', 3) uint8
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
    rgb[border] = BORDER_COLOUR
    sub, cog = decomposition.subdivision, decomposition.cogency
    edge_of_pixel = np.repeat(np.arange(sub.n_edges), np.diff(sub.edge_starts))
    flat = rgb.reshape(-1, 3)
    flat[sub.edge_pixels[cog.cogent[edge_of_pixel]]] = WALL_COLOUR
    flat[sub.edge_pixels[cog.door[edge_of_pixel]]] = DOOR_COLOUR
    racks = [np.round(r).astype(np.int32) for r in decomposition.rack_rows_px]
    if racks:
        cv2.polylines(rgb, racks, True, RACK_COLOUR, 2, cv2.LINE_8)
    image = np.ascontiguousarray(rgb[::-1])
    labelled = decomposition.labels[::-1] > 0
    if margin_m is not None and labelled.any():
        pad = max(0, round(margin_m / decomposition.resolution_m))
        rows, cols = np.flatnonzero(labelled.any(axis=1)), np.flatnonzero(labelled.any(axis=0))
        image = np.ascontiguousarray(
            image[max(0, rows[0] - pad) : rows[-1] + pad + 1, max(0, cols[0] - pad) : cols[-1] + pad + 1]
        )
    h, w = image.shape[:2]
    scale = min(1.0, max_side_px / max(h, w))
    if scale < 1.0:
        size = (max(1, round(w * scale)), max(1, round(h * scale)))
        image = np.asarray(cv2.resize(image, size, interpolation=cv2.INTER_AREA), dtype=np.uint8)
    elif max(h, w) < min_side_px:
        scale = float(math.ceil(min_side_px / max(h, w)))
        image = np.repeat(np.repeat(image, int(scale), axis=0), int(scale), axis=1)
    return _with_legend(image, decomposition, metres_per_px=decomposition.resolution_m / scale)


def _with_legend(
    image: npt.NDArray[np.uint8], decomposition: Decomposition, *, metres_per_px: float
) -> npt.NDArray[np.uint8]:
    """``image`` with a white legend panel on its right."""
    labels = decomposition.labels
    free = labels > 0
    share = np.bincount(labels[free], minlength=len(PlaceLabel)) / max(int(free.sum()), 1)
    rows: list[tuple[str, tuple[int, int, int], str]] = []
    for label in PlaceLabel:
        if label is not PlaceLabel.NONE and share[label.value] > 0:
            name = label.name.lower().replace("_", " ")
            rows.append(("box", LABEL_COLOURS[label], f"{name} {100 * share[label]:.1f} % of free space"))
    rows.append(("box", LABEL_COLOURS[PlaceLabel.NONE], "occupied / unknown"))
    rows.append(("line", WALL_COLOUR, "wall (cogent edge)"))
    rows.append(("line", DOOR_COLOUR, "door (closed doorway)"))
    rows.append(("line", BORDER_COLOUR, "region border"))
    if len(decomposition.rack_rows_px):
        rows.append(("line", RACK_COLOUR, f"rack row ({len(decomposition.rack_rows_px)})"))
    title = f"{len(decomposition.regions)} regions, {decomposition.subdivision.n_faces} cells"
    width = 20 + max(cv2.getTextSize(t, _FONT, 0.5, 1)[0][0] for t in [title] + [r[2] for r in rows]) + 40
    height = max(image.shape[0], _ROW_PX * (len(rows) + 4))
    panel = np.full((height, width, 3), 255, dtype=np.uint8)
    y = _ROW_PX
    cv2.putText(panel, title, (10, y), _FONT, 0.5, (0, 0, 0), 1, cv2.LINE_AA)
    for kind, colour, text in rows:
        y += _ROW_PX
        if kind == "box":
            cv2.rectangle(panel, (10, y - 13), (34, y + 3), colour, -1)
            cv2.rectangle(panel, (10, y - 13), (34, y + 3), (0, 0, 0), 1)
        else:
            cv2.line(panel, (10, y - 5), (34, y - 5), colour, 3)
        cv2.putText(panel, text, (42, y), _FONT, 0.5, (0, 0, 0), 1, cv2.LINE_AA)
    bar_m = _round_length((width - 80) * metres_per_px)
    bar_px = max(1, round(bar_m / metres_per_px))
    y += 2 * _ROW_PX
    cv2.line(panel, (10, y), (10 + bar_px, y), (0, 0, 0), 2)
    cv2.putText(panel, f"{bar_m:g} m", (16 + bar_px, y + 5), _FONT, 0.5, (0, 0, 0), 1, cv2.LINE_AA)
    canvas = np.full((height, image.shape[1], 3), 255, dtype=np.uint8)
    canvas[: image.shape[0]] = image
    return np.ascontiguousarray(np.concatenate([canvas, panel], axis=1))


def _round_length(metres: float) -> float:
    """The largest 1, 2 or 5 x 10^k not above ``metres`` (at least 0.1 m)."""
    if metres < 0.1:
        return 0.1
    power = 10.0 ** math.floor(math.log10(metres))
    return max(step * power for step in (1.0, 2.0, 5.0) if step * power <= metres)

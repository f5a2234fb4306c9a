"""Reading grid layers at map points, with decoded layers cached per layer version."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import cv2
import numpy as np

from atlas.cache import RevisionCache
from shared.store import GridLayer, MapStore
from shared.vocabulary import PlaceLabel

DRIVABLE_PLACES = frozenset(label.name.lower() for label in (PlaceLabel.CORRIDOR, PlaceLabel.JUNCTION, PlaceLabel.ROOM,
                                                             PlaceLabel.OPEN_AREA))
"""Place labels (grid decomposition) a vehicle drives in."""


def cached_layer(store: MapStore, cache: RevisionCache, map_id: int, name: str, revision: int | None
                 ) -> GridLayer | None:
    """Layer ``name`` as of ``revision`` (default: newest), decoded once per stored version."""
    version = store.layer_revision(map_id, name, revision=revision)
    if version is None:
        return None

    def load() -> GridLayer | None:
        stored = store.layer(map_id, name, revision=version)
        return None if stored is None else stored.layer

    return cache.get(("layer", store.url, map_id, name, version), load)


def cell_of(layer: GridLayer, x_m: float, y_m: float) -> tuple[int, int] | None:
    """(row, col) of the cell holding map point (x, y), or None outside the layer."""
    col = math.floor((x_m - layer.origin_x_m) / layer.resolution_m)
    row = math.floor((y_m - layer.origin_y_m) / layer.resolution_m)
    rows, cols = layer.data.shape
    return (row, col) if 0 <= row < rows and 0 <= col < cols else None


def value_at(layer: GridLayer, x_m: float, y_m: float) -> Any:
    """The layer's value at (x, y) as a Python number, or None outside it."""
    cell = cell_of(layer, x_m, y_m)
    return None if cell is None else layer.data[cell].item()


def region_holding(segments: GridLayer, labels: GridLayer, ring: Sequence[tuple[float, float]]
                   ) -> tuple[int, str] | None:
    """(id, label) of the region holding most cells whose centres lie in polygon ``ring`` (map metres); None
    where no region does (or the layers are not on one grid)."""
    if segments.data.shape != labels.data.shape or len(ring) < 3:
        return None
    res, origin = segments.resolution_m, np.array([segments.origin_x_m, segments.origin_y_m])
    corners = (np.asarray(ring, dtype=np.float64) - origin) / res - 0.5  # in cell-centre units
    rows, cols = segments.data.shape
    c0, r0 = np.maximum(np.floor(corners.min(axis=0)).astype(int), 0)
    c1, r1 = np.minimum(np.ceil(corners.max(axis=0)).astype(int) + 1, (cols, rows))
    if r0 >= r1 or c0 >= c1:
        return None
    inside = np.zeros((r1 - r0, c1 - c0), dtype=np.uint8)
    shift = 4
    cv2.fillPoly(inside, [np.round((corners - (c0, r0)) * (1 << shift)).astype(np.int32)], 1, cv2.LINE_8, shift)
    ids = segments.data[r0:r1, c0:c1][inside > 0]
    ids = ids[ids > 0]
    if ids.size == 0:
        return None
    values, counts = np.unique(ids, return_counts=True)
    best = int(values[counts.argmax()])
    codes = labels.data[r0:r1, c0:c1][segments.data[r0:r1, c0:c1] == best].astype(np.int64)
    codes = codes[codes > 0]  # a region's furniture and a rack's pallets carry no label
    return best, (class_name(labels, int(np.bincount(codes).argmax())) if codes.size else None) or "unknown"


def class_name(layer: GridLayer, code: int) -> str | None:
    """Name of label code ``code`` from the layer's ``meta["classes"]``, if it has one."""
    classes = layer.meta.get("classes")
    if isinstance(classes, list) and 0 <= code < len(classes):
        name = classes[code]
        return name if isinstance(name, str) else None
    return None


def nearest_drivable_region(segments: GridLayer, labels: GridLayer, x_m: float, y_m: float, *,
                            radius_m: float = 1.0) -> tuple[int, str] | None:
    """(id, label) of the drivable region (corridor, junction, room, open area) at or nearest (x, y) within
    ``radius_m``; None if there is none. Needs the segment and label layers on the same grid."""
    if segments.data.shape != labels.data.shape:
        return None
    drivable_codes = [code for code in range(256) if class_name(labels, code) in DRIVABLE_PLACES]
    res = segments.resolution_m
    cx = (x_m - segments.origin_x_m) / res
    cy = (y_m - segments.origin_y_m) / res
    r = max(1, math.ceil(radius_m / res))
    rows, cols = segments.data.shape
    r0, r1 = max(0, math.floor(cy) - r), min(rows, math.floor(cy) + r + 1)
    c0, c1 = max(0, math.floor(cx) - r), min(cols, math.floor(cx) + r + 1)
    if r0 >= r1 or c0 >= c1:
        return None
    window = segments.data[r0:r1, c0:c1]
    ok = np.isin(labels.data[r0:r1, c0:c1], drivable_codes) & (window > 0)
    if not ok.any():
        return None
    rr, cc = np.nonzero(ok)
    distance = np.hypot(rr + r0 + 0.5 - cy, cc + c0 + 0.5 - cx)
    best = int(np.argmin(distance))
    if distance[best] > radius_m / res:
        return None
    code = int(labels.data[rr[best] + r0, cc[best] + c0])
    return int(window[rr[best], cc[best]]), class_name(labels, code) or "unknown"

"""What a bin answer needs beyond the bin itself, built once per revision of a map: the WMS matching, the
junctions, and the place layers that tell which corridor an access pose is in."""

from __future__ import annotations

import itertools
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt

from api.cache import RevisionCache
from api.gridlookup import cached_layer, nearest_drivable_region
from api.reconcile import DetectedBin, Reconciliation, reconcile
from shared.store import GridLayer, MapStore, StoredFeature
from shared.store.records import bounds

BIN_KIND = "bin"
WMS_STAGE = "wms"
"""Stage name of the revisions that import the WMS's bin list."""
DEFAULT_TOLERANCE_M = 0.5
PLACE_LABELS_LAYER = "place_labels"
PLACE_SEGMENTS_LAYER = "place_segments"


@dataclass(frozen=True, slots=True)
class WmsMatching:
    reconciliation: Reconciliation
    tolerance_m: float
    revision_id: int
    """The revision that imported the WMS list."""

    def wms_of(self, detected_id: str) -> str | None:
        match = self.reconciliation.by_detected().get(detected_id)
        return None if match is None else match.wms_id

    def detected_of(self, wms_id: str) -> str | None:
        match = self.reconciliation.by_wms().get(wms_id)
        return None if match is None else match.detected_id


@dataclass(frozen=True, slots=True)
class CorridorShape:
    key: str
    aisle: int | None
    rings: list[npt.NDArray[np.float32]]
    """Outer rings (N, 1, 2) in map metres, as cv2.pointPolygonTest takes them; holes are ignored."""

    def holds(self, x_m: float, y_m: float) -> bool:
        return any(cv2.pointPolygonTest(ring, (x_m, y_m), False) >= 0 for ring in self.rings)


def _outer_rings(geometry: Mapping[str, Any]) -> list[npt.NDArray[np.float32]]:
    polygons = {"Polygon": [geometry.get("coordinates")], "MultiPolygon": geometry.get("coordinates")}.get(
        str(geometry.get("type")), [])
    return [np.asarray(polygon[0], dtype=np.float32).reshape(-1, 1, 2) for polygon in polygons or [] if polygon]


@dataclass(frozen=True, slots=True)
class BinIndex:
    matching: WmsMatching | None
    junction_keys: list[str]
    junction_xy: npt.NDArray[np.float64]
    corridors: list[CorridorShape]
    labels: GridLayer | None
    segments: GridLayer | None

    def corridor_at(self, x_m: float, y_m: float, *, aisle: int | None = None) -> str | None:
        """Key of the corridor feature holding (x, y): the aisle's own (pillar mapping) when ``aisle`` is given
        and one holds the point, else any."""
        holding = [c for c in self.corridors if c.holds(x_m, y_m)]
        own = [c for c in holding if aisle is not None and c.aisle == aisle]
        chosen = own or holding
        return chosen[0].key if chosen else None

    def nearest_junction(self, x_m: float, y_m: float) -> tuple[str, float] | None:
        if not self.junction_keys:
            return None
        distance = np.hypot(self.junction_xy[:, 0] - x_m, self.junction_xy[:, 1] - y_m)
        best = int(np.argmin(distance))
        return self.junction_keys[best], float(distance[best])

    def place_at(self, x_m: float, y_m: float) -> tuple[str, str] | None:
        """(region key, label) of the drivable place at or within a metre of (x, y)."""
        if self.labels is None or self.segments is None:
            return None
        found = nearest_drivable_region(self.segments, self.labels, x_m, y_m)
        return None if found is None else (f"r{found[0]}", found[1])


def detected_bin(stored: StoredFeature) -> DetectedBin:
    properties = stored.feature.properties
    centre = properties.get("centre")
    if isinstance(centre, list | tuple) and len(centre) == 2 and all(isinstance(v, int | float) for v in centre):
        x, y = float(centre[0]), float(centre[1])
    else:
        min_x, min_y, max_x, max_y = bounds(stored.feature.geometry)
        x, y = (min_x + max_x) / 2, (min_y + max_y) / 2
    level = properties.get("level")
    return DetectedBin(stored.feature.key, x, y, level if isinstance(level, int) else None)


def wms_matching(store: MapStore, map_id: int, revision: int | None) -> WmsMatching | None:
    """The WMS list live at ``revision`` matched to the bins live then, or None if no list was imported."""
    imported = store.latest_revision(map_id, stage=WMS_STAGE, at_or_before=revision)
    if imported is None:
        return None
    tolerance = imported.summary.get("tolerance_m", DEFAULT_TOLERANCE_M)
    tolerance_m = float(tolerance) if isinstance(tolerance, int | float) and tolerance > 0 else DEFAULT_TOLERANCE_M
    detected = [detected_bin(item) for item in store.features(map_id, kinds=[BIN_KIND], revision=revision)]
    result = reconcile(store.wms_bins(map_id, revision=revision), detected, tolerance_m=tolerance_m)
    return WmsMatching(result, tolerance_m, imported.id)


def bin_index(store: MapStore, cache: RevisionCache, map_id: int, revision: int | None) -> BinIndex:
    """The index as of ``revision`` (default: the newest), cached per revision."""
    at = revision
    if at is None:
        latest = store.latest_revision(map_id)
        at = 0 if latest is None else latest.id

    def build() -> BinIndex:
        junctions = store.features(map_id, kinds=["junction"], revision=at or None)
        xy = np.array([[(b[0] + b[2]) / 2, (b[1] + b[3]) / 2] for b in (bounds(j.feature.geometry) for j in junctions)],
                      dtype=float).reshape(-1, 2)
        corridors = [
            CorridorShape(c.feature.key, aisle if isinstance(aisle := c.feature.properties.get("aisle"), int) else None,
                          _outer_rings(c.feature.geometry))
            for c in store.features(map_id, kinds=["corridor"], revision=at or None)
        ]
        return BinIndex(
            matching=wms_matching(store, map_id, at or None),
            junction_keys=[j.feature.key for j in junctions],
            junction_xy=xy,
            corridors=corridors,
            labels=cached_layer(store, cache, map_id, PLACE_LABELS_LAYER, at or None),
            segments=cached_layer(store, cache, map_id, PLACE_SEGMENTS_LAYER, at or None),
        )

    return cache.get(("bins", store.url, map_id, at), build)


def corridors_along(corridors: list[CorridorShape], polyline: list[tuple[float, float]], *, step_m: float = 0.25
                    ) -> list[str]:
    """Keys of the corridors a polyline (map metres) runs through, in the order it enters them, each once.

    Where corridors overlap (an aisle crossing a cross aisle) both are listed, the one entered first first.
    """
    if not corridors or len(polyline) < 2:
        return []
    points = np.asarray(polyline, dtype=np.float64)
    samples = [points[0:1]]
    for a, b in itertools.pairwise(points):
        n = max(1, int(np.ceil(np.hypot(*(b - a)) / step_m)))
        samples.append(a + (b - a) * (np.arange(1, n + 1) / n)[:, None])
    path = np.vstack(samples)
    order: list[tuple[int, str]] = []
    for corridor in corridors:
        inside = [k for k, (x, y) in enumerate(path) if corridor.holds(float(x), float(y))]
        if inside:
            order.append((inside[0], corridor.key))
    return [key for _, key in sorted(order)]

"""Records the map store takes and gives: plain, typed, free of SQL."""

from __future__ import annotations

import datetime as dt
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Final

import numpy as np
import numpy.typing as npt

from shared.vocabulary import FeatureKind

FEATURE_KINDS: Final = frozenset(kind.value for kind in FeatureKind)
"""Every feature kind the store takes (the values of :class:`shared.vocabulary.FeatureKind`)."""


class StoreError(RuntimeError):
    """A store operation that cannot be done as asked (bad input or unreachable database)."""


@dataclass(frozen=True, slots=True)
class GridLayer:
    """A 2-D grid layer in the map frame.

    ``data[row, col]`` covers x = origin_x + (col + 0.5) * resolution, y = origin_y + (row + 0.5) *
    resolution: row 0 is the lowest y, as in nav_msgs/OccupancyGrid.
    """

    name: str
    data: npt.NDArray[Any]
    resolution_m: float
    origin_x_m: float
    origin_y_m: float
    meta: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.data.ndim != 2 or 0 in self.data.shape:
            raise StoreError(f"layer {self.name!r} must be a non-empty 2-D array, not shape {self.data.shape}")
        if not (np.isfinite(self.resolution_m) and self.resolution_m > 0):
            raise StoreError(f"layer {self.name!r}: resolution {self.resolution_m} must be positive")
        if not (np.isfinite(self.origin_x_m) and np.isfinite(self.origin_y_m)):
            raise StoreError(f"layer {self.name!r}: origin must be finite")


@dataclass(frozen=True, slots=True)
class Feature:
    """A typed map feature: GeoJSON geometry in map metres plus properties."""

    kind: str
    key: str
    geometry: Mapping[str, Any]
    properties: Mapping[str, Any] = field(default_factory=dict)
    confidence: float | None = None

    def __post_init__(self) -> None:
        if self.kind not in FEATURE_KINDS:
            raise StoreError(f"unknown feature kind {self.kind!r}; known: {sorted(FEATURE_KINDS)}")
        if "type" not in self.geometry or "coordinates" not in self.geometry:
            raise StoreError(f"feature {self.key!r}: geometry needs GeoJSON type and coordinates")
        coords = np.asarray(_flatten(self.geometry["coordinates"]), dtype=float)
        if coords.size == 0 or not np.all(np.isfinite(coords)):
            raise StoreError(f"feature {self.key!r}: coordinates must be finite and non-empty")


def _flatten(coordinates: Any) -> list[float]:
    if isinstance(coordinates, int | float):
        return [float(coordinates)]
    out: list[float] = []
    for item in coordinates:
        out.extend(_flatten(item))
    return out


def bounds(geometry: Mapping[str, Any]) -> tuple[float, float, float, float]:
    """(min_x, min_y, max_x, max_y) of a GeoJSON geometry."""
    xy = np.asarray(_flatten(geometry["coordinates"]), dtype=float).reshape(-1, 2)
    return float(xy[:, 0].min()), float(xy[:, 1].min()), float(xy[:, 0].max()), float(xy[:, 1].max())


@dataclass(frozen=True, slots=True)
class TopologyNode:
    key: str
    kind: str
    x_m: float | None = None
    y_m: float | None = None
    attributes: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True, slots=True)
class TopologyEdge:
    source: str
    target: str
    attributes: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True, slots=True)
class WmsBin:
    """A bin as the Warehouse Management System numbers it; position (map metres) and level when it knows them."""

    wms_id: str
    x_m: float | None = None
    y_m: float | None = None
    aisle: int | None = None
    bay: int | None = None
    level: int | None = None
    properties: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not self.wms_id or len(self.wms_id) > 128:
            raise StoreError(f"WMS bin id {self.wms_id!r} must be 1 to 128 characters")
        if (self.x_m is None) != (self.y_m is None):
            raise StoreError(f"WMS bin {self.wms_id!r}: give both x_m and y_m or neither")
        if self.x_m is not None and self.y_m is not None and not (np.isfinite(self.x_m) and np.isfinite(self.y_m)):
            raise StoreError(f"WMS bin {self.wms_id!r}: position must be finite")


@dataclass(frozen=True, slots=True)
class WmsStock:
    """Whether the Warehouse Management System says a bin holds stock, and what, by the bin's id (the WMS's own
    where a WMS bin list was imported, else Aisle's)."""

    bin_id: str
    holds_stock: bool
    sku: str | None = None
    quantity: float | None = None
    """How much the WMS books in the bin, in its own unit (pieces, cartons)."""

    def __post_init__(self) -> None:
        if not self.bin_id or len(self.bin_id) > 128:
            raise StoreError(f"WMS stock bin id {self.bin_id!r} must be 1 to 128 characters")
        if self.sku is not None and len(self.sku) > 128:
            raise StoreError(f"WMS stock of bin {self.bin_id!r}: an SKU must be at most 128 characters")
        if self.quantity is not None and not (np.isfinite(self.quantity) and self.quantity >= 0):
            raise StoreError(f"WMS stock of bin {self.bin_id!r}: quantity must be finite and >= 0")


@dataclass(frozen=True, slots=True)
class RevisionWrite:
    """Everything one stage writes at once; it lands whole or not at all.

    ``features`` maps each kind the stage now asserts to its complete list: the stage's
    previous features of those kinds are retired. For the kinds in ``partial`` the list holds only
    the features to add or replace (by key): the stage's other features of those kinds stay. ``topology``,
    when given, replaces the stage's graph.
    """

    stage: str
    layers: Sequence[GridLayer] = ()
    features: Mapping[str, Sequence[Feature]] = field(default_factory=dict)
    topology: tuple[Sequence[TopologyNode], Sequence[TopologyEdge]] | None = None
    input_start_ns: int | None = None
    input_end_ns: int | None = None
    summary: Mapping[str, Any] = field(default_factory=dict)
    partial: frozenset[str] = frozenset()

    def __post_init__(self) -> None:
        if not self.partial <= set(self.features):
            raise StoreError(f"partial kinds {sorted(self.partial - set(self.features))} have no features listed")
        for kind, items in self.features.items():
            if kind not in FEATURE_KINDS:
                raise StoreError(f"unknown feature kind {kind!r}")
            keys = [f.key for f in items]
            if any(f.kind != kind for f in items):
                raise StoreError(f"features listed under {kind!r} must all be of that kind")
            if len(set(keys)) != len(keys):
                raise StoreError(f"feature keys of kind {kind!r} must be unique within a revision")


@dataclass(frozen=True, slots=True)
class MapInfo:
    id: int
    name: str
    frame_id: str
    created_at: dt.datetime


@dataclass(frozen=True, slots=True)
class Revision:
    id: int
    map_id: int
    stage: str
    created_at: dt.datetime
    input_start_ns: int | None
    input_end_ns: int | None
    summary: Mapping[str, Any]
    pinned: bool = False
    """A client asked to keep it: compaction never thins it."""


@dataclass(frozen=True, slots=True)
class StoredFeature:
    id: int
    revision_id: int
    stage: str
    feature: Feature


@dataclass(frozen=True, slots=True)
class StoredLayer:
    revision_id: int
    layer: GridLayer


@dataclass(frozen=True, slots=True)
class WorkerInfo:
    name: str
    host: str
    pid: int
    started_at: dt.datetime
    heartbeat_at: dt.datetime
    counters: Mapping[str, int]

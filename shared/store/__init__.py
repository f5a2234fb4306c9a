"""The layered map store."""

from shared.store.records import (
    FEATURE_KINDS,
    Feature,
    GridLayer,
    MapInfo,
    Revision,
    RevisionWrite,
    StoredFeature,
    StoredLayer,
    StoreError,
    TopologyEdge,
    TopologyNode,
    WmsBin,
    WorkerInfo,
)
from shared.store.store import MapStore, StoreUnavailableError

__all__ = [
    "FEATURE_KINDS",
    "Feature",
    "GridLayer",
    "MapInfo",
    "MapStore",
    "Revision",
    "RevisionWrite",
    "StoreError",
    "StoreUnavailableError",
    "StoredFeature",
    "StoredLayer",
    "TopologyEdge",
    "TopologyNode",
    "WmsBin",
    "WorkerInfo",
]

"""The layered map store."""

from shared.store.compaction import CompactionReport
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
    WmsStock,
    WorkerInfo,
)
from shared.store.retention import RetentionPolicy
from shared.store.store import MapStore, StoreUnavailableError

__all__ = [
    "FEATURE_KINDS",
    "CompactionReport",
    "Feature",
    "GridLayer",
    "MapInfo",
    "MapStore",
    "RetentionPolicy",
    "Revision",
    "RevisionWrite",
    "StoreError",
    "StoreUnavailableError",
    "StoredFeature",
    "StoredLayer",
    "TopologyEdge",
    "TopologyNode",
    "WmsBin",
    "WmsStock",
    "WorkerInfo",
]

"""An in-memory index of each map's live features, so live GeoJSON area queries read no feature rows.

A map's index covers its newest revision. Each query first reads the newest revision id (one indexed row);
when revisions arrived since the index was built, their summaries say whether any of them wrote features:
if none did (occupancy, layers, topology), the index just moves on to the newest id; otherwise it is rebuilt
from the live rows, once, while other queries of that map wait for it. Features are kept as GeoJSON bytes
made from the JSON text stored; a rebuild encodes again only the features whose content changed (a stage
rewrites all its features in each revision, most of them as they were).

The newest revision id only grows, so an index never goes back in time; every feature write is a revision,
so an index that covers the newest revision is exactly what the store holds.
"""

from __future__ import annotations

import json
import threading
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from shared.store import MapStore
from shared.store.store import LiveFeatureRow

CATCH_UP_REVISIONS = 100
"""Revisions read to decide whether the features changed; after more than this many, the index is rebuilt."""


ADDED_PROPERTIES = ("kind", "key", "stage", "confidence", "revision_id")
"""Properties every GeoJSON feature gets from its row; they win over stored properties of the same names."""

Content = tuple[str, str, str, float | None, str, str]
"""What a feature's GeoJSON depends on besides its revision: kind, key, stage, confidence, geometry, properties."""


def _content(row: LiveFeatureRow) -> Content:
    return row.kind, row.key, row.stage, row.confidence, row.geometry_json, row.properties_json


def _head(row: LiveFeatureRow) -> bytes:
    """The feature's GeoJSON up to its revision id: ``{"type":"Feature",...,"properties":{...,"revision_id":``.

    The stored geometry text goes in as it is.
    """
    properties = {name: value for name, value in json.loads(row.properties_json).items()
                  if name not in ADDED_PROPERTIES}
    properties.update(kind=row.kind, key=row.key, stage=row.stage, confidence=row.confidence)
    encoded = json.dumps(properties, separators=(",", ":"))
    return (f'{{"type":"Feature","id":{json.dumps(f"{row.kind}/{row.key}")},"geometry":{row.geometry_json},'
            f'"properties":{encoded[:-1]},"revision_id":').encode()


def geojson_bytes(row: LiveFeatureRow, head: bytes | None = None) -> bytes:
    """One feature as the GeoJSON Feature the API returns (see :func:`api.routers.features.geojson_feature`).

    ``head`` is :func:`_head` of a row with the same content, if one is at hand.
    """
    return (head if head is not None else _head(row)) + str(row.revision_id).encode() + b"}}"


@dataclass(frozen=True, slots=True)
class FeatureIndex:
    """The live features of one map as of revision ``revision_id``, in id order (the order of the store)."""

    revision_id: int
    kinds: npt.NDArray[np.str_]
    """(n,) kind of each feature."""
    bounds: npt.NDArray[np.float64]
    """(n, 4) min_x, min_y, max_x, max_y of each feature, metres."""
    geojson: Sequence[bytes]
    """(n,) each feature's GeoJSON."""
    heads: Mapping[Content, bytes] = field(repr=False)
    """GeoJSON heads by content, for the next index to reuse (a stage rewrites mostly unchanged features)."""

    @classmethod
    def build(cls, revision_id: int, rows: Sequence[LiveFeatureRow], previous: FeatureIndex | None = None
              ) -> FeatureIndex:
        """The index of ``rows``, reusing the encoded features of ``previous`` where their content is the same."""
        known = {} if previous is None else previous.heads
        heads: dict[Content, bytes] = {}
        geojson = []
        for row in rows:
            content = _content(row)
            head = heads[content] = heads.get(content) or known.get(content) or _head(row)
            geojson.append(geojson_bytes(row, head))
        bounds = np.array([row.bounds for row in rows], dtype=np.float64).reshape(-1, 4)
        kinds = np.array([row.kind for row in rows], dtype=np.str_)
        return cls(revision_id, kinds, bounds, geojson, heads)

    def moved_to(self, revision_id: int) -> FeatureIndex:
        """The same features, covering the newer revision ``revision_id`` that wrote none."""
        return FeatureIndex(revision_id, self.kinds, self.bounds, self.geojson, self.heads)

    def select(self, *, kinds: Sequence[str] | None, bbox: tuple[float, float, float, float] | None
               ) -> npt.NDArray[np.intp]:
        """Positions of the features of ``kinds`` whose bounds touch ``bbox`` (as the store's query does)."""
        keep = np.ones(len(self.geojson), dtype=bool)
        if kinds:
            keep &= np.isin(self.kinds, list(kinds))
        if bbox is not None:
            min_x, min_y, max_x, max_y = bbox
            keep &= ((self.bounds[:, 2] >= min_x) & (self.bounds[:, 0] <= max_x)
                     & (self.bounds[:, 3] >= min_y) & (self.bounds[:, 1] <= max_y))
        return np.flatnonzero(keep)


@dataclass(slots=True)
class _MapState:
    index: FeatureIndex | None = None
    building: bool = False


class LiveFeatures:
    """The live feature index of every map this API process serves (thread-safe)."""

    def __init__(self) -> None:
        self._maps: dict[tuple[str, int], _MapState] = {}
        self._changed = threading.Condition()

    def index(self, store: MapStore, map_id: int) -> FeatureIndex | None:
        """The index covering the map's newest revision, or None while the map has no revisions.

        Blocks while another thread builds the index this one needs; builds it otherwise.
        """
        latest = store.latest_revision(map_id)
        if latest is None:
            return None
        with self._changed:
            state = self._maps.setdefault((store.url, map_id), _MapState())
            while True:
                current = state.index
                if current is not None and current.revision_id >= latest.id:
                    return current
                if not state.building:
                    state.building = True
                    break
                self._changed.wait()
        built: FeatureIndex | None = None
        try:
            built = self._catch_up(store, map_id, current, latest.id)
        finally:
            with self._changed:
                if built is not None and (state.index is None or built.revision_id > state.index.revision_id):
                    state.index = built
                state.building = False
                self._changed.notify_all()
        return built

    @staticmethod
    def _catch_up(store: MapStore, map_id: int, current: FeatureIndex | None, latest_id: int) -> FeatureIndex:
        if current is not None:
            since = store.revisions(map_id, after_id=current.revision_id, limit=CATCH_UP_REVISIONS)
            if len(since) < CATCH_UP_REVISIONS and not any(_writes_features(r.summary) for r in since):
                return current.moved_to(max([latest_id, *(r.id for r in since)]))
        newest = store.latest_revision(map_id)
        rows = store.live_feature_rows(map_id)
        return FeatureIndex.build(max(latest_id, 0 if newest is None else newest.id), rows, current)


def _writes_features(summary: Any) -> bool:
    """Whether a revision summary records features written (or retired); unknown summaries count as yes."""
    return not isinstance(summary, dict) or bool(summary.get("features", True))

"""Map features as GeoJSON, and an in-memory index of one map's live features, so live GeoJSON area queries and
bin lookups read no rows.

Features are kept as the GeoJSON bytes the API returns, made once per stored row from its JSON text, with
their bounds in numpy arrays for area queries. A new revision updates the index with just the rows it wrote
or retired (:meth:`FeatureIndex.updated`); a stage that rewrites all its features changes only the rows of
those that changed (see :meth:`shared.store.MapStore.write_revision`), so most rows are encoded only once.
:mod:`atlas.live` decides when to update it.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import numpy.typing as npt
from pydantic import BaseModel, ConfigDict, Field

from atlas.precision import json_bytes
from shared.store import Feature, StoredFeature
from shared.store.store import FeatureRow

BBox = tuple[float, float, float, float]
"""(min_x, min_y, max_x, max_y), map-frame metres."""

FEATURE_EXAMPLE: dict[str, Any] = {
    "type": "Feature", "id": "bin/03-014",
    "geometry": {"type": "Polygon",
                 "coordinates": [[[40.6, 17.1], [41.8, 17.1], [41.8, 18.1], [40.6, 18.1], [40.6, 17.1]]]},
    "properties": {"aisle": 3, "bay": 14, "row": "r0-006", "access_pose": [41.2, 15.6, 1.5708], "kind": "bin",
                   "key": "03-014", "stage": "pillar_mapping", "revision_id": 1207, "confidence": 0.92},
}
"""An example feature (OpenAPI docs)."""

ADDED_PROPERTIES = ("kind", "key", "stage", "confidence", "revision_id")
"""Properties every GeoJSON feature gets from its row; they win over stored properties of the same names."""


class GeoJSONFeature(BaseModel):
    type: Literal["Feature"] = "Feature"
    id: str = Field(description="`<kind>/<key>`.")
    geometry: dict[str, Any] = Field(description="GeoJSON geometry in map-frame metres.")
    properties: dict[str, Any] = Field(
        description="The feature's own properties plus kind, key, stage, revision_id and confidence (0..1). Lengths "
                    "and positions are metres in the map frame (`*_m`, `centre`, `x`, `y`, the first two values of "
                    "an `access_pose`), areas m² (`*_m2`), angles radians from the map frame's x axis (`*_rad`, "
                    "`theta`, the third value of an `access_pose`)."
    )

    model_config = ConfigDict(json_schema_extra={"examples": [FEATURE_EXAMPLE]})


def geojson_feature(stored: StoredFeature) -> GeoJSONFeature:
    """One stored feature as GeoJSON: its id ``<kind>/<key>``, its properties plus :data:`ADDED_PROPERTIES`."""
    feature = stored.feature
    return GeoJSONFeature(
        id=f"{feature.kind}/{feature.key}",
        geometry=dict(feature.geometry),
        properties={
            **feature.properties,
            "kind": feature.kind,
            "key": feature.key,
            "stage": stored.stage,
            "revision_id": stored.revision_id,
            "confidence": feature.confidence,
        },
    )


def live_collection(index: FeatureIndex, *, kinds: Sequence[str] | None, bbox: BBox | None, limit: int,
                    offset: int, next_cursor: Callable[[int], str]) -> bytes:
    """A page of the live map's FeatureCollection from its index as JSON (the same document as the store's at
    the index's revision).

    Features of ``kinds`` whose bounds touch ``bbox``, ``limit`` of them after skipping ``offset``;
    ``next_cursor(offset)`` is the cursor of the page that starts at ``offset`` at the index's revision.
    """
    page = index.select(kinds=kinds, bbox=bbox)[offset:offset + limit]
    next_offset = offset + len(page) if len(page) == limit else None
    cursor = None if next_offset is None else next_cursor(next_offset)
    return b"".join((b'{"type":"FeatureCollection","features":[', b",".join(index.geojson[p] for p in page),
                     f'],"revision":{index.revision_id},"limit":{limit},"offset":{offset},"next_offset":'
                     f'{json.dumps(next_offset)},"next_cursor":{json.dumps(cursor)}}}'.encode()))


def geojson_bytes(row: FeatureRow) -> bytes:
    """One feature as GeoJSON, the same document as :func:`geojson_feature` gives (rounded as
    :mod:`atlas.precision` says)."""
    properties = {name: value for name, value in json.loads(row.properties_json).items()
                  if name not in ADDED_PROPERTIES}
    properties.update(kind=row.kind, key=row.key, stage=row.stage, confidence=row.confidence,
                      revision_id=row.revision_id)
    return json_bytes({"type": "Feature", "id": f"{row.kind}/{row.key}", "geometry": json.loads(row.geometry_json),
                       "properties": properties})


def stored_feature(row: FeatureRow) -> StoredFeature:
    """The row as the store's :meth:`~shared.store.MapStore.feature` returns it, geometry and properties decoded."""
    return StoredFeature(row.id, row.revision_id, row.stage,
                         Feature(row.kind, row.key, json.loads(row.geometry_json), json.loads(row.properties_json),
                                 row.confidence))


@dataclass(frozen=True, slots=True)
class FeatureIndex:
    """The live features of one map as of revision ``revision_id``, in id order (the order of the store).

    Immutable: an update makes a new index, so a request holding one reads a consistent map.
    """

    revision_id: int
    rows: Sequence[FeatureRow]
    """(n,) the live rows, id order."""
    ids: npt.NDArray[np.int64]
    """(n,) row id of each feature."""
    kinds: npt.NDArray[np.str_]
    """(n,) kind of each feature."""
    bounds: npt.NDArray[np.float64]
    """(n, 4) min_x, min_y, max_x, max_y of each feature, metres."""
    geojson: Sequence[bytes]
    """(n,) each feature's GeoJSON."""
    newest: dict[tuple[str, str], FeatureRow]
    """The row of each (kind, key): the newest if several stages have one (as the store's ``feature`` picks)."""

    @classmethod
    def build(cls, revision_id: int, rows: Sequence[FeatureRow], previous: FeatureIndex | None = None
              ) -> FeatureIndex:
        """The index of ``rows``, the map's live rows as of ``revision_id`` (any order).

        Rows ``previous`` holds keep their encoded GeoJSON.
        """
        ordered = sorted(rows)
        known = {} if previous is None else dict(zip(previous.ids.tolist(), previous.geojson, strict=True))
        return cls._of(revision_id, ordered, [known.get(row.id) or geojson_bytes(row) for row in ordered])

    @classmethod
    def _of(cls, revision_id: int, rows: list[FeatureRow], geojson: list[bytes]) -> FeatureIndex:
        """The index of ``rows`` in id order with their GeoJSON."""
        newest: dict[tuple[str, str], FeatureRow] = {}
        for row in rows:
            known = newest.get((row.kind, row.key))
            if known is None or known.revision_id <= row.revision_id:
                newest[row.kind, row.key] = row
        return cls(revision_id, rows, np.array([row.id for row in rows], dtype=np.int64),
                   np.array([row.kind for row in rows], dtype=np.str_),
                   np.array([row.bounds for row in rows], dtype=np.float64).reshape(-1, 4), geojson, newest)

    def updated(self, revision_id: int, changed: Sequence[FeatureRow]) -> FeatureIndex:
        """The index as of the newer revision ``revision_id``, given the rows the revisions since wrote or retired.

        ``changed`` is :meth:`~shared.store.MapStore.feature_rows_changed` from ``self.revision_id`` to
        ``revision_id``. Rows retired by ``revision_id`` go; rows live then come in (once, even if the index
        has them already). Unchanged rows keep their encoded GeoJSON.
        """
        retired = {row.id for row in changed if row.retired_revision_id is not None
                   and row.retired_revision_id <= revision_id}
        ids = self.ids.tolist()
        known = set(ids)
        added = [row for row in changed if row.id not in retired and row.id not in known]
        keep = [position for position, row_id in enumerate(ids) if row_id not in retired]
        rows = [self.rows[p] for p in keep] + added
        geojson = [self.geojson[p] for p in keep] + [geojson_bytes(row) for row in added]
        if added and keep and added[0].id < rows[len(keep) - 1].id:  # rows written out of id order: re-sort
            order = sorted(range(len(rows)), key=lambda p: rows[p].id)
            rows, geojson = [rows[p] for p in order], [geojson[p] for p in order]
        return self._of(revision_id, rows, geojson)

    def moved_to(self, revision_id: int) -> FeatureIndex:
        """The same features, covering the newer revision ``revision_id`` that wrote none."""
        return FeatureIndex(revision_id, self.rows, self.ids, self.kinds, self.bounds, self.geojson, self.newest)

    def feature(self, kind: str, key: str) -> FeatureRow | None:
        """The live row of feature ``kind``/``key`` (the newest if several stages have one), or None."""
        return self.newest.get((kind, key))

    def select(self, *, kinds: Sequence[str] | None, bbox: BBox | None
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

"""What is at a point of the map, and the human label table that turns place categories into labels."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from atlas.cache import RevisionCache
from atlas.errors import InvalidQueryError
from atlas.grids import cached_layer, class_name, value_at
from shared.places import LABEL_OVERRIDES_KEY, LABEL_TABLE, LABEL_TABLE_STAGE, PlaceLabelError, parse_label_table
from shared.settings import Settings
from shared.store import MapInfo, MapStore, Revision, RevisionWrite, StoredFeature
from shared.vocabulary import REGION_KINDS, FeatureKind, PlaceLabel

NEAR_M = 0.25
"""Point and line features this close to a point count as at it, metres."""
MAX_NEAR_FEATURES = 500
"""Most features a point query looks at."""
_POINTLIKE = (FeatureKind.LINE, FeatureKind.PILLAR)
"""Kinds a point query leaves out."""


@dataclass(frozen=True, slots=True)
class SemanticAt:
    """The semantic grid's class at a point: its name, its code and the normalised entropy of the cell."""

    label: str | None
    code: int
    entropy: float | None
    layer_revision_id: int


@dataclass(frozen=True, slots=True)
class PlaceAt:
    """The region of the grid decomposition at a point and its place label."""

    region: str
    label: str
    layer_revision_id: int


@dataclass(frozen=True, slots=True)
class FeatureAtPoint:
    """A feature at a point: an area holding it, or a point or line within :data:`NEAR_M`."""

    kind: str
    key: str
    label: str | None
    """The feature's ``label``, ``id`` or ``name`` property, if any."""


@dataclass(frozen=True, slots=True)
class PointSemantics:
    """Everything at map point (x_m, y_m); parts with no layer, or outside it, are None."""

    x_m: float
    y_m: float
    occupancy: int | None
    semantic: SemanticAt | None
    place: PlaceAt | None
    features: list[FeatureAtPoint]


def _contains(stored: StoredFeature, x: float, y: float) -> bool:
    geometry = stored.feature.geometry
    kind, coords = geometry.get("type"), geometry.get("coordinates") or []
    if kind == "Polygon":
        ring = np.asarray(coords[0], dtype=np.float32).reshape(-1, 1, 2)
        return bool(cv2.pointPolygonTest(ring, (x, y), False) >= 0)
    if kind == "MultiPolygon":
        return any(cv2.pointPolygonTest(np.asarray(p[0], dtype=np.float32).reshape(-1, 1, 2), (x, y), False) >= 0
                   for p in coords)
    return True  # points and lines: the bbox query already kept those within NEAR_M


def _label(properties: Mapping[str, Any]) -> str | None:
    for name in ("label", "id", "name"):
        value = properties.get(name)
        if isinstance(value, str):
            return value
    return None


def semantics_at(store: MapStore, cache: RevisionCache, settings: Settings, map_info: MapInfo, *, x_m: float,
                 y_m: float, revision: int | None) -> PointSemantics:
    """Occupancy, semantic class and its entropy, place region and label, and the features at map point
    (``x_m``, ``y_m``) as of ``revision`` (default: now); layer names come from ``settings``."""
    x, y = x_m, y_m
    fusion, places_cfg = settings.fusion, settings.decomposition
    occupancy = cached_layer(store, cache, map_info.id, places_cfg.source_layer, revision)
    semantic = None
    labels = cached_layer(store, cache, map_info.id, fusion.label_layer, revision)
    if labels is not None and (code := value_at(labels, x, y)) is not None:
        entropy_layer = cached_layer(store, cache, map_info.id, fusion.entropy_layer, revision)
        entropy = None if entropy_layer is None else value_at(entropy_layer, x, y)
        no_data = None if entropy_layer is None else entropy_layer.meta.get("no_data")
        finite = isinstance(entropy, float) and np.isfinite(entropy) and entropy != no_data and entropy >= 0
        semantic = SemanticAt(label=class_name(labels, int(code)), code=int(code),
                              entropy=float(entropy) if finite and entropy is not None else None,
                              layer_revision_id=store.layer_revision(map_info.id, fusion.label_layer,
                                                                     revision=revision) or 0)
    place = None
    places = cached_layer(store, cache, map_info.id, places_cfg.label_layer, revision)
    segments = cached_layer(store, cache, map_info.id, places_cfg.segment_layer, revision)
    if places is not None and segments is not None:
        region, code = value_at(segments, x, y), value_at(places, x, y)
        if region and code is not None:
            place = PlaceAt(region=f"r{region}", label=class_name(places, int(code)) or str(code),
                            layer_revision_id=store.layer_revision(map_info.id, places_cfg.label_layer,
                                                                   revision=revision) or 0)
    near = store.features(map_info.id, bbox=(x - NEAR_M, y - NEAR_M, x + NEAR_M, y + NEAR_M), revision=revision,
                          limit=MAX_NEAR_FEATURES)
    found = [FeatureAtPoint(kind=f.feature.kind, key=f.feature.key, label=_label(f.feature.properties))
             for f in near if f.feature.kind not in _POINTLIKE and _contains(f, x, y)]
    return PointSemantics(x_m=x, y_m=y, occupancy=None if occupancy is None else value_at(occupancy, x, y),
                          semantic=semantic, place=place, features=found)


# -- the label table ---------------------------------------------------------------------------------

@dataclass(frozen=True, slots=True)
class LabelRow:
    """One label of the table: what places with it are for and the labels they may open onto."""

    label: str
    functionality: str
    connectable: list[str]


@dataclass(frozen=True, slots=True)
class CategoryRow:
    """A place category of the current decomposition, the label its regions carry and how much of them."""

    category: int
    label: str
    overridden: bool
    regions: int
    area_m2: float


@dataclass(frozen=True, slots=True)
class LabelTable:
    """The label table of a map: every label, the categories of its decomposition, and a person's overrides."""

    labels: list[LabelRow]
    categories: list[CategoryRow]
    overrides: dict[str, str]
    """A person's choices, category -> label."""
    overrides_revision_id: int | None
    """The revision that recorded them."""


def stored_overrides(store: MapStore, map_id: int, revision: int | None) -> tuple[dict[str, str], int | None]:
    """The label-table overrides live at ``revision`` and the revision that recorded them (None: none)."""
    found = store.latest_revision(map_id, stage=LABEL_TABLE_STAGE, at_or_before=revision)
    if found is None:
        return {}, None
    raw = found.summary.get(LABEL_OVERRIDES_KEY, {})
    return ({str(k): str(v) for k, v in raw.items()} if isinstance(raw, dict) else {}), found.id


def label_table(store: MapStore, map_info: MapInfo, *, revision: int | None) -> LabelTable:
    """Each label's functionality and connect-ability, each place category of the decomposition live at
    ``revision`` with its label (the one covering the most area of its regions), and the overrides."""
    overrides, overrides_revision = stored_overrides(store, map_info.id, revision)
    rows: dict[int, dict[str, Any]] = {}
    for stored in store.features(map_info.id, kinds=list(REGION_KINDS), revision=revision):
        props = stored.feature.properties
        category, label = props.get("category"), props.get("label")
        if not isinstance(category, int) or category < 0 or not isinstance(label, str):
            continue
        row = rows.setdefault(category, {"labels": {}, "regions": 0, "area_m2": 0.0})
        area = props.get("area_m2")
        area = float(area) if isinstance(area, int | float) else 0.0
        row["labels"][label] = row["labels"].get(label, 0.0) + area
        row["regions"] += 1
        row["area_m2"] += area
    categories = [
        CategoryRow(category=c, label=max(row["labels"], key=row["labels"].get), overridden=str(c) in overrides,
                    regions=row["regions"], area_m2=round(row["area_m2"], 2))
        for c, row in sorted(rows.items())
    ]
    labels = [LabelRow(label=label.name.lower(), functionality=semantics.functionality,
                       connectable=sorted(item.name.lower() for item in semantics.connectable))
              for label, semantics in LABEL_TABLE.items() if label is not PlaceLabel.NONE]
    return LabelTable(labels=labels, categories=categories, overrides=overrides,
                      overrides_revision_id=overrides_revision)


def write_overrides(store: MapStore, map_info: MapInfo, overrides: Mapping[str, str]
                    ) -> tuple[Revision, dict[str, str]]:
    """Record a person's label-table overrides (category -> label name) as a revision; the revision and the
    overrides as stored (label names normalised, categories in order).

    Raises
    ------
    InvalidQueryError
        A category that is not a non-negative integer, or a name that is no place label.
    """
    try:
        parsed = parse_label_table(overrides)
    except PlaceLabelError as err:
        raise InvalidQueryError(str(err)) from err
    stored = {str(c): label.name.lower() for c, label in sorted(parsed.items())}
    written = store.write_revision(map_info.id, RevisionWrite(LABEL_TABLE_STAGE, summary={LABEL_OVERRIDES_KEY: stored}))
    return written, stored

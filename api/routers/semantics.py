"""What is at a point, and the human label table that turns place categories into labels."""

from __future__ import annotations

from typing import Annotated, Any

import cv2
import numpy as np
from fastapi import APIRouter, Body, Depends, HTTPException, Query, status
from pydantic import BaseModel, Field

from api.cache import RevisionCache
from api.deps import AnnouncerDep, MapDep, RevisionQuery, SettingsDep, StoreDep, get_cache
from api.gridlookup import cached_layer, class_name, value_at
from api.models import COMMON_ERRORS, ErrorOut, Responses, example_config
from api.routers.features import MAX_BBOX_SIDE_M
from shared.places import LABEL_OVERRIDES_KEY, LABEL_TABLE, LABEL_TABLE_STAGE, PlaceLabelError, parse_label_table
from shared.store import RevisionWrite, StoredFeature
from shared.vocabulary import PlaceLabel

router = APIRouter(prefix="/v1/maps/{map_name}", tags=["semantics"], responses=COMMON_ERRORS)

REGION_KINDS = ("corridor", "junction", "room", "open_area", "region")

_ERRORS: Responses = {
    status.HTTP_404_NOT_FOUND: {"model": ErrorOut, "description": "No such map or revision."},
    status.HTTP_422_UNPROCESSABLE_CONTENT: {"model": ErrorOut, "description": "Bad coordinates or label table."},
}

CacheDep = Annotated[RevisionCache, Depends(get_cache)]


class SemanticLabelOut(BaseModel):
    label: str | None = Field(description="Class of the semantic grid (semantic fusion), e.g. `rack`; null where "
                                          "nothing was observed.")
    code: int
    entropy: float | None = Field(description="Normalised Shannon entropy of the cell's class distribution, 0 "
                                              "(certain) to 1; null where there is none.")
    layer_revision_id: int


class PlaceOut(BaseModel):
    region: str = Field(description="Key of the region feature and topology node, e.g. `r12`.")
    label: str = Field(description="Place label: corridor, junction, storage, room, open_area, unidentified.")
    layer_revision_id: int


class FeatureAt(BaseModel):
    kind: str
    key: str
    label: str | None = Field(description="The feature's `label` or `id` property, if any.")


class PointOut(BaseModel):
    x_m: float
    y_m: float
    occupancy: int | None = Field(description="Occupancy there: -1 unknown, 0 free .. 100 occupied; null outside.")
    semantic: SemanticLabelOut | None
    place: PlaceOut | None
    features: list[FeatureAt] = Field(description="Area features (bins, regions, docks...) whose polygon holds "
                                                  "the point, and point/line features within 0.25 m.")

    model_config = {"json_schema_extra": {"examples": [{
        "x_m": 12.4, "y_m": 7.9, "occupancy": 0,
        "semantic": {"label": "pallet", "code": 3, "entropy": 0.21, "layer_revision_id": 311},
        "place": {"region": "r12", "label": "corridor", "layer_revision_id": 305},
        "features": [{"kind": "corridor", "key": "r12", "label": "corridor"}]}]}}


_COORD = Query(ge=-MAX_BBOX_SIDE_M, le=MAX_BBOX_SIDE_M, description="Map-frame metres.", examples=[12.4])
NEAR_M = 0.25


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


@router.get("/semantics", summary="What is at a point", responses=_ERRORS)
def semantics_at(
    map_info: MapDep,
    store: StoreDep,
    settings: SettingsDep,
    cache: CacheDep,
    revision: RevisionQuery,
    x: Annotated[float, _COORD],
    y: Annotated[float, _COORD],
) -> PointOut:
    """Occupancy, semantic class and its entropy, place region and label, and the features at map point (x, y)
    (as of ``?revision=``). Parts with no layer yet, or outside it, are null."""
    fusion, places_cfg = settings.fusion, settings.decomposition
    occupancy = cached_layer(store, cache, map_info.id, places_cfg.source_layer, revision)
    semantic = None
    labels = cached_layer(store, cache, map_info.id, fusion.label_layer, revision)
    if labels is not None and (code := value_at(labels, x, y)) is not None:
        entropy_layer = cached_layer(store, cache, map_info.id, fusion.entropy_layer, revision)
        entropy = None if entropy_layer is None else value_at(entropy_layer, x, y)
        no_data = None if entropy_layer is None else entropy_layer.meta.get("no_data")
        finite = isinstance(entropy, float) and np.isfinite(entropy) and entropy != no_data and entropy >= 0
        semantic = SemanticLabelOut(label=class_name(labels, int(code)), code=int(code),
                                    entropy=float(entropy) if finite and entropy is not None else None,
                                    layer_revision_id=store.layer_revision(map_info.id, fusion.label_layer,
                                                                           revision=revision) or 0)
    place = None
    places = cached_layer(store, cache, map_info.id, places_cfg.label_layer, revision)
    segments = cached_layer(store, cache, map_info.id, places_cfg.segment_layer, revision)
    if places is not None and segments is not None:
        region, code = value_at(segments, x, y), value_at(places, x, y)
        if region and code is not None:
            place = PlaceOut(region=f"r{region}", label=class_name(places, int(code)) or str(code),
                             layer_revision_id=store.layer_revision(map_info.id, places_cfg.label_layer,
                                                                    revision=revision) or 0)
    near = store.features(map_info.id, bbox=(x - NEAR_M, y - NEAR_M, x + NEAR_M, y + NEAR_M), revision=revision,
                          limit=500)
    found = [FeatureAt(kind=f.feature.kind, key=f.feature.key,
                       label=_label(f.feature.properties))
             for f in near if f.feature.kind not in ("line", "pillar") and _contains(f, x, y)]
    return PointOut(x_m=x, y_m=y, occupancy=None if occupancy is None else value_at(occupancy, x, y),
                    semantic=semantic, place=place, features=found)


def _label(properties: Any) -> str | None:
    for name in ("label", "id", "name"):
        value = properties.get(name)
        if isinstance(value, str):
            return value
    return None


# -- the label table ---------------------------------------------------------------------------------

class LabelRow(BaseModel):
    label: str
    functionality: str = Field(description="What the place is for (paper C, Table II).")
    connectable: list[str] = Field(description="Labels a place with this label may open onto.")


class CategoryRow(BaseModel):
    category: int = Field(description="Place category found by unsupervised clustering of ray-cast features.")
    label: str = Field(description="The label its regions carry now.")
    overridden: bool = Field(description="Whether a person set this category's label.")
    regions: int
    area_m2: float


class LabelTableOut(BaseModel):
    model_config = example_config(
        labels=[{"label": "corridor", "functionality": "drivable & storage access",
                 "connectable": ["corridor", "junction", "open_area", "room", "storage"]}],
        categories=[{"category": 3, "label": "storage", "overridden": True, "regions": 102, "area_m2": 480.5}],
        overrides={"3": "storage"}, overrides_revision_id=57)

    labels: list[LabelRow]
    categories: list[CategoryRow] = Field(description="Categories of the current decomposition.")
    overrides: dict[str, str] = Field(description="A person's choices, category -> label.")
    overrides_revision_id: int | None = Field(description="The revision that recorded them.")


class LabelTableIn(BaseModel):
    model_config = example_config(overrides={"0": "corridor", "3": "storage"})

    overrides: dict[str, str] = Field(
        max_length=256,
        description="Category -> label for every category a person decides; others are assigned automatically. "
                    "An empty mapping returns all categories to automatic assignment.",
        examples=[{"0": "corridor", "3": "storage"}])


def stored_overrides(store: StoreDep, map_id: int, revision: int | None) -> tuple[dict[str, str], int | None]:
    found = store.latest_revision(map_id, stage=LABEL_TABLE_STAGE, at_or_before=revision)
    if found is None:
        return {}, None
    raw = found.summary.get(LABEL_OVERRIDES_KEY, {})
    return ({str(k): str(v) for k, v in raw.items()} if isinstance(raw, dict) else {}), found.id


@router.get("/label-table", summary="The place label table", responses=_ERRORS)
def get_label_table(map_info: MapDep, store: StoreDep, revision: RevisionQuery) -> LabelTableOut:
    """The human label semantics of grid decomposition: each label's functionality and connect-ability, each
    place category of the current decomposition with its label, and the overrides a person set."""
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
    return LabelTableOut(labels=labels, categories=categories, overrides=overrides,
                         overrides_revision_id=overrides_revision)


class LabelTableAccepted(BaseModel):
    model_config = example_config(revision_id=58, overrides={"0": "corridor", "3": "storage"})

    revision_id: int = Field(description="The revision that recorded the overrides; the grid decomposition "
                                         "worker re-labels the map from it in a later revision.")
    overrides: dict[str, str]


@router.put("/label-table", summary="Change the place label table", status_code=status.HTTP_202_ACCEPTED,
            responses=_ERRORS)
def put_label_table(map_info: MapDep, store: StoreDep, announcer: AnnouncerDep,
                    body: Annotated[LabelTableIn, Body()]) -> LabelTableAccepted:
    """Set which label each place category means (e.g. category 3 is storage). The choice is recorded as a
    revision; the grid decomposition worker then re-labels the map as a new revision (watch the events).
    Needs a `write` key."""
    try:
        parsed = parse_label_table(body.overrides)
    except PlaceLabelError as err:
        raise HTTPException(status.HTTP_422_UNPROCESSABLE_CONTENT, str(err)) from err
    overrides = {str(c): label.name.lower() for c, label in sorted(parsed.items())}
    written = store.write_revision(map_info.id,
                                   RevisionWrite(LABEL_TABLE_STAGE, summary={LABEL_OVERRIDES_KEY: overrides}))
    announcer.announce(map_info, written)
    return LabelTableAccepted(revision_id=written.id, overrides=overrides)

"""What is at a point, and the human label table that turns place categories into labels."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Body, Query, status
from pydantic import BaseModel, Field

from api.deps import AnnouncerDep, CacheDep, MapDep, RevisionQuery, SettingsDep, StoreDep
from api.models import COMMON_ERRORS, ErrorOut, Responses, example_config
from api.queries import MAX_BBOX_SIDE_M
from api.translate import http_error
from atlas import semantics
from atlas.errors import InvalidQueryError

router = APIRouter(prefix="/v1/maps/{map_name}", tags=["semantics"], responses=COMMON_ERRORS)

_ERRORS: Responses = {
    status.HTTP_404_NOT_FOUND: {"model": ErrorOut, "description": "No such map or revision."},
    status.HTTP_422_UNPROCESSABLE_CONTENT: {"model": ErrorOut, "description": "Bad coordinates or label table."},
}


class SemanticLabelOut(BaseModel):
    label: str | None = Field(description="Class of the semantic grid (semantic fusion), e.g. `rack`; null where "
                                          "nothing was observed.")
    code: int = Field(description="Class code in the semantic layer (its index in the layer's classes).")
    entropy: float | None = Field(description="Normalised Shannon entropy of the cell's class distribution, 0 "
                                              "(certain) to 1; null where there is none.")
    layer_revision_id: int = Field(description="Revision that wrote the semantic layer read.")


class PlaceOut(BaseModel):
    region: str = Field(description="Key of the region feature and topology node, e.g. `r12`.")
    label: str = Field(description="Place label: corridor, junction, storage, room, open_area, unidentified.")
    layer_revision_id: int = Field(description="Revision that wrote the place layers read.")


class FeatureAt(BaseModel):
    kind: str
    key: str
    label: str | None = Field(description="The feature's `label` or `id` property, if any.")


class PointOut(BaseModel):
    x_m: float = Field(description="x, metres, map frame.")
    y_m: float = Field(description="y, metres, map frame.")
    occupancy: int | None = Field(description="Occupancy of the cell there as the ROS OccupancyGrid gives it: the "
                                              "probability that it is occupied in percent, 0 (free) .. 100 "
                                              "(occupied), -1 never observed; null outside the layer.")
    occupancy_probability: float | None = Field(description="The same as a probability 0..1 that the cell is "
                                                            "occupied; null where never observed or outside.")
    semantic: SemanticLabelOut | None
    place: PlaceOut | None
    features: list[FeatureAt] = Field(description="Area features (bins, regions, docks...) whose polygon holds "
                                                  "the point, and point/line features within 0.25 m.")

    model_config = {"json_schema_extra": {"examples": [{
        "x_m": 12.4, "y_m": 7.9, "occupancy": 0, "occupancy_probability": 0.0,
        "semantic": {"label": "pallet", "code": 3, "entropy": 0.21, "layer_revision_id": 311},
        "place": {"region": "r12", "label": "corridor", "layer_revision_id": 305},
        "features": [{"kind": "corridor", "key": "r12", "label": "corridor"}]}]}}


_COORD = Query(ge=-MAX_BBOX_SIDE_M, le=MAX_BBOX_SIDE_M, description="Map-frame metres.", examples=[12.4])


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
    found = semantics.semantics_at(store, cache, settings, map_info, x_m=x, y_m=y, revision=revision)
    semantic, place = found.semantic, found.place
    return PointOut(
        x_m=found.x_m, y_m=found.y_m, occupancy=found.occupancy,
        occupancy_probability=None if found.occupancy is None or found.occupancy < 0 else found.occupancy / 100.0,
        semantic=None if semantic is None else SemanticLabelOut(
            label=semantic.label, code=semantic.code, entropy=semantic.entropy,
            layer_revision_id=semantic.layer_revision_id),
        place=None if place is None else PlaceOut(region=place.region, label=place.label,
                                                  layer_revision_id=place.layer_revision_id),
        features=[FeatureAt(kind=item.kind, key=item.key, label=item.label) for item in found.features])


# -- the label table ---------------------------------------------------------------------------------

class LabelRow(BaseModel):
    label: str
    functionality: str = Field(description="What the place is for (paper C, Table II).")
    connectable: list[str] = Field(description="Labels a place with this label may open onto.")


class CategoryRow(BaseModel):
    category: int = Field(description="Place category number found by unsupervised clustering of ray-cast "
                                      "features.")
    label: str = Field(description="The label its regions carry now.")
    overridden: bool = Field(description="Whether a person set this category's label.")
    regions: int = Field(description="Regions of this category, count.")
    area_m2: float = Field(description="Their total floor area, m².")


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


@router.get("/label-table", summary="The place label table", responses=_ERRORS)
def get_label_table(map_info: MapDep, store: StoreDep, revision: RevisionQuery) -> LabelTableOut:
    """The human label semantics of grid decomposition: each label's functionality and connect-ability, each
    place category of the current decomposition with its label, and the overrides a person set."""
    table = semantics.label_table(store, map_info, revision=revision)
    return LabelTableOut(
        labels=[LabelRow(label=row.label, functionality=row.functionality, connectable=row.connectable)
                for row in table.labels],
        categories=[CategoryRow(category=row.category, label=row.label, overridden=row.overridden,
                                regions=row.regions, area_m2=row.area_m2) for row in table.categories],
        overrides=table.overrides, overrides_revision_id=table.overrides_revision_id)


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
        written, overrides = semantics.write_overrides(store, map_info, body.overrides)
    except InvalidQueryError as err:
        raise http_error(err) from err
    announcer.announce(map_info, written)
    return LabelTableAccepted(revision_id=written.id, overrides=overrides)

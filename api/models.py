"""Response models of the REST API, kept apart from the store's records.

Every model carries an example (shown in ``/docs``), and :data:`COMMON_ERRORS`,
:data:`UNPROCESSABLE` and :func:`not_found` document the errors routes share.
"""

from __future__ import annotations

import datetime as dt
from typing import Any, Literal

from fastapi import status
from pydantic import BaseModel, ConfigDict, Field

from atlas.features import FEATURE_EXAMPLE, GeoJSONFeature
from shared.bins import ID_FORMAT
from shared.vocabulary import REVISION_HEADER

Responses = dict[int | str, dict[str, Any]]
"""The type of a route's ``responses=`` (extra OpenAPI responses)."""


def example_config(**example: Any) -> ConfigDict:
    """A model config whose JSON schema shows ``example`` (in ``/docs`` and to schema-driven tests)."""
    return ConfigDict(json_schema_extra={"examples": [example]})


class ValidationIssue(BaseModel):
    """One invalid part of a request, as FastAPI reports it."""

    loc: list[str | int] = Field(description="Where: `path`, `query`, `header` or `body`, then the name (or the "
                                             "index of a list item).")
    msg: str = Field(description="What is wrong with it.")
    type: str = Field(description="Error type, e.g. `string_too_long`.")
    input: Any = Field(None, description="The value sent.")
    ctx: dict[str, Any] | None = Field(None, description="Limits the value broke, e.g. `{\"max_length\": 64}`.")


class ErrorOut(BaseModel):
    detail: str | list[ValidationIssue] = Field(
        description="What went wrong, and where possible what would work instead; for a request that breaks a "
                    "parameter's or the body's declared limits (422), one entry per invalid part.")

    model_config = example_config(detail="no map named 'hall'; known maps: ['site']")


COMMON_ERRORS: Responses = {
    status.HTTP_400_BAD_REQUEST: {"model": ErrorOut, "description": "The body is not valid JSON, or the store "
                                                                    "refused the request as asked."},
    status.HTTP_401_UNAUTHORIZED: {"model": ErrorOut, "description": "No API key where one is needed, or a bad one."},
    status.HTTP_403_FORBIDDEN: {"model": ErrorOut, "description": "The API key's role is too low for this request."},
    status.HTTP_413_CONTENT_TOO_LARGE: {"model": ErrorOut, "description": "The request body is over the API's "
                                        "limit (`AISLE_API_MAX_BODY_BYTES`, 32 MiB by default)."},
    status.HTTP_429_TOO_MANY_REQUESTS: {"model": ErrorOut,
                                        "description": "Rate limit spent; retry after `Retry-After` seconds."},
    status.HTTP_503_SERVICE_UNAVAILABLE: {"model": ErrorOut,
                                          "description": "Database unreachable; retry after `Retry-After` seconds."},
}
"""Errors any route can answer: the app-wide key check and rate limit, a malformed or too large body, the store's
refusal and an unreachable database."""

UNPROCESSABLE: Responses = {
    status.HTTP_422_UNPROCESSABLE_CONTENT: {
        "model": ErrorOut, "description": "A parameter or the body is malformed or out of range."},
}


def not_found(description: str) -> Responses:
    """A documented 404 saying what may be missing, e.g. ``"No such map or revision."``."""
    return {status.HTTP_404_NOT_FOUND: {"model": ErrorOut, "description": description}}


REVISION_HEADER_DOC: dict[str, Any] = {
    "description": "The revision the answer covers: `?revision=` (or the cursor's) when given, else the newest "
                   "revision of the map when the request was served.",
    "schema": {"type": "integer"}}


def naming_revision(responses: Responses) -> Responses:
    """``responses`` with the success documented to carry the ``X-Aisle-Revision-Id`` header."""
    success = dict(responses.get(status.HTTP_200_OK, {}))
    success["headers"] = {**success.get("headers", {}), REVISION_HEADER: REVISION_HEADER_DOC}
    success.setdefault("description", "Successful Response")
    return {**responses, status.HTTP_200_OK: success}


def as_json(responses: Responses) -> Responses:
    """``responses`` documented as ``application/json`` whatever the route's own media type (for streams).

    FastAPI files a ``model`` under the route's response class's media type; a streaming route's errors
    are still JSON, so this names the schema of each model under ``application/json`` instead.
    """
    out: Responses = {}
    for code, response in responses.items():
        entry = {name: value for name, value in response.items() if name != "model"}
        if "model" in response:
            schema = {"$ref": f"#/components/schemas/{response['model'].__name__}"}
            entry["content"] = {"application/json": {"schema": schema}}
        out[code] = entry
    return out


# -- health -------------------------------------------------------------------------------
class DatabaseHealth(BaseModel):
    ok: bool
    detail: str
    url: str = Field(description="Database URL with any password masked.")


class BusHealth(BaseModel):
    ok: bool
    mode: str = Field(description='zenoh session mode, or "none" when the API runs without a bus.')
    detail: str
    counters: dict[str, int] = Field(description="This API process's bus counters (drops, malformed, ...).")


class WorkerHealth(BaseModel):
    name: str
    alive: bool = Field(description="Liveliness token seen on the bus or, without a bus, a recent heartbeat.")
    heartbeat_at: dt.datetime | None = Field(description="Last heartbeat stored in the database, if any.")
    counters: dict[str, int]


class HealthOut(BaseModel):
    status: Literal["ok", "degraded"]
    database: DatabaseHealth
    bus: BusHealth
    workers: list[WorkerHealth]
    missing_workers: list[str] = Field(description="Expected workers that are not alive.")

    model_config = example_config(
        status="ok",
        database={"ok": True, "detail": "reachable", "url": "postgresql+psycopg://aisle:***@db/aisle"},
        bus={"ok": True, "mode": "peer", "detail": "2 worker(s) seen", "counters": {"scan.dropped": 0}},
        workers=[{"name": "occupancy_mapping", "alive": True, "heartbeat_at": "2025-03-04T10:15:02Z",
                  "counters": {"scans": 18234}}],
        missing_workers=[],
    )


# -- maps and revisions ---------------------------------------------------------------------
_REVISION_EXAMPLE = {
    "id": 1207, "stage": "pillar_mapping", "created_at": "2025-03-04T10:15:00Z",
    "input_start_ns": 1741083240000000000, "input_end_ns": 1741083300000000000,
    "summary": {"layers_updated": [], "topology_changed": False,
                "features": {"bin": {"added": 2, "removed": 0, "moved": 1, "total": 8910}}},
    "pinned": False,
}


class RevisionOut(BaseModel):
    id: int = Field(description="Revision id (increasing with time; pass as `?revision=`).")
    stage: str = Field(description="The stage worker that wrote this revision.")
    created_at: dt.datetime
    input_start_ns: int | None = Field(description="Earliest sensor stamp the stage used, ns since epoch.")
    input_end_ns: int | None = Field(description="Latest sensor stamp the stage used, ns since epoch.")
    summary: dict[str, Any]
    pinned: bool = Field(description="Kept whatever the retention settings say (`PUT …/revisions/{id}/pin`); "
                         "revisions of stages `operator`, `label_table` and `wms` are kept anyway.")

    model_config = example_config(**_REVISION_EXAMPLE)


class RevisionPage(BaseModel):
    revisions: list[RevisionOut]
    next_after: int | None = Field(description="Pass as `?after=` for the next page (a revision id); null on the "
                                               "last page.")

    model_config = example_config(revisions=[_REVISION_EXAMPLE], next_after=None)


_MAP_EXAMPLE = {"name": "site", "frame_id": "map", "created_at": "2025-03-01T08:00:00Z", "latest_revision_id": 1207,
                "layers": ["occupancy", "place_labels", "semantic_label"]}


class MapSummary(BaseModel):
    name: str
    frame_id: str
    created_at: dt.datetime
    latest_revision_id: int | None = Field(description="Id of the map's newest revision; null before the first.")
    layers: list[str]

    model_config = example_config(**_MAP_EXAMPLE)


class MapDetail(MapSummary):
    latest_revision: RevisionOut | None

    model_config = example_config(**_MAP_EXAMPLE, latest_revision=_REVISION_EXAMPLE)


# -- layers ---------------------------------------------------------------------------------
class Origin(BaseModel):
    x_m: float = Field(description="x, metres, map frame.")
    y_m: float = Field(description="y, metres, map frame.")


_LAYER_EXAMPLE = {"name": "occupancy", "revision_id": 1206, "dtype": "int8", "shape": [500, 800],
                  "resolution_m": 0.05, "origin": {"x_m": -1.0, "y_m": -1.0}, "extent": [-1.0, -1.0, 39.0, 24.0],
                  "meta": {"encoding": "occupancy"}}


class LayerOut(BaseModel):
    name: str
    revision_id: int = Field(description="Revision that wrote this version of the layer.")
    dtype: str = Field(description="numpy dtype name, e.g. int8 (occupancy: -1 unknown, 0..100).")
    shape: tuple[int, int] = Field(description="(rows, cols), count of cells; row 0 is the lowest y.")
    resolution_m: float = Field(description="Cell side in metres.")
    origin: Origin = Field(description="Map-frame position of the outer corner of cell (0, 0).")
    extent: tuple[float, float, float, float] = Field(description="(min_x, min_y, max_x, max_y), metres, map "
                                                                  "frame.")
    meta: dict[str, Any]

    model_config = example_config(**_LAYER_EXAMPLE)


class LayerValuesOut(LayerOut):
    data: list[list[Any]] = Field(description="data[row][col], row 0 the lowest y; non-finite as null.")

    model_config = example_config(**{**_LAYER_EXAMPLE, "shape": [2, 3], "extent": [-1.0, -1.0, -0.85, -0.9]},
                            data=[[0, 0, -1], [100, 0, -1]])


# -- features -------------------------------------------------------------------------------
class FeatureCollection(BaseModel):
    type: Literal["FeatureCollection"] = "FeatureCollection"
    features: list[GeoJSONFeature]
    revision: int | None = Field(description="The revision read at (also in the `X-Aisle-Revision-Id` header): "
                                             "`?revision=` or the cursor's if given, else the newest; null only "
                                             "for a map without revisions.")
    limit: int = Field(description="Page size asked for, count of features.")
    offset: int = Field(description="Features skipped, count.")
    next_offset: int | None = Field(description="Pass as `?offset=` for the next page (a count of features); null "
                                                "on the last.")
    next_cursor: str | None = Field(None, description="Pass as `?cursor=` for the next page, read at the same "
                                                      "revision as this one; null on the last.")

    model_config = example_config(type="FeatureCollection", features=[FEATURE_EXAMPLE], revision=1207, limit=1000,
                                  offset=0, next_offset=None, next_cursor=None)


# -- bins ---------------------------------------------------------------------------------
class AccessPose(BaseModel):
    x_m: float = Field(description="x, metres, map frame.")
    y_m: float = Field(description="y, metres, map frame.")
    yaw_rad: float = Field(description="Heading to face the bin opening, radians from the map frame's x axis.")


class Opening(BaseModel):
    left: tuple[float, float] = Field(description="(x, y) of one end of the front edge, metres, map frame.")
    right: tuple[float, float] = Field(description="(x, y) of the other end, metres, map frame.")
    width_m: float = Field(description="Clear width between the uprights at the front, metres.")


class PlaceRef(BaseModel):
    key: str = Field(description="Feature key of the place (a `corridor`, `junction`, ... feature).")
    label: str = Field(description="Place label: corridor, junction, room, open_area.")
    distance_m: float | None = Field(None, description="From the bin's access pose (or centre), metres.")


BinStatus = Literal["matched", "unknown_to_wms", "unreconciled"]
OccupancyState = Literal["empty", "occupied", "unknown"]


class OccupancyOut(BaseModel):
    """What the robots saw in a bin (the load-scene stage's ``bin_state``)."""

    state: OccupancyState = Field(description="`empty`, `occupied` or `unknown` (never seen well enough, or no "
                                              "stage looks at loads).")
    confidence: float | None = Field(description="Probability 0..1 of `state`; null when nothing was stored.")
    last_seen: dt.datetime | None = Field(description="When a robot last saw the bin (UTC); null if never.")
    views: int = Field(description="Separate views the state rests on, count.")
    objects: list[str] = Field(description="Ids of the objects in the bin (pallet first), nodes of the bay's scene "
                                           "(`GET …/bins/{id}/scene`).")
    stable: bool | None = Field(description="False when a load in the bin touches another unstably (leaning, "
                                            "overhanging); null when empty or unknown.")
    hidden: bool = Field(description="True when an object in the bin was inferred, not seen (e.g. a second-deep "
                                     "pallet behind the front one).")
    bay: str | None = Field(description="Key of the rack bay (`load_scene` feature) the bin is in.")
    revision_id: int | None = Field(description="Revision that wrote this state; null when nothing was stored.")


UNKNOWN_OCCUPANCY = OccupancyOut(state="unknown", confidence=None, last_seen=None, views=0, objects=[], stable=None,
                                 hidden=False, bay=None, revision_id=None)
"""The occupancy of a bin nothing was stored for."""


class BinOut(BaseModel):
    id: str = Field(description="The id to use: the WMS's own id when the bin is matched to an imported WMS bin, "
                                f"else Aisle's: {ID_FORMAT}.", examples=["A-03-014", "03-014-02"])
    detected_id: str = Field(description=f"Aisle's id of the detected bin: {ID_FORMAT}.",
                             examples=["03-014", "03-014-02"])
    wms_id: str | None = Field(description="The WMS id it is matched to, if a WMS bin list was imported.")
    status: BinStatus = Field(description="`matched` to an imported WMS bin, `unknown_to_wms` (imported list "
                                          "lacks it) or `unreconciled` (no WMS list imported).")
    aisle: int | None = Field(description="Aisle number (Aisle's numbering); null if the bin has none.")
    bay: int | None = Field(description="Bay number along the aisle (odd on its left, even on its right); null if "
                                        "the bin has none.")
    level: int | None = Field(description="Shelf level number, 0 = floor; null while unknown.")
    centre: tuple[float, float] = Field(description="(x, y), metres, map frame.")
    footprint: list[tuple[float, float]] | None = Field(
        description="Closed polygon ring (x, y), metres, map frame, front edge first; null for point bins.")
    opening: Opening | None = Field(description="The front edge a fork enters by, from the footprint.")
    access_pose: AccessPose | None = Field(description="Where a vehicle stands in the aisle to reach the bin.")
    row: str | None = Field(description="Key of the aisle-facing rack row (a `rack_row` feature).")
    back_row: str | None = Field(description="Key of the rack row behind the bin, if any.")
    corridor: PlaceRef | None = Field(description="The corridor feature the access pose is in: the bin's aisle "
                                                  "(`aisle-03`, from the rack rows) where there is one, else a "
                                                  "decomposition corridor.")
    region: PlaceRef | None = Field(description="The drivable region of the grid decomposition the access pose is "
                                                "in (a topology node); null without place layers.")
    storage_region: PlaceRef | None = Field(
        description="The region of the grid decomposition holding most of the bin's footprint (a topology node; "
                    "`storage` where the racks are known); null for a bin without a footprint or place layers.")
    nearest_junction: PlaceRef | None = Field(description="The junction nearest the access pose, if any.")
    confidence: float | None = Field(
        description="How sure the pillar stage is of the bin, probability 0..1: the expected fraction of its four "
                    "uprights within 10 cm of where the map puts them (from their landmarks' covariance; an "
                    "upright no landmark supports counts 0); null for bins written without one.")
    stage: str = Field(description="The stage that wrote the bin.")
    revision_id: int = Field(description="Revision that wrote this version of the bin.")
    occupancy: OccupancyOut = Field(UNKNOWN_OCCUPANCY, description="What the robots saw in the bin: `unknown` "
                                                                   "until a stage stores a state for it.")

    model_config = {"json_schema_extra": {"examples": [{
        "id": "A-03-014", "detected_id": "03-014", "wms_id": "A-03-014", "status": "matched", "aisle": 3, "bay": 14,
        "level": None, "centre": [41.2, 17.6],
        "footprint": [[40.6, 17.1], [41.8, 17.1], [41.8, 18.1], [40.6, 18.1], [40.6, 17.1]],
        "opening": {"left": [40.6, 17.1], "right": [41.8, 17.1], "width_m": 1.2},
        "access_pose": {"x_m": 41.2, "y_m": 15.6, "yaw_rad": 1.5708}, "row": "r0-006", "back_row": "r0-007",
        "corridor": {"key": "aisle-03", "label": "corridor", "distance_m": None},
        "region": {"key": "r12", "label": "corridor", "distance_m": None},
        "storage_region": {"key": "r40", "label": "storage", "distance_m": None},
        "nearest_junction": {"key": "r3", "label": "junction", "distance_m": 18.4},
        "confidence": 0.92, "stage": "pillar_mapping", "revision_id": 1207,
        "occupancy": {"state": "occupied", "confidence": 0.97, "last_seen": "2026-11-26T03:10:04Z", "views": 3,
                      "objects": ["p1", "l1"], "stable": True, "hidden": False, "bay": "r0-006/14",
                      "revision_id": 1210}}]}}


class SceneNodeOut(BaseModel):
    """One object of a bay's scene graph."""

    model_config = example_config(id="l1", kind="load", centre=[41.2, 17.9, 1.05], size=[1.2, 0.8, 0.9],
                                  yaw_rad=1.5708, level=1, flags=[], probability=0.98)

    id: str = Field(description="The object's id in the scene.")
    kind: Literal["pallet", "load", "beam"] = Field(description="`pallet`, `load` (goods on a pallet) or `beam` "
                                                                "(the beam pair of a level).")
    centre: tuple[float, float, float] = Field(description="(x, y, z) of the box's centre, metres, map frame, z up "
                                                           "from the floor.")
    size: tuple[float, float, float] = Field(description="Extent along the box's own x, y and z axes, metres, in the "
                                                         "box's frame (the map frame turned by `yaw_rad`).")
    yaw_rad: float = Field(description="Turn of the box's x axis from the map x axis, radians.")
    level: int | None = Field(description="Rack level number the object is on (0 = floor); null if none.")
    flags: list[Literal["false_estimate", "hidden_below"]] = Field(
        description="`false_estimate`: a detection the evidence rejects (a ghost); `hidden_below`: an object nobody "
                    "saw, inferred because something would hover without it.")
    probability: float = Field(description="Posterior probability 0..1 that the object is there as described.")


class SceneEdgeOut(BaseModel):
    model_config = example_config(source="p1", target="l1", relation="supports", probability=0.99)

    source: str = Field(description="Id of the supporting (or touching) object.")
    target: str = Field(description="Id of the supported (or touched) object.")
    relation: Literal["supports", "unstable_contact"] = Field(
        description="`supports`: the source stably holds the target up; `unstable_contact`: they touch but neither "
                    "stably holds the other (a leaning or overhanging load).")
    probability: float = Field(description="Posterior probability 0..1 of the relation.")

"""Response models of the REST API, kept apart from the store's records."""

from __future__ import annotations

import datetime as dt
from typing import Any, Literal

from pydantic import BaseModel, Field

Responses = dict[int | str, dict[str, Any]]
"""The type of a route's ``responses=`` (extra OpenAPI responses)."""


class ErrorOut(BaseModel):
    detail: str = Field(description="What went wrong, and where possible what would work instead.")


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


# -- maps and revisions ---------------------------------------------------------------------
class RevisionOut(BaseModel):
    id: int
    stage: str = Field(description="The stage worker that wrote this revision.")
    created_at: dt.datetime
    input_start_ns: int | None = Field(description="Earliest sensor stamp the stage used, ns since epoch.")
    input_end_ns: int | None = Field(description="Latest sensor stamp the stage used, ns since epoch.")
    summary: dict[str, Any]


class RevisionPage(BaseModel):
    revisions: list[RevisionOut]
    next_after: int | None = Field(description="Pass as `?after=` for the next page; null on the last page.")


class MapSummary(BaseModel):
    name: str
    frame_id: str
    created_at: dt.datetime
    latest_revision_id: int | None
    layers: list[str]


class MapDetail(MapSummary):
    latest_revision: RevisionOut | None


# -- layers ---------------------------------------------------------------------------------
class Origin(BaseModel):
    x_m: float
    y_m: float


class LayerOut(BaseModel):
    name: str
    revision_id: int = Field(description="Revision that wrote this version of the layer.")
    dtype: str = Field(description="numpy dtype name, e.g. int8 (occupancy: -1 unknown, 0..100).")
    shape: tuple[int, int] = Field(description="(rows, cols); row 0 is the lowest y.")
    resolution_m: float = Field(description="Cell side in metres.")
    origin: Origin = Field(description="Map-frame position of the outer corner of cell (0, 0).")
    extent: tuple[float, float, float, float] = Field(description="(min_x, min_y, max_x, max_y) in metres.")
    meta: dict[str, Any]


class LayerValuesOut(LayerOut):
    data: list[list[Any]] = Field(description="data[row][col], row 0 the lowest y; non-finite as null.")


# -- features -------------------------------------------------------------------------------
class GeoJSONFeature(BaseModel):
    type: Literal["Feature"] = "Feature"
    id: str = Field(description="`<kind>/<key>`.")
    geometry: dict[str, Any] = Field(description="GeoJSON geometry in map-frame metres.")
    properties: dict[str, Any] = Field(
        description="The feature's own properties plus kind, key, stage, revision_id and confidence."
    )


class FeatureCollection(BaseModel):
    type: Literal["FeatureCollection"] = "FeatureCollection"
    features: list[GeoJSONFeature]
    revision: int | None = Field(description="The revision read at, or null for the live map.")
    limit: int
    offset: int
    next_offset: int | None = Field(description="Pass as `?offset=` for the next page; null on the last.")

"""Storage bins as a WMS wants them: by WMS id, with aisle, bay, level, footprint and where to stand."""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from typing import Annotated, Any, Literal

import anyio
import numpy as np
from fastapi import APIRouter, Depends, HTTPException, Path, Query, Response, status
from pydantic import BaseModel, Field

from api.binindex import BIN_KIND, BinIndex, bin_index
from api.cache import RevisionCache
from api.deps import ContextDep, MapDep, RevisionQuery, StoreDep, get_cache
from api.live import LiveMap
from api.live_features import stored_feature
from api.models import COMMON_ERRORS, ErrorOut, Responses, example_config
from api.routers.features import REVISION_HEADER, BBox, parse_bbox
from shared.store import MapInfo, MapStore, StoredFeature
from shared.store.records import bounds

router = APIRouter(prefix="/v1/maps/{map_name}/bins", tags=["bins"], responses=COMMON_ERRORS)

BIN_ID_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9._:-]{0,127}$"
"""What a bin id may look like (the pillar stage writes ``AA-BBB``: aisle, bay)."""
BIN_ID_REGEX = re.compile(BIN_ID_PATTERN)

_ERRORS: Responses = {
    status.HTTP_404_NOT_FOUND: {"model": ErrorOut, "description": "No such map, revision or bin."},
    status.HTTP_422_UNPROCESSABLE_CONTENT: {"model": ErrorOut, "description": "Bad id, filter, bbox or paging."},
}


class AccessPose(BaseModel):
    x_m: float
    y_m: float
    yaw_rad: float = Field(description="Heading to face the bin opening, radians from the map x axis.")


class Opening(BaseModel):
    left: tuple[float, float] = Field(description="(x, y) of one end of the front edge, metres.")
    right: tuple[float, float] = Field(description="(x, y) of the other end, metres.")
    width_m: float = Field(description="Clear width between the uprights at the front, metres.")


class PlaceRef(BaseModel):
    key: str = Field(description="Feature key of the place (a `corridor`, `junction`, ... feature).")
    label: str = Field(description="Place label: corridor, junction, room, open_area.")
    distance_m: float | None = Field(None, description="From the bin's access pose (or centre), metres.")


BinStatus = Literal["matched", "unknown_to_wms", "unreconciled"]


class BinOut(BaseModel):
    id: str = Field(description="The id to use: the WMS's own id when the bin is matched to an imported WMS bin, "
                                "else Aisle's (`AA-BBB`: aisle, bay).")
    detected_id: str = Field(description="Aisle's id of the detected bin.")
    wms_id: str | None = Field(description="The WMS id it is matched to, if a WMS bin list was imported.")
    status: BinStatus = Field(description="`matched` to an imported WMS bin, `unknown_to_wms` (imported list "
                                          "lacks it) or `unreconciled` (no WMS list imported).")
    aisle: int | None
    bay: int | None
    level: int | None = Field(description="Shelf level, 0 = floor; null while unknown.")
    centre: tuple[float, float] = Field(description="(x, y) in map-frame metres.")
    footprint: list[tuple[float, float]] | None = Field(
        description="Closed polygon ring (x, y) in metres, front edge first; null for point bins.")
    opening: Opening | None = Field(description="The front edge a fork enters by, from the footprint.")
    access_pose: AccessPose | None = Field(description="Where a vehicle stands in the aisle to reach the bin.")
    row: str | None = Field(description="Key of the aisle-facing rack row (a `rack_row` feature).")
    back_row: str | None = Field(description="Key of the rack row behind the bin, if any.")
    corridor: PlaceRef | None = Field(description="The corridor feature the access pose is in: the bin's aisle "
                                                  "(`aisle-03`, from the rack rows) where there is one, else a "
                                                  "decomposition corridor.")
    region: PlaceRef | None = Field(description="The drivable region of the grid decomposition the access pose is "
                                                "in (a topology node); null without place layers.")
    nearest_junction: PlaceRef | None = Field(description="The junction nearest the access pose, if any.")
    confidence: float | None
    stage: str = Field(description="The stage that wrote the bin.")
    revision_id: int = Field(description="Revision that wrote this version of the bin.")

    model_config = {"json_schema_extra": {"examples": [{
        "id": "A-03-014", "detected_id": "03-014", "wms_id": "A-03-014", "status": "matched", "aisle": 3, "bay": 14,
        "level": None, "centre": [41.2, 17.6],
        "footprint": [[40.6, 17.1], [41.8, 17.1], [41.8, 18.1], [40.6, 18.1], [40.6, 17.1]],
        "opening": {"left": [40.6, 17.1], "right": [41.8, 17.1], "width_m": 1.2},
        "access_pose": {"x_m": 41.2, "y_m": 15.6, "yaw_rad": 1.5708}, "row": "r0-006", "back_row": "r0-007",
        "corridor": {"key": "aisle-03", "label": "corridor", "distance_m": None},
        "region": {"key": "r12", "label": "corridor", "distance_m": None},
        "nearest_junction": {"key": "r3", "label": "junction", "distance_m": 18.4},
        "confidence": 0.92, "stage": "pillar_mapping", "revision_id": 1207}]}}


class BinPage(BaseModel):
    model_config = example_config(bins=[], total=240, revision=None, limit=100, offset=200, next_offset=None)

    bins: list[BinOut]
    total: int = Field(description="Bins matching the filters, over all pages.")
    revision: int | None = Field(description="The revision read at, or null for the live map.")
    limit: int
    offset: int
    next_offset: int | None = Field(description="Pass as `?offset=` for the next page; null on the last.")


def _int(value: Any) -> int | None:
    return value if isinstance(value, int) and not isinstance(value, bool) else None


def _str(value: Any) -> str | None:
    return value if isinstance(value, str) else None


def _xy(value: Any) -> tuple[float, float] | None:
    if (isinstance(value, Sequence) and len(value) == 2
            and all(isinstance(v, int | float) and not isinstance(v, bool) for v in value)):
        return float(value[0]), float(value[1])
    return None


def _footprint(geometry: Mapping[str, Any]) -> list[tuple[float, float]] | None:
    if geometry.get("type") != "Polygon" or not geometry.get("coordinates"):
        return None
    ring = [_xy(point) for point in geometry["coordinates"][0]]
    return None if any(point is None for point in ring) else [p for p in ring if p is not None]


def _centre(properties: Mapping[str, Any], geometry: Mapping[str, Any]) -> tuple[float, float]:
    """The ``centre`` property, else the middle of the geometry's bounds."""
    given = _xy(properties.get("centre"))
    if given is not None:
        return given
    min_x, min_y, max_x, max_y = bounds(geometry)
    return (min_x + max_x) / 2.0, (min_y + max_y) / 2.0


def _access_pose(value: Any) -> AccessPose | None:
    if (isinstance(value, Sequence) and len(value) == 3
            and all(isinstance(v, int | float) and not isinstance(v, bool) for v in value)):
        return AccessPose(x_m=float(value[0]), y_m=float(value[1]), yaw_rad=float(value[2]))
    return None


def _opening(footprint: list[tuple[float, float]] | None) -> Opening | None:
    if footprint is None or len(footprint) < 3:
        return None
    left, right = footprint[0], footprint[1]
    return Opening(left=left, right=right, width_m=float(np.hypot(right[0] - left[0], right[1] - left[1])))


def bin_out(stored: StoredFeature, index: BinIndex | None = None) -> BinOut:
    """A stored ``bin`` feature (as the pillar stage writes it) in WMS form; missing properties come out null.

    With ``index``, the bin also gets its WMS id and status, the corridor its access pose is in and the
    nearest junction.
    """
    feature = stored.feature
    properties = feature.properties
    footprint = _footprint(feature.geometry)
    centre = _centre(properties, feature.geometry)
    access = _access_pose(properties.get("access_pose"))
    wms_id = None if index is None or index.matching is None else index.matching.wms_of(feature.key)
    status: BinStatus = "unreconciled"
    if index is not None and index.matching is not None:
        status = "matched" if wms_id is not None else "unknown_to_wms"
    corridor = region = junction = None
    if index is not None:
        x, y = (access.x_m, access.y_m) if access is not None else centre
        place = index.place_at(x, y)
        region = None if place is None else PlaceRef(key=place[0], label=place[1], distance_m=None)
        corridor_key = index.corridor_at(x, y, aisle=_int(properties.get("aisle")))
        corridor = None if corridor_key is None else PlaceRef(key=corridor_key, label="corridor", distance_m=None)
        nearest = index.nearest_junction(x, y)
        junction = None if nearest is None else PlaceRef(key=nearest[0], label="junction", distance_m=nearest[1])
    detected_id = _str(properties.get("id")) or feature.key
    return BinOut(
        id=wms_id or detected_id,
        detected_id=detected_id,
        wms_id=wms_id,
        status=status,
        aisle=_int(properties.get("aisle")),
        bay=_int(properties.get("bay")),
        level=_int(properties.get("level")),
        centre=centre,
        footprint=footprint,
        opening=_opening(footprint),
        access_pose=access,
        row=_str(properties.get("row")),
        back_row=_str(properties.get("back_row")),
        corridor=corridor,
        region=region,
        nearest_junction=junction,
        confidence=feature.confidence,
        stage=stored.stage,
        revision_id=stored.revision_id,
    )


IndexDep = Annotated[RevisionCache, Depends(get_cache)]


@router.get("", summary="List and search bins", responses=_ERRORS)
def list_bins(
    map_info: MapDep,
    store: StoreDep,
    cache: IndexDep,
    revision: RevisionQuery,
    bbox: Annotated[BBox | None, Depends(parse_bbox)],
    aisle: Annotated[int | None, Query(ge=0, le=1_000_000, description="Only bins of this aisle.", examples=[3])
                     ] = None,
    row: Annotated[str | None, Query(max_length=128, description="Only bins facing this rack row (its key).",
                                     examples=["r0-006"])] = None,
    level: Annotated[int | None, Query(ge=0, le=1000, description="Only bins on this level (0 = floor).",
                                       examples=[0])] = None,
    id_prefix: Annotated[str | None, Query(max_length=128, description="Only bins whose id (WMS id when matched) "
                                                                       "or detected id starts so.", examples=["03-"])
                         ] = None,
    bin_status: Annotated[BinStatus | None, Query(alias="status", description="Only bins of this WMS status.",
                                                  examples=["matched"])] = None,
    limit: Annotated[int, Query(ge=1, le=1000, description="Page size.", examples=[100])] = 100,
    offset: Annotated[int, Query(ge=0, le=10_000_000, description="Bins to skip.", examples=[0])] = 0,
) -> BinPage:
    """Bins of the map (as of ``?revision=``), filtered, sorted by id and paged.

    Filters combine with AND; ``bbox`` keeps bins whose footprint touches the box. Corridor and
    nearest junction come from the grid decomposition's place layers and junctions of the same revision.
    """
    index = bin_index(store, cache, map_info.id, revision)
    matches = {} if index.matching is None else index.matching.reconciliation.by_detected()
    chosen: list[tuple[str, int, StoredFeature]] = []
    for stored in store.features(map_info.id, kinds=[BIN_KIND], bbox=bbox, revision=revision):
        item = bin_out(stored)
        match = matches.get(item.detected_id)
        status_now: BinStatus = ("unreconciled" if index.matching is None
                                 else "matched" if match is not None else "unknown_to_wms")
        shown = item.id if match is None else match.wms_id
        if ((aisle is None or item.aisle == aisle) and (row is None or item.row == row)
                and (level is None or item.level == level) and (bin_status is None or status_now == bin_status)
                and (id_prefix is None or shown.startswith(id_prefix) or item.detected_id.startswith(id_prefix))):
            chosen.append((shown, item.revision_id, stored))
    chosen.sort(key=lambda entry: (entry[0], entry[1]))
    page = [bin_out(stored, index) for _, _, stored in chosen[offset:offset + limit]]
    return BinPage(bins=page, total=len(chosen), revision=revision, limit=limit, offset=offset,
                   next_offset=offset + limit if offset + limit < len(chosen) else None)


@router.get("/{bin_id}", summary="One bin", responses=_ERRORS, response_model=BinOut)
async def get_bin(
    map_info: MapDep,
    store: StoreDep,
    cache: IndexDep,
    context: ContextDep,
    revision: RevisionQuery,
    bin_id: Annotated[str, Path(description="The bin's WMS id (when a WMS list was imported) or Aisle's id.",
                                pattern=BIN_ID_PATTERN, examples=["03-014"])],
) -> Response | BinOut:
    """One bin by its WMS id or Aisle's id (as of ``?revision=``), with where it is, its opening, where to stand,
    the corridor that leads to it and the nearest junction; 404 if there is none.

    The live map (no ``?revision=``) is served from memory, and may be up to 0.2 s behind the newest
    revision (revisions a client wrote through the API are always in); the header ``X-Aisle-Revision-Id``
    names the newest revision the answer covers."""
    if revision is not None:
        return await anyio.to_thread.run_sync(_stored_bin, store, cache, map_info, revision, bin_id)
    live = await context.live.get(map_info)
    if live is None:
        raise _no_bin(map_info, bin_id, revision)
    return Response(live_bin(live, map_info, bin_id), media_type="application/json",
                    headers={REVISION_HEADER: str(live.revision_id)})


def _no_bin(map_info: MapInfo, bin_id: str, revision: int | None) -> HTTPException:
    when = "now" if revision is None else f"at revision {revision}"
    return HTTPException(status.HTTP_404_NOT_FOUND,
                         f"map {map_info.name!r} has no bin {bin_id!r} {when}; list bins at "
                         f"/v1/maps/{map_info.name}/bins?id_prefix=")


def _stored_bin(store: MapStore, cache: RevisionCache, map_info: MapInfo, revision: int, bin_id: str) -> BinOut:
    """Bin ``bin_id`` as of ``revision``, read from the store."""
    index = bin_index(store, cache, map_info.id, revision)
    detected = index.matching.detected_of(bin_id) if index.matching is not None else None
    found = store.feature(map_info.id, BIN_KIND, detected or bin_id, revision=revision)
    if found is None:
        raise _no_bin(map_info, bin_id, revision)
    return bin_out(found, index)


def live_bin(live: LiveMap, map_info: MapInfo, bin_id: str) -> bytes:
    """Bin ``bin_id`` of the live map as JSON (404 if there is none), made once per version of the bin and of
    what it reads besides."""
    matching = live.bins.matching
    detected = matching.detected_of(bin_id) if matching is not None else None
    row = live.features.feature(BIN_KIND, detected or bin_id)
    if row is None:
        raise _no_bin(map_info, bin_id, None)
    body = live.bin_json.get(row.id)
    if body is None:
        body = live.bin_json[row.id] = bin_out(stored_feature(row), live.bins).model_dump_json().encode()
    return body

"""Storage bins as a WMS wants them: by WMS id, with aisle, bay, level, footprint and where to stand."""

from __future__ import annotations

import datetime as dt
from typing import Annotated

import anyio
from fastapi import APIRouter, Path, Query, Response, status
from pydantic import BaseModel, Field

from api.answers import bin_out, edge_out, live_bin, node_out, occupancy_out, stamp
from api.deps import CacheDep, ContextDep, MapDep, RevisionQuery, StoreDep, check_revision
from api.models import (
    COMMON_ERRORS,
    BinOut,
    BinStatus,
    ErrorOut,
    OccupancyOut,
    OccupancyState,
    Responses,
    SceneEdgeOut,
    SceneNodeOut,
    example_config,
    naming_revision,
)
from api.queries import BIN_ID_PATTERN, BBoxQuery, CursorQuery, next_cursor, page_start
from api.translate import http_error
from atlas.bins import BinNotFoundError, no_bin, select_bins, stored_bin
from atlas.bins import BinStatus as MapBinStatus
from atlas.cache import RevisionCache
from atlas.stock import SceneNotFoundError, bin_scene
from shared.bins import ID_FORMAT
from shared.loads import Occupancy
from shared.store import MapInfo, MapStore
from shared.vocabulary import REVISION_HEADER

router = APIRouter(prefix="/v1/maps/{map_name}/bins", tags=["bins"], responses=COMMON_ERRORS)

_ERRORS: Responses = {
    status.HTTP_404_NOT_FOUND: {"model": ErrorOut, "description": "No such map, revision or bin."},
    status.HTTP_422_UNPROCESSABLE_CONTENT: {"model": ErrorOut, "description": "Bad id, filter, bbox or paging."},
}


class BinPage(BaseModel):
    model_config = example_config(bins=[], total=240, revision=1207, limit=100, offset=200, next_offset=None,
                                  next_cursor=None)

    bins: list[BinOut]
    total: int = Field(description="Bins matching the filters over all pages, count.")
    revision: int | None = Field(description="The revision read at (also in the `X-Aisle-Revision-Id` header): "
                                             "`?revision=` or the cursor's if given, else the newest; null only "
                                             "for a map without revisions.")
    limit: int = Field(description="Page size asked for, count of bins.")
    offset: int = Field(description="Bins skipped, count.")
    next_offset: int | None = Field(description="Pass as `?offset=` for the next page (a count of bins); null on "
                                                "the last.")
    next_cursor: str | None = Field(description="Pass as `?cursor=` (with the same filters) for the next page, read "
                                                "at the same revision as this one; null on the last.")


@router.get("", summary="List and search bins", responses=naming_revision(_ERRORS))
def list_bins(
    response: Response,
    map_info: MapDep,
    store: StoreDep,
    cache: CacheDep,
    revision: RevisionQuery,
    cursor: CursorQuery,
    bbox: BBoxQuery,
    aisle: Annotated[int | None, Query(ge=0, le=1_000_000, description="Only bins of this aisle number.", examples=[3])
                     ] = None,
    row: Annotated[str | None, Query(max_length=128, description="Only bins facing this rack row (its key).",
                                     examples=["r0-006"])] = None,
    level: Annotated[int | None, Query(ge=0, le=1000, description="Only bins on this level number (0 = floor).",
                                       examples=[0])] = None,
    id_prefix: Annotated[str | None, Query(max_length=128, description="Only bins whose id (WMS id when matched) "
                                                                       "or detected id starts so.", examples=["03-"])
                         ] = None,
    bin_status: Annotated[BinStatus | None, Query(alias="status", description="Only bins of this WMS status.",
                                                  examples=["matched"])] = None,
    occupancy: Annotated[OccupancyState | None, Query(description="Only bins the robots saw so: `empty`, `occupied`, "
                                                                  "or `unknown` (not seen well enough, or no state "
                                                                  "stored).", examples=["occupied"])] = None,
    limit: Annotated[int, Query(ge=1, le=1000, description="Page size, count of bins.", examples=[100])] = 100,
    offset: Annotated[int, Query(ge=0, le=10_000_000, description="Bins to skip, count.", examples=[0])] = 0,
) -> BinPage:
    """Bins of the map (as of ``?revision=``), filtered, sorted by id and paged.

    Filters combine with AND; ``bbox`` keeps bins whose footprint touches the box; ``occupancy`` keeps bins by what
    the robots saw in them (each bin's ``occupancy``: state, confidence, when last seen, the objects). Corridor and
    nearest junction come from the grid decomposition's place layers and junctions of the same revision.
    The answer names the revision it was read at (`revision`, and the header `X-Aisle-Revision-Id`); page on
    with `?cursor=<next_cursor>` and every page is read at that same revision, however many revisions arrive
    meanwhile.
    """
    at, offset = page_start(cursor, revision, offset)
    if at is None:
        latest = store.latest_revision(map_info.id)
        at = None if latest is None else latest.id
    elif cursor is not None:
        check_revision(store, map_info, at)
    selection = select_bins(store, cache, map_info.id, revision=at, bbox=bbox, aisle=aisle, row=row,
                            level=level, id_prefix=id_prefix,
                            status=None if bin_status is None else MapBinStatus(bin_status),
                            occupancy=None if occupancy is None else Occupancy(occupancy), limit=limit, offset=offset)
    if at is not None:
        response.headers[REVISION_HEADER] = str(at)
    more = offset + limit < selection.total
    return BinPage(bins=[bin_out(answer) for answer in selection.bins], total=selection.total, revision=at,
                   limit=limit, offset=offset, next_offset=offset + limit if more else None,
                   next_cursor=next_cursor(at, offset + limit, more=more))


@router.get("/{bin_id}", summary="One bin", responses=_ERRORS, response_model=BinOut)
async def get_bin(
    map_info: MapDep,
    store: StoreDep,
    cache: CacheDep,
    context: ContextDep,
    revision: RevisionQuery,
    bin_id: Annotated[str, Path(description="The bin's WMS id (when a WMS list was imported) or Aisle's id: "
                                            f"{ID_FORMAT}.", pattern=BIN_ID_PATTERN, examples=["03-014-02"])],
) -> Response | BinOut:
    """One bin by its WMS id or Aisle's id (as of ``?revision=``), with where it is, its opening, where to stand,
    the corridor that leads to it, the nearest junction and what the robots saw in it (``occupancy``); 404 if there
    is none.

    The live map (no ``?revision=``) is served from memory, and may be up to 0.2 s behind the newest
    revision (revisions a client wrote through the API are always in); the header ``X-Aisle-Revision-Id``
    names the newest revision the answer covers."""
    if revision is not None:
        return await anyio.to_thread.run_sync(_stored_bin, store, cache, map_info, revision, bin_id)
    live = await context.live.get(map_info)
    if live is None:
        raise http_error(no_bin(map_info, bin_id, revision))
    return Response(live_bin(live, map_info, bin_id), media_type="application/json",
                    headers={REVISION_HEADER: str(live.revision_id)})


def _stored_bin(store: MapStore, cache: RevisionCache, map_info: MapInfo, revision: int, bin_id: str) -> BinOut:
    """Bin ``bin_id`` as of ``revision``, read from the store."""
    try:
        return bin_out(stored_bin(store, cache, map_info, bin_id, revision=revision))
    except BinNotFoundError as err:
        raise http_error(err) from err


class BinSceneOut(BaseModel):
    model_config = example_config(
        bin_id="A-03-014", detected_id="03-014-02", bay="r0-006/14",
        occupancy={"state": "occupied", "confidence": 0.97, "last_seen": "2026-11-26T03:10:04Z", "views": 3,
                   "objects": ["p1", "l1"], "stable": True, "hidden": False, "bay": "r0-006/14", "revision_id": 1210},
        stamp="2026-11-26T03:10:04Z", iterations=240,
        nodes=[{"id": "b1", "kind": "beam", "centre": [41.2, 17.6, 0.94], "size": [2.7, 1.1, 0.12], "yaw_rad": 1.5708,
                "level": 1, "flags": [], "probability": 1.0},
               {"id": "p1", "kind": "pallet", "centre": [41.2, 17.9, 1.07], "size": [1.2, 0.8, 0.14],
                "yaw_rad": 1.5708, "level": 1, "flags": [], "probability": 0.99},
               {"id": "l1", "kind": "load", "centre": [41.2, 17.9, 1.59], "size": [1.2, 0.8, 0.9],
                "yaw_rad": 1.5708, "level": 1, "flags": [], "probability": 0.97}],
        edges=[{"source": "b1", "target": "p1", "relation": "supports", "probability": 0.99},
               {"source": "p1", "target": "l1", "relation": "supports", "probability": 0.97}],
        scene_revision_id=1210, revision=1215)

    bin_id: str = Field(description="The bin as asked for (its WMS id or Aisle's).")
    detected_id: str = Field(description=f"Aisle's id of the bin: {ID_FORMAT}.")
    bay: str = Field(description="Key of the rack bay the bin is in (its `load_scene` feature).")
    occupancy: OccupancyOut = Field(description="What the robots saw in the bin itself.")
    stamp: dt.datetime | None = Field(description="Time of the newest view the scene rests on (UTC).")
    iterations: int = Field(description="MCMC iterations the scene inference ran, count.")
    nodes: list[SceneNodeOut] = Field(description="The objects of the bay: beams, pallets, loads; false estimates "
                                                  "and inferred hidden objects carry their flag.")
    edges: list[SceneEdgeOut] = Field(description="Which object supports which, and unstable contacts.")
    scene_revision_id: int = Field(description="Revision that wrote this version of the scene.")
    revision: int | None = Field(description="The revision read at (also in the `X-Aisle-Revision-Id` header): "
                                             "`?revision=` if given, else the newest.")


@router.get("/{bin_id}/scene", summary="The scene graph of a bin's bay",
            responses={**naming_revision(_ERRORS), status.HTTP_404_NOT_FOUND: {
                "model": ErrorOut, "description": "No such map, revision or bin, or no scene of its bay (the robots "
                                                  "have not seen it)."}})
def get_bin_scene(
    response: Response,
    map_info: MapDep,
    store: StoreDep,
    cache: CacheDep,
    revision: RevisionQuery,
    bin_id: Annotated[str, Path(description="The bin's WMS id (when a WMS bin list was imported) or Aisle's id: "
                                            f"{ID_FORMAT}.", pattern=BIN_ID_PATTERN, examples=["03-014"])],
) -> BinSceneOut:
    """What stands in the rack bay of bin ``bin_id`` (as of ``?revision=``): the objects (beams, pallets, loads,
    each with its 3D box in the map frame), which supports which and which touch unstably, detections the
    inference rejects (`false_estimate`) and objects it infers unseen (`hidden_below`); with the bin's own
    occupancy. 404 when the robots have not seen the bay."""
    at = revision
    if at is None:
        latest = store.latest_revision(map_info.id)
        at = None if latest is None else latest.id
    try:
        found = bin_scene(store, cache, map_info, bin_id, revision=at)
    except (BinNotFoundError, SceneNotFoundError) as err:
        raise http_error(err) from err
    if at is not None:
        response.headers[REVISION_HEADER] = str(at)
    scene = found.scene
    return BinSceneOut(bin_id=bin_id, detected_id=found.detected_id, bay=scene.bay,
                       occupancy=occupancy_out(found.occupancy, found.state_revision_id),
                       stamp=stamp(scene.stamp_ns or None), iterations=scene.iterations,
                       nodes=[node_out(node) for node in scene.nodes], edges=[edge_out(edge) for edge in scene.edges],
                       scene_revision_id=found.scene_revision_id, revision=at)

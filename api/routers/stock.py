"""The WMS's stock list (which bins hold stock) and the bins where the robots saw otherwise."""

from __future__ import annotations

import datetime as dt
from typing import Annotated, Any, Literal

import anyio
from fastapi import APIRouter, Query, Request, Response, status
from pydantic import BaseModel, Field

from api.announce import Announcer
from api.answers import node_out, occupancy_out
from api.background import background_work
from api.deps import AnnouncerDep, CacheDep, MapDep, RevisionQuery, SettingsDep, StoreDep, check_revision
from api.invalid import parse_bin_list
from api.models import COMMON_ERRORS, ErrorOut, OccupancyOut, Responses, SceneNodeOut, example_config, naming_revision
from api.queries import BIN_ID_PATTERN, CursorQuery, next_cursor, page_start
from api.translate import http_error
from atlas.cache import RevisionCache
from atlas.precision import json_bytes
from atlas.stock import (
    NoStockListError,
    StockCheck,
    StockDiscrepancy,
    import_wms_stock,
    stock_discrepancies,
    with_evidence,
)
from shared.store import MapInfo, MapStore, WmsStock
from shared.vocabulary import REVISION_HEADER

router = APIRouter(prefix="/v1/maps/{map_name}/wms-stock", tags=["bins"], responses=COMMON_ERRORS)

MAX_WMS_STOCK = 200_000
"""Most bins one stock list may name."""
_QUANTITY = 1e12
DEFAULT_LIMIT = 1000
"""Discrepancies per page unless ``?limit=`` says otherwise."""

_ERRORS: Responses = {
    status.HTTP_404_NOT_FOUND: {"model": ErrorOut, "description": "No such map or revision, or no WMS stock list."},
    status.HTTP_422_UNPROCESSABLE_CONTENT: {"model": ErrorOut, "description": "Bad stock list or parameters."},
}


class StockIn(BaseModel):
    model_config = example_config(id="A-03-014", holds_stock=True, sku="4006381333931", quantity=40)

    id: str = Field(pattern=BIN_ID_PATTERN, description="The bin's id: the WMS's own where a WMS bin list was "
                                                        "imported (`PUT …/wms-bins`), else Aisle's.",
                    examples=["A-03-014"])
    holds_stock: bool = Field(description="Whether the WMS books stock in the bin.")
    sku: str | None = Field(None, max_length=128, description="The article the WMS books there, if it says.")
    quantity: float | None = Field(None, ge=0, le=_QUANTITY, description="How much the WMS books there, count in "
                                                                         "its own unit (pieces, cartons).")


class StockImport(BaseModel):
    bins: list[StockIn] = Field(max_length=MAX_WMS_STOCK, description="The bins the WMS has a view of.")
    complete: bool = Field(False, description="`true`: the list names every bin that holds stock, so a bin it leaves "
                                              "out is empty as the WMS sees it (and reported when the robots saw it "
                                              "occupied).")

    model_config = {"json_schema_extra": {"examples": [{
        "bins": [{"id": "A-03-014", "holds_stock": True, "sku": "4006381333931", "quantity": 40},
                 {"id": "03-015-01", "holds_stock": False}], "complete": False}]}}


class StockDiscrepancyOut(BaseModel):
    bin_id: str = Field(description="The bin as the stock list names it (the WMS's id where a WMS bin list matched "
                                    "it, else Aisle's).")
    detected_id: str = Field(description="Aisle's id of the bin.")
    wms_holds_stock: bool = Field(description="What the WMS says: whether the bin holds stock.")
    sku: str | None = Field(description="The article the WMS books there, if it said.")
    quantity: float | None = Field(description="How much the WMS books there, count in its own unit.")
    robots_saw: Literal["occupied", "empty"] = Field(description="What the robots saw in the bin.")
    confidence: float = Field(description="Probability 0..1 of what the robots saw.")
    views: int = Field(description="Separate views it rests on, count.")
    last_seen: dt.datetime | None = Field(description="When a robot last saw the bin (UTC).")
    occupancy: OccupancyOut = Field(description="The bin's whole stored state.")
    evidence: list[SceneNodeOut] = Field(description="The objects the robots saw in the bin (3D boxes, map frame); "
                                                     "empty when they saw it empty.")


class StockCheckOut(BaseModel):
    model_config = example_config(
        stock_revision_id=1300, complete=False, min_views=2,
        discrepancies=[{"bin_id": "A-03-014", "detected_id": "03-014-02", "wms_holds_stock": False, "sku": None,
                        "quantity": None, "robots_saw": "occupied", "confidence": 0.97, "views": 3,
                        "last_seen": "2026-11-26T03:10:04Z",
                        "occupancy": {"state": "occupied", "confidence": 0.97, "last_seen": "2026-11-26T03:10:04Z",
                                      "views": 3, "objects": ["p1"], "stable": True, "hidden": False,
                                      "bay": "r0-006/14", "revision_id": 1210},
                        "evidence": [{"id": "p1", "kind": "pallet", "centre": [41.2, 17.9, 1.07],
                                      "size": [1.2, 0.8, 0.14], "yaw_rad": 1.5708, "level": 1, "flags": [],
                                      "probability": 0.99}]}],
        counts={"listed": 120, "agreeing": 96, "discrepancies": 1, "not_seen_well": 23},
        total=1, revision=1310, next_cursor=None)

    stock_revision_id: int = Field(description="The revision that imported the stock list.")
    complete: bool = Field(description="Whether the list names every bin that holds stock.")
    min_views: int = Field(description="Views a bin needed to be checked, count (fewer: left unchecked).")
    discrepancies: list[StockDiscrepancyOut] = Field(description="Bins where the robots saw otherwise, by id; a page.")
    counts: dict[str, int] = Field(description="Bins `listed` (count), `agreeing`, `discrepancies` and "
                                               "`not_seen_well` (unknown, or fewer views than `min_views`: never "
                                               "reported).")
    total: int = Field(description="Discrepancies over all pages, count.")
    revision: int | None = Field(description="The revision read at (also in the `X-Aisle-Revision-Id` header).")
    next_cursor: str | None = Field(description="Pass as `?cursor=` for the next page, read at the same revision; "
                                                "null on the last.")


def _discrepancy_out(item: StockDiscrepancy) -> StockDiscrepancyOut:
    occupancy = occupancy_out(item.seen, item.state_revision_id)
    return StockDiscrepancyOut(
        bin_id=item.bin_id, detected_id=item.detected_id, wms_holds_stock=item.wms.holds_stock, sku=item.wms.sku,
        quantity=item.wms.quantity, robots_saw=item.seen.state.value, confidence=item.seen.confidence,
        views=item.seen.views, last_seen=occupancy.last_seen, occupancy=occupancy,
        evidence=[node_out(node) for node in item.evidence])


def _check_out(store: MapStore, map_info: MapInfo, check: StockCheck, *, revision: int | None, offset: int,
               limit: int) -> StockCheckOut:
    page = with_evidence(store, map_info, check.discrepancies[offset:offset + limit], revision=revision)
    more = offset + limit < len(check.discrepancies)
    return StockCheckOut(
        stock_revision_id=check.stock_revision_id, complete=check.complete, min_views=check.min_views,
        discrepancies=[_discrepancy_out(item) for item in page],
        counts={"listed": check.listed, "agreeing": check.agreeing, "discrepancies": len(check.discrepancies),
                "not_seen_well": check.not_seen_well},
        total=len(check.discrepancies), revision=revision, next_cursor=next_cursor(revision, offset + limit,
                                                                                   more=more))


def _import_body() -> dict[str, Any]:
    """The import's body as OpenAPI documents it (the route reads and validates it itself, off the event loop)."""
    schema = StockImport.model_json_schema(ref_template="#/components/schemas/{model}")
    schema.pop("$defs", None)
    return {"requestBody": {"required": True, "content": {"application/json": {"schema": schema}}}}


@router.put("", summary="Import the WMS's stock list", responses=_ERRORS, response_model=StockCheckOut,
            openapi_extra=_import_body())
async def import_stock(request: Request, map_info: MapDep, store: StoreDep, cache: CacheDep, settings: SettingsDep,
                       announcer: AnnouncerDep) -> Response:
    """Replace the map's WMS stock list with ``bins`` (one new revision) and return the first page of the bins where
    the robots saw otherwise (as ``GET …/wms-stock/discrepancies``).

    Each bin is named by the WMS's id (where a WMS bin list was imported) or Aisle's; ``holds_stock`` says whether
    the WMS books stock there. ``complete`` says the list names every bin that holds stock. Needs a `write` key.
    The list is parsed, checked and stored in a worker thread, so reads go on being answered meanwhile.
    """
    body = await request.body()
    answer = await anyio.to_thread.run_sync(_import, body, store, cache, map_info, announcer,
                                            settings.api_stock_min_views)
    return Response(answer, media_type="application/json")


def _import(body: bytes, store: MapStore, cache: RevisionCache, map_info: MapInfo, announcer: Announcer,
            min_views: int) -> bytes:
    """Parse, check and store the stock list in ``body``; the first page of discrepancies as JSON."""
    with background_work():
        parsed = parse_bin_list(StockImport, body, "bin ids of a stock list")
        items = [WmsStock(b.id, b.holds_stock, b.sku, b.quantity) for b in parsed.bins]
        written = import_wms_stock(store, map_info.id, items, complete=parsed.complete)
        announcer.announce(map_info, written)
        check = stock_discrepancies(store, cache, map_info, revision=written.id, min_views=min_views)
        return json_bytes(_check_out(store, map_info, check, revision=written.id, offset=0, limit=DEFAULT_LIMIT)
                          .model_dump(mode="json"))


@router.get("/discrepancies", summary="Bins where the robots saw otherwise than the WMS",
            responses=naming_revision(_ERRORS))
def get_discrepancies(
    response: Response,
    map_info: MapDep,
    store: StoreDep,
    cache: CacheDep,
    settings: SettingsDep,
    revision: RevisionQuery,
    cursor: CursorQuery,
    min_views: Annotated[int | None, Query(ge=1, le=1000, description=(
        "Views a bin needs to be checked, count (default `AISLE_API_STOCK_MIN_VIEWS`, 2)."), examples=[2])] = None,
    limit: Annotated[int, Query(ge=1, le=10_000, description="Page size, count of bins.", examples=[1000])
                     ] = DEFAULT_LIMIT,
    offset: Annotated[int, Query(ge=0, le=10_000_000, description="Discrepancies to skip, count.", examples=[0])] = 0,
) -> StockCheckOut:
    """The bins where what the robots saw disagrees with the WMS stock list (as of ``?revision=``): seen occupied
    where the WMS books no stock, seen empty where it books some; each with what the WMS says, what the robots saw,
    how sure, from how many views, when last seen and the objects seen (the evidence).

    A bin the robots did not see well (state ``unknown``, or fewer views than ``min_views``) is never reported: it
    is counted under ``not_seen_well``. Page on with `?cursor=<next_cursor>`, read at the same revision.
    """
    at, offset = page_start(cursor, revision, offset)
    if at is None:
        latest = store.latest_revision(map_info.id)
        at = None if latest is None else latest.id
    elif cursor is not None:
        check_revision(store, map_info, at)
    try:
        check = stock_discrepancies(store, cache, map_info, revision=at,
                                    min_views=settings.api_stock_min_views if min_views is None else min_views)
    except NoStockListError as err:
        raise http_error(err) from err
    if at is not None:
        response.headers[REVISION_HEADER] = str(at)
    return _check_out(store, map_info, check, revision=at, offset=offset, limit=limit)


@router.get("", summary="The imported WMS stock list", responses=_ERRORS)
def list_wms_stock(map_info: MapDep, store: StoreDep, revision: RevisionQuery) -> list[StockIn]:
    """The WMS stock list as last imported (as of ``?revision=``); empty if none was."""
    return [StockIn(id=item.bin_id, holds_stock=item.holds_stock, sku=item.sku, quantity=item.quantity)
            for item in store.wms_stock(map_info.id, revision=revision)]

"""The WMS's own bin numbering: import it, and see how it matches the bins Aisle detected."""

from __future__ import annotations

from typing import Any, Literal

import anyio
from fastapi import APIRouter, HTTPException, Request, Response, status
from pydantic import BaseModel, Field, model_validator

from api.announce import Announcer
from api.background import background_work
from api.deps import AnnouncerDep, CacheDep, MapDep, RevisionQuery, StoreDep
from api.invalid import parse_bin_list
from api.memory import return_freed_memory
from api.models import COMMON_ERRORS, ErrorOut, Responses, example_config
from api.queries import BIN_ID_PATTERN
from atlas.bins import import_wms_list
from atlas.cache import RevisionCache
from atlas.precision import json_bytes
from atlas.reconcile import MatchBy, Verdict, WmsMatching, wms_matching
from shared.store import MapInfo, MapStore, WmsBin

router = APIRouter(prefix="/v1/maps/{map_name}/wms-bins", tags=["bins"], responses=COMMON_ERRORS)

MAX_WMS_BINS = 200_000
_COORD = 100_000.0

_ERRORS: Responses = {
    status.HTTP_404_NOT_FOUND: {"model": ErrorOut, "description": "No such map or revision, or no WMS list."},
    status.HTTP_422_UNPROCESSABLE_CONTENT: {"model": ErrorOut, "description": "Bad bin list or parameters."},
}


class WmsBinIn(BaseModel):
    model_config = example_config(id="A-03-014", x_m=41.2, y_m=17.6, aisle=3, bay=14, level=0)

    id: str = Field(pattern=BIN_ID_PATTERN, description="The WMS's id of the bin.", examples=["A-03-014"])
    x_m: float | None = Field(None, ge=-_COORD, le=_COORD, description="Bin centre x, metres, map frame, if known.")
    y_m: float | None = Field(None, ge=-_COORD, le=_COORD, description="Bin centre y, metres, map frame, if known.")
    aisle: int | None = Field(None, ge=0, le=1_000_000, description="The WMS's aisle number, if it has one.")
    bay: int | None = Field(None, ge=0, le=1_000_000, description="The WMS's bay number, if it has one.")
    level: int | None = Field(None, ge=0, le=1000, description="Shelf level number, 0 = floor.")

    @model_validator(mode="after")
    def _both_or_neither(self) -> WmsBinIn:
        if (self.x_m is None) != (self.y_m is None):
            raise ValueError(f"bin {self.id!r}: give both x_m and y_m or neither")
        return self


class WmsImport(BaseModel):
    bins: list[WmsBinIn] = Field(max_length=MAX_WMS_BINS, description="The WMS's complete bin list.")
    tolerance_m: float = Field(0.5, gt=0.0, le=10.0, description="Largest distance between a WMS position and a "
                               "detected bin centre that still matches, metres (about half a bay); a bin matched "
                               "by id further than this is reported as a discrepancy.")
    match_by: Literal["id", "position"] = Field(
        "id", description="`id`: equal ids first, then the nearest position for the rest; `position`: the nearest "
                          "position wherever the WMS gives one (for a site whose ids look like Aisle's but count "
                          "differently), equal ids only for bins without a position.")

    model_config = {"json_schema_extra": {"examples": [{
        "bins": [{"id": "A-03-014", "x_m": 41.2, "y_m": 17.6, "level": 0}, {"id": "03-015"}],
        "tolerance_m": 0.5, "match_by": "id"}]}}


class MatchOut(BaseModel):
    wms_id: str
    detected_id: str = Field(description="Aisle's id of the matched bin.")
    by: str = Field(description="`id` (same id on both sides) or `position`.")
    distance_m: float | None = Field(description="WMS position to detected centre, metres; null without a WMS "
                                                 "position.")


class DiscrepancyOut(BaseModel):
    wms_id: str = Field(description="The WMS id, equal to the id of the detected bin it is matched to.")
    wms_position: tuple[float, float] = Field(description="(x, y) the WMS gives, metres, map frame.")
    detected_position: tuple[float, float] = Field(description="(x, y) of the detected bin's centre, metres, "
                                                               "map frame.")
    delta_m: tuple[float, float] = Field(description="Detected minus WMS position (dx, dy), metres, map frame.")
    distance_m: float = Field(description="Between the two positions, metres (more than the tolerance).")
    nearest_detected_id: str | None = Field(description="The detected bin within the tolerance of the WMS "
                                                        "position (same level first), if any.")


class IdShiftOut(BaseModel):
    aisle: int = Field(description="Aisle number difference (detected minus WMS), count.")
    bay: int = Field(description="Bay number difference (detected minus WMS), count.")
    level: int = Field(description="Level number difference (detected minus WMS), count.")
    support: int = Field(description="Discrepancies this shift explains, count.")


class NumberingOut(BaseModel):
    verdict: Verdict = Field(description="`consistent` (every id match within the tolerance), `some_far` (a few "
                                         "are not; see `discrepancies`), `renumbered` (most are not, and one "
                                         "constant id shift explains them: the site numbers bins differently "
                                         "from Aisle's scheme), `shifted` (most are off by one constant offset: "
                                         "the WMS positions are in another frame), `inconsistent` (most are off, "
                                         "no common explanation) or `unchecked` (no id match has a WMS "
                                         "position).")
    id_matches: int = Field(description="Bins matched by id that have a WMS position, count.")
    far: int = Field(description="Of them, those further than the tolerance from the detected bin, count.")
    median_distance_m: float | None = Field(description="Median WMS-to-detected distance of the id matches, "
                                                        "metres.")
    offset_m: tuple[float, float] | None = Field(description="Median detected-minus-WMS offset (dx, dy) of the id "
                                                             "matches, metres, map frame.")
    offset_support: int = Field(description="Id matches within the tolerance once `offset_m` is taken away, "
                                            "count.")
    id_shift: IdShiftOut | None = Field(description="The commonest shift from a far bin's WMS id to the id of "
                                                    "the detected bin at its WMS position.")
    message: str = Field(description="The verdict in words, with what to do.")


class ReconciliationOut(BaseModel):
    model_config = example_config(
        wms_revision_id=88, tolerance_m=0.5, match_by="id",
        matched=[{"wms_id": "A-03-014", "detected_id": "03-014", "by": "position", "distance_m": 0.07},
                 {"wms_id": "01-002-01", "detected_id": "01-002-01", "by": "id", "distance_m": 4.09}],
        missing_in_map=["A-99-001"], unknown_to_wms=["03-015"],
        discrepancies=[{"wms_id": "01-002-01", "wms_position": [6.37, 6.05], "detected_position": [2.28, 6.1],
                        "delta_m": [-4.09, 0.05], "distance_m": 4.09, "nearest_detected_id": "01-004-01"}],
        numbering={"verdict": "some_far", "id_matches": 1, "far": 1, "median_distance_m": 4.09,
                   "offset_m": [-4.09, 0.05], "offset_support": 1, "id_shift": {"aisle": 0, "bay": 2, "level": 0,
                                                                                 "support": 1},
                   "message": "1 of 1 bins matched by id lie further than 0.5 m from their WMS position ..."},
        counts={"matched": 2, "missing_in_map": 1, "unknown_to_wms": 1, "discrepancies": 1})

    wms_revision_id: int = Field(description="The revision that imported the WMS list.")
    tolerance_m: float = Field(description="The matching tolerance the list was imported with, metres.")
    match_by: Literal["id", "position"] = Field(description="What the list was matched by first.")
    matched: list[MatchOut]
    missing_in_map: list[str] = Field(description="WMS bin ids with no detected bin (not yet mapped, or gone).")
    unknown_to_wms: list[str] = Field(description="Detected bin ids the WMS list lacks.")
    discrepancies: list[DiscrepancyOut] = Field(
        description="Bins matched by id whose WMS position is further than the tolerance from the detected bin "
                    "(they stay matched: the ids are equal), furthest first.")
    numbering: NumberingOut = Field(description="What the id matches' positions say about the site's numbering.")
    counts: dict[str, int] = Field(description="Sizes of the four lists.")


def _reconciliation(store: StoreDep, map_id: int, map_name: str, revision: int | None) -> ReconciliationOut:
    matching = wms_matching(store, map_id, revision)
    if matching is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND,
                            f"map {map_name!r} has no WMS bin list; import one with PUT /v1/maps/{map_name}/wms-bins")
    return _reconciliation_out(matching)


def _reconciliation_out(matching: WmsMatching) -> ReconciliationOut:
    result = matching.reconciliation
    check = result.numbering
    shift = check.id_shift
    return ReconciliationOut(
        wms_revision_id=matching.revision_id,
        tolerance_m=matching.tolerance_m,
        match_by=matching.match_by.value,
        matched=[MatchOut(wms_id=m.wms_id, detected_id=m.detected_id, by=m.by, distance_m=m.distance_m)
                 for m in result.matched],
        missing_in_map=result.missing_in_map,
        unknown_to_wms=result.unknown_to_wms,
        discrepancies=[DiscrepancyOut(wms_id=d.wms_id, wms_position=d.wms_xy, detected_position=d.detected_xy,
                                      delta_m=d.delta_m, distance_m=d.distance_m,
                                      nearest_detected_id=d.nearest_detected_id) for d in result.discrepancies],
        numbering=NumberingOut(
            verdict=check.verdict, id_matches=check.id_matches, far=check.far,
            median_distance_m=check.median_distance_m, offset_m=check.offset_m, offset_support=check.offset_support,
            id_shift=None if shift is None else IdShiftOut(aisle=shift.aisle, bay=shift.bay, level=shift.level,
                                                           support=shift.support),
            message=check.message),
        counts={"matched": len(result.matched), "missing_in_map": len(result.missing_in_map),
                "unknown_to_wms": len(result.unknown_to_wms), "discrepancies": len(result.discrepancies)},
    )


def _import_body() -> dict[str, Any]:
    """The import's body as OpenAPI documents it (the route reads and validates it itself, off the event loop).

    :class:`WmsBinIn` is referred to in the components, where the list route's answer puts it.
    """
    schema = WmsImport.model_json_schema(ref_template="#/components/schemas/{model}")
    schema.pop("$defs", None)
    return {"requestBody": {"required": True, "content": {"application/json": {"schema": schema}}}}


@router.put("", summary="Import the WMS's bin list", responses=_ERRORS, response_model=ReconciliationOut,
            openapi_extra=_import_body())
async def import_wms_bins(request: Request, map_info: MapDep, store: StoreDep, cache: CacheDep,
                          announcer: AnnouncerDep) -> Response:
    """Replace the map's WMS bin list with ``bins`` (one new revision) and return how it matches the detected bins.

    Bins are matched by equal id first, then by position (nearest detected bin within ``tolerance_m``, same
    level when both know it); ``match_by=position`` matches by position wherever the WMS gives one. Matched bins
    are then served under the WMS's id, so a site keeps its numbering. A bin matched by id whose WMS position is
    further than ``tolerance_m`` from the detected bin is listed under ``discrepancies``, and ``numbering`` says
    when most are so (the site numbers bins differently, or surveyed in another frame). Needs a `write` key. A
    large list (up to 200 000 bins) is parsed, checked and stored in a worker thread, so reads go on being
    answered meanwhile.
    """
    body = await request.body()
    answer = await anyio.to_thread.run_sync(_import, body, store, cache, map_info, announcer)
    return Response(answer, media_type="application/json")


def _import(body: bytes, store: MapStore, cache: RevisionCache, map_info: MapInfo, announcer: Announcer) -> bytes:
    """Parse, check and store the WMS list in ``body``; the reconciliation as JSON (in a worker thread)."""
    with background_work():
        answer = _import_list(body, store, cache, map_info, announcer)
    return_freed_memory()
    return answer


def _import_list(body: bytes, store: MapStore, cache: RevisionCache, map_info: MapInfo, announcer: Announcer
                 ) -> bytes:
    """:func:`_import` without its memory handling."""
    parsed = parse_bin_list(WmsImport, body, "WMS bin ids")
    items = [WmsBin(b.id, b.x_m, b.y_m, b.aisle, b.bay, b.level) for b in parsed.bins]
    tolerance_m, match_by = parsed.tolerance_m, MatchBy(parsed.match_by)
    del parsed
    written, matching = import_wms_list(store, cache, map_info.id, items, tolerance_m=tolerance_m, match_by=match_by)
    del items
    announcer.announce(map_info, written)
    return json_bytes(_reconciliation_out(matching).model_dump(mode="json"))


@router.get("/reconciliation", summary="WMS bins against detected bins", responses=_ERRORS)
def get_reconciliation(map_info: MapDep, store: StoreDep, revision: RevisionQuery) -> ReconciliationOut:
    """Which WMS bins are matched to detected bins, which are missing in the map and which detected bins the WMS
    does not know, as of ``?revision=``."""
    return _reconciliation(store, map_info.id, map_info.name, revision)


@router.get("", summary="The imported WMS bin list", responses=_ERRORS)
def list_wms_bins(map_info: MapDep, store: StoreDep, revision: RevisionQuery) -> list[WmsBinIn]:
    """The WMS bin list as last imported (as of ``?revision=``); empty if none was."""
    return [WmsBinIn(id=b.wms_id, x_m=b.x_m, y_m=b.y_m, aisle=b.aisle, bay=b.bay, level=b.level)
            for b in store.wms_bins(map_info.id, revision=revision)]

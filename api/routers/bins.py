"""Storage bins as a WMS wants them: by WMS id, with aisle, bay, level, footprint and where to stand."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Annotated, Any

from fastapi import APIRouter, Depends, HTTPException, Path, Query, status
from pydantic import BaseModel, Field

from api.deps import MapDep, RevisionQuery, StoreDep
from api.models import ErrorOut, Responses
from api.routers.features import BBox, parse_bbox
from shared.store import StoredFeature
from shared.store.records import bounds

router = APIRouter(prefix="/v1/maps/{map_name}/bins", tags=["bins"])

BIN_KIND = "bin"
BIN_ID_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9._:-]{0,127}$"
"""What a bin id may look like (the pillar stage writes ``AA-BBB``: aisle, bay)."""

_ERRORS: Responses = {
    status.HTTP_404_NOT_FOUND: {"model": ErrorOut, "description": "No such map, revision or bin."},
    status.HTTP_422_UNPROCESSABLE_CONTENT: {"model": ErrorOut, "description": "Bad id, filter, bbox or paging."},
}


class AccessPose(BaseModel):
    x_m: float
    y_m: float
    yaw_rad: float = Field(description="Heading to face the bin opening, radians from the map x axis.")


class BinOut(BaseModel):
    id: str = Field(description="WMS id, e.g. `03-014` (aisle 3, bay 14).")
    aisle: int | None
    bay: int | None
    level: int | None = Field(description="Shelf level, 0 = floor; null while unknown.")
    centre: tuple[float, float] = Field(description="(x, y) in map-frame metres.")
    footprint: list[tuple[float, float]] | None = Field(
        description="Closed polygon ring (x, y) in metres, front edge first; null for point bins.")
    access_pose: AccessPose | None = Field(description="Where a vehicle stands in the aisle to reach the bin.")
    row: str | None = Field(description="Key of the aisle-facing rack row (a `rack_row` feature).")
    back_row: str | None = Field(description="Key of the rack row behind the bin, if any.")
    confidence: float | None
    stage: str = Field(description="The stage that wrote the bin.")
    revision_id: int = Field(description="Revision that wrote this version of the bin.")


class BinPage(BaseModel):
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


def bin_out(stored: StoredFeature) -> BinOut:
    """A stored ``bin`` feature (as the pillar stage writes it) in WMS form; missing properties come out null."""
    feature = stored.feature
    properties = feature.properties
    footprint = _footprint(feature.geometry)
    return BinOut(
        id=_str(properties.get("id")) or feature.key,
        aisle=_int(properties.get("aisle")),
        bay=_int(properties.get("bay")),
        level=_int(properties.get("level")),
        centre=_centre(properties, feature.geometry),
        footprint=footprint,
        access_pose=_access_pose(properties.get("access_pose")),
        row=_str(properties.get("row")),
        back_row=_str(properties.get("back_row")),
        confidence=feature.confidence,
        stage=stored.stage,
        revision_id=stored.revision_id,
    )


@router.get("", summary="List and search bins", responses=_ERRORS)
def list_bins(
    map_info: MapDep,
    store: StoreDep,
    revision: RevisionQuery,
    bbox: Annotated[BBox | None, Depends(parse_bbox)],
    aisle: Annotated[int | None, Query(ge=0, le=1_000_000, description="Only bins of this aisle.")] = None,
    row: Annotated[str | None, Query(max_length=128, description="Only bins facing this rack row (its key).")] = None,
    level: Annotated[int | None, Query(ge=0, le=1000, description="Only bins on this level (0 = floor).")] = None,
    id_prefix: Annotated[str | None, Query(max_length=128, description="Only bins whose id starts so, e.g. `03-`.")
                         ] = None,
    limit: Annotated[int, Query(ge=1, le=1000, description="Page size.")] = 100,
    offset: Annotated[int, Query(ge=0, le=10_000_000, description="Bins to skip.")] = 0,
) -> BinPage:
    """Bins of the map (as of ``?revision=``), filtered, sorted by id and paged.

    Filters combine with AND; ``bbox`` keeps bins whose footprint touches the box.
    """
    found = [bin_out(stored) for stored in store.features(map_info.id, kinds=[BIN_KIND], bbox=bbox,
                                                          revision=revision)]
    matching = sorted(
        (item for item in found
         if (aisle is None or item.aisle == aisle) and (row is None or item.row == row)
         and (level is None or item.level == level) and (id_prefix is None or item.id.startswith(id_prefix))),
        key=lambda item: (item.id, item.revision_id),
    )
    page = matching[offset:offset + limit]
    return BinPage(bins=page, total=len(matching), revision=revision, limit=limit, offset=offset,
                   next_offset=offset + limit if offset + limit < len(matching) else None)


@router.get("/{bin_id}", summary="One bin", responses=_ERRORS)
def get_bin(
    map_info: MapDep,
    store: StoreDep,
    revision: RevisionQuery,
    bin_id: Annotated[str, Path(description="WMS id of the bin, e.g. `03-014`.", pattern=BIN_ID_PATTERN)],
) -> BinOut:
    """One bin by its WMS id (as of ``?revision=``), or 404."""
    found = store.feature(map_info.id, BIN_KIND, bin_id, revision=revision)
    if found is None:
        when = "now" if revision is None else f"at revision {revision}"
        raise HTTPException(status.HTTP_404_NOT_FOUND,
                            f"map {map_info.name!r} has no bin {bin_id!r} {when}; list bins at "
                            f"/v1/maps/{map_info.name}/bins?id_prefix=")
    return bin_out(found)

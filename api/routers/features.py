"""Typed map features (walls, rack rows, bins, docks, ...) as GeoJSON."""

from __future__ import annotations

import json
import math
from typing import Annotated

from fastapi import APIRouter, Depends, HTTPException, Path, Query, Response, status

from api.deps import ContextDep, MapDep, RevisionQuery, StoreDep
from api.live_features import FeatureIndex
from api.models import COMMON_ERRORS, UNPROCESSABLE, FeatureCollection, GeoJSONFeature, Responses, not_found
from shared.store import FEATURE_KINDS, StoredFeature

router = APIRouter(prefix="/v1/maps/{map_name}/features", tags=["features"], responses=COMMON_ERRORS)

MAX_BBOX_SIDE_M = 100_000.0
"""Longest accepted bbox side; a warehouse is far smaller, so anything larger is a mistake."""

BBox = tuple[float, float, float, float]

REVISION_HEADER = "X-Aisle-Revision-Id"
"""Response header naming the newest revision a live answer covers."""
MAX_OFFSET = 10_000_000
"""Largest ``?offset=``; a map has far fewer features."""

_ERRORS: Responses = {**not_found("No such map, revision or feature."), **UNPROCESSABLE}


def _check_kinds(kinds: list[str]) -> list[str]:
    unknown = sorted(set(kinds) - FEATURE_KINDS)
    if unknown:
        raise HTTPException(
            status.HTTP_422_UNPROCESSABLE_CONTENT,
            f"unknown feature kind(s) {unknown}; valid kinds: {sorted(FEATURE_KINDS)}",
        )
    return kinds


async def get_kinds(
    kind: Annotated[
        list[str] | None,
        Query(description="Only features of these kinds (repeatable). One of: "
                          f"{', '.join(sorted(FEATURE_KINDS))}.", examples=[["bin", "rack_row"]]),
    ] = None,
) -> list[str] | None:
    return None if kind is None else _check_kinds(kind)


async def parse_bbox(
    bbox: Annotated[
        str | None,
        Query(description="`minx,miny,maxx,maxy` in map-frame metres: only features whose bounds touch it.",
              examples=["0,0,25.5,40"], max_length=200),
    ] = None,
) -> BBox | None:
    """The ``?bbox=`` box, or 422 saying what is wrong with it."""
    if bbox is None:
        return None
    parts = bbox.split(",")
    try:
        values = [float(part) for part in parts]
    except ValueError:
        values = []
    if len(values) != 4 or not all(math.isfinite(v) for v in values):
        raise HTTPException(
            status.HTTP_422_UNPROCESSABLE_CONTENT,
            f"bbox must be four finite numbers minx,miny,maxx,maxy in metres, not {bbox!r}",
        )
    min_x, min_y, max_x, max_y = values
    if min_x > max_x or min_y > max_y:
        raise HTTPException(
            status.HTTP_422_UNPROCESSABLE_CONTENT,
            f"bbox {bbox!r} has min greater than max; order is minx,miny,maxx,maxy",
        )
    if max_x - min_x > MAX_BBOX_SIDE_M or max_y - min_y > MAX_BBOX_SIDE_M:
        raise HTTPException(
            status.HTTP_422_UNPROCESSABLE_CONTENT,
            f"bbox {bbox!r} is more than {MAX_BBOX_SIDE_M:.0f} m on a side; "
            "coordinates are metres in the map frame",
        )
    return min_x, min_y, max_x, max_y


KindsQuery = Annotated[list[str] | None, Depends(get_kinds)]
BBoxQuery = Annotated[BBox | None, Depends(parse_bbox)]


def geojson_feature(stored: StoredFeature) -> GeoJSONFeature:
    feature = stored.feature
    return GeoJSONFeature(
        id=f"{feature.kind}/{feature.key}",
        geometry=dict(feature.geometry),
        properties={
            **feature.properties,
            "kind": feature.kind,
            "key": feature.key,
            "stage": stored.stage,
            "revision_id": stored.revision_id,
            "confidence": feature.confidence,
        },
    )


def _live_collection(index: FeatureIndex, *, kinds: list[str] | None, bbox: BBox | None, limit: int,
                     offset: int) -> Response:
    """The FeatureCollection of the live map from its index, as JSON bytes (the same document as the store's)."""
    page = index.select(kinds=kinds, bbox=bbox)[offset:offset + limit]
    next_offset = offset + len(page) if len(page) == limit else None
    body = b"".join((b'{"type":"FeatureCollection","features":[', b",".join(index.geojson[p] for p in page),
                     f'],"revision":null,"limit":{limit},"offset":{offset},"next_offset":'
                     f'{json.dumps(next_offset)}}}'.encode()))
    return Response(body, media_type="application/json", headers={REVISION_HEADER: str(index.revision_id)})


@router.get("", summary="Features as GeoJSON", responses=_ERRORS, response_model=FeatureCollection)
def list_features(
    *,
    context: ContextDep,
    map_info: MapDep,
    store: StoreDep,
    revision: RevisionQuery,
    kinds: KindsQuery,
    bbox: BBoxQuery,
    limit: Annotated[int, Query(ge=1, le=10_000, description="Page size.", examples=[1000])] = 1000,
    offset: Annotated[int, Query(ge=0, le=MAX_OFFSET, description="Features to skip (paging).", examples=[0])] = 0,
) -> Response | FeatureCollection:
    """A GeoJSON FeatureCollection of the map's features live at ``?revision=`` (default: now).

    Each feature's ``id`` is ``<kind>/<key>``; its properties carry kind, key, the stage and
    revision that wrote it, and its confidence. Features come in a stable order, so
    ``offset``/``limit`` page through them. The header ``X-Aisle-Revision-Id`` names the newest
    revision the answer covers; the live map is served from an in-memory index of its features.
    """
    if revision is None:
        index = context.live_features.index(store, map_info.id)
        if index is not None:
            return _live_collection(index, kinds=kinds, bbox=bbox, limit=limit, offset=offset)
    found = store.features(map_info.id, kinds=kinds, bbox=bbox, revision=revision, limit=limit, offset=offset)
    return FeatureCollection(
        features=[geojson_feature(item) for item in found],
        revision=revision,
        limit=limit,
        offset=offset,
        next_offset=offset + len(found) if len(found) == limit else None,
    )


@router.get("/{kind}/{key:path}", summary="One feature", responses=_ERRORS)
def get_feature(
    map_info: MapDep,
    store: StoreDep,
    revision: RevisionQuery,
    kind: Annotated[str, Path(description="Feature kind, e.g. `bin`.", max_length=32, examples=["bin"])],
    key: Annotated[str, Path(description="Feature key, unique within its kind.", max_length=128,
                             examples=["03-014"])],
) -> GeoJSONFeature:
    """One feature by kind and key, as GeoJSON (newest if several stages assert the same key)."""
    _check_kinds([kind])
    found = store.feature(map_info.id, kind, key, revision=revision)
    if found is None:
        when = "now" if revision is None else f"at revision {revision}"
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"map {map_info.name!r} has no {kind} {key!r} {when}")
    return geojson_feature(found)

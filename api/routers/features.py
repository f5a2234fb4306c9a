"""Typed map features (walls, rack rows, bins, docks, ...) as GeoJSON."""

from __future__ import annotations

import json
import math
from functools import partial
from typing import Annotated

import anyio
from fastapi import APIRouter, Depends, HTTPException, Path, Query, Response, status

from api.deps import ContextDep, MapDep, RevisionQuery, StoreDep
from api.live_features import FeatureIndex
from api.models import COMMON_ERRORS, UNPROCESSABLE, FeatureCollection, GeoJSONFeature, Responses, not_found
from shared.store import FEATURE_KINDS, StoredFeature

router = APIRouter(prefix="/v1/maps/{map_name}/features", tags=["features"], responses=COMMON_ERRORS)

MAX_BBOX_SIDE_M = 100_000.0
"""Longest accepted bbox side; a warehouse is far smaller, so anything larger is a mistake."""

BBox = tuple[float, float, float, float]
MAX_BBOX_TEXT = 200
"""Longest accepted ``?bbox=`` text, characters."""

REVISION_HEADER = "X-Aisle-Revision-Id"
"""Response header naming the newest revision a live answer covers."""
MAX_LIMIT = 10_000
"""Largest page (``?limit=``), features."""
DEFAULT_LIMIT = 1000
MAX_OFFSET = 10_000_000
"""Largest ``?offset=``; a map has far fewer features."""

_ERRORS: Responses = {**not_found("No such map, revision or feature."), **UNPROCESSABLE}


def check_kinds(kinds: list[str]) -> list[str]:
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
    return None if kind is None else check_kinds(kind)


async def parse_bbox(
    bbox: Annotated[
        str | None,
        Query(description="`minx,miny,maxx,maxy` in map-frame metres: only features whose bounds touch it.",
              examples=["0,0,25.5,40"], max_length=MAX_BBOX_TEXT),
    ] = None,
) -> BBox | None:
    """The ``?bbox=`` box, or 422 saying what is wrong with it."""
    return None if bbox is None else bbox_of(bbox)


def bbox_of(text: str) -> BBox:
    """The box ``minx,miny,maxx,maxy`` (metres) of a ``?bbox=``, or 422 saying what is wrong with it."""
    parts = text.split(",")
    try:
        values = [float(part) for part in parts]
    except ValueError:
        values = []
    if len(values) != 4 or not all(math.isfinite(v) for v in values):
        raise HTTPException(
            status.HTTP_422_UNPROCESSABLE_CONTENT,
            f"bbox must be four finite numbers minx,miny,maxx,maxy in metres, not {text!r}",
        )
    min_x, min_y, max_x, max_y = values
    if min_x > max_x or min_y > max_y:
        raise HTTPException(
            status.HTTP_422_UNPROCESSABLE_CONTENT,
            f"bbox {text!r} has min greater than max; order is minx,miny,maxx,maxy",
        )
    if max_x - min_x > MAX_BBOX_SIDE_M or max_y - min_y > MAX_BBOX_SIDE_M:
        raise HTTPException(
            status.HTTP_422_UNPROCESSABLE_CONTENT,
            f"bbox {text!r} is more than {MAX_BBOX_SIDE_M:.0f} m on a side; "
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


def live_collection(index: FeatureIndex, *, kinds: list[str] | None, bbox: BBox | None, limit: int,
                    offset: int) -> bytes:
    """The FeatureCollection of the live map from its index as JSON (the same document as the store's)."""
    page = index.select(kinds=kinds, bbox=bbox)[offset:offset + limit]
    next_offset = offset + len(page) if len(page) == limit else None
    return b"".join((b'{"type":"FeatureCollection","features":[', b",".join(index.geojson[p] for p in page),
                     f'],"revision":null,"limit":{limit},"offset":{offset},"next_offset":'
                     f'{json.dumps(next_offset)}}}'.encode()))


@router.get("", summary="Features as GeoJSON", responses=_ERRORS, response_model=FeatureCollection)
async def list_features(
    *,
    context: ContextDep,
    map_info: MapDep,
    store: StoreDep,
    revision: RevisionQuery,
    kinds: KindsQuery,
    bbox: BBoxQuery,
    limit: Annotated[int, Query(ge=1, le=MAX_LIMIT, description="Page size.", examples=[1000])] = DEFAULT_LIMIT,
    offset: Annotated[int, Query(ge=0, le=MAX_OFFSET, description="Features to skip (paging).", examples=[0])] = 0,
) -> Response | FeatureCollection:
    """A GeoJSON FeatureCollection of the map's features live at ``?revision=`` (default: now).

    Each feature's ``id`` is ``<kind>/<key>``; its properties carry kind, key, the stage and
    revision that wrote it, and its confidence. Features come in a stable order, so
    ``offset``/``limit`` page through them.

    The live map (no ``?revision=``) is served from memory, and may be up to 0.2 s behind the newest
    revision (revisions a client wrote through the API are always in); the header ``X-Aisle-Revision-Id``
    names the newest revision the answer covers.
    """
    if revision is None:
        live = await context.live.get(map_info)
        if live is not None:
            return Response(live_collection(live.features, kinds=kinds, bbox=bbox, limit=limit, offset=offset),
                            media_type="application/json", headers={REVISION_HEADER: str(live.revision_id)})
    found = await anyio.to_thread.run_sync(partial(store.features, map_info.id, kinds=kinds, bbox=bbox,
                                                   revision=revision, limit=limit, offset=offset))
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
    check_kinds([kind])
    found = store.feature(map_info.id, kind, key, revision=revision)
    if found is None:
        when = "now" if revision is None else f"at revision {revision}"
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"map {map_info.name!r} has no {kind} {key!r} {when}")
    return geojson_feature(found)

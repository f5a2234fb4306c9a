"""Typed map features (walls, rack rows, bins, docks, ...) as GeoJSON."""

from __future__ import annotations

from functools import partial
from typing import Annotated

import anyio
from fastapi import APIRouter, HTTPException, Path, Query, Response, status

from api.deps import ContextDep, MapDep, RevisionQuery, StoreDep, check_revision
from api.models import COMMON_ERRORS, UNPROCESSABLE, FeatureCollection, Responses, naming_revision, not_found
from api.queries import (
    DEFAULT_LIMIT,
    MAX_LIMIT,
    MAX_OFFSET,
    BBoxQuery,
    CursorQuery,
    KindsQuery,
    check_kinds,
    cursors_at,
    next_cursor,
    page_start,
)
from atlas.features import GeoJSONFeature, geojson_feature, live_collection
from atlas.precision import json_bytes
from shared.vocabulary import REVISION_HEADER

router = APIRouter(prefix="/v1/maps/{map_name}/features", tags=["features"], responses=COMMON_ERRORS)

_ERRORS: Responses = {**not_found("No such map, revision or feature."), **UNPROCESSABLE}


@router.get("", summary="Features as GeoJSON", responses=naming_revision(_ERRORS), response_model=FeatureCollection)
async def list_features(
    *,
    context: ContextDep,
    map_info: MapDep,
    store: StoreDep,
    revision: RevisionQuery,
    cursor: CursorQuery,
    kinds: KindsQuery,
    bbox: BBoxQuery,
    limit: Annotated[int, Query(ge=1, le=MAX_LIMIT, description="Page size, count of features.",
                                examples=[1000])] = DEFAULT_LIMIT,
    offset: Annotated[int, Query(ge=0, le=MAX_OFFSET, description="Features to skip (paging), count.",
                                 examples=[0])] = 0,
) -> Response:
    """A GeoJSON FeatureCollection of the map's features live at ``?revision=`` (default: now).

    Each feature's ``id`` is ``<kind>/<key>``; its properties carry kind, key, the stage and
    revision that wrote it, and its confidence. Features come in a stable order, so
    ``offset``/``limit`` page through them; ``?cursor=<next_cursor>`` pages through them at the revision the
    first page was read at, however many revisions arrive meanwhile.

    The live map (no ``?revision=``) is served from memory, and may be up to 0.2 s behind the newest
    revision (revisions a client wrote through the API are always in); ``revision`` and the header
    ``X-Aisle-Revision-Id`` name the revision the answer covers.
    """
    at, offset = page_start(cursor, revision, offset)
    if cursor is not None:
        await anyio.to_thread.run_sync(check_revision, store, map_info, cursor.revision)
    if revision is None:
        live = await context.live.get(map_info)
        if live is not None and (at is None or at == live.revision_id):
            body = live_collection(live.features, kinds=kinds, bbox=bbox, limit=limit, offset=offset,
                                   next_cursor=cursors_at(live.revision_id))
            return Response(body, media_type="application/json", headers={REVISION_HEADER: str(live.revision_id)})
    found = await anyio.to_thread.run_sync(partial(store.features, map_info.id, kinds=kinds, bbox=bbox,
                                                   revision=at, limit=limit, offset=offset))
    next_offset = offset + len(found) if len(found) == limit else None
    page = FeatureCollection(
        features=[geojson_feature(item) for item in found],
        revision=at,
        limit=limit,
        offset=offset,
        next_offset=next_offset,
        next_cursor=next_cursor(at, offset + limit, more=next_offset is not None),
    )
    return Response(json_bytes(page.model_dump(mode="json")), media_type="application/json",
                    headers={} if at is None else {REVISION_HEADER: str(at)})


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

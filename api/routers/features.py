"""Typed map features (walls, rack rows, bins, docks, ...) as GeoJSON."""

from __future__ import annotations

import math
from typing import Annotated

from fastapi import APIRouter, Depends, HTTPException, Path, Query, status

from api.deps import MapDep, RevisionQuery, StoreDep
from api.models import ErrorOut, FeatureCollection, GeoJSONFeature, Responses
from shared.store import FEATURE_KINDS, StoredFeature

router = APIRouter(prefix="/v1/maps/{map_name}/features", tags=["features"])

MAX_BBOX_SIDE_M = 100_000.0
"""Longest accepted bbox side; a warehouse is far smaller, so anything larger is a mistake."""

BBox = tuple[float, float, float, float]

_ERRORS: Responses = {
    status.HTTP_404_NOT_FOUND: {"model": ErrorOut, "description": "No such map, revision or feature."},
    status.HTTP_422_UNPROCESSABLE_CONTENT: {"model": ErrorOut, "description": "Bad kind, bbox or paging."},
}


def _check_kinds(kinds: list[str]) -> list[str]:
    unknown = sorted(set(kinds) - FEATURE_KINDS)
    if unknown:
        raise HTTPException(
            status.HTTP_422_UNPROCESSABLE_CONTENT,
            f"unknown feature kind(s) {unknown}; valid kinds: {sorted(FEATURE_KINDS)}",
        )
    return kinds


def get_kinds(
    kind: Annotated[
        list[str] | None,
        Query(description="Only features of these kinds (repeatable). One of: "
                          f"{', '.join(sorted(FEATURE_KINDS))}."),
    ] = None,
) -> list[str] | None:
    return None if kind is None else _check_kinds(kind)


def parse_bbox(
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


@router.get("", summary="Features as GeoJSON", responses=_ERRORS)
def list_features(
    *,
    map_info: MapDep,
    store: StoreDep,
    revision: RevisionQuery,
    kinds: KindsQuery,
    bbox: BBoxQuery,
    limit: Annotated[int, Query(ge=1, le=10_000, description="Page size.")] = 1000,
    offset: Annotated[int, Query(ge=0, description="Features to skip (paging).")] = 0,
) -> FeatureCollection:
    """A GeoJSON FeatureCollection of the map's features live at ``?revision=`` (default: now).

    Each feature's ``id`` is ``<kind>/<key>``; its properties carry kind, key, the stage and
    revision that wrote it, and its confidence. Features come in a stable order, so
    ``offset``/``limit`` page through them.
    """
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
    kind: Annotated[str, Path(description="Feature kind, e.g. `bin`.")],
    key: Annotated[str, Path(description="Feature key, unique within its kind.")],
) -> GeoJSONFeature:
    """One feature by kind and key, as GeoJSON (newest if several stages assert the same key)."""
    _check_kinds([kind])
    matches = [item for item in store.features(map_info.id, kinds=[kind], revision=revision)
               if item.feature.key == key]
    if not matches:
        when = "now" if revision is None else f"at revision {revision}"
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"map {map_info.name!r} has no {kind} {key!r} {when}")
    return geojson_feature(max(matches, key=lambda item: item.revision_id))

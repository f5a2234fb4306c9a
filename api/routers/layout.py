"""The whole layered map at once: as one GeoJSON FeatureCollection, and as a picture (PNG or SVG) with a legend."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, HTTPException, Query, Response, status

from api.answers import MetricJSONResponse
from api.deps import MAX_ID, MapDep, RevisionQuery, SettingsDep, StoreDep
from api.models import COMMON_ERRORS, UNPROCESSABLE, ErrorOut, Responses, as_json, naming_revision, not_found
from api.queries import BBoxQuery, KindsQuery
from api.translate import http_error
from atlas.features import BBox
from atlas.layout import MEDIA_TYPE as GEOJSON_MEDIA_TYPE
from atlas.layout import LayoutCollection, LayoutTooLargeError, Picture, layout_collection, layout_picture
from atlas.render.layers import RenderError
from atlas.render.scene import DEFAULT_KINDS, MAX_SIDE_PX, MIN_WIDTH_PX, NothingToDrawError
from atlas.render.svg import MEDIA_TYPE as SVG_MEDIA_TYPE
from shared.settings import Settings
from shared.store import MapInfo, MapStore
from shared.vocabulary import REVISION_HEADER

router = APIRouter(prefix="/v1/maps/{map_name}", tags=["layout"])

MAX_LAYOUT_FEATURES = 20_000
"""Most features ``/layout`` returns at once (the 250 m x 72 m test hall has about 12 800); more is a 413."""
MAX_PICTURE_FEATURES = 100_000
"""Most features a picture draws; more is a 413."""

_ERRORS: Responses = {
    **COMMON_ERRORS,
    **not_found("No such map or revision, or (pictures without a bbox) nothing to draw yet."),
    status.HTTP_413_CONTENT_TOO_LARGE: {"model": ErrorOut,
                                        "description": "Too many features; narrow the bbox or the kinds."},
    **UNPROCESSABLE,
}


class GeoJSONResponse(MetricJSONResponse):
    media_type = GEOJSON_MEDIA_TYPE


@router.get(
    "/layout",
    summary="The whole map as GeoJSON",
    response_model=LayoutCollection,
    response_class=GeoJSONResponse,
    responses=naming_revision(as_json(_ERRORS)),
)
def get_layout(map_info: MapDep, store: StoreDep, revision: RevisionQuery, kinds: KindsQuery,
               bbox: BBoxQuery, since: Annotated[int | None, Query(ge=0, le=MAX_ID, examples=[1200], description=(
                   "Only what changed after this revision: the features added or changed since, and in `removed` "
                   "the keys of those gone (a viewer keeping its copy up to date)."))] = None) -> Response:
    """Every feature of the map (walls, corridors, junctions, rooms, open areas, rack rows, pillars, bins,
    docks, gates, chargers, objects, ...) as one GeoJSON FeatureCollection, in map-frame metres.

    Filter with `?kind=` (repeatable) and `?bbox=minx,miny,maxx,maxy` (features whose bounds touch
    it). The collection also gives the features' `bbox`, the `frame` the coordinates are in, the
    `revision_id` read at (the newest when `?revision=` is not given; also the header `X-Aisle-Revision-Id`)
    and a count per kind. It is
    not paged: more than 20 000 matching features is a 413; narrow the bbox or the kinds, or page
    through `/features`. With `?since=<revision>` it holds only what changed after that revision: the
    features added or changed, and `removed`, the keys per kind of the features gone.
    """
    try:
        collection = layout_collection(store, map_info, revision=revision, kinds=kinds, bbox=bbox,
                                       max_features=MAX_LAYOUT_FEATURES, since=since)
    except LayoutTooLargeError as err:
        raise http_error(err) from err
    headers = {} if collection.revision_id is None else {REVISION_HEADER: str(collection.revision_id)}
    return Response(collection.to_json(), media_type=GEOJSON_MEDIA_TYPE, headers=headers)


WidthQuery = Annotated[int, Query(ge=MIN_WIDTH_PX, le=MAX_SIDE_PX, examples=[1024],
                                  description="Width of the map part of the picture in pixels; the legend is "
                                              "drawn to its right.")]

_PICTURE_DOC = """

The occupancy layer is the background (free white, occupied black, unknown grey), place labels
tint it (corridors, junctions, storage, ...), and the features are drawn on top with a fixed
colour per kind: rooms and corridors outlined, rack rows and walls as lines, bins as small
polygons, pillars as dots, docks, gates, chargers and objects as markers. The legend on the right
names the revision, every kind drawn with its count, the place labels shown, and a scale bar.

`kind` (repeatable) picks the kinds drawn (default: all but `line`, the decomposition's cut
lines, and `bin_state` and `load_scene`, a dot on every bin and bay); `bbox` the area shown (default: the whole
map); `width` the map's width in pixels (64..4096; the height follows the map's aspect, at most 4096).
"""


def _scene_response(store: MapStore, settings: Settings, map_info: MapInfo, revision: int | None,
                    kinds: list[str] | None, bbox: BBox | None, width: int, *, svg: bool) -> Response:
    try:
        picture: Picture = layout_picture(
            store, map_info, revision=revision, kinds=kinds or DEFAULT_KINDS, bbox=bbox, width_px=width, svg=svg,
            occupancy_layer=settings.occupancy.layer, label_layer=settings.decomposition.label_layer,
            max_features=MAX_PICTURE_FEATURES)
    except LayoutTooLargeError as err:
        raise http_error(err) from err
    except NothingToDrawError as err:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"map {map_info.name!r}: {err}; pass ?bbox= to draw an "
                                                       "empty area") from err
    except RenderError as err:
        raise HTTPException(status.HTTP_422_UNPROCESSABLE_CONTENT, str(err)) from err
    headers = {} if picture.revision_id is None else {REVISION_HEADER: str(picture.revision_id)}
    return Response(picture.content, media_type=picture.media_type, headers=headers)


@router.get(
    "/layout.png",
    summary="The map as a PNG picture with a legend",
    response_class=Response,
    responses={status.HTTP_200_OK: {"content": {"image/png": {}}, "description": "PNG, north up."}, **_ERRORS},
    description=f"The map drawn as a PNG, north up (x right, y up).{_PICTURE_DOC}",
)
def layout_png(map_info: MapDep, store: StoreDep, settings: SettingsDep, revision: RevisionQuery, kinds: KindsQuery,
               bbox: BBoxQuery, width: WidthQuery = 1024) -> Response:
    return _scene_response(store, settings, map_info, revision, kinds, bbox, width, svg=False)


@router.get(
    "/layout.svg",
    summary="The map as an SVG picture with a legend",
    response_class=Response,
    responses={status.HTTP_200_OK: {"content": {SVG_MEDIA_TYPE: {}}, "description": "SVG, north up."}, **_ERRORS},
    description=(
        "The map drawn as SVG: features in map metres under a y-flipping transform, each with a `<title>` "
        "(kind and key) shown on hover; the background embedded as a PNG image." + _PICTURE_DOC
    ),
)
def layout_svg(map_info: MapDep, store: StoreDep, settings: SettingsDep, revision: RevisionQuery, kinds: KindsQuery,
               bbox: BBoxQuery, width: WidthQuery = 1024) -> Response:
    return _scene_response(store, settings, map_info, revision, kinds, bbox, width, svg=True)

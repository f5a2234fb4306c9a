"""The whole layered map at once: as one GeoJSON FeatureCollection (the ``layout``), and as a picture (PNG or SVG)
with a legend."""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field

from atlas.errors import TooLargeError
from atlas.features import BBox, GeoJSONFeature, geojson_feature, stored_feature
from atlas.precision import json_bytes
from atlas.render.png import render_png
from atlas.render.scene import layout_scene
from atlas.render.svg import MEDIA_TYPE as SVG_MEDIA_TYPE
from atlas.render.svg import render_svg
from shared.store import MapInfo, MapStore, StoredFeature
from shared.store.records import bounds

MEDIA_TYPE = "application/geo+json"
"""Media type of GeoJSON."""


LAYOUT_EXAMPLE: dict[str, Any] = {
    "type": "FeatureCollection", "bbox": [40.6, 17.1, 41.8, 18.1],
    "frame": {"map": "site", "frame_id": "map", "units": "m",
              "axes": "x, y in the map frame (not WGS84 longitude/latitude); y up, as in ROS"},
    "revision_id": 1207, "kinds": {"bin": 1},
    "features": [{"type": "Feature", "id": "bin/03-014",
                  "geometry": {"type": "Polygon", "coordinates": [[[40.6, 17.1], [41.8, 17.1], [41.8, 18.1],
                                                                   [40.6, 18.1], [40.6, 17.1]]]},
                  "properties": {"aisle": 3, "bay": 14, "kind": "bin", "key": "03-014", "stage": "pillar_mapping",
                                 "revision_id": 1207, "confidence": 0.92}}],
}
"""An example layout (OpenAPI docs)."""


class LayoutTooLargeError(TooLargeError):
    """More features than a layout request may return at once."""


class LayoutFrame(BaseModel):
    """The frame the coordinates are in."""

    map: str = Field(description="Map name.")
    frame_id: str = Field(description="ROS frame of the coordinates, e.g. `map`.")
    units: Literal["m"] = Field("m", description="Coordinates are metres.")
    axes: str = Field("x, y in the map frame (not WGS84 longitude/latitude); y up, as in ROS",
                      description="What the coordinates mean.")

    model_config = ConfigDict(json_schema_extra={"examples": [{
        "map": "site", "frame_id": "map", "units": "m",
        "axes": "x, y in the map frame (not WGS84 longitude/latitude); y up, as in ROS"}]})


class LayoutCollection(BaseModel):
    """A GeoJSON FeatureCollection of every feature of the map, with its extent and frame.

    ``frame`` and ``revision_id`` are foreign members (RFC 7946, section 6.1); ``bbox`` is the
    standard member and is left out when there are no features.
    """

    type: Literal["FeatureCollection"] = "FeatureCollection"
    bbox: BBox | None = Field(
        None, description="[min_x, min_y, max_x, max_y] of the features' geometries, metres, map frame (RFC 7946 "
                          "bbox)."
    )
    frame: LayoutFrame
    revision_id: int | None = Field(
        description="The revision read at: `?revision=` if given, else the newest when the request was served; "
                    "null for a map without revisions."
    )
    kinds: dict[str, int] = Field(description="How many of the features are of each kind.")
    features: list[GeoJSONFeature]
    since_revision_id: int | None = Field(
        None, description="With `?since=`: the revision the changes are counted from; `features` then holds only "
                          "the features added or changed after it, and `removed` the keys of those gone since.")
    removed: dict[str, list[str]] | None = Field(
        None, description="With `?since=`: per kind, the keys of features live at `since_revision_id` and not now.")

    model_config = ConfigDict(json_schema_extra={"examples": [LAYOUT_EXAMPLE]})

    def to_json(self) -> bytes:
        """The collection as GeoJSON text; ``bbox`` is left out when there are no features (RFC 7946 wants
        an array or nothing)."""
        leave_out = {name for name in ("bbox", "since_revision_id", "removed") if getattr(self, name) is None}
        return json_bytes(self.model_dump(mode="json", exclude=leave_out or None))


def read_revision(store: MapStore, map_info: MapInfo, revision: int | None) -> int | None:
    """``revision`` if given, else the map's newest revision id (None when it has none)."""
    if revision is not None:
        return revision
    latest = store.latest_revision(map_info.id)
    return None if latest is None else latest.id


def features_bbox(found: Sequence[StoredFeature]) -> BBox | None:
    """The union of the features' bounds (metres), or None for no features."""
    if not found:
        return None
    boxes = [bounds(item.feature.geometry) for item in found]
    return (min(b[0] for b in boxes), min(b[1] for b in boxes), max(b[2] for b in boxes), max(b[3] for b in boxes))


def layout_features(store: MapStore, map_info: MapInfo, *, revision: int | None, kinds: Sequence[str] | None = None,
                    bbox: BBox | None = None, max_features: int | None = None) -> list[StoredFeature]:
    """The features live at ``revision`` (of ``kinds``, touching ``bbox``), in a stable order.

    Raises
    ------
    LayoutTooLargeError
        More than ``max_features`` match.
    """
    found = store.features(map_info.id, kinds=kinds, bbox=bbox, revision=revision,
                           limit=None if max_features is None else max_features + 1)
    if max_features is not None and len(found) > max_features:
        where = "in that bbox" if bbox is not None else "in the whole map"
        raise LayoutTooLargeError(
            f"more than {max_features} features {where}; narrow ?bbox= or ask for fewer ?kind=, "
            f"or page through /v1/maps/{map_info.name}/features"
        )
    return found


def layout_collection(store: MapStore, map_info: MapInfo, *, revision: int | None,
                      kinds: Sequence[str] | None = None, bbox: BBox | None = None,
                      max_features: int | None = None, since: int | None = None) -> LayoutCollection:
    """The map's layout as of ``revision`` (default: the newest), optionally of ``kinds`` and touching ``bbox``.

    Parameters
    ----------
    store, map_info
        The store and the map to read.
    revision : int, optional
        Revision id to read at; None: the newest, named in the result's ``revision_id``.
    kinds : sequence of str, optional
        Feature kinds to include (default: all).
    bbox : (min_x, min_y, max_x, max_y), optional
        Only features whose bounds touch this box, metres.
    max_features : int, optional
        Refuse (:class:`LayoutTooLargeError`) when more features match.
    since : int, optional
        Only what changed after this revision (a client's copy): the features written after it, and the keys of
        those removed since (``removed``). ``max_features`` then bounds the changed features.
    """
    at = read_revision(store, map_info, revision)
    removed: dict[str, list[str]] | None = None
    if since is None:
        found = layout_features(store, map_info, revision=at, kinds=kinds, bbox=bbox, max_features=max_features)
    else:
        found, removed = _changes(store, map_info, since=since, at=at, kinds=kinds, bbox=bbox)
        if max_features is not None and len(found) > max_features:
            raise LayoutTooLargeError(f"more than {max_features} features changed since revision {since}; "
                                      "read the layout without ?since=")
    return LayoutCollection(
        bbox=features_bbox(found),
        frame=LayoutFrame(map=map_info.name, frame_id=map_info.frame_id),
        revision_id=at,
        kinds=dict(sorted(Counter(item.feature.kind for item in found).items())),
        features=[geojson_feature(item) for item in found],
        since_revision_id=since,
        removed=removed,
    )




def _changes(store: MapStore, map_info: MapInfo, *, since: int, at: int | None, kinds: Sequence[str] | None,
             bbox: BBox | None) -> tuple[list[StoredFeature], dict[str, list[str]]]:
    """The features live at ``at`` that revisions after ``since`` wrote, and per kind the keys live at ``since``
    and not at ``at``; read from the rows those revisions wrote or retired, not from the whole map."""
    if at is None or at <= since:
        return [], {}
    rows = [row for row in store.feature_rows_changed(map_info.id, after=since, upto=at)
            if (not kinds or row.kind in kinds) and (bbox is None or _touches(row.bounds, bbox))]
    live = [row for row in rows if row.revision_id > since
            and (row.retired_revision_id is None or row.retired_revision_id > at)]
    live_keys = {(row.kind, row.key) for row in live}
    gone: dict[str, set[str]] = {}
    for row in rows:
        if row.revision_id <= since and (row.kind, row.key) not in live_keys:
            gone.setdefault(row.kind, set()).add(row.key)
    return [stored_feature(row) for row in live], {kind: sorted(keys) for kind, keys in sorted(gone.items())}


def _touches(bounds: BBox, bbox: BBox) -> bool:
    return bounds[2] >= bbox[0] and bounds[0] <= bbox[2] and bounds[3] >= bbox[1] and bounds[1] <= bbox[3]


@dataclass(frozen=True, slots=True)
class Picture:
    """A picture of the layout: its bytes, their media type and the revision drawn (None: no revisions)."""

    content: bytes
    media_type: str
    revision_id: int | None


def layout_picture(store: MapStore, map_info: MapInfo, *, revision: int | None, kinds: Sequence[str],
                   bbox: BBox | None, width_px: int, svg: bool, occupancy_layer: str, label_layer: str,
                   max_features: int) -> Picture:
    """The map as of ``revision`` (default: the newest) drawn as SVG or PNG (:func:`atlas.render.scene.layout_scene`).

    Parameters
    ----------
    store, map_info
        The store and the map to draw.
    revision : int, optional
        Revision id to draw; None: the newest.
    kinds : sequence of str
        Feature kinds drawn.
    bbox : (min_x, min_y, max_x, max_y), optional
        The area drawn, metres; None: the whole map.
    width_px : int
        Width of the map part of the picture, pixels.
    svg : bool
        SVG if true, else PNG.
    occupancy_layer, label_layer : str
        Names of the background's occupancy layer and of the place-label layer that tints it.
    max_features : int
        Refuse (:class:`LayoutTooLargeError`) to draw more features.

    Raises
    ------
    LayoutTooLargeError
        More than ``max_features`` features to draw.
    NothingToDrawError
        Nothing to draw and no ``bbox``.
    RenderError
        A picture that cannot be drawn as asked.
    """
    at = read_revision(store, map_info, revision)
    found = layout_features(store, map_info, revision=at, kinds=kinds, bbox=bbox, max_features=max_features)
    occupancy = labels = None
    if at is not None:
        occupancy = store.layer(map_info.id, occupancy_layer, revision=at)
        labels = store.layer(map_info.id, label_layer, revision=at)
    scene = layout_scene([item.feature for item in found], occupancy=None if occupancy is None else occupancy.layer,
                         place_labels=None if labels is None else labels.layer, bbox=bbox, width_px=width_px,
                         title=f"{map_info.name} @ revision {at}")
    if svg:
        return Picture(render_svg(scene), SVG_MEDIA_TYPE, at)
    return Picture(render_png(scene), "image/png", at)

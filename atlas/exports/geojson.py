"""The ``geojson`` export: the whole layered map as one GeoJSON FeatureCollection (:mod:`atlas.layout`)."""

from __future__ import annotations

from atlas.exports.base import Export, ExportOptions
from atlas.layout import MEDIA_TYPE, layout_collection
from shared.store import MapInfo, MapStore


def export_geojson(store: MapStore, map_info: MapInfo, revision: int, options: ExportOptions) -> Export:
    """The ``geojson`` export: every feature of the map as of ``revision``, as a :class:`LayoutCollection`."""
    collection = layout_collection(store, map_info, revision=revision)
    return Export({f"{options.stem}.geojson": collection.to_json()}, MEDIA_TYPE)

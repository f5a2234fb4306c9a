"""VDMA LIF 1.0 (Layout Interchange Format) of a map: its waypoint network as nodes, edges and stations.

Junction, room and open-area hubs, portals between regions, bin access points, docks, gates and
chargers are nodes (:mod:`atlas.navigation.network`); each leg inside a region becomes two directed
edges named after the region (``edgeName``: the corridor's key); every bin (``stationId`` = its WMS
id) and every place (``dock-G1``, ``charger-C1``) is a station at its access node. One vehicle type
(``vehicle_type_id``) may use everything; blocked regions and connections are left out.
"""

from __future__ import annotations

import datetime as dt
import math
from typing import Any

from atlas.exports.base import Export, ExportNotFoundError, ExportOptions
from atlas.navigation import NavigationError, load_navmap
from atlas.navigation.network import Network, waypoint_network
from atlas.precision import json_bytes
from shared.store import Feature, MapInfo, MapStore
from shared.vocabulary import PLACE_KINDS, FeatureKind

LIF_VERSION = "1.0.0"
MEDIA_TYPE = "application/json"


def _angle(yaw: float | None) -> float | None:
    return None if yaw is None else math.atan2(math.sin(yaw), math.cos(yaw))


def newest_features(store: MapStore, map_id: int, kinds: list[str], revision: int | None) -> list[Feature]:
    """Features of ``kinds`` live at ``revision``, one per kind and key (the newest when stages disagree)."""
    newest: dict[tuple[str, str], tuple[int, Feature]] = {}
    for stored in store.features(map_id, kinds=kinds, revision=revision):
        ident = (stored.feature.kind, stored.feature.key)
        if ident not in newest or stored.revision_id >= newest[ident][0]:
            newest[ident] = (stored.revision_id, stored.feature)
    return [feature for _, feature in newest.values()]


def map_network(store: MapStore, map_info: MapInfo, revision: int | None) -> tuple[Network, int | None]:
    """The waypoint network of a map as of ``revision``, with its bins and places, and the revision read at.

    Raises
    ------
    NavigationUnavailableError
        The map has not been decomposed into regions.
    """
    nav = load_navmap(store, map_info.id, revision=revision)
    bins = newest_features(store, map_info.id, [FeatureKind.BIN], nav.revision)
    places = newest_features(store, map_info.id, list(PLACE_KINDS), nav.revision)
    return waypoint_network(nav, bins=bins, places=places), nav.revision


def lif_document(store: MapStore, map_info: MapInfo, revision: int | None, *, project_id: str = "Aisle",
                 creator: str = "Aisle", vehicle_type_id: str = "aisle.default", level_id: str = "L1"
                 ) -> dict[str, Any]:
    """The map as of ``revision`` (default: now) as a LIF 1.0 document (one layout).

    Parameters
    ----------
    store, map_info : MapStore, MapInfo
        The map.
    revision : int or None
        Revision to export.
    project_id, creator : str
        ``metaInformation`` fields.
    vehicle_type_id : str
        The vehicle type every node and edge is open to.
    level_id : str
        ``layoutLevelId``.

    Raises
    ------
    NavigationUnavailableError
        The map has not been decomposed into regions.
    """
    net, at = map_network(store, map_info, revision)
    vehicle = {"vehicleTypeId": vehicle_type_id}
    nodes = []
    for node in net.nodes:
        theta = _angle(node.yaw_rad)
        named = node.bins[0] if node.bins else node.place[1] if node.place else node.id
        nodes.append({
            "nodeId": node.id,
            "nodeName": named,
            "nodeDescription": f"{node.kind} in region {node.region}",
            "mapId": map_info.name,
            "nodePosition": {"x": node.x_m, "y": node.y_m},
            "vehicleTypeNodeProperties": [vehicle if theta is None else {**vehicle, "theta": theta}],
        })
    edges = []
    for edge in net.edges:
        for suffix, start, end in (("ab", edge.a, edge.b), ("ba", edge.b, edge.a)):
            edges.append({
                "edgeId": f"{edge.id}/{suffix}",
                "edgeName": edge.region,
                "edgeDescription": f"{edge.region_kind} {edge.region}, {edge.length_m:.2f} m",
                "startNodeId": start,
                "endNodeId": end,
                "vehicleTypeEdgeProperties": [{**vehicle, "rotationAllowed": True}],
            })
    stations = []
    for station in net.stations:
        position: dict[str, float] = {"x": station.x_m, "y": station.y_m}
        theta = _angle(station.yaw_rad)
        if theta is not None:
            position["theta"] = theta
        item: dict[str, Any] = {
            "stationId": station.id,
            "interactionNodeIds": [station.node],
            "stationName": station.name or station.key,
            "stationDescription": f"{station.kind} {station.key}",
            "stationPosition": position,
        }
        if station.height_m is not None and station.height_m >= 0:
            item["stationHeight"] = station.height_m
        stations.append(item)
    left = f"; left out (no drivable region within reach): {', '.join(net.left_out)}" if net.left_out else ""
    return {
        "metaInformation": {
            "projectIdentification": project_id,
            "creator": creator,
            "exportTimestamp": dt.datetime.now(dt.UTC).strftime("%Y-%m-%dT%H:%M:%S.%f")[:-4] + "Z",
            "lifVersion": LIF_VERSION,
        },
        "layouts": [{
            "layoutId": map_info.name,
            "layoutName": map_info.name,
            "layoutVersion": str(at if at is not None else 0),
            "layoutLevelId": level_id,
            "layoutDescription": f"Aisle map {map_info.name!r} at revision {at} (frame {map_info.frame_id}, "
                                 f"metres){left}",
            "nodes": nodes,
            "edges": edges,
            "stations": stations,
        }],
    }


def export_lif(store: MapStore, map_info: MapInfo, revision: int, options: ExportOptions) -> Export:
    """The ``lif`` export: ``<stem>.lif.json`` (see :func:`lif_document`)."""
    try:
        document = lif_document(store, map_info, revision)
    except NavigationError as err:
        raise ExportNotFoundError(str(err)) from err
    return Export({f"{options.stem}.lif.json": json_bytes(document, indent=1)}, MEDIA_TYPE)

"""The region graph of a navigation map as networkx node-link data and as GeoJSON features."""

from __future__ import annotations

from typing import Any

import networkx as nx

from atlas.navigation.graph import NavMap


def topology_graph(nav: NavMap, *, map_name: str) -> nx.Graph:
    """The regions of ``nav`` (nodes keyed ``r<id>``: kind, centroid, area, aisle, drivable, blocked) and their
    connections (connection, blocked, portal (x, y) metres, width), for ``networkx.node_link_data``."""
    graph = nx.Graph(map=map_name, revision=nav.revision, segments_revision_id=nav.grid.segments_revision)
    for _, data in sorted(nav.graph.nodes(data=True)):
        region = data["region"]
        graph.add_node(region.key, kind=region.kind, x=region.x_m, y=region.y_m, area_m2=region.area_m2,
                       aisle=region.aisle, drivable=region.drivable, blocked=data["blocked"])
    for a, b, data in sorted(nav.graph.edges(data=True)):
        portal = data["portal"]
        graph.add_edge(nav.key(a), nav.key(b), connection=data["connection"], blocked=data["blocked"],
                       portal=None if portal is None else (portal.x_m, portal.y_m),
                       width_m=None if portal is None else portal.width_m)
    return graph


def topology_node_link(nav: NavMap, *, map_name: str) -> dict[str, Any]:
    """:func:`topology_graph` as networkx node-link data (``networkx.node_link_graph(data, edges="edges")``
    reads it back)."""
    data: dict[str, Any] = nx.node_link_data(topology_graph(nav, map_name=map_name), edges="edges")
    return data


def topology_features(nav: NavMap) -> list[dict[str, Any]]:
    """GeoJSON features of ``nav``: each region with a centroid as a Point, each connection with a portal as a
    LineString hub, portal, hub (map metres)."""
    features: list[dict[str, Any]] = []
    for _, data in sorted(nav.graph.nodes(data=True)):
        region = data["region"]
        if region.x_m is None or region.y_m is None:
            continue
        features.append({
            "id": region.key, "geometry": {"type": "Point", "coordinates": [region.x_m, region.y_m]},
            "properties": {"kind": region.kind, "area_m2": region.area_m2, "aisle": region.aisle,
                           "drivable": region.drivable, "blocked": data["blocked"]}})
    for a, b, data in sorted(nav.graph.edges(data=True)):
        portal, hubs = data["portal"], (nav.hub(a), nav.hub(b))
        if portal is None or hubs[0] is None or hubs[1] is None:
            continue
        line = [list(hubs[0]), [portal.x_m, portal.y_m], list(hubs[1])]
        features.append({
            "id": f"{nav.key(a)}-{nav.key(b)}", "geometry": {"type": "LineString", "coordinates": line},
            "properties": {"source": nav.key(a), "target": nav.key(b), "connection": data["connection"],
                           "blocked": data["blocked"], "width_m": portal.width_m}})
    return features

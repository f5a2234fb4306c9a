"""Open-RMF navigation graph of a map, as ``rmf_building_map_tools`` writes it and ``parse_graph`` reads it.

``{building_name, levels: {L1: {vertices: [[x, y, {name, ...}]], lanes: [[i, j, {...}]]}}, lifts, doors}``:
vertices are the waypoint network's nodes (:mod:`atlas.navigation.network`), with their names (a bin
access point takes its first bin's id, a place its key) and flags (a charger ``is_charger``,
``is_parking_spot``, ``is_holding_point``; a dock ``dock_name``). Each leg becomes two lanes, one
each way, as the building map generator writes bidirectional lanes (``parse_graph`` reads every lane
as one-way).
"""

from __future__ import annotations

from collections import Counter
from typing import Any

import yaml

from atlas.exports.base import Export, ExportNotFoundError, ExportOptions
from atlas.exports.lif import map_network
from atlas.navigation import NavigationError
from atlas.navigation.network import NetNode
from atlas.precision import rounded
from shared.store import MapInfo, MapStore
from shared.vocabulary import FeatureKind

MEDIA_TYPE = "application/yaml"


def _name(node: NetNode, clashes: Counter[str]) -> str:
    if node.bins:
        return node.bins[0]
    if node.place is not None:
        kind, key = node.place
        return key if clashes[key] == 1 else f"{kind}_{key}"
    return ""


def _options(node: NetNode, name: str) -> dict[str, Any]:
    options: dict[str, Any] = {"name": name}
    if node.place is not None and node.place[0] == "charger":
        options.update(is_charger=True, is_parking_spot=True, is_holding_point=True)
    elif node.place is not None and node.place[0] == FeatureKind.DOCK:
        options["dock_name"] = node.place[1]
    if node.bins:
        options["bins"] = list(node.bins)
    return options


def rmf_nav_graph(store: MapStore, map_info: MapInfo, revision: int | None, *, level_name: str = "L1"
                  ) -> dict[str, Any]:
    """The map as of ``revision`` (default: now) as an Open-RMF nav graph (one level, ``level_name``).

    Raises
    ------
    NavigationUnavailableError
        The map has not been decomposed into regions.
    """
    net, _ = map_network(store, map_info, revision)
    clashes = Counter(node.place[1] for node in net.nodes if node.place is not None)
    index = {node.id: i for i, node in enumerate(net.nodes)}
    vertices = [[node.x_m, node.y_m, _options(node, _name(node, clashes))] for node in net.nodes]
    lanes = []
    for edge in net.edges:
        lanes.append([index[edge.a], index[edge.b], {}])
        lanes.append([index[edge.b], index[edge.a], {}])
    return {"building_name": map_info.name, "levels": {level_name: {"vertices": vertices, "lanes": lanes}},
            "lifts": {}, "doors": {}}


def export_rmf(store: MapStore, map_info: MapInfo, revision: int, options: ExportOptions) -> Export:
    """The ``rmf`` export: ``<stem>.nav.yaml`` (see :func:`rmf_nav_graph`)."""
    try:
        graph = rmf_nav_graph(store, map_info, revision)
    except NavigationError as err:
        raise ExportNotFoundError(str(err)) from err
    return Export({f"{options.stem}.nav.yaml": yaml.safe_dump(rounded(graph), sort_keys=False).encode()}, MEDIA_TYPE)

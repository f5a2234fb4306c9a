"""LIF 1.0 and Open-RMF nav graph exports of a simulated, decomposed warehouse."""

from __future__ import annotations

import json
import math
from typing import Any

import jsonschema
import networkx as nx
import numpy as np
import pytest
import yaml

from atlas.exports.base import ExportNotFoundError, ExportOptions
from atlas.exports.lif import export_lif, lif_document
from atlas.exports.rmf import export_rmf, rmf_nav_graph
from atlas.navigation import Block, write_blocks
from shared.store import GridLayer, MapInfo, MapStore, RevisionWrite
from tests.api.warehouse_map import warehouse, write_warehouse
from tests.helpers import data_path


@pytest.fixture
def warehouse_map(store: MapStore) -> MapInfo:
    return write_warehouse(store)


def _layout(document: dict[str, Any]) -> dict[str, Any]:
    [layout] = document["layouts"]
    return layout  # type: ignore[no-any-return]


def test_lif_export_validates_against_the_vdma_schema(store: MapStore, warehouse_map: MapInfo) -> None:
    schema = json.loads(data_path("schemas", "LIF.schema.json").read_text())
    document = lif_document(store, warehouse_map, None, project_id="nav-test")
    jsonschema.validate(document, schema)
    assert document["metaInformation"]["lifVersion"] == "1.0.0"


def test_lif_has_every_bin_and_dock_as_a_station_at_a_node_by_its_access_pose(store: MapStore,
                                                                              warehouse_map: MapInfo) -> None:
    layout = _layout(lif_document(store, warehouse_map, None))
    nodes = {node["nodeId"]: node for node in layout["nodes"]}
    stations = {station["stationId"]: station for station in layout["stations"]}
    world = warehouse().world
    assert {b.id for b in world.bins} | {"dock-G1", "dock-G2", "charger-C1"} == set(stations)
    for b in world.bins:
        [node_id] = stations[b.id]["interactionNodeIds"]
        position = nodes[node_id]["nodePosition"]
        assert math.dist((position["x"], position["y"]), b.access_pose[:2]) <= 0.1
    kinds = {node["nodeDescription"].split()[0] for node in layout["nodes"]}
    assert {"hub", "portal", "access", "place"} <= kinds


def test_lif_edges_join_existing_nodes_in_both_directions_named_by_region(store: MapStore,
                                                                          warehouse_map: MapInfo) -> None:
    layout = _layout(lif_document(store, warehouse_map, None))
    nodes = {node["nodeId"] for node in layout["nodes"]}
    directed = {(e["startNodeId"], e["endNodeId"]) for e in layout["edges"]}
    assert all(a in nodes and b in nodes for a, b in directed)
    assert all((b, a) in directed for a, b in directed)
    assert len({e["edgeId"] for e in layout["edges"]}) == len(layout["edges"])
    graph = nx.Graph(list(directed))
    assert nx.is_connected(graph) and set(graph.nodes) == nodes
    access = next(s for s in layout["stations"] if s["stationId"] == warehouse().world.bins[0].id)
    aisle = {e["edgeName"] for e in layout["edges"] if access["interactionNodeIds"][0] in (e["startNodeId"],
                                                                                            e["endNodeId"])}
    assert len(aisle) == 1 and next(iter(aisle)).startswith("r")


def test_exports_leave_out_blocked_regions(store: MapStore, warehouse_map: MapInfo) -> None:
    before = _layout(lif_document(store, warehouse_map, None))
    named = {e["edgeName"] for e in before["edges"]}
    corridor = sorted(named)[0]
    node = next(n for n in store.topology(warehouse_map.id)[0] if n.key == corridor)
    assert node.x_m is not None and node.y_m is not None
    write_blocks(store, warehouse_map.id, [Block((corridor,), node.x_m, node.y_m)], change="test")
    after = _layout(lif_document(store, warehouse_map, None))
    assert corridor not in {e["edgeName"] for e in after["edges"]}


def test_rmf_nav_graph_lanes_join_vertices_and_docks_and_chargers_are_named(store: MapStore,
                                                                             warehouse_map: MapInfo) -> None:
    graph = rmf_nav_graph(store, warehouse_map, None)
    assert graph["building_name"] == "site"
    level = graph["levels"]["L1"]
    vertices, lanes = level["vertices"], level["lanes"]
    assert all(0 <= i < len(vertices) and 0 <= j < len(vertices) and i != j for i, j, _ in lanes)
    assert {(j, i) for i, j, _ in lanes} == {(i, j) for i, j, _ in lanes}
    by_name = {v[2]["name"]: v for v in vertices if v[2]["name"]}
    assert {"G1", "G2", "C1"} <= set(by_name)
    assert by_name["C1"][2]["is_charger"] is True and by_name["C1"][2]["is_parking_spot"] is True
    assert by_name["G1"][2]["dock_name"] == "G1"
    charger = warehouse().world.chargers[0]
    assert math.dist(by_name["C1"][:2], charger.pose[:2]) <= 0.1
    assert nx.is_connected(nx.Graph([(i, j) for i, j, _ in lanes]))
    names = [v[2]["name"] for v in vertices if v[2]["name"]]
    assert len(names) == len(set(names))
    assert yaml.safe_load(yaml.safe_dump(graph)) == graph


def test_export_files_and_a_map_without_regions(store: MapStore, warehouse_map: MapInfo) -> None:
    revision = store.latest_revision(warehouse_map.id)
    assert revision is not None
    lif = export_lif(store, warehouse_map, revision.id, ExportOptions("site_r4"))
    assert list(lif.files) == ["site_r4.lif.json"]
    assert _layout(json.loads(lif.files["site_r4.lif.json"]))["layoutVersion"] == str(revision.id)
    rmf = export_rmf(store, warehouse_map, revision.id, ExportOptions("site_r4"))
    assert "levels" in yaml.safe_load(rmf.files["site_r4.nav.yaml"])
    bare = store.ensure_map("bare")
    occupancy = GridLayer("occupancy", np.zeros((4, 4), dtype=np.int8), 0.5, 0.0, 0.0)
    only = store.write_revision(bare.id, RevisionWrite("occupancy_mapping", layers=[occupancy])).id
    with pytest.raises(ExportNotFoundError, match="place_segments"):
        export_lif(store, bare, only, ExportOptions("bare"))
    with pytest.raises(ExportNotFoundError, match="place_segments"):
        export_rmf(store, bare, only, ExportOptions("bare"))

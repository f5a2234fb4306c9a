"""The region graph over the API, and operators blocking and unblocking regions and connections."""

from __future__ import annotations

import dataclasses
import itertools
from typing import Any

import cv2
import networkx as nx
import numpy as np
import pytest
from fastapi.testclient import TestClient

from services.grid_decomposition.records import decomposition_layers, decomposition_topology
from shared.store import Feature, MapInfo, MapStore, RevisionWrite, TopologyEdge, TopologyNode
from shared.store.keys import Role, create_key
from tests.api.conftest import ClientFactory
from tests.api.warehouse_map import warehouse, write_warehouse


@pytest.fixture
def warehouse_map(store: MapStore) -> MapInfo:
    return write_warehouse(store)


@pytest.fixture
def operator(store: MapStore, make_client: ClientFactory, warehouse_map: MapInfo) -> TestClient:
    client = make_client(store, rate_limit_per_s=None)
    client.headers["X-API-Key"] = create_key(store, role=Role.WRITE, name="shift-lead")[1]
    return client


def _graph(client: TestClient, **params: Any) -> nx.Graph:
    response = client.get("/v1/maps/site/topology", params=params)
    assert response.status_code == 200, response.text
    return nx.node_link_graph(response.json(), edges="edges")


def _corridor_and_neighbour(graph: nx.Graph) -> tuple[str, str]:
    """A corridor and a junction it is connected to."""
    return next((a, b) for a, b, data in graph.edges(data=True) if data["connection"] == "connected"
                and {graph.nodes[a]["kind"], graph.nodes[b]["kind"]} == {"corridor", "junction"})


def test_topology_is_node_link_json_of_every_region_and_connection(operator: TestClient) -> None:
    graph = _graph(operator)
    decomposition = warehouse().decomposition
    assert set(graph.nodes) == {f"r{i}" for i in decomposition.topology.nodes}
    assert graph.number_of_edges() == decomposition.topology.number_of_edges()
    kinds = {data["kind"] for _, data in graph.nodes(data=True)}
    assert {"corridor", "junction", "storage"} <= kinds
    for *_, data in graph.edges(data=True):
        assert data["connection"] in {"connected", "storage_access", "door", "disconnected"}
        assert data["blocked"] is False
        if data["connection"] == "connected":
            assert data["portal"] is not None and data["width_m"] > 0
    assert all(data["drivable"] == (data["kind"] in {"corridor", "junction", "room", "open_area"})
               for _, data in graph.nodes(data=True))


def test_topology_as_geojson_has_regions_as_points_and_connections_as_lines(operator: TestClient) -> None:
    response = operator.get("/v1/maps/site/topology", params={"format": "geojson"})
    assert response.status_code == 200
    body = response.json()
    types = {f["geometry"]["type"] for f in body["features"]}
    assert body["type"] == "FeatureCollection" and types == {"Point", "LineString"}
    lines = [f for f in body["features"] if f["geometry"]["type"] == "LineString"]
    assert all(len(f["geometry"]["coordinates"]) == 3 for f in lines)


def test_a_map_not_decomposed_has_an_empty_graph(client: TestClient, site: dict[str, int]) -> None:
    body = client.get("/v1/maps/site/topology").json()
    assert body["nodes"] == [] and body["edges"] == []
    assert client.get("/v1/maps/site/topology", params={"format": "svg"}).status_code == 422


def test_blocking_a_region_is_stored_as_an_operator_revision_and_shown(operator: TestClient, store: MapStore,
                                                                       warehouse_map: MapInfo) -> None:
    corridor, _ = _corridor_and_neighbour(_graph(operator))
    first = operator.put(f"/v1/maps/site/topology/blocked/regions/{corridor}", json={"reason": "spill"})
    assert first.status_code == 201
    assert first.json()["block"]["regions"] == [corridor]
    assert first.json()["block"]["blocked_by"] == "shift-lead"
    revision = store.latest_revision(warehouse_map.id)
    assert revision is not None and revision.stage == "operator" and revision.id == first.json()["revision_id"]

    again = operator.put(f"/v1/maps/site/topology/blocked/regions/{corridor}", json={"reason": "still wet"})
    assert again.status_code == 200
    listed = operator.get("/v1/maps/site/topology/blocked").json()["blocks"]
    assert [(b["target"], b["regions"], b["reason"]) for b in listed] == [("region", [corridor], "still wet")]
    assert _graph(operator).nodes[corridor]["blocked"] is True
    assert _graph(operator, revision=first.json()["revision_id"] - 1).nodes[corridor]["blocked"] is False

    removed = operator.delete(f"/v1/maps/site/topology/blocked/regions/{corridor}")
    assert removed.status_code == 200 and removed.json()["removed"][0]["regions"] == [corridor]
    assert operator.get("/v1/maps/site/topology/blocked").json()["blocks"] == []
    assert operator.delete(f"/v1/maps/site/topology/blocked/regions/{corridor}").status_code == 404


def _regions_passed(client: TestClient, start: str, goal: str) -> list[str]:
    response = client.get("/v1/maps/site/routes", params={"from": start, "to": goal})
    assert response.status_code == 200, response.text
    return [r["key"] for r in response.json()["regions"]]


def test_blocking_a_connection_works_in_either_order_and_routes_go_round_it(operator: TestClient) -> None:
    first, second = _regions_passed(operator, "dock:G1", "dock:G2")[:2]
    response = operator.put(f"/v1/maps/site/topology/blocked/connections/{second}/{first}", json=None)
    assert response.status_code == 201
    assert sorted(response.json()["block"]["regions"]) == sorted([first, second])
    graph = _graph(operator)
    assert graph.edges[first, second]["blocked"] is True
    assert graph.nodes[first]["blocked"] is False and graph.nodes[second]["blocked"] is False
    regions = _regions_passed(operator, "dock:G1", "dock:G2")
    assert regions[0] == first
    assert all({a, b} != {first, second} for a, b in itertools.pairwise(regions))
    assert operator.delete(f"/v1/maps/site/topology/blocked/connections/{first}/{second}").status_code == 200
    assert _graph(operator).edges[first, second]["blocked"] is False


def test_bad_blocks_are_refused_and_change_nothing(operator: TestClient, store: MapStore, warehouse_map: MapInfo,
                                                   make_client: ClientFactory) -> None:
    graph = _graph(operator)
    storage = next(n for n, data in graph.nodes(data=True) if data["kind"] == "storage")
    apart = next((a, b) for a in graph.nodes for b in graph.nodes if a != b and not graph.has_edge(a, b))
    revisions = len(store.revisions(warehouse_map.id))
    assert operator.put("/v1/maps/site/topology/blocked/regions/r99999").status_code == 404
    assert operator.put(f"/v1/maps/site/topology/blocked/regions/{storage}").status_code == 422
    assert operator.put("/v1/maps/site/topology/blocked/regions/aisle_3").status_code == 422
    assert operator.put("/v1/maps/site/topology/blocked/regions/aisle-03").status_code == 404  # no such aisle
    assert operator.put(f"/v1/maps/site/topology/blocked/connections/{apart[0]}/{apart[1]}").status_code == 404
    assert operator.put(f"/v1/maps/site/topology/blocked/regions/{apart[0]}",
                        json={"reason": "x" * 201}).status_code == 422
    anonymous = make_client(store)
    corridor, _ = _corridor_and_neighbour(graph)
    assert anonymous.put(f"/v1/maps/site/topology/blocked/regions/{corridor}").status_code == 401
    assert len(store.revisions(warehouse_map.id)) == revisions


def _renumber(store: MapStore, info: MapInfo, shift: int) -> None:
    """Store the same decomposition again with every region id moved by ``shift`` (as a new run may number them)."""
    decomposition = warehouse().decomposition
    labels, segments = decomposition_layers(decomposition)
    moved = segments.data.copy()
    moved[moved > 0] += shift
    nodes, edges = decomposition_topology(decomposition)

    def key(old: str) -> str:
        return f"r{int(old[1:]) + shift}"

    store.write_revision(info.id, RevisionWrite(
        "grid_decomposition", layers=[labels, dataclasses.replace(segments, data=moved)],
        topology=([TopologyNode(key(n.key), n.kind, n.x_m, n.y_m, n.attributes) for n in nodes],
                  [TopologyEdge(key(e.source), key(e.target), e.attributes) for e in edges]),
    ))


def test_a_block_follows_its_region_when_the_decomposition_renumbers_it(operator: TestClient, store: MapStore,
                                                                         warehouse_map: MapInfo) -> None:
    corridor, _ = _corridor_and_neighbour(_graph(operator))
    assert operator.put(f"/v1/maps/site/topology/blocked/regions/{corridor}").status_code == 201
    _renumber(store, warehouse_map, 1000)
    moved = f"r{int(corridor[1:]) + 1000}"
    [block] = operator.get("/v1/maps/site/topology/blocked").json()["blocks"]
    assert block["blocked_keys"] == [corridor] and block["regions"] == [moved]
    assert _graph(operator).nodes[moved]["blocked"] is True
    assert operator.delete(f"/v1/maps/site/topology/blocked/regions/{moved}").status_code == 200
    assert operator.put(f"/v1/maps/site/topology/blocked/regions/{moved}").status_code == 201
    _renumber(store, warehouse_map, 2000)
    gone = operator.delete(f"/v1/maps/site/topology/blocked/regions/{moved}")  # the key it was blocked by
    assert gone.status_code == 200, gone.text


def _write_aisles(store: MapStore, info: MapInfo) -> dict[int, list[str]]:
    """The world's aisles as the pillar stage writes them (``aisle-NN`` corridors); the region keys in each."""
    world = warehouse().world
    sections: dict[int, list[list[list[float]]]] = {}
    for area in world.areas:
        if area.kind.name == "CORRIDOR" and isinstance(area.detail.get("aisle"), int):
            ring = [[float(x), float(y)] for x, y in area.polygon]
            sections.setdefault(area.detail["aisle"], []).append([*ring, ring[0]])
    features = [Feature("corridor", f"aisle-{aisle:02d}", {"type": "MultiPolygon", "coordinates": [
        [ring] for ring in rings]}, {"kind": "corridor", "aisle": aisle}) for aisle, rings in sorted(sections.items())]
    store.write_revision(info.id, RevisionWrite("pillar_mapping", features={"corridor": features}))
    return {aisle: [f"r{i}" for i in _regions_in(rings)] for aisle, rings in sections.items()}


def _regions_in(rings: list[list[list[float]]]) -> set[int]:
    """Drivable regions of the stored decomposition with most of their cells in the rings."""
    decomposition = warehouse().decomposition
    res, (ox, oy) = decomposition.resolution_m, decomposition.origin_xy_m
    inside = np.zeros(decomposition.segments.shape, dtype=np.uint8)
    cv2.fillPoly(inside, [np.round((np.asarray(r) - (ox, oy)) / res - 0.5).astype(np.int32) for r in rings], 1)
    return {rid for rid, info in decomposition.regions.items()
            if info.label.name in {"CORRIDOR", "JUNCTION", "ROOM", "OPEN_AREA"}
            and np.mean(inside[decomposition.segments == rid]) >= 0.5}


def test_an_aisle_is_blocked_as_every_drivable_region_in_it(operator: TestClient, store: MapStore,
                                                            warehouse_map: MapInfo) -> None:
    in_aisle = _write_aisles(store, warehouse_map)
    aisle, regions = min(in_aisle.items())
    assert regions, "the decomposition has corridor regions in the aisle"
    response = operator.put(f"/v1/maps/site/topology/blocked/regions/aisle-{aisle:02d}", json={"reason": "spill"})
    assert response.status_code == 201, response.text
    block = response.json()["block"]
    assert block["blocked_keys"] == [f"aisle-{aisle:02d}"] and sorted(block["regions"]) == sorted(regions)
    graph = _graph(operator)
    assert all(graph.nodes[key]["blocked"] for key in regions)
    assert sum(data["blocked"] for _, data in graph.nodes(data=True)) == len(regions)
    refused = operator.delete(f"/v1/maps/site/topology/blocked/regions/{regions[0]}")
    assert refused.status_code == 404 and f"aisle-{aisle:02d}" in refused.json()["detail"]
    assert operator.put(f"/v1/maps/site/topology/blocked/regions/aisle-{aisle:02d}").status_code == 200
    assert operator.delete(f"/v1/maps/site/topology/blocked/regions/aisle-{aisle:02d}").status_code == 200
    assert not any(data["blocked"] for _, data in _graph(operator).nodes(data=True))

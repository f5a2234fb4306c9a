"""Routes through a simulated, decomposed warehouse: bins to docks, blocked corridors, bad ends."""

from __future__ import annotations

import itertools
import math
from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient

from services.grid_decomposition.records import region_key
from shared.store import MapInfo, MapStore
from shared.store.keys import Role, create_key
from tests.api.conftest import ClientFactory
from tests.api.warehouse_map import warehouse, write_warehouse

FAR_BIN = "02-016-03"
"""A bin in the other aisle and the other section from the first bin."""


@pytest.fixture
def warehouse_map(store: MapStore) -> MapInfo:
    return write_warehouse(store)


@pytest.fixture
def operator(store: MapStore, make_client: ClientFactory, warehouse_map: MapInfo) -> TestClient:
    """A client with a write key over the warehouse map."""
    client = make_client(store, rate_limit_per_s=None)
    client.headers["X-API-Key"] = create_key(store, role=Role.WRITE, name="shift-lead")[1]
    return client


def _route(client: TestClient, start: str, goal: str, **params: Any) -> dict[str, Any]:
    response = client.get("/v1/maps/site/routes", params={"from": start, "to": goal, **params})
    assert response.status_code == 200, response.text
    body: dict[str, Any] = response.json()
    return body


def _region_at(x: float, y: float) -> str:
    grids = warehouse().grids
    row = math.floor((y - grids.origin_y_m) / grids.resolution_m)
    col = math.floor((x - grids.origin_x_m) / grids.resolution_m)
    return region_key(int(warehouse().decomposition.segments[row, col]))


def _legs_on_free_cells(route: dict[str, Any]) -> bool:
    """Every straight leg between consecutive waypoints, sampled every 1 cm, on a free ground-truth cell."""
    grids = warehouse().grids
    points = [(w["x_m"], w["y_m"]) for w in route["waypoints"]]
    for (ax, ay), (bx, by) in itertools.pairwise(points):
        t = np.linspace(0.0, 1.0, max(2, math.ceil(math.dist((ax, ay), (bx, by)) / 0.01)))
        rows = np.floor((ay + (by - ay) * t - grids.origin_y_m) / grids.resolution_m).astype(int)
        cols = np.floor((ax + (bx - ax) * t - grids.origin_x_m) / grids.resolution_m).astype(int)
        values = grids.occupancy[rows, cols]
        if not ((values >= 0) & (values < 50)).all():
            return False
    return True


def test_route_from_a_bin_to_a_dock_starts_in_the_bins_aisle_and_is_drivable(operator: TestClient) -> None:
    first = warehouse().world.bins[0]
    dock = next(g for g in warehouse().world.gates if g.id == "G1")
    route = _route(operator, f"bin:{first.id}", "dock:G1")
    aisle = _region_at(*first.access_pose[:2])
    assert route["start"]["region"] == aisle
    assert route["corridors"][0] == aisle
    assert route["waypoints"][0]["kind"] == "start" and route["waypoints"][-1]["kind"] == "goal"
    assert (route["waypoints"][0]["x_m"], route["waypoints"][0]["y_m"]) == pytest.approx(first.access_pose[:2])
    dock_middle = ((dock.a[0] + dock.b[0]) / 2, (dock.a[1] + dock.b[1]) / 2)
    assert math.dist((route["waypoints"][-1]["x_m"], route["waypoints"][-1]["y_m"]), dock_middle) <= 1.0
    assert _legs_on_free_cells(route)
    assert route["regions"][0] == {"key": aisle, "kind": "corridor"}
    assert all(r["kind"] in {"corridor", "junction", "room", "open_area"} for r in route["regions"])
    lengths = [math.dist((a["x_m"], a["y_m"]), (b["x_m"], b["y_m"]))
               for a, b in zip(route["waypoints"], route["waypoints"][1:], strict=False)]
    assert route["length_m"] == pytest.approx(sum(lengths), abs=1e-3)


def test_route_between_aisles_lists_the_regions_it_passes_from_start_to_goal(operator: TestClient) -> None:
    route = _route(operator, f"bin:{warehouse().world.bins[0].id}", f"bin:{FAR_BIN}")
    passed = [r["key"] for r in route["regions"]]
    assert passed[0] == route["start"]["region"] and passed[-1] == route["goal"]["region"]
    assert {w["region"] for w in route["waypoints"]} <= set(passed)
    assert route["start"]["region"] != route["goal"]["region"]
    assert _legs_on_free_cells(route)


def test_blocking_a_corridor_on_the_route_reroutes_round_it(operator: TestClient) -> None:
    start, goal = f"bin:{warehouse().world.bins[0].id}", f"bin:{FAR_BIN}"
    before = _route(operator, start, goal)
    passed = [r["key"] for r in before["regions"][1:-1] if r["kind"] == "corridor"]
    assert passed, "the route between aisles should cross a corridor between them"
    blocked = operator.put(f"/v1/maps/site/topology/blocked/regions/{passed[0]}", json={"reason": "spill"})
    assert blocked.status_code == 201, blocked.text

    after = _route(operator, start, goal)
    assert passed[0] not in [r["key"] for r in after["regions"]]
    assert after["length_m"] >= before["length_m"]
    assert _legs_on_free_cells(after)
    at_first = _route(operator, start, goal, revision=before["revision"])
    assert [r["key"] for r in at_first["regions"]] == [r["key"] for r in before["regions"]]


def test_a_blocked_start_corridor_gives_409_naming_it(operator: TestClient) -> None:
    first = warehouse().world.bins[0]
    aisle = _region_at(*first.access_pose[:2])
    assert operator.put(f"/v1/maps/site/topology/blocked/regions/{aisle}",
                        json={"reason": "racking inspection"}).status_code == 201
    response = operator.get("/v1/maps/site/routes", params={"from": f"bin:{first.id}", "to": "dock:G1"})
    assert response.status_code == 409
    assert aisle in response.json()["detail"] and "racking inspection" in response.json()["detail"]


def test_avoid_keeps_a_route_out_of_a_region_without_storing_anything(operator: TestClient, store: MapStore,
                                                                       warehouse_map: MapInfo) -> None:
    start, goal = f"bin:{warehouse().world.bins[0].id}", f"bin:{FAR_BIN}"
    passed = [r["key"] for r in _route(operator, start, goal)["regions"][1:-1]]
    revisions = len(store.revisions(warehouse_map.id))
    route = _route(operator, start, goal, avoid=passed[:1])
    assert passed[0] not in [r["key"] for r in route["regions"]]
    assert len(store.revisions(warehouse_map.id)) == revisions


def test_routes_to_points_and_chargers(operator: TestClient) -> None:
    charger = warehouse().world.chargers[0]
    route = _route(operator, "charger:C1", "point:15.3,8.3")
    assert (route["start"]["x_m"], route["start"]["y_m"]) == pytest.approx(charger.pose[:2], abs=5e-4)
    assert route["start"]["yaw_rad"] == pytest.approx(charger.pose[2], abs=5e-5)  # served to 4 decimals
    assert route["waypoints"][-1]["x_m"] == pytest.approx(15.3)
    same = _route(operator, "point:15.3,8.3", "point:15.3,8.3")
    assert same["length_m"] == 0.0 and len(same["waypoints"]) == 2


UNKNOWN_ENDS = [("bin:99-999-99", "dock:G1"), ("bin:01-001-01", "dock:G9"), ("place:charger/C7", "dock:G1")]
MALFORMED_ENDS = ["bin01", "crate:7", "place:dock", "point:1", "point:nan,2", "point:1e9,0", "bin:", "dock:a b"]


def test_unknown_ends_are_404_and_malformed_ones_422(operator: TestClient, subtests: pytest.Subtests) -> None:
    for start, goal in UNKNOWN_ENDS:
        with subtests.test(start=start, goal=goal):
            response = operator.get("/v1/maps/site/routes", params={"from": start, "to": goal})
            assert response.status_code == 404
            assert "has no" in response.json()["detail"]
    for end in MALFORMED_ENDS:
        with subtests.test(end=end):
            response = operator.get("/v1/maps/site/routes", params={"from": end, "to": "bin:99-999-99"})
            assert response.status_code == 422
            assert "point:<x>,<y>" in response.json()["detail"]
    for avoid in ("corridor-1", "r999999"):
        with subtests.test(avoid=avoid):
            response = operator.get("/v1/maps/site/routes",
                                    params={"from": "dock:G1", "to": "dock:G2", "avoid": avoid})
            assert response.status_code == 422
            assert avoid in response.json()["detail"]


def test_a_point_off_every_drivable_region_is_409(operator: TestClient) -> None:
    response = operator.get("/v1/maps/site/routes", params={"from": "point:-20,-20", "to": "dock:G1"})
    assert response.status_code == 409
    assert "not within" in response.json()["detail"]


def test_a_map_without_regions_answers_409(client: TestClient, site: dict[str, int]) -> None:
    response = client.get("/v1/maps/site/routes", params={"from": "point:0,2.2", "to": "point:1,2.2"})
    assert response.status_code == 409
    assert "place_segments" in response.json()["detail"]

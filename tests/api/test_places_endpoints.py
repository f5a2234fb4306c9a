"""Operators setting docks, gates and chargers, and routes to them."""

from __future__ import annotations

from typing import Any

import pytest
from fastapi.testclient import TestClient

from shared.store import MapInfo, MapStore
from shared.store.keys import Role, create_key
from tests.api.conftest import ClientFactory
from tests.api.warehouse_map import write_warehouse

DOCK: dict[str, Any] = {
    "geometry": {"type": "Polygon", "coordinates": [[[11.0, 0.0], [14.0, 0.0], [14.0, 0.5], [11.0, 0.5],
                                                     [11.0, 0.0]]]},
    "name": "Dock 3",
    "approach_pose": {"x_m": 12.5, "y_m": 1.5, "yaw_rad": -1.5708},
    "properties": {"door_height_m": 4.2, "refrigerated": False},
}


@pytest.fixture
def warehouse_map(store: MapStore) -> MapInfo:
    return write_warehouse(store)


@pytest.fixture
def operator(store: MapStore, make_client: ClientFactory, warehouse_map: MapInfo) -> TestClient:
    client = make_client(store, rate_limit_per_s=None)
    client.headers["X-API-Key"] = create_key(store, role=Role.WRITE, name="shift-lead")[1]
    return client


def test_a_place_is_created_read_replaced_and_removed(operator: TestClient, store: MapStore,
                                                      warehouse_map: MapInfo) -> None:
    created = operator.put("/v1/maps/site/places/dock/D3", json=DOCK)
    assert created.status_code == 201, created.text
    body = created.json()
    assert (body["kind"], body["key"], body["name"], body["stage"]) == ("dock", "D3", "Dock 3", "operator")
    assert body["target"] == [12.5, 1.5]
    assert body["properties"] == {"door_height_m": 4.2, "refrigerated": False}
    assert operator.get("/v1/maps/site/places/dock/D3").json()["approach_pose"]["y_m"] == 1.5

    moved = {**DOCK, "approach_pose": {"x_m": 12.0, "y_m": 2.0, "yaw_rad": 4.712}}
    replaced = operator.put("/v1/maps/site/places/dock/D3", json=moved)
    assert replaced.status_code == 200
    assert replaced.json()["approach_pose"]["yaw_rad"] == pytest.approx(-1.5712, abs=1e-3)
    docks = operator.get("/v1/maps/site/places", params={"kind": "dock"}).json()["places"]
    assert [(p["key"], p["stage"]) for p in docks] == [("D3", "operator"), ("G1", "ground_truth"),
                                                       ("G2", "ground_truth")]

    removed = operator.delete("/v1/maps/site/places/dock/D3")
    assert removed.status_code == 200
    revision = store.latest_revision(warehouse_map.id)
    assert revision is not None and revision.stage == "operator" and revision.id == removed.json()["revision_id"]
    assert operator.get("/v1/maps/site/places/dock/D3").status_code == 404
    assert operator.delete("/v1/maps/site/places/dock/D3").status_code == 404
    at_creation = operator.get("/v1/maps/site/places/dock/D3", params={"revision": body["revision_id"]})
    assert at_creation.status_code == 200


def test_a_route_to_a_placed_dock_ends_at_its_approach_pose(operator: TestClient) -> None:
    assert operator.put("/v1/maps/site/places/dock/D3", json=DOCK).status_code == 201
    for goal in ("dock:D3", "place:dock/D3"):
        route = operator.get("/v1/maps/site/routes", params={"from": "charger:C1", "to": goal})
        assert route.status_code == 200, route.text
        last = route.json()["waypoints"][-1]
        assert (last["x_m"], last["y_m"]) == pytest.approx((12.5, 1.5))
        assert route.json()["goal"]["yaw_rad"] == pytest.approx(-1.5708)


def test_places_of_other_stages_cannot_be_removed_here(operator: TestClient) -> None:
    response = operator.delete("/v1/maps/site/places/dock/G1")
    assert response.status_code == 404
    assert "ground_truth" in response.json()["detail"]


def _with(**changes: Any) -> dict[str, Any]:
    return {**DOCK, **changes}


BAD_PLACES = [
    (_with(geometry={"type": "Polygon", "coordinates": [[[0, 0], [2, 2], [2, 0], [0, 2], [0, 0]]]}), "crosses"),
    (_with(geometry={"type": "Polygon", "coordinates": [[[0, 0], [2, 0], [2, 2], [0, 2]]]}), "closed"),
    (_with(geometry={"type": "Polygon", "coordinates": [[[0, 0], [1, 1], [2, 2], [0, 0]]]}), "no area"),
    (_with(geometry={"type": "Polygon", "coordinates": [[[0, 0], [900, 0], [900, 1], [0, 1], [0, 0]]]}),
     "across"),
    (_with(properties={"name": "Dock 3b"}), "reserved"),
    (_with(approach_pose={"x_m": 90.0, "y_m": 90.0, "yaw_rad": 0.0}), "approach pose"),
]
MALFORMED = [
    ("/v1/maps/site/places/crane/K1", DOCK),
    ("/v1/maps/site/places/dock/a%20b", DOCK),
    ("/v1/maps/site/places/dock/D4", _with(geometry={"type": "Point", "coordinates": [1e9, 0]})),
    ("/v1/maps/site/places/dock/D4", _with(geometry={"type": "LineString", "coordinates": [[0, 0], [1, 0]]})),
    ("/v1/maps/site/places/dock/D4", _with(properties={"nested": {"a": 1}})),
    ("/v1/maps/site/places/dock/D4", _with(name="x" * 129)),
]


def test_bad_places_are_422_saying_why_and_store_nothing(operator: TestClient, store: MapStore,
                                                         warehouse_map: MapInfo, subtests: pytest.Subtests) -> None:
    revisions = len(store.revisions(warehouse_map.id))
    for body, message in BAD_PLACES:
        with subtests.test(message=message):
            response = operator.put("/v1/maps/site/places/dock/D4", json=body)
            assert response.status_code == 422
            assert message in response.json()["detail"]
    for path, body in MALFORMED:
        with subtests.test(path=path, body=body):
            assert operator.put(path, json=body).status_code == 422
    assert len(store.revisions(warehouse_map.id)) == revisions


def test_setting_a_place_needs_a_write_key(store: MapStore, make_client: ClientFactory,
                                           warehouse_map: MapInfo) -> None:
    reader = make_client(store)
    reader.headers["X-API-Key"] = create_key(store, role=Role.READ, name="wms")[1]
    assert reader.put("/v1/maps/site/places/dock/D3", json=DOCK).status_code == 403
    assert make_client(store).delete("/v1/maps/site/places/dock/G1").status_code == 401
    assert reader.get("/v1/maps/site/places").status_code == 200

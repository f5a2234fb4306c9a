"""What is at a point, the label table and revision diffs, through the API."""

from __future__ import annotations

import time
from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient

from shared import messages
from shared.bus import WORKER_NAMESPACE, Bus
from shared.places import LABEL_TABLE_STAGE
from shared.store import Feature, GridLayer, MapStore, RevisionWrite
from shared.store.keys import Role, create_key
from shared.worker import MAP_EVENTS_TOPIC
from tests.api.conftest import ClientFactory

URL = "/v1/maps/hall"
RES = 0.5


def _box(x0: float, y0: float, x1: float, y1: float) -> dict[str, object]:
    return {"type": "Polygon", "coordinates": [[[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]]]}


@pytest.fixture
def hall(store: MapStore) -> dict[str, int]:
    """A 10 m x 5 m hall at 0.5 m: a corridor (region 1, x < 6) and a storage region (2, x >= 6), a rack
    along the top wall in the semantic grid, and a bin over the storage region."""
    map_id = store.ensure_map("hall").id
    shape = (10, 20)
    occupancy = np.zeros(shape, np.int8)
    occupancy[-1, :] = 100
    segments = np.ones(shape, np.uint16)
    segments[:, 12:] = 2
    segments[-1, :] = 0
    labels = np.where(segments == 1, 1, np.where(segments == 2, 3, 0)).astype(np.uint8)
    place_meta = {"encoding": "place_labels", "classes": ["none", "corridor", "junction", "storage", "room",
                                                          "open_area", "unidentified"]}
    semantic = np.zeros(shape, np.uint8)
    semantic[-1, :] = 2
    entropy = np.full(shape, -1.0, np.float32)
    entropy[-1, :] = 0.1
    regions = {
        "corridor": [Feature("corridor", "r1", _box(0, 0, 6, 4.5), {"label": "corridor", "category": 0,
                                                                   "area_m2": 27.0})],
        "region": [Feature("region", "r2", _box(6, 0, 10, 4.5), {"label": "storage", "category": 1,
                                                                "area_m2": 18.0})],
    }
    first = store.write_revision(map_id, RevisionWrite("grid_decomposition", layers=[
        GridLayer("occupancy", occupancy, RES, 0.0, 0.0),
        GridLayer("place_labels", labels, RES, 0.0, 0.0, place_meta),
        GridLayer("place_segments", segments, RES, 0.0, 0.0, {"encoding": "place_segments"}),
    ], features=regions)).id
    second = store.write_revision(map_id, RevisionWrite("semantic_fusion", layers=[
        GridLayer("semantic_label", semantic, RES, 0.0, 0.0, {"encoding": "semantic_labels",
                                                              "classes": ["unknown", "wall", "rack"]}),
        GridLayer("semantic_entropy", entropy, RES, 0.0, 0.0, {"encoding": "normalised_entropy", "no_data": -1.0}),
    ])).id
    third = store.write_revision(map_id, RevisionWrite("pillar_mapping", features={
        "bin": [Feature("bin", "01-001", _box(7, 1, 8, 2), {"id": "01-001"})]})).id
    return {"places": first, "semantics": second, "bins": third}


def test_a_point_tells_its_place_class_and_features(client: TestClient, hall: dict[str, int]) -> None:
    in_bin = client.get(f"{URL}/semantics", params={"x": 7.5, "y": 1.5}).json()
    on_rack = client.get(f"{URL}/semantics", params={"x": 2.2, "y": 4.7}).json()
    outside = client.get(f"{URL}/semantics", params={"x": -30, "y": 1}).json()

    assert in_bin["place"]["region"] == "r2" and in_bin["place"]["label"] == "storage"
    assert {(f["kind"], f["key"]) for f in in_bin["features"]} == {("bin", "01-001"), ("region", "r2")}
    assert in_bin["semantic"]["entropy"] is None and in_bin["occupancy"] == 0
    assert on_rack["semantic"]["label"] == "rack" and on_rack["semantic"]["entropy"] == pytest.approx(0.1)
    assert on_rack["occupancy"] == 100 and on_rack["place"] is None
    assert outside["occupancy"] is None and outside["semantic"] is None and outside["features"] == []


def test_occupancy_says_its_scale(client: TestClient, store: MapStore, hall: dict[str, int]) -> None:
    grid = np.array([[-1, 0, 65, 100]], np.int8)
    store.write_revision(store.ensure_map("hall").id, RevisionWrite("occupancy_mapping", layers=[
        GridLayer("occupancy", grid, RES, 0.0, 0.0)]))
    schema = client.get("/openapi.json").json()["components"]["schemas"]["PointOut"]["properties"]

    answers = [client.get(f"{URL}/semantics", params={"x": RES * (k + 0.5), "y": 0.1}).json() for k in range(4)]

    assert [a["occupancy"] for a in answers] == [-1, 0, 65, 100]
    assert [a["occupancy_probability"] for a in answers] == [None, 0.0, 0.65, 1.0]
    assert "percent" in schema["occupancy"]["description"]
    assert "0..1" in schema["occupancy_probability"]["description"]


def test_a_point_reads_the_map_as_it_was(client: TestClient, hall: dict[str, int]) -> None:
    then = client.get(f"{URL}/semantics", params={"x": 2.2, "y": 4.7, "revision": hall["places"]}).json()

    assert then["semantic"] is None and then["occupancy"] == 100


@pytest.mark.parametrize("params", [{"x": "nan", "y": 1}, {"x": 1}, {"x": 1e12, "y": 0}, {"x": "1;DROP", "y": 2}])
def test_bad_points_get_422(client: TestClient, hall: dict[str, int], params: dict[str, Any]) -> None:
    response = client.get(f"{URL}/semantics", params=params)

    assert response.status_code == 422 and response.json()["detail"]


def test_label_table_lists_categories_and_records_overrides(client: TestClient, store: MapStore,
                                                            hall: dict[str, int]) -> None:
    writer = {"X-API-Key": create_key(store, role=Role.WRITE, name="operator")[1]}

    before = client.get(f"{URL}/label-table").json()
    accepted = client.put(f"{URL}/label-table", json={"overrides": {"1": "Pallet cell", "0": "corridor"}},
                          headers=writer)
    after = client.get(f"{URL}/label-table").json()

    assert [(c["category"], c["label"], c["overridden"]) for c in before["categories"]] == [
        (0, "corridor", False), (1, "storage", False)]
    assert {row["label"] for row in before["labels"]} >= {"corridor", "junction", "storage", "room"}
    assert accepted.status_code == 202
    assert after["overrides"] == {"0": "corridor", "1": "storage"}
    assert after["overrides_revision_id"] == accepted.json()["revision_id"]
    assert all(c["overridden"] for c in after["categories"])


@pytest.mark.parametrize("overrides", [{"x": "corridor"}, {"1": "kitchen"}, {"-1": "room"}])
def test_bad_label_tables_are_refused(client: TestClient, store: MapStore, hall: dict[str, int],
                                      overrides: dict[str, str]) -> None:
    writer = {"X-API-Key": create_key(store, role=Role.WRITE, name="operator")[1]}
    revisions = len(store.revisions(store.ensure_map("hall").id))

    response = client.put(f"{URL}/label-table", json={"overrides": overrides}, headers=writer)

    assert response.status_code == 422 and response.json()["detail"]
    assert len(store.revisions(store.ensure_map("hall").id)) == revisions


def test_diff_names_what_changed(client: TestClient, store: MapStore, hall: dict[str, int]) -> None:
    map_id = store.ensure_map("hall").id
    latest = store.write_revision(map_id, RevisionWrite("pillar_mapping", features={"bin": [
        Feature("bin", "01-001", _box(7.1, 1, 8.1, 2), {"id": "01-001"}),
        Feature("bin", "01-002", _box(8, 1, 9, 2), {"id": "01-002"})]})).id

    diff = client.get(f"{URL}/revisions/{hall['places']}/diff", params={"to": latest}).json()
    back = client.get(f"{URL}/revisions/{hall['bins']}/diff").json()

    assert diff["features"]["bin"]["added"] == ["01-001", "01-002"]
    assert {layer["name"] for layer in diff["layers"]} == {"semantic_label", "semantic_entropy"}
    assert back["to_revision"] == latest and back["features"]["bin"]["moved"] == ["01-001"]
    assert back["features"]["bin"]["added"] == ["01-002"] and back["layers"] == []
    assert client.get(f"{URL}/revisions/99999/diff").status_code == 404


def test_revisions_the_api_writes_are_announced_on_the_bus(store: MapStore, make_client: ClientFactory,
                                                          bus_pair: tuple[Bus, Bus], hall: dict[str, int]) -> None:
    api_bus, fleet_manager = bus_pair
    events = fleet_manager.subscribe(MAP_EVENTS_TOPIC, messages.MAP_EVENT, namespaces=[WORKER_NAMESPACE])
    client = make_client(store, bus=api_bus)
    time.sleep(0.5)  # let the subscription reach the API's peer
    writer = {"X-API-Key": create_key(store, role=Role.WRITE, name="operator")[1]}

    accepted = client.put(f"{URL}/label-table", json={"overrides": {"0": "corridor"}}, headers=writer).json()
    received = events.receive(timeout=10.0)

    assert received is not None
    assert received.message.map_name == "hall" and received.message.revision_id == accepted["revision_id"]
    assert received.message.stage == LABEL_TABLE_STAGE

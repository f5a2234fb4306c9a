"""What the robots saw in the bins, through the API: occupancy on bins, a bin's bay scene, the WMS stock list and
the discrepancies against it, and the events that announce occupancy changes.

Bin states and scenes are written by the store writer the load-scene stage uses (``write_scene_revision``).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

from api import create_app
from shared.loads import Occupancy, write_scene_revision
from shared.settings import Settings
from shared.store import MapStore
from shared.store.keys import Role, create_key
from tests.api.conftest import ClientFactory
from tests.api.test_events_endpoint import FAST, _read
from tests.helpers import wait_for
from tests.loads_data import BAY_1, bay_1_scene, bay_2_scene, first_survey, seen, write_bins

URL = "/v1/maps/site"


@pytest.fixture
def surveyed(store: MapStore) -> dict[str, int]:
    """The racked map with the first survey stored; revision ids ``bins`` and ``survey``."""
    bins = write_bins(store)
    written = write_scene_revision(store, store.ensure_map("site").id, [bay_1_scene(), bay_2_scene()],
                                   first_survey())
    assert written.revision is not None
    return {"bins": bins, "survey": written.revision.id}


@pytest.fixture
def keys(store: MapStore) -> dict[str, dict[str, str]]:
    return {role: {"X-API-Key": create_key(store, role=Role(role), name=f"{role}-client")[1]}
            for role in ("read", "write")}


def _ids(answer: dict[str, Any]) -> list[str]:
    return [item["id"] for item in answer["bins"]]


def test_bins_carry_what_the_robots_saw_and_filter_by_it(client: TestClient, store: MapStore,
                                                         surveyed: dict[str, int]) -> None:
    occupied = client.get(f"{URL}/bins", params={"occupancy": "occupied"})
    assert occupied.status_code == 200, occupied.text
    assert _ids(occupied.json()) == ["01-001-01", "01-002-01"]
    first = occupied.json()["bins"][0]["occupancy"]
    assert first["state"] == "occupied" and first["objects"] == ["p1", "l1", "l2"] and first["views"] == 3
    assert first["last_seen"].startswith("2025-11-26T03:00:00") and first["confidence"] == pytest.approx(0.97)
    assert first["revision_id"] == surveyed["survey"] and first["bay"] == BAY_1
    assert _ids(client.get(f"{URL}/bins", params={"occupancy": "empty"}).json()) == ["01-001-02", "01-002-02"]
    unknown = client.get(f"{URL}/bins", params={"occupancy": "unknown"}).json()
    assert _ids(unknown) == ["01-003-01"] and unknown["bins"][0]["occupancy"]["last_seen"] is None
    assert client.get(f"{URL}/bins", params={"occupancy": "full"}).status_code == 422
    before = client.get(f"{URL}/bins", params={"occupancy": "occupied", "revision": surveyed["bins"]}).json()
    assert before["total"] == 0, "before the survey no bin was seen"

    assert client.get(f"{URL}/bins/01-001-02").json()["occupancy"]["state"] == "empty"
    write_scene_revision(store, store.ensure_map("site").id, [],
                         [seen("01-001-02", Occupancy.OCCUPIED, views=3, objects=("p9",), bay=BAY_1)])
    wait_for(lambda: client.get(f"{URL}/bins/01-001-02").json()["occupancy"]["objects"] == ["p9"], timeout_s=5.0,
             what="the live bin read to follow the new state")
    as_was = client.get(f"{URL}/bins/01-001-02", params={"revision": surveyed["survey"]}).json()
    assert as_was["occupancy"]["state"] == "empty"


def test_the_scene_of_a_bin_s_bay(client: TestClient, surveyed: dict[str, int]) -> None:
    answer = client.get(f"{URL}/bins/01-001-02/scene")
    assert answer.status_code == 200, answer.text
    body = answer.json()
    assert body["bay"] == BAY_1 and body["occupancy"]["state"] == "empty"
    assert answer.headers["X-Aisle-Revision-Id"] == str(body["revision"])
    flags = {node["id"]: node["flags"] for node in body["nodes"]}
    assert flags["g1"] == ["false_estimate"] and flags["p1"] == []
    assert {(e["source"], e["target"], e["relation"]) for e in body["edges"]} == {
        ("p1", "l1", "supports"), ("p1", "l2", "supports"), ("l1", "l2", "unstable_contact")}
    hidden = client.get(f"{URL}/bins/01-002-01/scene").json()
    assert [node["flags"] for node in hidden["nodes"] if node["id"] == "p3"] == [["hidden_below"]]

    never_seen = client.get(f"{URL}/bins/01-003-01/scene")
    assert never_seen.status_code == 404 and "not seen" in never_seen.json()["detail"]
    assert client.get(f"{URL}/bins/77-777-01/scene").status_code == 404
    assert client.get(f"{URL}/bins/01-001-02/scene", params={"revision": surveyed["bins"]}).status_code == 404


STOCK = [
    {"id": "01-001-01", "holds_stock": False},  # the robots saw a pallet: a discrepancy
    {"id": "01-001-02", "holds_stock": True, "sku": "4006381333931", "quantity": 40},  # seen empty: a discrepancy
    {"id": "01-002-01", "holds_stock": True},  # seen occupied: agrees
    {"id": "01-002-02", "holds_stock": True},  # seen empty but only once: never reported
    {"id": "01-003-01", "holds_stock": False},  # never seen: never reported
]


def test_wms_stock_discrepancies_are_what_the_robots_saw_otherwise(
        client: TestClient, surveyed: dict[str, int], keys: dict[str, dict[str, str]]) -> None:
    assert client.get(f"{URL}/wms-stock/discrepancies").status_code == 404, "no stock list yet"
    put = client.put(f"{URL}/wms-stock", json={"bins": STOCK}, headers=keys["write"])
    assert put.status_code == 200, put.text
    answer = client.get(f"{URL}/wms-stock/discrepancies")
    assert answer.json() == put.json()
    body = answer.json()
    found = {item["bin_id"]: item for item in body["discrepancies"]}
    assert sorted(found) == ["01-001-01", "01-001-02"]
    assert body["counts"] == {"listed": 5, "agreeing": 1, "discrepancies": 2, "not_seen_well": 2}
    pallet = found["01-001-01"]
    assert (pallet["wms_holds_stock"], pallet["robots_saw"], pallet["views"]) == (False, "occupied", 3)
    assert [node["id"] for node in pallet["evidence"]] == ["p1", "l1", "l2"]
    assert pallet["last_seen"].startswith("2025-11-26T03:00:00")
    empty = found["01-001-02"]
    assert (empty["robots_saw"], empty["sku"], empty["quantity"], empty["evidence"]) == (
        "empty", "4006381333931", 40, [])

    once = client.get(f"{URL}/wms-stock/discrepancies", params={"min_views": 1}).json()
    assert sorted(item["bin_id"] for item in once["discrepancies"]) == ["01-001-01", "01-001-02", "01-002-02"]
    assert "01-003-01" not in {item["bin_id"] for item in once["discrepancies"]}, "an unseen bin never is"
    page = client.get(f"{URL}/wms-stock/discrepancies", params={"limit": 1}).json()
    rest = client.get(f"{URL}/wms-stock/discrepancies", params={"cursor": page["next_cursor"]}).json()
    assert [i["bin_id"] for i in page["discrepancies"] + rest["discrepancies"]] == ["01-001-01", "01-001-02"]

    complete = client.put(f"{URL}/wms-stock", json={"bins": STOCK[1:2], "complete": True}, headers=keys["write"])
    assert {item["bin_id"] for item in complete.json()["discrepancies"]} == {"01-001-01", "01-001-02", "01-002-01"}, \
        "a complete list leaving out occupied bins says they are empty"
    assert client.get(f"{URL}/wms-stock").json() == [{**STOCK[1], "quantity": 40.0}]


def test_the_stock_list_needs_a_write_key_and_valid_bins(
        client: TestClient, store: MapStore, surveyed: dict[str, int], keys: dict[str, dict[str, str]],
        tmp_path: Path) -> None:
    assert client.put(f"{URL}/wms-stock", json={"bins": STOCK}).status_code == 401
    assert client.put(f"{URL}/wms-stock", json={"bins": STOCK}, headers=keys["read"]).status_code == 403
    bad_id = client.put(f"{URL}/wms-stock", json={"bins": [{"id": "../x", "holds_stock": True}]},
                        headers=keys["write"])
    assert bad_id.status_code == 422 and bad_id.json()["detail"][0]["loc"][:3] == ["body", "bins", 0]
    nan = client.put(f"{URL}/wms-stock", content=b'{"bins": [{"id": "01-001-01", "holds_stock": true, '
                                                  b'"quantity": NaN}]}',
                     headers={**keys["write"], "Content-Type": "application/json"})
    assert nan.status_code == 422 and "finite" in json.dumps(nan.json())
    twice = client.put(f"{URL}/wms-stock", json={"bins": [STOCK[0], STOCK[0]]}, headers=keys["write"])
    assert twice.status_code == 422 and "repeated" in twice.json()["detail"]
    assert store.wms_stock(store.ensure_map("site").id) == [], "nothing refused was stored"

    app = create_app(store=store, settings=Settings(data_dir=tmp_path, database_url=store.url,
                                                    api_max_body_bytes=4096))
    try:
        with TestClient(app) as small:
            huge = {"bins": [{"id": f"01-{i:03d}-01", "holds_stock": True} for i in range(1000)]}
            refused = small.put(f"{URL}/wms-stock", json=huge, headers=keys["write"])
            assert refused.status_code == 413 and "detail" in refused.json()
    finally:
        app.state.context.live.close()


def test_occupancy_changes_are_announced(store: MapStore, make_client: ClientFactory,
                                         surveyed: dict[str, int]) -> None:
    client = make_client(store, **FAST)
    with client.stream("GET", f"{URL}/events", params={"after": surveyed["bins"]}) as stream:
        lines = stream.iter_lines()
        (survey,), _ = _read(lines, 1)
        write_scene_revision(store, store.ensure_map("site").id, [],
                             [seen("01-002-02", Occupancy.OCCUPIED, views=2, objects=("p4",), bay="r0-001/2"),
                              seen("01-001-01", Occupancy.OCCUPIED, views=4, objects=("p1", "l1", "l2"), bay=BAY_1)])
        (change,), _ = _read(lines, 1)
    assert survey.data["features"]["bin_state"]["added"] == 4
    assert survey.data["occupancy_changed"] == ["01-001-01", "01-001-02", "01-002-01", "01-002-02"]
    assert change.data["stage"] == "load_scenes"
    assert change.data["features"] == {"bin_state": {"added": 0, "removed": 0, "moved": 0, "changed": 2, "total": 4}}
    assert change.data["occupancy_changed"] == ["01-002-02"], "a new sighting of an occupied bin is no change"


def test_layout_and_its_pictures_take_the_new_kinds(client: TestClient, surveyed: dict[str, int]) -> None:
    layout = client.get(f"{URL}/layout", params={"kind": ["bin_state", "load_scene"]})
    assert layout.status_code == 200, layout.text
    kinds = sorted({feature["properties"]["kind"] for feature in layout.json()["features"]})
    assert kinds == ["bin_state", "load_scene"] and len(layout.json()["features"]) == 4 + 2
    for picture in ("layout.png", "layout.svg"):
        assert client.get(f"{URL}/{picture}", params={"kind": ["bin", "bin_state", "load_scene"]}).status_code == 200
        assert client.get(f"{URL}/{picture}").status_code == 200

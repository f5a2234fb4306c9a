"""Importing the WMS's own bin ids and serving matched bins under them."""

from __future__ import annotations

import http.client
import json
import sqlite3
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import sqlalchemy as sa
from fastapi.testclient import TestClient

from api import create_app
from atlas.reconcile import DetectedBin, reconcile
from services.pillar_mapping import fit_layout
from services.pillar_mapping.layout import layout_features
from services.pillar_mapping.synthetic import noisy_landmarks, rack_region
from shared.settings import Settings
from shared.store import Feature, MapStore, RevisionWrite, WmsBin, schema
from shared.store.keys import Role, create_key
from tests.api.conftest import served

URL = "/v1/maps/hall"


@pytest.fixture(scope="module")
def detected() -> list[Feature]:
    """Bins of one fit of a hall (3 aisles x 10 bays), as the pillar stage writes them."""
    hall = rack_region(aisles=3, bays=10)
    return layout_features(fit_layout(noisy_landmarks(hall, np.random.default_rng(0))[0]))["bin"]


@pytest.fixture
def hall(store: MapStore, detected: list[Feature]) -> int:
    map_id = store.ensure_map("hall").id
    return store.write_revision(map_id, RevisionWrite("pillar_mapping", features={"bin": detected})).id


@pytest.fixture
def writer(store: MapStore) -> dict[str, str]:
    return {"X-API-Key": create_key(store, role=Role.WRITE, name="operator")[1]}


def _site_numbering(detected: list[Feature], rng: np.random.Generator) -> list[dict[str, Any]]:
    """The WMS's list: its own ids ("A-<aisle>-<bay>") at surveyed positions 15 cm off, with the first three
    detected bins missing from it and two bins the map has not got."""
    out = []
    for item in detected[3:]:
        x, y = item.properties["centre"]
        dx, dy = rng.normal(0.0, 0.1, 2)
        out.append({"id": f"A-{item.key}", "x_m": x + dx, "y_m": y + dy})
    out += [{"id": "A-99-001", "x_m": 500.0, "y_m": 500.0}, {"id": "A-99-002"}]
    return out


def test_import_matches_by_position_and_bins_keep_the_site_numbering(
    client: TestClient, hall: int, detected: list[Feature], writer: dict[str, str]
) -> None:
    wms = _site_numbering(detected, np.random.default_rng(1))

    result = client.put(f"{URL}/wms-bins", json={"bins": wms, "tolerance_m": 0.6}, headers=writer)

    assert result.status_code == 200, result.text
    body = result.json()
    assert {(m["wms_id"], m["detected_id"]) for m in body["matched"]} == {(f"A-{f.key}", f.key) for f in detected[3:]}
    assert body["missing_in_map"] == ["A-99-001", "A-99-002"]
    assert body["unknown_to_wms"] == sorted(f.key for f in detected[:3])
    one = detected[5]
    by_wms = client.get(f"{URL}/bins/A-{one.key}").json()
    assert by_wms["detected_id"] == one.key and by_wms["status"] == "matched" and by_wms["id"] == f"A-{one.key}"
    assert client.get(f"{URL}/bins/{one.key}").json() == by_wms
    listed = client.get(f"{URL}/bins", params={"status": "unknown_to_wms"}).json()
    assert sorted(b["id"] for b in listed["bins"]) == sorted(f.key for f in detected[:3])
    assert client.get(f"{URL}/bins", params={"id_prefix": "A-"}).json()["total"] == len(detected) - 3


def test_reconciliation_follows_the_revisions(client: TestClient, store: MapStore, hall: int,
                                              detected: list[Feature], writer: dict[str, str]) -> None:
    first = client.put(f"{URL}/wms-bins", json={"bins": [{"id": detected[0].key}]}, headers=writer).json()
    client.put(f"{URL}/wms-bins", json={"bins": [{"id": detected[1].key}]}, headers=writer)

    then = client.get(f"{URL}/wms-bins/reconciliation", params={"revision": first["wms_revision_id"]}).json()
    now = client.get(f"{URL}/wms-bins/reconciliation").json()

    assert [m["detected_id"] for m in then["matched"]] == [detected[0].key]
    assert [m["detected_id"] for m in now["matched"]] == [detected[1].key] and now["matched"][0]["by"] == "id"
    assert [b["id"] for b in client.get(f"{URL}/wms-bins").json()] == [detected[1].key]


@pytest.mark.parametrize("body", [
    {"bins": [{"id": "A"}, {"id": "A"}]},
    {"bins": [{"id": "A", "x_m": 1.0}]},
    {"bins": [{"id": "A", "x_m": "nan", "y_m": 1.0}]},
    {"bins": [{"id": "'; DROP TABLE wms_bins; --"}]},
    {"bins": [], "tolerance_m": -1},
    {"bins": "all"},
])
def test_bad_imports_are_refused_and_change_nothing(client: TestClient, store: MapStore, hall: int,
                                                   writer: dict[str, str], body: dict[str, Any]) -> None:
    client.put(f"{URL}/wms-bins", json={"bins": [{"id": "KEEP"}]}, headers=writer)

    response = client.put(f"{URL}/wms-bins", json=body, headers=writer)

    assert response.status_code == 422 and response.json()["detail"]
    assert [b.wms_id for b in store.wms_bins(store.ensure_map("hall").id)] == ["KEEP"]


def test_import_needs_a_write_key(client: TestClient, store: MapStore, hall: int) -> None:
    reader = {"X-API-Key": create_key(store, role=Role.READ, name="wms")[1]}

    assert client.put(f"{URL}/wms-bins", json={"bins": []}).status_code == 401
    assert client.put(f"{URL}/wms-bins", json={"bins": []}, headers=reader).status_code == 403
    assert client.get(f"{URL}/wms-bins/reconciliation").status_code == 404


def test_matching_takes_closest_pairs_first_and_respects_levels() -> None:
    detected = [DetectedBin("a", 0.0, 0.0, 0), DetectedBin("b", 1.0, 0.0, 0), DetectedBin("c", 1.0, 0.0, 1)]
    wms = [WmsBin("W1", 0.45, 0.0, level=0), WmsBin("W2", 0.6, 0.0, level=0), WmsBin("W3", 1.1, 0.0, level=1)]

    result = reconcile(wms, detected, tolerance_m=0.5)

    assert {(m.wms_id, m.detected_id) for m in result.matched} == {("W1", "a"), ("W2", "b"), ("W3", "c")}
    assert result.missing_in_map == [] and result.unknown_to_wms == []


def test_routes_take_the_wms_id_of_a_matched_bin(client: TestClient, store: MapStore, hall: int,
                                                 detected: list[Feature], writer: dict[str, str]) -> None:
    one = detected[4]
    client.put(f"{URL}/wms-bins", json={"bins": [{"id": "SITE-7", "x_m": one.properties["centre"][0],
                                                  "y_m": one.properties["centre"][1]}]}, headers=writer)
    x, y, _ = one.properties["access_pose"]

    by_wms = client.get(f"{URL}/routes", params={"from": "bin:SITE-7", "to": f"point:{x},{y}"})
    by_aisle_id = client.get(f"{URL}/routes", params={"from": f"bin:{one.key}", "to": f"point:{x},{y}"})

    assert by_wms.status_code == by_aisle_id.status_code  # no place layers here: both 409, never 404
    assert by_wms.json()["detail"] == by_aisle_id.json()["detail"]


def test_an_id_match_far_from_its_wms_position_is_reported_with_both_positions() -> None:
    detected = [DetectedBin("01-002-01", 2.28, 6.10, 0), DetectedBin("01-004-01", 6.40, 6.05, 0)]
    wms = [WmsBin("01-002-01", 6.37, 6.05, level=0)]

    result = reconcile(wms, detected, tolerance_m=0.5)

    assert [(m.wms_id, m.detected_id, m.by) for m in result.matched] == [("01-002-01", "01-002-01", "id")]
    (far,) = result.discrepancies
    assert far.wms_xy == (6.37, 6.05) and far.detected_xy == (2.28, 6.10)
    assert far.delta_m == pytest.approx((-4.09, 0.05)) and far.distance_m == pytest.approx(4.09, abs=0.01)
    assert far.nearest_detected_id == "01-004-01"
    assert result.numbering.far == 1 and result.numbering.verdict != "consistent"


def test_positions_in_another_frame_are_told_apart_from_a_renumbering() -> None:
    detected = [DetectedBin(f"01-{bay:03d}", 2.7 * bay, 0.0) for bay in range(1, 11)]
    wms = [WmsBin(d.id, d.x_m + 20.0, d.y_m - 3.0) for d in detected]

    check = reconcile(wms, detected, tolerance_m=0.5).numbering

    assert check.verdict == "shifted" and check.far == check.id_matches == 10
    assert check.offset_m == pytest.approx((-20.0, 3.0)) and check.offset_support == 10
    assert "another frame" in check.message


def _renumbered(detected: list[Feature]) -> list[dict[str, Any]]:
    """A site that counts bays from 2 lower than Aisle: the WMS's bin (a, b) is Aisle's (a, b + 2), with Aisle's
    id format, at its surveyed position (5 cm off)."""
    ids = {f.key for f in detected}
    out = []
    for item in detected:
        aisle, bay = (int(part) for part in item.key.split("-"))
        if bay > 2 and f"{aisle:02d}-{bay - 2:03d}" in ids:
            x, y = item.properties["centre"]
            out.append({"id": f"{aisle:02d}-{bay - 2:03d}", "x_m": x + 0.05, "y_m": y})
    return out


def test_a_site_numbering_bays_differently_is_detected_at_once(
    client: TestClient, hall: int, detected: list[Feature], writer: dict[str, str]
) -> None:
    wms = _renumbered(detected)

    body = client.put(f"{URL}/wms-bins", json={"bins": wms}, headers=writer).json()

    assert body["counts"]["discrepancies"] == len(wms) == len(body["discrepancies"])
    numbering = body["numbering"]
    assert numbering["verdict"] == "renumbered" and numbering["far"] == len(wms)
    assert numbering["id_shift"] == {"aisle": 0, "bay": 2, "level": 0, "support": len(wms)}
    assert "numbers bins differently" in numbering["message"] and "match_by=position" in numbering["message"]
    first = body["discrepancies"][0]
    assert first["distance_m"] > 0.5 and set(first) >= {"wms_position", "detected_position", "delta_m"}
    assert client.get(f"{URL}/wms-bins/reconciliation").json()["numbering"] == numbering


def test_matching_by_position_first_follows_the_site_numbering(
    client: TestClient, hall: int, detected: list[Feature], writer: dict[str, str]
) -> None:
    wms = _renumbered(detected)

    body = client.put(f"{URL}/wms-bins", json={"bins": wms, "match_by": "position"}, headers=writer).json()

    assert body["match_by"] == "position" and body["discrepancies"] == []
    assert all(m["by"] == "position" and m["distance_m"] < 0.1 for m in body["matched"])
    moved = {m["wms_id"]: m["detected_id"] for m in body["matched"]}
    aisle, bay = (int(part) for part in wms[0]["id"].split("-"))
    assert moved[wms[0]["id"]] == f"{aisle:02d}-{bay + 2:03d}"


@contextmanager
def _map_write_locked(store: MapStore, map_id: int) -> Iterator[None]:
    """Hold the database's lock that a revision of map ``map_id`` needs (SQLite: the write lock; PostgreSQL: the
    map's row), so an import waits in the middle until the block ends."""
    if store.url.startswith("sqlite"):
        lite = sqlite3.connect(str(sa.make_url(store.url).database), isolation_level=None)
        try:
            lite.execute("BEGIN IMMEDIATE")
            yield
            lite.execute("ROLLBACK")
        finally:
            lite.close()
        return
    with store.engine.connect() as connection, connection.begin():
        connection.execute(sa.select(schema.maps.c.id).where(schema.maps.c.id == map_id).with_for_update())
        yield


def test_bins_are_read_while_an_import_is_under_way(store: MapStore, tmp_path: Path, hall: int,
                                                    detected: list[Feature], writer: dict[str, str]) -> None:
    """Through a real server: an import held at the database's lock does not hold up reads, and once it is in,
    reads serve the WMS ids at once."""
    map_id = store.ensure_map("hall").id
    listed = _site_numbering(detected, np.random.default_rng(3))
    body = json.dumps({"bins": listed, "tolerance_m": 0.5}).encode()
    app = create_app(store=store, settings=Settings(data_dir=tmp_path, database_url=store.url))
    with served(app) as port:
        reader = http.client.HTTPConnection("127.0.0.1", port, timeout=60)

        def read(bin_id: str) -> tuple[int, dict[str, Any]]:
            reader.request("GET", f"{URL}/bins/{bin_id}")
            response = reader.getresponse()
            return response.status, json.loads(response.read())

        before = read(detected[5].key)
        with ThreadPoolExecutor(1) as pool, _map_write_locked(store, map_id):
            def put() -> tuple[int, bytes]:
                importer = http.client.HTTPConnection("127.0.0.1", port, timeout=120)
                try:
                    importer.request("PUT", f"{URL}/wms-bins", body=body,
                                     headers={**writer, "Content-Type": "application/json"})
                    response = importer.getresponse()
                    return response.status, response.read()
                finally:
                    importer.close()

            imported = pool.submit(put)
            during = [read(item.key) for item in detected[3:13]]
            assert not imported.done()  # the import is still waiting for the lock
        status, answer = imported.result(timeout=120)
        after = read(f"A-{detected[5].key}")
        reader.close()

    assert before == (200, before[1]) and before[1]["status"] == "unreconciled"
    assert [code for code, _ in during] == [200] * 10
    assert status == 200 and json.loads(answer)["counts"]["matched"] == len(detected) - 3
    assert after[0] == 200 and after[1]["detected_id"] == detected[5].key and after[1]["status"] == "matched"

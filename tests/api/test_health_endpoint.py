"""/v1/health: database, bus and workers; 503 with the same JSON body when degraded."""

from __future__ import annotations

import datetime as dt
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from shared.bus import Bus
from shared.settings import ZenohSettings
from shared.store import MapStore
from shared.store import schema as store_schema
from tests.helpers import wait_for

URL = "/v1/health"
STARTED = dt.datetime(2026, 1, 1, tzinfo=dt.UTC)


def _age_heartbeat(store: MapStore, name: str, seconds: float) -> None:
    with store.engine.begin() as connection:
        connection.execute(store_schema.workers.update().where(store_schema.workers.c.name == name).values(
            heartbeat_at=dt.datetime.now(dt.UTC) - dt.timedelta(seconds=seconds)))


def test_healthy_with_fresh_heartbeats(store: MapStore, make_client: Callable[..., TestClient]) -> None:
    store.heartbeat("occupancy_mapping", {"scans": 12}, started_at=STARTED)
    client = make_client(store, expected_workers=["occupancy_mapping"])

    response = client.get(URL)

    assert response.status_code == 200
    body = response.json()
    assert body["status"] == "ok"
    assert body["database"]["ok"] is True
    assert body["bus"] == {"ok": True, "mode": "none", "counters": {},
                           "detail": "no bus; worker liveness from database heartbeats"}
    assert [(w["name"], w["alive"], w["counters"]) for w in body["workers"]] == [
        ("occupancy_mapping", True, {"scans": 12})]
    assert body["missing_workers"] == []


def test_stale_heartbeat_means_the_worker_is_missing(store: MapStore,
                                                     make_client: Callable[..., TestClient]) -> None:
    store.heartbeat("occupancy_mapping", {}, started_at=STARTED)
    _age_heartbeat(store, "occupancy_mapping", 60)
    client = make_client(store, expected_workers=["occupancy_mapping", "semantics"])

    response = client.get(URL)

    assert response.status_code == 503
    body = response.json()
    assert body["status"] == "degraded"
    assert body["database"]["ok"] is True
    assert body["missing_workers"] == ["occupancy_mapping", "semantics"]
    workers = {w["name"]: w for w in body["workers"]}
    assert workers["occupancy_mapping"]["alive"] is False
    assert workers["occupancy_mapping"]["heartbeat_at"] is not None
    assert workers["semantics"] == {"name": "semantics", "alive": False, "heartbeat_at": None, "counters": {}}


@pytest.fixture(params=["postgres refusing", "sqlite path is a directory"])
def down_store(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[MapStore]:
    """A store whose database cannot be opened (no server on port 1; a directory as the SQLite file)."""
    url = "postgresql+psycopg://aisle:s3cret@127.0.0.1:1/none" if request.param.startswith("postgres") \
        else f"sqlite:///{tmp_path}"
    map_store = MapStore(url)
    yield map_store
    map_store.close()


def test_database_down_is_degraded_503(down_store: MapStore, make_client: Callable[..., TestClient]) -> None:
    response = make_client(down_store, expected_workers=["occupancy_mapping"]).get(URL)

    assert response.status_code == 503
    body = response.json()
    assert body["status"] == "degraded"
    assert body["database"]["ok"] is False
    assert body["database"]["detail"].startswith("database unavailable")
    assert "s3cret" not in response.text
    assert body["missing_workers"] == ["occupancy_mapping"]


def test_reads_while_database_down_are_503_json(down_store: MapStore,
                                                make_client: Callable[..., TestClient]) -> None:
    client = make_client(down_store)

    for path in ("/v1/maps", "/v1/maps/site", "/v1/maps/site/features"):
        response = client.get(path)

        assert response.status_code == 503, path
        assert response.json()["detail"].startswith("database unavailable")
        assert response.headers["retry-after"] == "5"


@pytest.fixture
def bus(zenoh_listen: ZenohSettings) -> Iterator[Bus]:
    with Bus.open(zenoh_listen, domain_id=42) as opened:
        yield opened


def test_worker_alive_by_bus_liveliness(store: MapStore, bus: Bus,
                                        make_client: Callable[..., TestClient]) -> None:
    client = make_client(store, bus=bus, expected_workers=["occupancy_mapping"])
    assert client.get(URL).json()["missing_workers"] == ["occupancy_mapping"]

    token = bus.declare_worker("occupancy_mapping")
    try:
        wait_for(lambda: client.get(URL).status_code == 200, what="the worker to show as alive")
        body = client.get(URL).json()
    finally:
        token.undeclare()

    assert body["bus"]["ok"] is True
    assert body["bus"]["mode"] == "peer"
    # alive by the bus even though it never wrote a heartbeat
    assert body["workers"] == [
        {"name": "occupancy_mapping", "alive": True, "heartbeat_at": None, "counters": {}}]


def test_fresh_heartbeat_without_liveliness_is_not_alive_when_a_bus_is_used(
    store: MapStore, bus: Bus, make_client: Callable[..., TestClient]
) -> None:
    store.heartbeat("occupancy_mapping", {}, started_at=STARTED)

    body = make_client(store, bus=bus, expected_workers=["occupancy_mapping"]).get(URL).json()

    assert body["workers"][0]["alive"] is False
    assert body["missing_workers"] == ["occupancy_mapping"]


def test_broken_bus_is_degraded(store: MapStore, bus: Bus, make_client: Callable[..., TestClient]) -> None:
    client = make_client(store, bus=bus)
    bus.close()

    response = client.get(URL)

    assert response.status_code == 503
    assert response.json()["bus"]["ok"] is False
    assert "liveliness query failed" in response.json()["bus"]["detail"]

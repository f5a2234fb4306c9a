"""Fixtures for API tests: a TestClient over the real ``store`` of tests/conftest.py and a sample map.

``store`` runs each test on a SQLite file and, when ``AISLE_TEST_POSTGRES_URL`` is set, on a PostgreSQL schema
too; both at the newest schema and empty (migrated once per test process, see ``migrated_store_url``).
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import uvicorn
from fastapi import FastAPI
from fastapi.testclient import TestClient

from api import create_app
from shared.bus import Bus
from shared.settings import Settings
from shared.store import Feature, GridLayer, MapStore, RevisionWrite
from tests.helpers import free_port, wait_for

ClientFactory = Callable[..., TestClient]


@pytest.fixture
def make_client(tmp_path: Path) -> Iterator[ClientFactory]:
    """Build a TestClient over a store, as ``make_client(store, bus=..., expected_workers=...)``.

    Other keyword arguments (``require_keys_for_reads``, ``rate_limit_per_s``, ...) go to :func:`create_app`.
    """
    clients: list[tuple[TestClient, FastAPI]] = []

    def build(map_store: MapStore, *, bus: Bus | None = None, expected_workers: Sequence[str] = (),
              raise_server_exceptions: bool = True, **options: Any) -> TestClient:
        settings = Settings(data_dir=tmp_path, database_url=map_store.url)
        app = create_app(store=map_store, settings=settings, bus=bus, expected_workers=expected_workers,
                         **options)
        client = TestClient(app, raise_server_exceptions=raise_server_exceptions)
        clients.append((client, app))
        return client

    yield build
    for client, app in clients:
        client.close()
        app.state.context.live.close()  # waits for live refreshes under way, before the store closes


@pytest.fixture
def client(store: MapStore, make_client: ClientFactory) -> TestClient:
    return make_client(store)


OCCUPANCY_1 = np.array([[0, 0, 0, 0], [-1, -1, -1, -1], [100, 100, 100, 100]], dtype=np.int8)
"""3 x 4 cells of 0.5 m from (-1, 2): free along the lowest y, unknown, occupied along the highest y."""
OCCUPANCY_2 = np.zeros((3, 4), dtype=np.int8)
TRAVERSABILITY = np.array([[0.0, 1.0], [np.nan, 0.5]], dtype=np.float32)


def _point(x: float, y: float) -> dict[str, object]:
    return {"type": "Point", "coordinates": [x, y]}


def _box(min_x: float, min_y: float, max_x: float, max_y: float) -> dict[str, object]:
    ring = [[min_x, min_y], [max_x, min_y], [max_x, max_y], [min_x, max_y], [min_x, min_y]]
    return {"type": "Polygon", "coordinates": [ring]}


@pytest.fixture
def site(store: MapStore) -> dict[str, int]:
    """Map ``site`` written in four revisions, and a map ``other`` with one; their revision ids by name.

    1. ``occupancy_1``, occupancy_mapping: ``occupancy`` = OCCUPANCY_1
    2. ``semantics_1``, semantics: rack_row R1 (box 0..10 x 0..1), bins B1 at (1, 1) and B2 at
       (50, 50), dock D1 at (-5, 0), layer ``traversability`` (float32 with a NaN)
    3. ``occupancy_2``, occupancy_mapping: ``occupancy`` = OCCUPANCY_2
    4. ``semantics_2``, semantics: bins only: B1 moved to (2, 1), B2 gone (R1 and D1 stay live)

    ``other``: map ``other``'s one revision.
    """
    site_id = store.ensure_map("site").id
    layer = GridLayer("occupancy", OCCUPANCY_1, 0.5, -1.0, 2.0, {"encoding": "occupancy"})
    first_occupancy = store.write_revision(site_id, RevisionWrite("occupancy_mapping", layers=[layer])).id
    first_semantics = store.write_revision(site_id, RevisionWrite(
        "semantics",
        layers=[GridLayer("traversability", TRAVERSABILITY, 1.0, 0.0, 0.0)],
        features={
            "rack_row": [Feature("rack_row", "R1", _box(0, 0, 10, 1), {"aisle": "A"}, 0.8)],
            "bin": [Feature("bin", "B1", _point(1, 1), {"level": 2}, 0.9),
                    Feature("bin", "B2", _point(50, 50), {"level": 0}, 0.7)],
            "dock": [Feature("dock", "D1", _point(-5, 0))],
        },
    )).id
    layer = GridLayer("occupancy", OCCUPANCY_2, 0.5, -1.0, 2.0, {"encoding": "occupancy"})
    second_occupancy = store.write_revision(site_id, RevisionWrite("occupancy_mapping", layers=[layer])).id
    second_semantics = store.write_revision(site_id, RevisionWrite(
        "semantics", features={"bin": [Feature("bin", "B1", _point(2, 1), {"level": 2}, 0.95)]},
    )).id
    other_id = store.ensure_map("other").id
    other_map = store.write_revision(other_id, RevisionWrite(
        "semantics", features={"bin": [Feature("bin", "X1", _point(0, 0))]},
    )).id
    return {"occupancy_1": first_occupancy, "semantics_1": first_semantics, "occupancy_2": second_occupancy,
            "semantics_2": second_semantics, "other": other_map}


@contextmanager
def served(app: FastAPI) -> Iterator[int]:
    """``app`` served by uvicorn on a free loopback port (in a thread of this process), as ``aisle serve`` serves
    it; yields the port once it listens, and stops the server (and the app's live state) afterwards."""
    port = free_port()
    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=port, log_level="warning", access_log=False))
    thread = threading.Thread(target=server.run, name="api-under-test")
    thread.start()
    try:
        wait_for(lambda: server.started or not thread.is_alive(), timeout_s=30.0, what="uvicorn to start")
        assert server.started, f"uvicorn did not start on port {port}"
        yield port
    finally:
        server.should_exit = True
        thread.join(timeout=30.0)
        app.state.context.live.close()

"""The viewer's page and files: served from the package, open to all while map reads may need a key."""

from __future__ import annotations

import cv2
import numpy as np
from fastapi.testclient import TestClient

from shared.store import GridLayer, MapStore, RevisionWrite
from tests.api.conftest import ClientFactory


def test_page_and_files_need_no_key_where_map_reads_do(store: MapStore, make_client: ClientFactory) -> None:
    client = make_client(store, require_keys_for_reads=True)

    for path in ("/", "/viewer", "/viewer/viewer.js", "/viewer/leaflet/leaflet.css", "/viewer/leaflet/LICENSE"):
        assert client.get(path).status_code == 200, path
    assert client.get("/").headers["content-type"].startswith("text/html")
    assert client.get("/viewer/viewer.js").headers["content-type"].startswith("text/javascript")
    assert client.get("/v1/maps").status_code == 401


def test_only_the_viewer_files_are_served(client: TestClient) -> None:
    for path in ("/viewer/nothing.js", "/viewer/..%2Fapp.py", "/viewer/../routers/viewer.py", "/viewer/leaflet"):
        assert client.get(path).status_code == 404, path


def test_a_layer_overlay_is_transparent_where_nothing_is_known(client: TestClient, store: MapStore) -> None:
    site = store.ensure_map("site").id
    occupancy = np.array([[0, -1], [100, -1]], dtype=np.int8)
    store.write_revision(site, RevisionWrite("occupancy_mapping", layers=[
        GridLayer("occupancy", occupancy, 0.5, 0.0, 0.0, {"encoding": "occupancy"})]))

    response = client.get("/v1/maps/site/layers/occupancy/overlay.png")
    image = cv2.imdecode(np.frombuffer(response.content, np.uint8), cv2.IMREAD_UNCHANGED)

    assert response.status_code == 200 and image is not None and image.shape == (2, 2, 4)
    assert image[:, 1, 3].tolist() == [0, 0] and image[:, 0, 3].min() > 0
    assert client.get("/v1/maps/site/layers/occupancy/overlay.png", params={"entropy": "nope"}).status_code == 404

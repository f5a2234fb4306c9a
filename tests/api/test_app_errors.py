"""api.app: docs, and every error as JSON with a detail."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from fastapi.testclient import TestClient

from shared.store import MapStore, StoredFeature, StoreError


def test_openapi_docs_are_served(client: TestClient) -> None:
    spec = client.get("/openapi.json").json()

    assert client.get("/docs").status_code == 200
    assert spec["info"]["title"] == "Aisle"
    assert "/v1/maps/{map_name}/layers/{layer}.png" in spec["paths"]
    assert "/v1/maps/{map_name}/features" in spec["paths"]


def test_unknown_path_is_json_404(client: TestClient) -> None:
    response = client.get("/v2/everything")

    assert response.status_code == 404
    assert response.json() == {"detail": "Not Found"}


class _RefusingStore(MapStore):
    def features(self, map_id: int, **kwargs: Any) -> list[StoredFeature]:
        raise StoreError("bbox too complex for this store")


class _BrokenStore(MapStore):
    def features(self, map_id: int, **kwargs: Any) -> list[StoredFeature]:
        raise RuntimeError("bug")


def test_store_refusal_is_400_with_its_message(migrated_store_url: str,
                                               make_client: Callable[..., TestClient]) -> None:
    store = _RefusingStore(migrated_store_url)
    store.ensure_map("site")

    response = make_client(store).get("/v1/maps/site/features")
    store.close()

    assert response.status_code == 400
    assert response.json() == {"detail": "bbox too complex for this store"}


def test_unexpected_failure_is_json_500_without_internals(migrated_store_url: str,
                                                          make_client: Callable[..., TestClient]) -> None:
    store = _BrokenStore(migrated_store_url)
    store.ensure_map("site")

    response = make_client(store, raise_server_exceptions=False).get("/v1/maps/site/features")
    store.close()

    assert response.status_code == 500
    assert response.json() == {"detail": "internal error; the server log has the details"}

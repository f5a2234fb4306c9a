"""/v1/maps: maps and their revisions."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from shared.store import MapStore, RetentionPolicy
from shared.store.keys import Role, create_key
from tests.api.conftest import ClientFactory


def test_list_maps_gives_latest_revision_and_layer_names(client: TestClient, site: dict[str, int]) -> None:
    response = client.get("/v1/maps")

    assert response.status_code == 200
    by_name = {item["name"]: item for item in response.json()}
    assert set(by_name) == {"site", "other"}
    assert by_name["site"]["latest_revision_id"] == site["semantics_2"]
    assert by_name["site"]["layers"] == ["occupancy", "traversability"]
    assert by_name["site"]["frame_id"] == "map"
    assert by_name["other"]["layers"] == []


def test_get_map_includes_its_latest_revision(client: TestClient, site: dict[str, int]) -> None:
    body = client.get("/v1/maps/site").json()

    assert body["latest_revision"]["id"] == site["semantics_2"]
    assert body["latest_revision"]["stage"] == "semantics"
    assert body["latest_revision"]["summary"]["features"]["bin"] == {
        "added": 0, "removed": 1, "moved": 1, "changed": 0, "total": 1}


def test_map_without_revisions_has_no_latest(client: TestClient, store: MapStore) -> None:
    store.ensure_map("empty")

    body = client.get("/v1/maps/empty").json()

    assert body["latest_revision_id"] is None
    assert body["latest_revision"] is None
    assert body["layers"] == []


def test_unknown_map_is_404_naming_the_known_maps(client: TestClient, site: dict[str, int]) -> None:
    for suffix in ("", "/revisions", "/layers", "/layers/occupancy.png", "/features"):
        path = f"/v1/maps/nope{suffix}"
        response = client.get(path)

        assert response.status_code == 404, path
        assert response.json()["detail"] == "no map named 'nope'; known maps: ['site', 'other']"


def test_revisions_are_paged_oldest_first(client: TestClient, site: dict[str, int]) -> None:
    first = client.get("/v1/maps/site/revisions", params={"limit": 3}).json()
    rest = client.get("/v1/maps/site/revisions", params={"limit": 3, "after": first["next_after"]}).json()

    assert [r["id"] for r in first["revisions"]] == [
        site["occupancy_1"], site["semantics_1"], site["occupancy_2"]]
    assert [r["stage"] for r in first["revisions"]] == ["occupancy_mapping", "semantics", "occupancy_mapping"]
    assert [r["id"] for r in rest["revisions"]] == [site["semantics_2"]]
    assert rest["next_after"] is None


@pytest.mark.parametrize(
    "params", [{"limit": 0}, {"limit": 1001}, {"limit": -1}, {"after": -1}, {"after": "x"}])
def test_bad_revision_paging_is_422(client: TestClient, site: dict[str, int],
                                    params: dict[str, int | str]) -> None:
    response = client.get("/v1/maps/site/revisions", params=params)

    assert response.status_code == 422
    assert response.json()["detail"][0]["loc"] == ["query", next(iter(params))]


def test_get_revision_by_id(client: TestClient, site: dict[str, int]) -> None:
    body = client.get(f"/v1/maps/site/revisions/{site['semantics_1']}").json()

    assert body["id"] == site["semantics_1"]
    assert body["stage"] == "semantics"
    assert body["summary"]["layers_updated"] == ["traversability"]


def test_revision_of_another_map_is_404(client: TestClient, site: dict[str, int]) -> None:
    response = client.get(f"/v1/maps/site/revisions/{site['other']}")

    assert response.status_code == 404
    assert response.json()["detail"] == f"revision {site['other']} is not a revision of map 'site'"


def test_revision_id_must_be_positive(client: TestClient, site: dict[str, int]) -> None:
    assert client.get("/v1/maps/site/revisions/0").status_code == 422


def test_a_pinned_revision_survives_compaction_and_unpinning_lets_it_go(
        store: MapStore, make_client: ClientFactory, site: dict[str, int]) -> None:
    writer = make_client(store)
    writer.headers["X-API-Key"] = create_key(store, role=Role.WRITE, name="wms")[1]
    pinned = writer.put(f"/v1/maps/site/revisions/{site['occupancy_1']}/pin")
    assert pinned.status_code == 200 and pinned.json()["pinned"] is True
    assert writer.get(f"/v1/maps/site/revisions/{site['occupancy_1']}").json()["pinned"] is True
    thin_all = RetentionPolicy(keep_all_s=0, hourly_s=0)
    site_id = store.ensure_map("site").id

    store.compact(site_id, thin_all)
    assert writer.get(f"/v1/maps/site/revisions/{site['occupancy_1']}").status_code == 200

    assert writer.delete(f"/v1/maps/site/revisions/{site['occupancy_1']}/pin").json()["pinned"] is False
    store.compact(site_id, thin_all)
    gone = writer.get("/v1/maps/site/layers/occupancy", params={"revision": site["occupancy_1"]})
    assert gone.status_code == 404 and "thinned by the retention settings" in gone.json()["detail"]


def test_pinning_needs_a_write_key_and_a_revision_of_the_map(
        store: MapStore, make_client: ClientFactory, site: dict[str, int]) -> None:
    reader = make_client(store)
    reader.headers["X-API-Key"] = create_key(store, role=Role.READ, name="viewer")[1]
    assert reader.put(f"/v1/maps/site/revisions/{site['occupancy_1']}/pin").status_code == 403
    reader.headers["X-API-Key"] = create_key(store, role=Role.WRITE, name="wms")[1]
    missing = reader.put(f"/v1/maps/site/revisions/{site['other']}/pin")
    assert missing.status_code == 404 and "not a revision of map 'site'" in missing.json()["detail"]

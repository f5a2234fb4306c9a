"""Live GeoJSON queries come from an in-memory index: the same answers as the store gives at the revision the
index covers, updated with just the rows each new revision changed."""

from __future__ import annotations

import asyncio
import json
from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient

from atlas.cache import RevisionCache
from atlas.features import FeatureIndex, geojson_bytes
from atlas.live import LiveMaps
from shared.store import Feature, GridLayer, MapStore, RevisionWrite
from tests.api.conftest import ClientFactory

URL = "/v1/maps/site/features"
QUERIES: list[dict[str, Any]] = [
    {},
    {"bbox": "0,0,3,3"},
    {"bbox": "-10,-10,0,0.5"},
    {"kind": ["bin"]},
    {"kind": ["rack_row", "dock"], "bbox": "-6,-1,5,5"},
    {"limit": 1, "offset": 1},
    {"bbox": "1000,1000,1001,1001"},
]


def _live_and_at_newest(client: TestClient, query: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    live = client.get(URL, params=query)
    newest = int(live.headers["X-Aisle-Revision-Id"])
    exact = client.get(URL, params={**query, "revision": newest})
    assert live.status_code == exact.status_code == 200
    return live.json(), exact.json()


@pytest.mark.parametrize("query", QUERIES)
def test_live_answer_is_the_store_answer_at_the_newest_revision(client: TestClient, site: dict[str, int],
                                                                query: dict[str, Any]) -> None:
    live, exact = _live_and_at_newest(client, query)

    assert live == exact  # the features, paging and cursor, and the revision they are of
    assert live["revision"] == site["semantics_2"]


@pytest.mark.parametrize("query", QUERIES)
def test_answers_from_memory_are_the_answers_of_the_route(client: TestClient, site: dict[str, int],
                                                         query: dict[str, Any]) -> None:
    first = client.get(URL, params=query)  # the route: it builds the live state
    again = client.get(URL, params=query)  # answered from memory before FastAPI

    assert first.status_code == again.status_code == 200
    assert first.content == again.content
    assert first.headers["X-Aisle-Revision-Id"] == again.headers["X-Aisle-Revision-Id"] == str(site["semantics_2"])
    assert first.headers["content-type"] == again.headers["content-type"] == "application/json"


def test_live_answers_follow_every_new_revision(store: MapStore, make_client: ClientFactory, site: dict[str, int]
                                                ) -> None:
    client = make_client(store, live_staleness_s=0)  # each read looks at the store: it sees writes made beside
    site_id = store.ensure_map("site").id
    assert [f["id"] for f in client.get(URL, params={"kind": "bin"}).json()["features"]] == ["bin/B1"]

    moved = store.write_revision(site_id, RevisionWrite("semantics", features={"bin": [
        Feature("bin", "B1", {"type": "Point", "coordinates": [7.0, 1.0]}),
        Feature("bin", "B3", {"type": "Point", "coordinates": [8.0, 1.0]})]})).id
    after_move = client.get(URL, params={"kind": "bin"})
    layer_only = store.write_revision(site_id, RevisionWrite("occupancy_mapping", layers=[
        GridLayer("occupancy", np.zeros((2, 2), dtype=np.int8), 0.5, 0.0, 0.0)])).id
    after_layer = client.get(URL, params={"kind": "bin"})
    gone = store.write_revision(site_id, RevisionWrite("semantics", features={"bin": []})).id
    after_removal = client.get(URL, params={"kind": "bin"})

    assert [f["geometry"]["coordinates"] for f in after_move.json()["features"]] == [[7.0, 1.0], [8.0, 1.0]]
    assert after_move.headers["X-Aisle-Revision-Id"] == str(moved)
    assert after_layer.json()["features"] == after_move.json()["features"]
    assert after_layer.headers["X-Aisle-Revision-Id"] == str(layer_only)
    assert after_removal.json()["features"] == []
    assert after_removal.headers["X-Aisle-Revision-Id"] == str(gone)


def test_each_map_has_its_own_index(client: TestClient, site: dict[str, int]) -> None:
    site_ids = [f["id"] for f in client.get(URL).json()["features"]]
    other_ids = [f["id"] for f in client.get("/v1/maps/other/features").json()["features"]]

    assert "bin/B1" in site_ids and "bin/X1" not in site_ids
    assert other_ids == ["bin/X1"]


def test_a_map_without_revisions_has_no_live_state(store: MapStore) -> None:
    empty = store.ensure_map("empty")

    assert asyncio.run(LiveMaps(store, RevisionCache()).get(empty)) is None


def test_stored_properties_named_like_the_added_ones_are_replaced(store: MapStore, client: TestClient) -> None:
    site_id = store.ensure_map("site").id
    store.write_revision(site_id, RevisionWrite("pillar_mapping", features={"bin": [
        Feature("bin", "01-001", {"type": "Point", "coordinates": [1.0, 2.0]},
                {"kind": "storage", "stage": "old", "aisle": 1}, 0.5)]}))
    row = store.live_feature_rows(site_id)[0]

    live = client.get(URL).json()["features"][0]

    assert live["properties"] == {"kind": "bin", "stage": "pillar_mapping", "aisle": 1, "key": "01-001",
                                  "revision_id": row.revision_id, "confidence": 0.5}
    assert geojson_bytes(row).count(b'"kind"') == 1


def test_an_updated_index_is_the_index_built_anew_and_keeps_unchanged_features(store: MapStore,
                                                                               site: dict[str, int]) -> None:
    site_id = store.ensure_map("site").id
    before = FeatureIndex.build(site["semantics_2"], store.live_feature_rows(site_id))
    newer = store.write_revision(site_id, RevisionWrite("semantics", features={"bin": [
        Feature("bin", "B1", {"type": "Point", "coordinates": [2.0, 1.0]}, {"level": 2}, 0.95),  # as it was
        Feature("bin", "B4", {"type": "Point", "coordinates": [4.0, 1.0]})]})).id
    store.write_revision(site_id, RevisionWrite("occupancy_mapping", layers=[
        GridLayer("occupancy", np.zeros((2, 2), dtype=np.int8), 0.5, 0.0, 0.0)]))
    changed = store.feature_rows_changed(site_id, after=before.revision_id, upto=newer)

    after = before.updated(newer, changed)
    anew = FeatureIndex.build(newer, store.live_feature_rows(site_id))

    assert [row.key for row in changed] == ["B4"]  # B1 was written as stored: its row stays
    assert list(after.geojson) == list(anew.geojson)
    assert after.rows == anew.rows and after.newest == anew.newest
    assert after.geojson[0] is before.geojson[0]  # not encoded again
    assert [json.loads(item)["properties"]["revision_id"] for item in after.geojson] == [
        row.revision_id for row in anew.rows]

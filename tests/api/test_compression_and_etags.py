"""Large answers go gzip-compressed, event streams never; reads carry an ETag and a matching If-None-Match is 304."""

from __future__ import annotations

import time

import numpy as np
import pytest
from fastapi.testclient import TestClient

from api.conditional import accepts_gzip, matches
from shared.store import GridLayer, MapInfo, MapStore, RevisionWrite
from tests.api.conftest import ClientFactory
from tests.api.warehouse_map import write_warehouse

GZIP = {"Accept-Encoding": "gzip"}
IDENTITY = {"Accept-Encoding": "identity"}


@pytest.fixture
def hall(store: MapStore) -> MapInfo:
    return write_warehouse(store)


@pytest.fixture
def reader(store: MapStore, make_client: ClientFactory, hall: MapInfo) -> TestClient:
    return make_client(store, rate_limit_per_s=None, live_staleness_s=0, gzip_min_bytes=4096)


def test_a_large_json_answer_is_gzipped_for_a_client_that_accepts_it(reader: TestClient) -> None:
    plain = reader.get("/v1/maps/site/layout", headers=IDENTITY)
    zipped = reader.get("/v1/maps/site/layout", headers=GZIP)

    assert plain.status_code == zipped.status_code == 200
    assert "content-encoding" not in plain.headers
    assert zipped.headers["content-encoding"] == "gzip"
    assert int(zipped.headers["content-length"]) < len(plain.content) / 4
    assert zipped.json() == plain.json()
    assert "content-encoding" not in reader.get("/v1/health", headers=GZIP).headers  # small: sent as it is


@pytest.mark.timeout(60)  # a compressed (buffered) stream would hang here instead of failing
def test_event_streams_are_not_compressed_and_events_still_arrive(store: MapStore, make_client: ClientFactory
                                                                   ) -> None:
    client = make_client(store, event_poll_s=0.02, event_heartbeat_s=0.1)
    site = store.ensure_map("site")
    layer = GridLayer("occupancy", np.zeros((2, 2), dtype=np.int8), 0.5, 0.0, 0.0)
    with client.stream("GET", "/v1/maps/site/events", params={"after": 0}, headers=GZIP) as response:
        assert response.status_code == 200
        assert "content-encoding" not in response.headers and "etag" not in response.headers
        lines = response.iter_lines()
        for _ in range(3):
            written = store.write_revision(site.id, RevisionWrite("occupancy_mapping", layers=[layer])).id
            deadline = time.monotonic() + 10
            while next(lines) != f"id: {written}":
                assert time.monotonic() < deadline, f"revision {written} not announced within 10 s"


READS_AT_A_REVISION = ["/v1/maps/site/layout", "/v1/maps/site/layers/occupancy", "/v1/maps/site/layers/occupancy.png",
                       "/v1/maps/site/features", "/v1/maps/site/bins"]


def test_a_read_at_a_revision_has_an_etag_and_the_same_tag_back_is_304(reader: TestClient, store: MapStore,
                                                                      hall: MapInfo) -> None:
    revision = {"revision": store.latest_revision(hall.id).id}  # type: ignore[union-attr]
    for path in READS_AT_A_REVISION:
        first = reader.get(path, params=revision, headers=GZIP)
        assert first.status_code == 200, (path, first.text)
        etag = first.headers["etag"]
        assert reader.get(path, params=revision, headers=IDENTITY).headers["etag"] == etag  # whatever the encoding

        again = reader.get(path, params=revision, headers={"If-None-Match": etag, **GZIP})
        assert (again.status_code, again.content, again.headers["etag"]) == (304, b"", etag), path
        assert reader.get(path, params=revision, headers={"If-None-Match": 'W/"other"'}).status_code == 200


def test_a_live_read_is_304_until_the_map_changes(reader: TestClient, store: MapStore, hall: MapInfo) -> None:
    bin_id = reader.get("/v1/maps/site/bins", params={"limit": 1}).json()["bins"][0]["id"]
    path = f"/v1/maps/site/bins/{bin_id}"
    layout = reader.get("/v1/maps/site/layout")
    tags = {"bin": reader.get(path).headers["etag"], "layout": layout.headers["etag"]}
    assert reader.get(path, headers={"If-None-Match": tags["bin"]}).status_code == 304
    assert reader.get("/v1/maps/site/layout", headers={"If-None-Match": tags["layout"]}).status_code == 304

    store.write_revision(hall.id, RevisionWrite("pillar_mapping", features={"bin": []}))  # every bin gone

    assert reader.get(path, headers={"If-None-Match": tags["bin"]}).status_code == 404
    changed = reader.get("/v1/maps/site/layout", headers={"If-None-Match": tags["layout"]})
    assert changed.status_code == 200 and changed.headers["etag"] != tags["layout"]


def test_if_none_match_compares_weakly_and_takes_lists_and_star() -> None:
    assert matches('"abc"', 'W/"abc"') and matches('W/"x", W/"abc"', 'W/"abc"') and matches("*", 'W/"abc"')
    assert not matches('W/"abcd"', 'W/"abc"')


def test_gzip_is_used_only_where_accept_encoding_allows_it() -> None:
    assert accepts_gzip("gzip") and accepts_gzip("br, gzip;q=0.5") and accepts_gzip("*") and accepts_gzip("GZIP")
    assert not accepts_gzip(None) and not accepts_gzip("identity") and not accepts_gzip("gzip;q=0")
    assert not accepts_gzip("br, gzip; q=0.0")

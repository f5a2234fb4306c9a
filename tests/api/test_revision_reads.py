"""Every read names the revision it covers, and paging with a cursor stays at the first page's revision.

Lists (bins, features), the layout and the topology carry the revision in their body and in ``X-Aisle-Revision-Id``;
``next_cursor`` pages on at the same revision even after new revisions are written (a real store, written to
between the pages).
"""

from __future__ import annotations

from typing import Any

import pytest
from fastapi.testclient import TestClient

from shared.store import Feature, MapStore, RevisionWrite
from shared.vocabulary import REVISION_HEADER

SITE = "/v1/maps/site"


def _bin(key: str, x: float) -> Feature:
    return Feature("bin", key, {"type": "Point", "coordinates": [x, 1.0]}, {"level": 0}, 0.9)


@pytest.mark.parametrize("path", ["/bins", "/features", "/layout", "/topology", "/topology?format=geojson"])
def test_a_read_without_revision_names_the_newest_in_body_and_header(client: TestClient, site: dict[str, int],
                                                                     path: str) -> None:
    response = client.get(SITE + path)

    assert response.status_code == 200
    body = response.json()
    named = body["graph"]["revision"] if "graph" in body else body.get("revision", body.get("revision_id"))
    assert named == site["semantics_2"]
    assert response.headers[REVISION_HEADER] == str(site["semantics_2"])


@pytest.mark.parametrize("path", ["/bins", "/features", "/layout", "/topology"])
def test_a_read_at_a_revision_names_it_in_the_header(client: TestClient, site: dict[str, int], path: str) -> None:
    response = client.get(SITE + path, params={"revision": site["semantics_1"]})

    assert response.status_code == 200
    assert response.headers[REVISION_HEADER] == str(site["semantics_1"])


@pytest.fixture
def aisle(store: MapStore) -> tuple[int, int]:
    """Map ``aisle`` with bins k00..k09 in one revision; (map id, revision id)."""
    map_id = store.ensure_map("aisle").id
    written = store.write_revision(map_id, RevisionWrite(
        "pillar_mapping", features={"bin": [_bin(f"k{i:02d}", float(i)) for i in range(10)]}))
    return map_id, written.id


def _rewrite(store: MapStore, map_id: int) -> int:
    """A new revision that renumbers the first bins and drops k05: offsets of the newest revision shift."""
    bins = [_bin(f"a{i:02d}", -float(i)) for i in range(3)] + [_bin(f"k{i:02d}", float(i)) for i in range(10)
                                                                 if i != 5]
    return store.write_revision(map_id, RevisionWrite("pillar_mapping", features={"bin": bins})).id


def _keys(page: dict[str, Any]) -> list[str]:
    if "bins" in page:
        return [item["id"] for item in page["bins"]]
    return [item["properties"]["key"] for item in page["features"]]


@pytest.mark.parametrize(("path", "query"), [("/bins", {}), ("/features", {"kind": "bin"})])
def test_the_next_page_is_read_at_the_first_pages_revision(client: TestClient, store: MapStore,
                                                           aisle: tuple[int, int], path: str,
                                                           query: dict[str, str]) -> None:
    map_id, first_revision = aisle
    url = "/v1/maps/aisle" + path
    first = client.get(url, params={**query, "limit": 4})
    newer = _rewrite(store, map_id)
    second = client.get(url, params={**query, "limit": 4, "cursor": first.json()["next_cursor"]})
    third = client.get(url, params={**query, "limit": 4, "cursor": second.json()["next_cursor"]})
    newer_second = client.get(url, params={**query, "limit": 4, "offset": 4, "revision": newer})

    assert [page.status_code for page in (first, second, third, newer_second)] == [200] * 4
    assert [page.json()["revision"] for page in (first, second, third)] == [first_revision] * 3
    assert [page.headers[REVISION_HEADER] for page in (first, second, third)] == [str(first_revision)] * 3
    assert _keys(first.json()) + _keys(second.json()) + _keys(third.json()) == [f"k{i:02d}" for i in range(10)]
    assert third.json()["next_cursor"] is None
    assert _keys(newer_second.json()) != _keys(second.json())  # what paging by offset alone would have mixed in


@pytest.mark.parametrize("path", ["/bins", "/features"])
def test_a_cursor_that_is_not_ours_is_a_422(client: TestClient, aisle: tuple[int, int], path: str) -> None:
    url = "/v1/maps/aisle" + path
    cursor = client.get(url, params={"limit": 1}).json()["next_cursor"]

    garbage = client.get(url, params={"cursor": "not-a-cursor"})
    with_offset = client.get(url, params={"cursor": cursor, "offset": 1})
    with_revision = client.get(url, params={"cursor": cursor, "revision": aisle[1]})

    assert cursor is not None
    assert [r.status_code for r in (garbage, with_offset, with_revision)] == [422] * 3
    assert "cursor" in garbage.json()["detail"] and "not both" in with_offset.json()["detail"]


def test_a_cursor_of_another_maps_revision_is_a_404(client: TestClient, site: dict[str, int]) -> None:
    cursor = client.get("/v1/maps/site/features", params={"limit": 1}).json()["next_cursor"]

    response = client.get("/v1/maps/other/features", params={"cursor": cursor})

    assert response.status_code == 404
    assert "not a revision of map 'other'" in response.json()["detail"]


def test_the_openapi_document_names_the_revision_header_of_reads(client: TestClient) -> None:
    paths = client.get("/openapi.json").json()["paths"]

    for path in ("/bins", "/features", "/layout", "/topology"):
        assert REVISION_HEADER in paths["/v1/maps/{map_name}" + path]["get"]["responses"]["200"]["headers"], path
    assert "cursor" in [p["name"] for p in paths["/v1/maps/{map_name}/bins"]["get"]["parameters"]]

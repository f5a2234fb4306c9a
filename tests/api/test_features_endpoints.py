"""/v1/maps/{map}/features: GeoJSON features, filtered, paged and read at a revision."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

URL = "/v1/maps/site/features"


def _ids(body: dict[str, list[dict[str, str]]]) -> list[str]:
    return sorted(feature["id"] for feature in body["features"])


def test_features_are_a_geojson_feature_collection(client: TestClient, site: dict[str, int]) -> None:
    body = client.get(URL).json()

    assert body["type"] == "FeatureCollection"
    assert _ids(body) == ["bin/B1", "dock/D1", "rack_row/R1"]
    b1 = next(f for f in body["features"] if f["id"] == "bin/B1")
    assert b1["type"] == "Feature"
    assert b1["geometry"] == {"type": "Point", "coordinates": [2, 1]}
    assert b1["properties"] == {"kind": "bin", "key": "B1", "stage": "semantics",
                                "revision_id": site["semantics_2"], "confidence": 0.95, "level": 2}


def test_features_filter_by_repeated_kind(client: TestClient, site: dict[str, int]) -> None:
    body = client.get(URL, params={"kind": ["bin", "dock"]}).json()

    assert _ids(body) == ["bin/B1", "dock/D1"]


def test_unknown_kind_is_422_listing_valid_kinds(client: TestClient, site: dict[str, int]) -> None:
    response = client.get(URL, params={"kind": ["bin", "shelf"]})

    assert response.status_code == 422
    detail = response.json()["detail"]
    assert "unknown feature kind(s) ['shelf']" in detail
    assert "'rack_row'" in detail


def test_bbox_keeps_features_whose_bounds_touch_it(client: TestClient, site: dict[str, int]) -> None:
    # R1 spans x 0..10, y 0..1; B1 is at (2, 1); D1 at (-5, 0)
    assert _ids(client.get(URL, params={"bbox": "5,0.5,20,3"}).json()) == ["rack_row/R1"]
    assert _ids(client.get(URL, params={"bbox": "1.5,0.5,2.5,1.5"}).json()) == ["bin/B1", "rack_row/R1"]
    assert _ids(client.get(URL, params={"bbox": "-6,-1,-4,1", "kind": "dock"}).json()) == ["dock/D1"]
    assert _ids(client.get(URL, params={"bbox": "100,100,101,101"}).json()) == []


@pytest.mark.parametrize(
    ("bbox", "message"),
    [
        ("1,2,3", "four finite numbers"),
        ("a,b,c,d", "four finite numbers"),
        ("0,0,1,1,2", "four finite numbers"),
        ("nan,0,1,1", "four finite numbers"),
        ("0,0,inf,1", "four finite numbers"),
        ("", "four finite numbers"),
        ("5,0,1,1", "min greater than max"),
        ("0,5,1,1", "min greater than max"),
        ("0,0,100001,1", "more than 100000 m on a side"),
    ],
)
def test_malformed_bbox_is_422_saying_why(client: TestClient, site: dict[str, int], bbox: str,
                                          message: str) -> None:
    response = client.get(URL, params={"bbox": bbox})

    assert response.status_code == 422
    assert message in response.json()["detail"]


def test_features_page_with_limit_and_offset(client: TestClient, site: dict[str, int]) -> None:
    pages = []
    offset: int | None = 0
    while offset is not None:
        body = client.get(URL, params={"limit": 2, "offset": offset}).json()
        pages.append(_ids(body))
        offset = body["next_offset"]

    assert [len(page) for page in pages] == [2, 1]
    assert sorted(pages[0] + pages[1]) == ["bin/B1", "dock/D1", "rack_row/R1"]


@pytest.mark.parametrize("params", [{"limit": -1}, {"limit": 0}, {"limit": 10_001}, {"offset": -1}])
def test_bad_paging_is_422(client: TestClient, site: dict[str, int], params: dict[str, int]) -> None:
    response = client.get(URL, params=params)

    assert response.status_code == 422
    assert response.json()["detail"][0]["loc"] == ["query", next(iter(params))]


def test_revision_reads_features_live_then(client: TestClient, site: dict[str, int]) -> None:
    then = client.get(URL, params={"revision": site["semantics_1"], "kind": "bin"}).json()
    before = client.get(URL, params={"revision": site["occupancy_1"]}).json()

    assert then["revision"] == site["semantics_1"]
    assert _ids(then) == ["bin/B1", "bin/B2"]
    b1 = next(f for f in then["features"] if f["id"] == "bin/B1")
    assert b1["geometry"]["coordinates"] == [1, 1]
    assert _ids(before) == []


@pytest.mark.parametrize("which", ["missing", "other"])
def test_unknown_revision_is_404(client: TestClient, site: dict[str, int], which: str) -> None:
    revision = 99 if which == "missing" else site["other"]  # 'other' is a revision of map 'other'

    response = client.get(URL, params={"revision": revision})

    assert response.status_code == 404
    assert response.json()["detail"] == (
        f"revision {revision} is not a revision of map 'site'; its newest is {site['semantics_2']} (old revisions "
        "are thinned by the retention settings unless pinned)")


def test_revision_must_be_a_positive_integer(client: TestClient, site: dict[str, int]) -> None:
    for revision in ("0", "-3", "latest"):
        response = client.get(URL, params={"revision": revision})

        assert response.status_code == 422
        assert response.json()["detail"][0]["loc"] == ["query", "revision"]


def test_get_one_feature_now_and_then(client: TestClient, site: dict[str, int]) -> None:
    now = client.get(f"{URL}/bin/B1").json()
    then = client.get(f"{URL}/bin/B1", params={"revision": site['semantics_1']}).json()

    assert now["id"] == "bin/B1"
    assert now["geometry"]["coordinates"] == [2, 1]
    assert then["geometry"]["coordinates"] == [1, 1]


def test_missing_feature_is_404(client: TestClient, site: dict[str, int]) -> None:
    gone = client.get(f"{URL}/bin/B2")
    still_there = client.get(f"{URL}/bin/B2", params={"revision": site['semantics_1']})

    assert gone.status_code == 404
    assert gone.json()["detail"] == "map 'site' has no bin 'B2' now"
    assert still_there.status_code == 200


def test_one_feature_of_unknown_kind_is_422(client: TestClient, site: dict[str, int]) -> None:
    response = client.get(f"{URL}/shelf/B1")

    assert response.status_code == 422
    assert "valid kinds" in response.json()["detail"]

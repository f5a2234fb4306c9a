"""/v1/maps/{map}/bins: the pillar stage's bins in WMS form, searched, paged and read at a revision."""

from __future__ import annotations

import re
from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient

from services.pillar_mapping import fit_layout, rack_profile
from services.pillar_mapping.layout import layout_features
from services.pillar_mapping.synthetic import noisy_landmarks, rack_region
from shared.bins import ID_PATTERN
from shared.store import Feature, MapStore, RevisionWrite

URL = "/v1/maps/hall/bins"


@pytest.fixture(scope="module")
def layouts() -> list[dict[str, list[Feature]]]:
    """Two fits of one hall (3 aisles x 10 bays) from differently noisy landmarks, as the pillar stage writes them."""
    hall = rack_region(aisles=3, bays=10)
    return [layout_features(fit_layout(noisy_landmarks(hall, np.random.default_rng(seed))[0])) for seed in (0, 1)]


@pytest.fixture
def hall(store: MapStore, layouts: list[dict[str, list[Feature]]]) -> list[int]:
    """Map ``hall`` with the first fit, then the second with one bin fewer; their revision ids."""
    map_id = store.ensure_map("hall").id
    first = store.write_revision(map_id, RevisionWrite("pillar_mapping", features=layouts[0])).id
    second_fit = dict(layouts[1])
    second_fit["bin"] = [item for item in layouts[1]["bin"] if item.key != "01-001"]
    second = store.write_revision(map_id, RevisionWrite("pillar_mapping", features=second_fit)).id
    return [first, second]


def _all_bins(client: TestClient, **params: Any) -> list[dict[str, Any]]:
    bins: list[dict[str, Any]] = []
    offset: int | None = 0
    while offset is not None:
        page = client.get(URL, params={**params, "offset": offset, "limit": 7}).json()
        bins += page["bins"]
        offset = page["next_offset"]
    return bins


def test_bins_come_in_wms_form(client: TestClient, hall: list[int], layouts: list[dict[str, list[Feature]]]) -> None:
    page = client.get(URL, params={"id_prefix": "01-002"}).json()

    assert page["total"] == 1
    (item,) = page["bins"]
    written = next(f for f in layouts[1]["bin"] if f.key == "01-002")
    assert item["id"] == "01-002" and item["aisle"] == 1 and item["bay"] == 2 and item["level"] is None
    assert item["centre"] == pytest.approx(written.properties["centre"], abs=5e-4)  # served to the millimetre
    np.testing.assert_allclose(item["footprint"], written.geometry["coordinates"][0], atol=5e-4)
    x, y, yaw = written.properties["access_pose"]
    assert item["access_pose"] == pytest.approx({"x_m": x, "y_m": y, "yaw_rad": yaw}, abs=5e-4)
    assert item["row"] == written.properties["row"] and item["back_row"] == written.properties["back_row"]
    assert item["revision_id"] == hall[1] and item["stage"] == "pillar_mapping"
    assert item["corridor"]["key"] == "aisle-01"  # the aisle its access pose is in
    assert item["opening"]["width_m"] == pytest.approx(np.hypot(*np.subtract(*item["footprint"][:2])))


def test_pages_partition_the_bins_sorted_by_id(client: TestClient, hall: list[int],
                                               layouts: list[dict[str, list[Feature]]]) -> None:
    bins = _all_bins(client)

    ids = [item["id"] for item in bins]
    assert ids == sorted({f.key for f in layouts[1]["bin"]} - {"01-001"})
    assert client.get(URL).json()["total"] == len(ids)


def test_one_bin_by_id_matches_the_list(client: TestClient, hall: list[int]) -> None:
    for item in _all_bins(client)[:5]:
        assert client.get(f"{URL}/{item['id']}").json() == item


@pytest.mark.parametrize("params", [
    {"aisle": 2}, {"level": 0}, {"id_prefix": "03-"}, {"row": "r0-002"}, {"aisle": 1, "id_prefix": "01-00"},
    {"bbox": "0,0,10,10"}, {"aisle": 99},
])
def test_filters_keep_exactly_the_matching_bins(client: TestClient, hall: list[int], params: dict[str, Any]) -> None:
    everything = _all_bins(client)

    kept = _all_bins(client, **params)

    def matches(item: dict[str, Any]) -> bool:
        if "bbox" in params:
            min_x, min_y, max_x, max_y = (float(v) for v in params["bbox"].split(","))
            xs = [p[0] for p in item["footprint"]]
            ys = [p[1] for p in item["footprint"]]
            if max(xs) < min_x or min(xs) > max_x or max(ys) < min_y or min(ys) > max_y:
                return False
        return bool(item["aisle"] == params.get("aisle", item["aisle"])
                and item["level"] == params.get("level", item["level"])
                and item["row"] == params.get("row", item["row"])
                and item["id"].startswith(params.get("id_prefix", "")))

    assert kept == [item for item in everything if matches(item)]


def test_revision_reads_the_bins_as_they_were(client: TestClient, hall: list[int]) -> None:
    then = client.get(f"{URL}/01-001", params={"revision": hall[0]})
    now = client.get(f"{URL}/01-001")

    assert then.status_code == 200 and then.json()["revision_id"] == hall[0]
    assert now.status_code == 404
    assert "no bin '01-001' now" in now.json()["detail"]
    assert client.get(URL, params={"revision": hall[0]}).json()["total"] == client.get(URL).json()["total"] + 1


def test_bins_written_with_few_properties_still_come_out(client: TestClient, site: dict[str, int]) -> None:
    # the api fixture's bins are points with only a level: id falls back to the key, centre to the point
    item = client.get("/v1/maps/site/bins/B1").json()

    assert item["id"] == "B1" and item["level"] == 2 and item["centre"] == [2.0, 1.0]
    assert item["footprint"] is None and item["access_pose"] is None and item["aisle"] is None
    assert client.get("/v1/maps/site/bins", params={"level": 2}).json()["total"] == 1


@pytest.mark.parametrize(("path", "params", "status", "message"), [
    ("/v1/maps/nowhere/bins", {}, 404, "no map named 'nowhere'"),
    (URL, {"limit": -1}, 422, "greater than or equal to 1"),
    (URL, {"limit": 0}, 422, "greater than or equal to 1"),
    (URL, {"limit": 100_000}, 422, "less than or equal to 1000"),
    (URL, {"offset": -5}, 422, "greater than or equal to 0"),
    (URL, {"aisle": "one"}, 422, "valid integer"),
    (URL, {"bbox": "0,0,1e9,1"}, 422, "more than 100000 m on a side"),
    (URL, {"bbox": "1,2,3"}, 422, "four finite numbers"),
    (URL, {"revision": 999_999}, 404, "not a revision of map 'hall'"),
    (URL, {"id_prefix": "x" * 129}, 422, "at most 128 characters"),
    (f"{URL}/01-001%27%20OR%20%271%27=%271", {}, 422, "should match pattern"),
    (f"{URL}/..%2F..%2Fetc%2Fpasswd", {}, 404, ""),
    (f"{URL}/{'9' * 200}", {}, 422, "should match pattern"),
    (f"{URL}/99-999", {}, 404, "no bin '99-999'"),
])
def test_bad_requests_get_a_clear_4xx_and_change_nothing(
    client: TestClient, store: MapStore, hall: list[int], path: str, params: dict[str, Any], status: int,
    message: str,
) -> None:
    before = client.get(URL).json()

    response = client.get(path, params=params)

    assert response.status_code == status
    assert message in str(response.json()["detail"])
    assert client.get(URL).json() == before
    latest = store.latest_revision(store.ensure_map("hall").id)
    assert latest is not None and latest.id == hall[1]


def test_bins_on_levels_come_with_the_id_format_the_schema_documents_and_a_confidence(
    client: TestClient, store: MapStore
) -> None:
    hall = rack_region(aisles=2, bays=4)
    table = noisy_landmarks(hall, np.random.default_rng(2))[0]
    features = layout_features(fit_layout(table, profiles=[rack_profile([0.0, 1.5, 3.0])]))
    store.write_revision(store.ensure_map("hall").id, RevisionWrite("pillar_mapping", features=features))
    schema = client.get("/openapi.json").json()["components"]["schemas"]["BinOut"]["properties"]

    served = _all_bins(client)

    assert len(served) == len(features["bin"]) > 0
    for documented in (schema["id"], schema["detected_id"]):
        assert "`AA-BBB-LL`" in documented["description"]
        assert all(re.fullmatch(ID_PATTERN, example) for example in documented["examples"][1:])
    assert all(re.fullmatch(ID_PATTERN, item["id"]) and item["id"].endswith(f"-{item['level'] + 1:02d}")
               for item in served)
    assert {item["level"] for item in served} == {0, 1, 2}
    assert all(0.0 <= item["confidence"] <= 1.0 for item in served)
    assert "0..1" in schema["confidence"]["description"]

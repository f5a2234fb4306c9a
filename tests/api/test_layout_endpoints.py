"""/v1/maps/{map}/layout: the whole map as one GeoJSON collection, and as a PNG or SVG picture with a legend."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import cv2
import numpy as np
import pytest
from fastapi.testclient import TestClient

from api.routers import layout
from services.floor_plan import SEED_SCHEDULE, ChainSettings, FloorPlanSettings, Phase, floor_plan
from services.floor_plan.records import plan_features, plan_layer, plan_topology
from shared.store import Feature, MapStore, RevisionWrite
from shared.vocabulary import REVISION_HEADER

SVG = "{http://www.w3.org/2000/svg}"


def _ids(body: dict[str, object]) -> set[str]:
    features = body["features"]
    assert isinstance(features, list)
    return {feature["id"] for feature in features}


def _legend(svg: bytes) -> list[str]:
    root = ET.fromstring(svg)
    legend = next(g for g in root.iter(f"{SVG}g") if g.get("id") == "legend")
    return [text.text or "" for text in legend.iter(f"{SVG}text")]


def test_layout_is_one_collection_of_every_live_feature_with_frame_and_extent(
        client: TestClient, site: dict[str, int]) -> None:
    response = client.get("/v1/maps/site/layout")

    assert response.status_code == 200
    assert response.headers["content-type"] == "application/geo+json"
    body = response.json()
    assert body["type"] == "FeatureCollection"
    assert _ids(body) == {"rack_row/R1", "bin/B1", "dock/D1"}
    assert body["kinds"] == {"bin": 1, "dock": 1, "rack_row": 1}
    assert body["bbox"] == [-5.0, 0.0, 10.0, 1.0]
    assert body["frame"]["map"] == "site" and body["frame"]["frame_id"] == "map" and body["frame"]["units"] == "m"
    assert body["revision_id"] == site["semantics_2"]


def test_layout_filters_by_kind_and_by_area(client: TestClient, site: dict[str, int]) -> None:
    by_kind = client.get("/v1/maps/site/layout", params=[("kind", "bin"), ("kind", "dock")]).json()
    in_area = client.get("/v1/maps/site/layout", params={"bbox": "1.5,0.5,3,2"}).json()
    both = client.get("/v1/maps/site/layout", params={"bbox": "1.5,0.5,3,2", "kind": "rack_row"}).json()

    assert _ids(by_kind) == {"bin/B1", "dock/D1"}
    assert _ids(in_area) == {"rack_row/R1", "bin/B1"}
    assert in_area["bbox"] == [0.0, 0.0, 10.0, 1.0]
    assert _ids(both) == {"rack_row/R1"}


def test_layout_reads_the_map_as_it_was_at_a_revision(client: TestClient, site: dict[str, int]) -> None:
    body = client.get("/v1/maps/site/layout", params={"revision": site["semantics_1"]}).json()

    assert _ids(body) == {"rack_row/R1", "bin/B1", "bin/B2", "dock/D1"}
    assert body["revision_id"] == site["semantics_1"]
    b1 = next(f for f in body["features"] if f["id"] == "bin/B1")
    assert b1["geometry"]["coordinates"] == [1, 1]


def test_layout_over_the_limit_is_refused_with_advice_to_narrow_it(
        client: TestClient, site: dict[str, int], monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(layout, "MAX_LAYOUT_FEATURES", 2)

    refused = client.get("/v1/maps/site/layout")
    narrowed = client.get("/v1/maps/site/layout", params={"bbox": "-6,-1,-4,1"})

    assert refused.status_code == 413
    assert "more than 2 features" in refused.json()["detail"] and "bbox" in refused.json()["detail"]
    assert narrowed.status_code == 200 and _ids(narrowed.json()) == {"dock/D1"}


def test_layout_of_a_map_without_features_is_an_empty_collection_without_bbox(
        client: TestClient, store: MapStore) -> None:
    store.ensure_map("empty")

    body = client.get("/v1/maps/empty/layout").json()

    assert body["features"] == [] and body["kinds"] == {} and body["revision_id"] is None
    assert "bbox" not in body


@pytest.mark.parametrize(
    ("path", "params", "status", "detail"),
    [
        ("/v1/maps/site/layout", {"kind": "shelf"}, 422, "valid kinds"),
        ("/v1/maps/site/layout", {"bbox": "1,2,3"}, 422, "four finite numbers"),
        ("/v1/maps/site/layout", {"revision": 999}, 404, "not a revision"),
        ("/v1/maps/nowhere/layout", {}, 404, "no map named"),
        ("/v1/maps/site/layout.png", {"width": 63}, 422, None),
        ("/v1/maps/site/layout.svg", {"width": 4097}, 422, None),
        ("/v1/maps/site/layout.png", {"bbox": "5,0,1,1"}, 422, "min greater than max"),
        ("/v1/maps/site/layout.svg", {"kind": "shelf"}, 422, "valid kinds"),
    ],
)
def test_bad_parameters_get_a_4xx_that_says_why(client: TestClient, site: dict[str, int], path: str,
                                                params: dict[str, str | int], status: int, detail: str | None) -> None:
    response = client.get(path, params=params)

    assert response.status_code == status
    if detail is not None:
        assert detail in response.json()["detail"]


def test_png_is_north_up_as_wide_as_asked_with_the_legend_beside_it(client: TestClient, site: dict[str, int]) -> None:
    response = client.get("/v1/maps/site/layout.png", params={"width": 300, "bbox": "-1,2,1,3.5"})

    assert response.status_code == 200 and response.headers["content-type"] == "image/png"
    assert response.headers[REVISION_HEADER] == str(site["semantics_2"])
    image = cv2.imdecode(np.frombuffer(response.content, np.uint8), cv2.IMREAD_COLOR)
    assert image is not None and image.shape[1] > 300
    # 2 m x 1.5 m at 150 px/m, all free now (OCCUPANCY_2): the map part is white, the legend has dark text
    assert image[:225, :300].min() >= 250
    assert image[:, 300:].min() < 50


def test_png_background_shows_occupied_cells_at_the_top_of_a_north_up_image(
        client: TestClient, site: dict[str, int]) -> None:
    response = client.get("/v1/maps/site/layout.png",
                          params={"width": 200, "bbox": "-1,2,1,3.5", "revision": site["occupancy_1"]})

    image = cv2.imdecode(np.frombuffer(response.content, np.uint8), cv2.IMREAD_GRAYSCALE)
    assert image is not None
    # OCCUPANCY_1: rows from y=2: free, unknown, occupied (highest y); 200 px over 2 m, 0.5 m cells = 50 px
    assert image[10, 100] < 30
    assert 190 < image[75, 100] < 220
    assert image[140, 100] > 250


def test_svg_parses_and_its_legend_names_each_kind_drawn(client: TestClient, site: dict[str, int]) -> None:
    response = client.get("/v1/maps/site/layout.svg")
    only_bins = client.get("/v1/maps/site/layout.svg", params={"kind": "bin"})

    assert response.status_code == 200 and response.headers["content-type"].startswith("image/svg+xml")
    legend = _legend(response.content)
    assert {"bin (1)", "dock (1)", "rack_row (1)"} <= set(legend)
    assert f"site @ revision {site['semantics_2']}" in legend
    assert not any(text.startswith(("dock", "rack_row")) for text in _legend(only_bins.content))


def test_svg_draws_features_in_map_metres_under_a_y_flip_over_the_background(
        client: TestClient, site: dict[str, int]) -> None:
    root = ET.fromstring(client.get("/v1/maps/site/layout.svg", params={"bbox": "0,0,10,5", "width": 200}).content)

    clip = root.find(f"{SVG}defs/{SVG}clipPath/{SVG}rect")
    assert clip is not None and (clip.get("width"), clip.get("height")) == ("200", "100")
    features = next(g for g in root.iter(f"{SVG}g") if g.get("id") == "features")
    scale = [float(v) for v in features.get("transform", "").removeprefix("matrix(").rstrip(")").split()]
    assert scale[0] == pytest.approx(20.0) and scale[3] == pytest.approx(-20.0)
    assert [g.get("data-kind") for g in features.findall(f"{SVG}g")] == ["rack_row", "bin"]
    titles = {t.text for t in features.iter(f"{SVG}title")}
    assert {"rack_row R1", "bin B1"} <= titles
    background = next(i for i in root.iter(f"{SVG}image") if i.get("id") == "background")
    assert background.get("{http://www.w3.org/1999/xlink}href", "").startswith("data:image/png;base64,")


def test_svg_escapes_names_that_look_like_markup(client: TestClient, store: MapStore) -> None:
    name = 'dc <east> & "west"'
    map_id = store.ensure_map(name).id
    revision = store.write_revision(map_id, RevisionWrite("semantics", features={
        "dock": [Feature("dock", "D<1>&", {"type": "Point", "coordinates": [1.0, 2.0]})]})).id

    response = client.get(f"/v1/maps/{name}/layout.svg")

    root = ET.fromstring(response.content)
    assert root.findtext(f"{SVG}title") == f"{name} @ revision {revision}"
    assert "dock D<1>&" in {t.text for t in root.iter(f"{SVG}title")}


def test_picture_of_a_map_with_nothing_yet_needs_a_bbox(client: TestClient, store: MapStore) -> None:
    store.ensure_map("empty")

    without = client.get("/v1/maps/empty/layout.png")
    with_area = client.get("/v1/maps/empty/layout.svg", params={"bbox": "0,0,20,10"})

    assert without.status_code == 404 and "bbox" in without.json()["detail"]
    assert with_area.status_code == 200
    ET.fromstring(with_area.content)


def test_layout_since_a_revision_holds_only_what_changed_and_what_went(
        client: TestClient, site: dict[str, int]) -> None:
    # semantics_2 moved B1 and dropped B2; R1 and D1 were not written again
    body = client.get("/v1/maps/site/layout", params={"since": site["semantics_1"], "kind": ["bin", "dock"]}).json()

    assert _ids(body) == {"bin/B1"} and body["features"][0]["geometry"]["coordinates"] == [2.0, 1.0]
    assert body["removed"] == {"bin": ["B2"]} and body["since_revision_id"] == site["semantics_1"]
    unchanged = client.get("/v1/maps/site/layout", params={"since": site["semantics_2"]}).json()
    assert unchanged["features"] == [] and unchanged["removed"] == {}
    assert "removed" not in client.get("/v1/maps/site/layout").json()


def test_layout_serves_the_floor_plans_units_and_doors(client: TestClient, store: MapStore) -> None:
    occ = np.full((80, 120), -1, np.int8)
    for c0, c1 in ((10, 60), (59, 109)):
        occ[10:70, c0 : c1 + 1] = 100
        occ[12:68, c0 + 2 : c1 - 1] = 0
    occ[35:48, 59:61] = 0
    short = tuple(Phase(None if p.until is None else p.until // 4, p.probabilities) for p in SEED_SCHEDULE)
    plan = floor_plan(occ, resolution_m=0.05, settings=FloorPlanSettings(
        chain=ChainSettings(iterations=2000, seed=1, schedule=short)))
    map_id = store.ensure_map("plan").id
    store.write_revision(map_id, RevisionWrite("floor_plan", layers=[plan_layer(plan, name="floor_plan")],
                                               features=plan_features(plan), topology=plan_topology(plan)))

    body = client.get("/v1/maps/plan/layout", params=[("kind", "unit"), ("kind", "door")]).json()

    assert body["kinds"] == {"unit": 2, "door": 1}
    doors = [f for f in body["features"] if f["properties"].get("units")]
    assert len(doors) == 1 and len(doors[0]["properties"]["units"]) == 2

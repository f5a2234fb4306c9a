"""/v1/maps/{map}/layers: metadata, PNG and raw values, now and at a revision."""

from __future__ import annotations

import io

import cv2
import numpy as np
import pytest
from fastapi.testclient import TestClient

from shared.store import GridLayer, MapStore, RevisionWrite

URL = "/v1/maps/site/layers"


def _png(client: TestClient, path: str, **params: int) -> np.ndarray:
    response = client.get(path, params=params)
    assert response.status_code == 200, response.text
    assert response.headers["content-type"] == "image/png"
    image = cv2.imdecode(np.frombuffer(response.content, np.uint8), cv2.IMREAD_UNCHANGED)
    assert image is not None
    return np.asarray(image)


def test_list_layers_with_metadata(client: TestClient, site: dict[str, int]) -> None:
    body = client.get(URL).json()

    assert [layer["name"] for layer in body] == ["occupancy", "traversability"]
    assert body[0]["revision_id"] == site["occupancy_2"]
    assert body[1]["revision_id"] == site["semantics_1"]


def test_list_layers_at_a_revision_omits_later_layers(client: TestClient, site: dict[str, int]) -> None:
    body = client.get(URL, params={"revision": site["occupancy_1"]}).json()

    assert [(layer["name"], layer["revision_id"]) for layer in body] == [("occupancy", site["occupancy_1"])]


def test_layer_metadata_gives_shape_resolution_origin_and_extent(client: TestClient,
                                                                 site: dict[str, int]) -> None:
    body = client.get(f"{URL}/occupancy").json()

    assert body == {
        "name": "occupancy", "revision_id": site["occupancy_2"], "dtype": "int8", "shape": [3, 4],
        "resolution_m": 0.5, "origin": {"x_m": -1.0, "y_m": 2.0}, "extent": [-1.0, 2.0, 1.0, 3.5],
        "meta": {"encoding": "occupancy"},
    }


def test_occupancy_png_is_north_up_like_map_server(client: TestClient, site: dict[str, int]) -> None:
    image = _png(client, f"{URL}/occupancy.png", revision=site["occupancy_1"])

    # stored row 0 (lowest y) is free, row 1 unknown, row 2 (highest y) occupied
    assert image.shape == (3, 4)
    assert image.dtype == np.uint8
    assert image[0].tolist() == [0, 0, 0, 0]  # top of the image = highest y = occupied = black
    assert image[1].tolist() == [205] * 4  # unknown
    assert image[2].tolist() == [255] * 4  # free


def test_png_carries_the_revision_it_shows(client: TestClient, site: dict[str, int]) -> None:
    response = client.get(f"{URL}/occupancy.png")

    assert response.headers["x-aisle-revision-id"] == str(site["occupancy_2"])


def test_float_layer_png_is_min_max_scaled(client: TestClient, site: dict[str, int]) -> None:
    image = _png(client, f"{URL}/traversability.png")

    # values [[0, 1], [nan, 0.5]], flipped: top row is stored row 1
    assert image.tolist() == [[0, 128], [0, 255]]


def test_values_as_npy_round_trip(client: TestClient, site: dict[str, int]) -> None:
    response = client.get(f"{URL}/occupancy/values", params={"revision": site["occupancy_1"]})

    assert response.status_code == 200
    assert response.headers["content-type"] == "application/x-npy"
    assert f'filename="site_occupancy_r{site["occupancy_1"]}.npy"' in response.headers["content-disposition"]
    values = np.load(io.BytesIO(response.content), allow_pickle=False)
    assert values.dtype == np.int8
    assert values.tolist() == [[0, 0, 0, 0], [-1, -1, -1, -1], [100, 100, 100, 100]]


def test_values_as_json_give_rows_from_lowest_y_and_null_for_nan(client: TestClient,
                                                                 site: dict[str, int]) -> None:
    body = client.get(f"{URL}/traversability/values", params={"format": "json"}).json()

    assert body["shape"] == [2, 2]
    assert body["dtype"] == "float32"
    assert body["resolution_m"] == 1.0
    assert body["origin"] == {"x_m": 0.0, "y_m": 0.0}
    assert body["data"] == [[0.0, 1.0], [None, 0.5]]


def test_large_layer_as_json_is_413_pointing_to_npy(client: TestClient, store: MapStore) -> None:
    map_id = store.ensure_map("big").id
    store.write_revision(map_id, RevisionWrite("occupancy_mapping", layers=[
        GridLayer("occupancy", np.zeros((1001, 1000), np.int8), 0.05, 0.0, 0.0)]))

    as_json = client.get("/v1/maps/big/layers/occupancy/values", params={"format": "json"})
    as_npy = client.get("/v1/maps/big/layers/occupancy/values")

    assert as_json.status_code == 413
    assert "use ?format=npy" in as_json.json()["detail"]
    assert as_npy.status_code == 200


def test_unknown_format_is_422(client: TestClient, site: dict[str, int]) -> None:
    response = client.get(f"{URL}/occupancy/values", params={"format": "csv"})

    assert response.status_code == 422
    assert response.json()["detail"][0]["loc"] == ["query", "format"]


@pytest.mark.parametrize("suffix", ["", ".png", "/values"])
def test_unknown_layer_is_404_listing_known_layers(client: TestClient, site: dict[str, int],
                                                   suffix: str) -> None:
    response = client.get(f"{URL}/height{suffix}")

    assert response.status_code == 404
    assert response.json()["detail"] == (
        "map 'site' has no layer 'height'; known layers: ['occupancy', 'traversability']")


def test_layer_before_it_was_written_is_404(client: TestClient, site: dict[str, int]) -> None:
    response = client.get(f"{URL}/traversability", params={"revision": site["occupancy_1"]})

    assert response.status_code == 404
    assert "has no version at or before revision" in response.json()["detail"]


def test_unknown_revision_is_404(client: TestClient, site: dict[str, int]) -> None:
    response = client.get(f"{URL}/occupancy.png", params={"revision": 999})

    assert response.status_code == 404
    assert response.json()["detail"].startswith("revision 999 is not a revision of map 'site'")


def test_complex_layer_has_no_image_or_json_but_has_npy(client: TestClient, store: MapStore) -> None:
    map_id = store.ensure_map("odd").id
    store.write_revision(map_id, RevisionWrite("test", layers=[
        GridLayer("phase", np.ones((2, 2), np.complex64), 1.0, 0.0, 0.0)]))

    png = client.get("/v1/maps/odd/layers/phase.png")
    as_json = client.get("/v1/maps/odd/layers/phase/values", params={"format": "json"})
    as_npy = client.get("/v1/maps/odd/layers/phase/values")

    assert png.status_code == 422
    assert "cannot be rendered" in png.json()["detail"]
    assert as_json.status_code == 422
    assert "use ?format=npy" in as_json.json()["detail"]
    assert np.load(io.BytesIO(as_npy.content), allow_pickle=False).dtype == np.complex64

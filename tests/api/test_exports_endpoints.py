"""/v1/maps/{map}/exports: standard formats as files to download."""

from __future__ import annotations

import io
import json
import zipfile
from pathlib import Path

import numpy as np
import pytest
import yaml
from fastapi.testclient import TestClient

from shared.mapfiles import read_map_yaml
from shared.store import GridLayer, MapStore, RevisionWrite
from shared.vocabulary import REVISION_HEADER
from tests.api.conftest import OCCUPANCY_1, OCCUPANCY_2
from tests.api.warehouse_map import write_warehouse


def test_export_formats_are_listed_with_their_options(client: TestClient, site: dict[str, int]) -> None:
    formats = {item["name"]: item for item in client.get("/v1/maps/site/exports").json()}

    assert {"geojson", "map_server"} <= set(formats)
    assert formats["map_server"]["options"] == ["layer"] and formats["geojson"]["options"] == []


def test_each_format_is_listed_with_the_file_and_media_type_it_serves(client: TestClient, store: MapStore) -> None:
    write_warehouse(store)
    for item in client.get("/v1/maps/site/exports").json():
        served = client.get(f"/v1/maps/site/exports/{item['name']}")

        assert served.status_code == 200, served.text
        assert served.headers["content-type"] == item["media_type"]
        assert served.headers["content-disposition"].endswith(f'{item["extension"]}"')
        if item["extension"] == ".zip":
            with zipfile.ZipFile(io.BytesIO(served.content)) as archive:
                names = archive.namelist()
            assert len(names) == len(item["files"]) and all(map(str.endswith, names, item["files"]))
        else:
            assert item["files"] == [item["extension"]]


def test_geojson_export_is_one_file_of_every_feature(client: TestClient, site: dict[str, int]) -> None:
    response = client.get("/v1/maps/site/exports/geojson")

    assert response.status_code == 200
    assert response.headers["content-type"] == "application/geo+json"
    assert response.headers["content-disposition"] == f'attachment; filename="site_r{site["semantics_2"]}.geojson"'
    body = json.loads(response.content)
    assert {f["id"] for f in body["features"]} == {"rack_row/R1", "bin/B1", "dock/D1"}


def test_map_server_export_is_a_zip_of_yaml_and_pgm_that_reads_back_as_the_layer(
        client: TestClient, site: dict[str, int], tmp_path: Path) -> None:
    response = client.get("/v1/maps/site/exports/map_server", params={"revision": site["semantics_1"]})

    assert response.status_code == 200 and response.headers["content-type"] == "application/zip"
    stem = f"site_occupancy_r{site['semantics_1']}"
    assert response.headers["content-disposition"] == f'attachment; filename="{stem}.zip"'
    assert response.headers[REVISION_HEADER] == str(site["semantics_1"])
    with zipfile.ZipFile(io.BytesIO(response.content)) as archive:
        assert archive.namelist() == [f"{stem}.yaml", f"{stem}.pgm"]
        archive.extractall(tmp_path)
    assert yaml.safe_load((tmp_path / f"{stem}.yaml").read_text())["image"] == f"{stem}.pgm"
    read = read_map_yaml(tmp_path / f"{stem}.yaml")
    np.testing.assert_array_equal(read.occupancy, OCCUPANCY_1)
    assert (read.resolution_m, read.origin_x_m, read.origin_y_m) == (0.5, -1.0, 2.0)


def test_map_server_exports_any_layer_by_name(client: TestClient, site: dict[str, int], tmp_path: Path) -> None:
    newest = client.get("/v1/maps/site/exports/map_server")
    other = client.get("/v1/maps/site/exports/map_server", params={"layer": "traversability"})

    with zipfile.ZipFile(io.BytesIO(newest.content)) as archive:
        archive.extractall(tmp_path)
        names = archive.namelist()
    np.testing.assert_array_equal(read_map_yaml(tmp_path / names[0]).occupancy, OCCUPANCY_2)
    with zipfile.ZipFile(io.BytesIO(other.content)) as archive:
        document = yaml.safe_load(archive.read(archive.namelist()[0]))
    assert document["mode"] == "scale" and document["aisle"]["layer"] == "traversability"


@pytest.mark.parametrize(
    ("path", "params", "status", "detail"),
    [
        ("/v1/maps/site/exports/shapefile", {}, 404, "known formats: ['geojson', 'lif', 'map_server', 'rmf']"),
        ("/v1/maps/site/exports/map_server", {"layer": "nope"}, 404, "known layers: ['occupancy', 'traversability']"),
        ("/v1/maps/site/exports/geojson", {"layer": "occupancy"}, 422, "leave out the layer option"),
        ("/v1/maps/site/exports/geojson", {"revision": 999}, 404, "not a revision"),
        ("/v1/maps/site/exports/map_server", {"layer": "x" * 65}, 422, None),
        ("/v1/maps/nowhere/exports/geojson", {}, 404, "no map named"),
    ],
)
def test_bad_export_requests_say_what_would_work(client: TestClient, site: dict[str, int], path: str,
                                                 params: dict[str, str | int], status: int, detail: str | None) -> None:
    response = client.get(path, params=params)

    assert response.status_code == status
    if detail is not None:
        assert detail in response.json()["detail"]


def test_layer_without_a_version_at_the_revision_is_404(client: TestClient, site: dict[str, int]) -> None:
    response = client.get("/v1/maps/site/exports/map_server",
                          params={"layer": "traversability", "revision": site["occupancy_1"]})

    assert response.status_code == 404 and "no version at or before" in response.json()["detail"]


def test_map_without_revisions_has_nothing_to_export(client: TestClient, store: MapStore) -> None:
    store.ensure_map("empty")

    response = client.get("/v1/maps/empty/exports/geojson")

    assert response.status_code == 404 and "no revisions yet" in response.json()["detail"]


def test_layer_that_cannot_be_written_is_422(client: TestClient, store: MapStore) -> None:
    map_id = store.ensure_map("odd").id
    store.write_revision(map_id, RevisionWrite("lab", layers=[GridLayer("phase", np.ones((2, 2), np.complex64),
                                                                        1.0, 0.0, 0.0)]))

    response = client.get("/v1/maps/odd/exports/map_server", params={"layer": "phase"})

    assert response.status_code == 422 and "no map_server form" in response.json()["detail"]


def test_map_names_with_quotes_and_spaces_give_safe_file_names(client: TestClient, store: MapStore) -> None:
    map_id = store.ensure_map('dc "east" 2').id
    revision = store.write_revision(map_id, RevisionWrite("lab", layers=[GridLayer("occupancy", OCCUPANCY_2, 1.0,
                                                                                    0.0, 0.0)])).id

    response = client.get('/v1/maps/dc "east" 2/exports/map_server')

    assert response.status_code == 200
    assert response.headers["content-disposition"] == f'attachment; filename="dc_east_2_occupancy_r{revision}.zip"'


def test_a_decomposed_warehouse_downloads_as_lif_and_rmf(client: TestClient, store: MapStore) -> None:
    write_warehouse(store, map_name="dc")

    lif = client.get("/v1/maps/dc/exports/lif")
    rmf = client.get("/v1/maps/dc/exports/rmf")

    assert lif.status_code == 200 and lif.headers["content-type"] == "application/json"
    assert lif.headers["content-disposition"].endswith('.lif.json"')
    stations = json.loads(lif.content)["layouts"][0]["stations"]
    assert {"dock-G1", "dock-G2"} <= {station["stationId"] for station in stations}
    assert rmf.status_code == 200 and rmf.headers["content-type"] == "application/yaml"
    assert "L1" in yaml.safe_load(rmf.content)["levels"]


def test_lif_of_a_map_not_yet_decomposed_is_404_saying_so(client: TestClient, site: dict[str, int]) -> None:
    response = client.get("/v1/maps/site/exports/lif")

    assert response.status_code == 404 and "decompose" in response.json()["detail"]

"""``aisle export FORMAT --out FILE``: the stored map in a standard format, offline, against the configured store."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from services.cli import main
from shared.mapfiles import read_map_yaml
from shared.settings import get_settings
from shared.store import Feature, GridLayer, MapStore, RevisionWrite

OCCUPANCY = np.array([[0, 0, -1], [100, 0, -1]], np.int8)


@pytest.fixture
def written(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> Iterator[dict[str, int]]:
    """The configured store (a SQLite file under AISLE_DATA_DIR) holding map ``site`` in two revisions."""
    monkeypatch.setenv("AISLE_DATA_DIR", str(tmp_path / "var"))
    get_settings.cache_clear()
    store = MapStore(get_settings().database_url)
    store.upgrade()
    map_id = store.ensure_map("site").id
    first = store.write_revision(map_id, RevisionWrite("occupancy_mapping", layers=[
        GridLayer("occupancy", OCCUPANCY, 0.05, -1.0, 2.0)])).id
    second = store.write_revision(map_id, RevisionWrite("semantics", features={
        "dock": [Feature("dock", "D1", {"type": "Point", "coordinates": [1.0, 2.0]})]})).id
    store.close()
    yield {"occupancy": first, "features": second}
    get_settings.cache_clear()


def test_map_server_export_writes_yaml_and_pgm_that_read_back(written: dict[str, int], tmp_path: Path,
                                                               capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["export", "map_server", "--out", str(tmp_path / "maps" / "site")]) == 0

    read = read_map_yaml(tmp_path / "maps" / "site.yaml")
    np.testing.assert_array_equal(read.occupancy, OCCUPANCY)
    assert (tmp_path / "maps" / "site.pgm").is_file()
    printed = capsys.readouterr().out
    assert str(tmp_path / "maps" / "site.yaml") in printed and str(tmp_path / "maps" / "site.pgm") in printed


def test_out_may_name_the_yaml_itself(written: dict[str, int], tmp_path: Path) -> None:
    assert main(["export", "map_server", "--out", str(tmp_path / "site.yaml"), "--layer", "occupancy"]) == 0

    assert sorted(path.name for path in tmp_path.glob("site.*")) == ["site.pgm", "site.yaml"]


def test_geojson_export_writes_the_named_file_at_a_revision(written: dict[str, int], tmp_path: Path) -> None:
    out = tmp_path / "layout.json"

    assert main(["export", "geojson", "--out", str(out)]) == 0
    assert main(["export", "geojson", "--out", str(tmp_path / "old.json"), "--revision",
                 str(written["occupancy"])]) == 0

    assert [f["id"] for f in json.loads(out.read_text())["features"]] == ["dock/D1"]
    assert json.loads((tmp_path / "old.json").read_text())["features"] == []


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["export", "shapefile"], "known formats"),
        (["export", "geojson", "--map", "elsewhere"], "no map named 'elsewhere'"),
        (["export", "map_server", "--layer", "nope"], "known layers: ['occupancy']"),
        (["export", "geojson", "--revision", "99"], "not a revision"),
    ],
)
def test_unknown_format_map_layer_or_revision_exits_with_code_2(
        written: dict[str, int], tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str],
        message: str) -> None:
    assert main([*args, "--out", str(tmp_path / "x")]) == 2

    assert message in capsys.readouterr().err
    assert not list(tmp_path.glob("x*"))

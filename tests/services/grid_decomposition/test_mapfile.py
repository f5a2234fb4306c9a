"""decompose_map_file: reading map files, writing outputs, rejecting bad files."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from PIL import Image

from services.grid_decomposition import (
    DecompositionError,
    decompose_map_file,
    parse_label_overrides,
    read_map_file,
)
from shared.vocabulary import PlaceLabel
from tests.helpers import data_path
from tests.services.grid_decomposition.warehouse import tuw_truth


def _office_png(path: Path) -> Path:
    img = np.full((100, 180), 205, dtype=np.uint8)
    img[5:95, 5:175] = 0
    img[8:92, 8:172] = 254
    img[8:92, 88:91] = 0
    img[40:58, 88:91] = 254
    Image.fromarray(img).save(path)
    return path


def test_decompose_map_file_writes_all_outputs_in_image_order(tmp_path: Path) -> None:
    png = _office_png(tmp_path / "office.png")
    (tmp_path / "office.yaml").write_text("image: office.png\nresolution: 0.05\norigin: [1.0, 2.0, 0.0]\n")
    decompose_map_file(tmp_path / "office.yaml", tmp_path / "out")
    with Image.open(tmp_path / "out" / "labels.png") as image:
        labels = np.asarray(image)
    segments = cv2.imread(str(tmp_path / "out" / "segments.png"), cv2.IMREAD_UNCHANGED)
    assert segments is not None
    with Image.open(png) as image:
        source = np.asarray(image)
    assert labels.dtype == np.uint8 and segments.dtype == np.uint16
    assert labels.shape == segments.shape == source.shape
    assert ((labels > 0) == (source == 254)).all()  # same row order as the input image
    layout = json.loads((tmp_path / "out" / "layout.geojson").read_text())
    kinds = {f["properties"]["kind"] for f in layout["features"]}
    assert kinds == {"region", "wall", "line"}
    region = next(f for f in layout["features"] if f["properties"]["kind"] == "region")
    xs = [p[0] for p in region["geometry"]["coordinates"][0][0]]
    assert min(xs) >= 1.0 and max(xs) <= 1.0 + 180 * 0.05
    topology = json.loads((tmp_path / "out" / "topology.json").read_text())
    assert len(topology["nodes"]) == 2
    assert {link["connection"] for link in topology["links"]} <= {"connected", "storage_access", "door", "disconnected"}
    with Image.open(tmp_path / "out" / "overview.png") as overview:
        assert overview.mode == "RGB"


def test_bare_image_needs_a_resolution(tmp_path: Path) -> None:
    png = _office_png(tmp_path / "office.png")
    with pytest.raises(DecompositionError, match="give its resolution"):
        decompose_map_file(png, tmp_path / "out")
    decompose_map_file(png, tmp_path / "out", resolution_m=0.05)
    assert (tmp_path / "out" / "labels.png").exists()


@pytest.mark.parametrize(
    ("name", "content", "message"),
    [
        ("m.yaml", "image: missing.png\nresolution: 0.05\norigin: [0, 0, 0]\n", "does not exist"),
        ("m.yaml", "resolution: 0.05\n", "lacks"),
        ("m.yaml", ": : :\n", "not readable YAML"),
        ("m.png", "not an image", "not a readable image"),
        ("m.txt", "hello", "neither a map_server YAML nor an image"),
    ],
)
def test_bad_map_files_raise_decomposition_error(tmp_path: Path, name: str, content: str, message: str) -> None:
    (tmp_path / name).write_text(content)
    with pytest.raises(DecompositionError, match=message):
        decompose_map_file(tmp_path / name, tmp_path / "out", resolution_m=0.05)


def test_a_yaml_naming_a_missing_image_points_at_the_images_beside_it(tmp_path: Path) -> None:
    _office_png(tmp_path / "map.png")
    (tmp_path / "map.yaml").write_text("image: map_rotated.png\nresolution: 0.05\norigin: [0, 0, 0]\n")
    with pytest.raises(DecompositionError, match=r"map_rotated.png does not exist; .* holds map.png: .*--resolution"):
        decompose_map_file(tmp_path / "map.yaml", tmp_path / "out")


def test_an_empty_file_raises_decomposition_error(tmp_path: Path) -> None:
    for name in ("empty.png", "empty.yaml"):
        (tmp_path / name).write_bytes(b"")
        with pytest.raises(DecompositionError):
            decompose_map_file(tmp_path / name, tmp_path / "out", resolution_m=0.05)


def test_all_unknown_and_one_pixel_images_raise_decomposition_error(tmp_path: Path) -> None:
    Image.fromarray(np.full((30, 30), 205, np.uint8)).save(tmp_path / "unknown.png")
    with pytest.raises(DecompositionError, match="no free cell"):
        decompose_map_file(tmp_path / "unknown.png", tmp_path / "out", resolution_m=0.05)
    Image.fromarray(np.full((1, 1), 254, np.uint8)).save(tmp_path / "pixel.png")
    with pytest.raises(DecompositionError, match="at least 2 x 2"):
        decompose_map_file(tmp_path / "pixel.png", tmp_path / "out", resolution_m=0.05)


def test_missing_map_file_raises_decomposition_error(tmp_path: Path) -> None:
    with pytest.raises(DecompositionError, match="does not exist"):
        decompose_map_file(tmp_path / "nope.yaml", tmp_path / "out")


def test_parse_label_overrides() -> None:
    assert parse_label_overrides("0=corridor, 3=pallet_cell") == {0: PlaceLabel.CORRIDOR, 3: PlaceLabel.STORAGE}
    with pytest.raises(DecompositionError, match="CATEGORY=LABEL"):
        parse_label_overrides("corridor")


@pytest.mark.parametrize("name", ["warehouse008", "warehouse032", "warehouse200"])
def test_tuw_warehouse_roads_are_corridors_and_every_crossing_a_junction(tmp_path: Path, name: str) -> None:
    yaml_path = data_path("maps", "tuw_warehouse", name, "map.yaml")
    d = decompose_map_file(yaml_path, tmp_path)
    occupancy, _, _ = read_map_file(yaml_path)
    truth = tuw_truth(occupancy)
    free = occupancy == 0
    assert (d.labels[free] == truth[free]).mean() >= 0.95
    junction = free & (truth == PlaceLabel.JUNCTION.value)
    n, parts = cv2.connectedComponents(junction.astype(np.uint8), connectivity=4)
    found = np.bincount(parts[junction], weights=d.labels[junction] == PlaceLabel.JUNCTION.value, minlength=n)
    assert (found[1:] > 0.5 * np.bincount(parts[junction], minlength=n)[1:]).all()

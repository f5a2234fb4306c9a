"""atlas.exports.mapserver: any grid layer as a ROS map_server YAML + PGM that reads back as the same grid."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt
import pytest
import yaml

from atlas.exports import ExportError
from atlas.exports.mapserver import map_server_files, occupancy_pixels
from shared.mapfiles import read_map_yaml
from shared.store import GridLayer


def _write(files: dict[str, bytes], folder: Path) -> Path:
    for name, content in files.items():
        (folder / name).write_bytes(content)
    return folder / next(iter(files))


def _pgm(content: bytes) -> npt.NDArray[Any]:
    pixels = cv2.imdecode(np.frombuffer(content, np.uint8), cv2.IMREAD_UNCHANGED)
    assert pixels is not None
    return np.asarray(pixels)


def _yaml(files: dict[str, bytes]) -> dict[str, Any]:
    document = yaml.safe_load(next(iter(files.values())))
    assert isinstance(document, dict)
    return document


def test_occupancy_pixels_follow_map_saver() -> None:
    occupancy = np.array([[-1, 0, 25, 26, 64, 65, 100, 101]], np.int8)

    assert occupancy_pixels(occupancy).tolist() == [[205, 254, 254, 205, 205, 0, 0, 205]]


def test_occupancy_round_trips_through_map_server_files(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    occupancy = rng.choice(np.array([-1, 0, 100], np.int8), size=(40, 70))
    layer = GridLayer("occupancy", occupancy, 0.05, -3.2, 7.5)

    files = map_server_files(layer, stem="site", about={"map": "site", "revision_id": 7})
    read = read_map_yaml(_write(files, tmp_path))

    assert list(files) == ["site.yaml", "site.pgm"]
    np.testing.assert_array_equal(read.occupancy, occupancy)
    assert (read.resolution_m, read.origin_x_m, read.origin_y_m) == (0.05, -3.2, 7.5)
    document = _yaml(files)
    assert document["image"] == "site.pgm" and document["mode"] == "trinary"
    assert document["occupied_thresh"] == 0.65 and document["origin"] == [-3.2, 7.5, 0.0]
    assert document["aisle"]["revision_id"] == 7


def test_pgm_row_0_is_the_top_of_the_map(tmp_path: Path) -> None:
    occupancy = np.array([[0, 0], [100, 100]], np.int8)  # occupied along the highest y
    files = map_server_files(GridLayer("occupancy", occupancy, 1.0, 0.0, 0.0), stem="m", about={})

    pixels = _pgm(files["m.pgm"])

    assert pixels.tolist() == [[0, 0], [254, 254]]


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_label_layers_keep_their_codes_in_raw_mode(tmp_path: Path, dtype: type) -> None:
    top = 6 if dtype is np.uint8 else 4000
    codes: npt.NDArray[Any] = np.random.default_rng(1).integers(0, top + 1, size=(9, 13)).astype(dtype)
    layer = GridLayer("place_labels", codes, 0.1, 0.0, 0.0, {"encoding": "place_labels",
                                                               "classes": ["none", "corridor"]})

    files = map_server_files(layer, stem="labels", about={})
    pixels = _pgm(files["labels.pgm"])

    np.testing.assert_array_equal(pixels[::-1], codes)
    document = _yaml(files)
    assert document["mode"] == "raw" and document["aisle"]["classes"] == ["none", "corridor"]


def test_float_layers_are_scaled_with_their_value_range_stated(tmp_path: Path) -> None:
    values = np.array([[0.25, 0.5], [np.nan, 2.25]], np.float32)
    layer = GridLayer("traversability", values, 1.0, 0.0, 0.0)

    files = map_server_files(layer, stem="t", about={})
    document = _yaml(files)
    pixels = _pgm(files["t.pgm"])[::-1].astype(float)

    meta = document["aisle"]
    assert document["mode"] == "scale" and (meta["value_min"], meta["value_max"]) == (0.25, 2.25)
    missing = pixels == meta["no_data_pixel"]
    assert missing.tolist() == [[False, False], [True, False]]
    restored = meta["value_min"] + pixels / 254 * (meta["value_max"] - meta["value_min"])
    np.testing.assert_allclose(restored[~missing], values[~missing], atol=2.0 / 254 / 2)


def test_a_layer_no_data_marker_counts_as_no_value() -> None:
    layer = GridLayer("semantic_entropy", np.array([[-1.0, 0.2, 0.8]], np.float32), 1.0, 0.0, 0.0,
                      {"encoding": "normalised_entropy", "no_data": -1.0})

    files = map_server_files(layer, stem="e", about={})
    pixels = _pgm(files["e.pgm"])

    assert pixels.tolist() == [[255, 0, 254]]
    assert _yaml(files)["aisle"]["value_min"] == pytest.approx(0.2)


def test_layers_without_a_map_server_form_are_refused() -> None:
    layer = GridLayer("phase", np.ones((2, 2), np.complex128), 1.0, 0.0, 0.0)

    with pytest.raises(ExportError, match="complex128 values"):
        map_server_files(layer, stem="p", about={})

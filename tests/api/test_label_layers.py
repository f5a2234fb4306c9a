"""Semantic label layers: drawn in their classes' colours with a legend; values served raw."""

from __future__ import annotations

import io
import re
from typing import Any

import cv2
import numpy as np
import pytest
from fastapi.testclient import TestClient

from atlas.render.layers import DEFAULT_LABEL_COLOURS, SEMANTIC_LABELS, RenderError, label_image, render_layer
from shared.store import GridLayer, MapStore, RevisionWrite
from tests.api.conftest import ClientFactory

URL = "/v1/maps/site/layers"
CLASSES = ["none", "wall", "rack", "human"]
COLOURS = [[255, 255, 255], [40, 40, 40], [31, 119, 180], [148, 103, 189]]
LABELS = np.array([[1, 1, 1, 0, 0], [0, 2, 0, 0, 2], [0, 0, 0, 0, 0]], dtype=np.uint8)
"""3 x 5 cells: a wall along the lowest y, two rack cells above it, nothing in the top row; no human."""


def _write(store: MapStore, data: np.ndarray, meta: dict[str, Any], name: str = "semantic_label") -> None:
    site = store.ensure_map("site").id
    store.write_revision(site, RevisionWrite("semantic_fusion", layers=[GridLayer(name, data, 0.05, 1.0, 2.0, meta)]))


def _rgb(png: bytes) -> np.ndarray:
    decoded = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_UNCHANGED)
    assert decoded is not None
    return cv2.cvtColor(decoded, cv2.COLOR_BGR2RGB) if decoded.ndim == 3 else decoded


def _legend_has(image: np.ndarray, colour: list[int], *, map_cols: int) -> bool:
    return bool((image[:, map_cols:].reshape(-1, 3) == colour).all(axis=1).any())


def test_label_layer_png_is_coloured_north_up_with_a_legend_of_present_classes(
        store: MapStore, make_client: ClientFactory) -> None:
    _write(store, LABELS, {"encoding": SEMANTIC_LABELS, "classes": CLASSES, "colours": COLOURS})
    client: TestClient = make_client(store)

    response = client.get(f"{URL}/semantic_label.png")

    assert response.status_code == 200 and response.headers["content-type"] == "image/png"
    image = _rgb(response.content)
    assert image.ndim == 3 and image.shape[1] > LABELS.shape[1]
    rows = LABELS.shape[0]
    for r, c in np.ndindex(LABELS.shape):
        assert image[rows - 1 - r, c].tolist() == COLOURS[LABELS[r, c]]
    assert _legend_has(image, COLOURS[1], map_cols=5) and _legend_has(image, COLOURS[2], map_cols=5)
    assert not _legend_has(image, COLOURS[3], map_cols=5)  # no human cell, no human row


def test_label_layer_values_are_the_raw_codes(store: MapStore, make_client: ClientFactory) -> None:
    _write(store, LABELS, {"encoding": SEMANTIC_LABELS, "classes": CLASSES, "colours": COLOURS})
    client: TestClient = make_client(store)

    npy = client.get(f"{URL}/semantic_label/values")
    described = client.get(f"{URL}/semantic_label").json()

    np.testing.assert_array_equal(np.load(io.BytesIO(npy.content), allow_pickle=False), LABELS)
    assert described["dtype"] == "uint8" and described["meta"]["classes"] == CLASSES


def test_label_layer_without_colours_gets_the_default_palette(store: MapStore, make_client: ClientFactory) -> None:
    _write(store, LABELS, {"encoding": SEMANTIC_LABELS, "classes": CLASSES})
    client: TestClient = make_client(store)

    image = _rgb(client.get(f"{URL}/semantic_label.png").content)

    assert image[2, 0].tolist() == list(DEFAULT_LABEL_COLOURS[0])  # code 1, bottom-left
    assert image[0, 0].tolist() == [255, 255, 255]  # code 0


@pytest.mark.parametrize(
    ("meta", "detail"),
    [
        ({"encoding": SEMANTIC_LABELS}, "needs meta\\['classes'\\]"),
        ({"encoding": SEMANTIC_LABELS, "classes": ["none", "wall"]}, "not all named"),
        ({"encoding": SEMANTIC_LABELS, "classes": CLASSES, "colours": [[0, 0, 0]]}, "\\[r, g, b\\]"),
        ({"encoding": SEMANTIC_LABELS, "classes": CLASSES, "colours": [[0, 0, 300]] * 4}, "\\[r, g, b\\]"),
    ],
)
def test_label_layer_with_unusable_meta_is_422(store: MapStore, make_client: ClientFactory, meta: dict[str, Any],
                                               detail: str) -> None:
    _write(store, LABELS, meta)
    client: TestClient = make_client(store)

    response = client.get(f"{URL}/semantic_label.png")

    assert response.status_code == 422
    assert re.search(detail, response.json()["detail"])


def test_uint8_layer_without_the_label_encoding_stays_greyscale(store: MapStore, make_client: ClientFactory) -> None:
    _write(store, LABELS, {}, name="counts")
    client: TestClient = make_client(store)

    image = _rgb(client.get(f"{URL}/counts.png").content)

    assert image.shape == LABELS.shape
    assert image[0].tolist() == [0] * 5 and image[2, 0] == 128  # min-max scaled, north up


def test_label_image_rejects_non_integer_layers() -> None:
    with pytest.raises(RenderError, match="integer codes"):
        label_image(np.zeros((2, 2), np.float32), class_names=["none"])


def test_render_layer_draws_occupancy_as_before() -> None:
    occupancy = np.array([[0, 100, -1]], dtype=np.int8)

    assert render_layer(occupancy, {"encoding": "occupancy"}).tolist() == [[255, 0, 205]]

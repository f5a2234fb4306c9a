"""atlas.render.layers: grid layers as north-up greyscale images."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from atlas.render.layers import UNKNOWN_GREY, RenderError, encode_png, layer_image


def test_occupancy_is_white_when_free_black_when_occupied_and_shaded_between() -> None:
    occupancy = np.array([[0, 25, 35, 45, 55, 65, 100]], dtype=np.int8)

    row = layer_image(occupancy)[0].tolist()

    assert row[:2] == [255, 255] and row[-2:] == [0, 0]
    assert row[1] > row[2] > row[3] > row[4] > row[5]


def test_occupancy_outside_0_to_100_is_unknown_grey() -> None:
    occupancy = np.array([[-1, 101, -128, 127]], dtype=np.int8)

    assert layer_image(occupancy).tolist() == [[UNKNOWN_GREY] * 4]


def test_top_row_of_the_image_is_the_highest_y() -> None:
    rng = np.random.default_rng(0)
    data = rng.integers(-1, 101, size=(7, 5)).astype(np.int8)

    image = layer_image(data)

    assert image.shape == data.shape
    np.testing.assert_array_equal(image[0], layer_image(data[-1:])[0])
    np.testing.assert_array_equal(image[-1], layer_image(data[:1])[0])


def test_other_dtypes_are_scaled_min_max_and_non_finite_is_black() -> None:
    data = np.array([[10.0, 20.0, np.inf, np.nan]], dtype=np.float64)

    assert layer_image(data).tolist() == [[0, 255, 0, 0]]


def test_constant_layer_is_black() -> None:
    assert layer_image(np.full((2, 3), 7, dtype=np.uint16)).tolist() == [[0, 0, 0]] * 2


@pytest.mark.parametrize(
    ("data", "match"),
    [
        (np.zeros(3, dtype=np.int8), "only 2-D layers"),
        (np.zeros((2, 2), dtype=np.complex128), "dtype complex128 cannot be rendered"),
    ],
)
def test_unrenderable_layers_raise(data: np.ndarray, match: str) -> None:
    with pytest.raises(RenderError, match=match):
        layer_image(data)


def test_png_decodes_to_the_same_pixels() -> None:
    image = np.arange(12, dtype=np.uint8).reshape(3, 4)

    decoded = cv2.imdecode(np.frombuffer(encode_png(image), np.uint8), cv2.IMREAD_UNCHANGED)

    np.testing.assert_array_equal(decoded, image)

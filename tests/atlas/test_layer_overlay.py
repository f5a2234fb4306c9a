"""atlas.render.overlay: grid layers as transparent RGBA overlays for the viewer."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from atlas.render.layers import RenderError, encode_png
from atlas.render.overlay import OVERLAY_ALPHA, overlay_image

PLACES = {"encoding": "place_labels", "classes": ["none", "corridor", "junction"],
          "colours": [[0, 0, 0], [120, 200, 120], [70, 110, 230]]}


def test_unknown_occupancy_is_transparent_and_the_rest_map_saver_grey_north_up() -> None:
    occupancy = np.array([[0, 100], [-1, -1]], dtype=np.int8)  # row 0 is the lowest y

    rgba = overlay_image(occupancy, {"encoding": "occupancy"})

    assert rgba[1, :, 3].tolist() == [OVERLAY_ALPHA, OVERLAY_ALPHA] and rgba[0, :, 3].tolist() == [0, 0]
    assert rgba[1, 0, :3].tolist() == [255, 255, 255] and rgba[1, 1, :3].tolist() == [0, 0, 0]


def test_labels_take_their_colours_and_unlabelled_cells_stay_clear() -> None:
    labels = np.array([[0, 1, 2]], dtype=np.uint8)

    rgba = overlay_image(labels, PLACES)

    assert rgba[0, :, 3].tolist() == [0, OVERLAY_ALPHA, OVERLAY_ALPHA]
    assert rgba[0, 1, :3].tolist() == [120, 200, 120] and rgba[0, 2, :3].tolist() == [70, 110, 230]


def test_uncertain_labels_are_fainter_and_cells_without_data_vanish() -> None:
    labels = np.array([[1, 1, 1, 1]], dtype=np.uint8)
    certainty = np.array([[1.0, 0.5, 0.0, -1.0]])

    alpha = overlay_image(labels, PLACES, certainty=certainty)[0, :, 3]

    assert alpha[0] == OVERLAY_ALPHA and 0 < alpha[1] < alpha[0] and alpha[2] == 0 and alpha[3] == 0


def test_a_certainty_layer_of_another_shape_is_refused() -> None:
    with pytest.raises(RenderError, match="shape"):
        overlay_image(np.zeros((2, 2), np.uint8), PLACES, certainty=np.ones((3, 2)))


def test_label_codes_without_a_name_are_refused() -> None:
    with pytest.raises(RenderError, match="classes"):
        overlay_image(np.array([[5]], np.uint8), PLACES)


def test_rgba_images_encode_as_png_with_their_transparency() -> None:
    rgba = overlay_image(np.array([[0, -1]], dtype=np.int8), {"encoding": "occupancy"})

    decoded = cv2.imdecode(np.frombuffer(encode_png(rgba), np.uint8), cv2.IMREAD_UNCHANGED)

    assert decoded is not None and decoded.shape == (1, 2, 4) and decoded[0, :, 3].tolist() == [OVERLAY_ALPHA, 0]

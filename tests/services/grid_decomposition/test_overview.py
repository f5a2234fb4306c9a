"""overview_image: the map in label colours with a legend beside it."""

from __future__ import annotations

import numpy as np

from services.grid_decomposition import decompose, overview_image
from services.grid_decomposition.overview import LABEL_COLOURS
from shared.vocabulary import PlaceLabel
from tests.services.grid_decomposition.warehouse import synthetic_warehouse


def test_overview_shows_every_place_colour_and_a_legend_beside_the_map() -> None:
    wh = synthetic_warehouse(3, n_double_rows=2, n_sections=2, bays_per_section=3)
    d = decompose(wh.occupancy, resolution_m=wh.resolution_m)
    image = overview_image(d, min_side_px=0)
    h, w = d.labels.shape
    assert image.dtype == np.uint8 and image.shape[0] >= h and image.shape[1] > w + 100
    map_part, legend = image[:h, :w], image[:, w:]
    for label in (PlaceLabel.CORRIDOR, PlaceLabel.JUNCTION, PlaceLabel.STORAGE):
        colour = np.array(LABEL_COLOURS[label])
        assert (map_part == colour).all(axis=-1).any(), label
        assert (legend == colour).all(axis=-1).any(), label  # its swatch
    storage = map_part[::-1][d.labels == PlaceLabel.STORAGE.value]
    assert (storage == LABEL_COLOURS[PlaceLabel.STORAGE]).all(axis=-1).mean() > 0.8


def test_a_small_map_is_enlarged_for_reading() -> None:
    occ = np.zeros((60, 80), dtype=np.int8)
    occ[:2], occ[-2:], occ[:, :2], occ[:, -2:] = 100, 100, 100, 100
    image = overview_image(decompose(occ, resolution_m=0.05), min_side_px=400)
    assert image.shape[0] >= 300 and image.shape[1] >= 400


def test_a_small_building_in_a_large_unknown_canvas_is_cropped_to_it() -> None:
    occ = np.full((400, 400), -1, dtype=np.int8)
    occ[100:160, 200:280] = 100
    occ[102:158, 202:278] = 0
    d = decompose(occ, resolution_m=0.05)
    whole = overview_image(d, min_side_px=0, margin_m=None)
    cropped = overview_image(d, min_side_px=0, margin_m=1.0)
    assert whole.shape[1] > 400 and cropped.shape[1] < whole.shape[1] - 200

import numpy as np
import pytest

from services.semantic_fusion import (
    N_CLASSES,
    NO_ENTROPY,
    GridCells,
    SemanticFusionError,
    infer_labels,
    normalised_entropy,
    rasterise,
)
from services.semantic_fusion.classes import column_of
from shared.vocabulary import SemanticClass


def _cells(entries: list[tuple[int, int, dict[SemanticClass, float], float]]) -> GridCells:
    """(row, col, {class: log-evidence}, height) per cell, 5 hits each."""
    evidence = np.zeros((len(entries), N_CLASSES), np.float32)
    for i, (_, _, ev, _) in enumerate(entries):
        for cls, value in ev.items():
            evidence[i, column_of(cls)] = value
    return GridCells(np.array([(r, c) for r, c, _, _ in entries], np.int64), evidence,
                     np.full(len(entries), 5.0, np.float32), np.array([h for *_, h in entries], np.float32))


def test_normalised_entropy_is_one_for_uniform_and_near_zero_for_certain() -> None:
    h = normalised_entropy(np.array([[0.0] * 7, [40.0] + [0.0] * 6]))
    assert h[0] == pytest.approx(1.0)
    assert h[1] < 1e-6


def test_band_cell_takes_the_label_of_its_surface() -> None:
    wall = {SemanticClass.WALL: 8.0}
    unsure = {SemanticClass.WALL: 2.5, SemanticClass.GATE: 2.7}
    cells = _cells([(0, c, wall, 3.0) for c in (0, 1, 3, 4)] + [(0, 2, unsure, 3.0)])
    result = infer_labels(cells, confident_entropy=0.3, unconfident_entropy=0.95)
    assert result.raw_labels[-1] == SemanticClass.GATE
    assert result.labels[-1] == SemanticClass.WALL


def test_band_cell_ignores_neighbours_of_another_height_or_across_a_gap() -> None:
    pallet = {SemanticClass.PALLET: 8.0}
    unsure = {SemanticClass.RACK: 2.7, SemanticClass.PALLET: 2.5}
    low = _cells([(0, 0, unsure, 3.0), (0, 1, pallet, 1.4), (1, 0, pallet, 1.4)])
    gap = _cells([(0, 0, unsure, 3.0), (0, 2, pallet, 3.0), (2, 2, pallet, 3.0)])
    for cells in (low, gap):
        result = infer_labels(cells, confident_entropy=0.3, unconfident_entropy=0.95)
        assert result.labels[0] == SemanticClass.RACK


def test_confident_thin_upright_survives_among_pallets() -> None:
    pallet = {SemanticClass.PALLET: 8.0}
    upright = {SemanticClass.RACK: 7.0}
    cells = _cells([(0, c, pallet, 3.0) for c in range(5) if c != 2] + [(0, 2, upright, 3.0)])
    result = infer_labels(cells)
    assert result.labels[-1] == SemanticClass.RACK


def test_unconfident_cells_are_unknown_and_rare_cells_are_empty() -> None:
    cells = _cells([(0, 0, {SemanticClass.WALL: 0.1}, 3.0), (5, 5, {SemanticClass.WALL: 8.0}, 3.0)])
    cells = cells._replace(hits=np.array([5.0, 1.0], np.float32))
    result = infer_labels(cells, min_hits=2.0)
    assert result.labels.tolist() == [SemanticClass.UNKNOWN, SemanticClass.NONE]


def test_rasterise_places_cells_on_the_world_lattice() -> None:
    cells = _cells([(-2, 3, {SemanticClass.WALL: 8.0}, 3.0), (0, 5, {SemanticClass.GATE: 8.0}, 3.0)])
    layers = rasterise(cells, infer_labels(cells), resolution_m=0.1)
    assert layers.labels.shape == (3, 3)
    assert (layers.origin_x_m, layers.origin_y_m) == pytest.approx((0.3, -0.2))
    assert layers.labels[0, 0] == SemanticClass.WALL and layers.labels[2, 2] == SemanticClass.GATE
    assert layers.entropy[1, 1] == NO_ENTROPY
    label_layer, entropy_layer = layers.grid_layers()
    assert label_layer.data.dtype == np.uint8 and entropy_layer.data.dtype == np.float32


def test_infer_labels_rejects_inverted_bands() -> None:
    with pytest.raises(SemanticFusionError, match="confident_entropy"):
        infer_labels(_cells([(0, 0, {}, 0.0)]), confident_entropy=0.8, unconfident_entropy=0.5)

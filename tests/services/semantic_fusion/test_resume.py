import numpy as np
import pytest

from services.semantic_fusion import (
    N_CLASSES,
    SemanticFusionError,
    SemanticGrid,
    evidence_for_entropy,
    infer_labels,
    normalised_entropy,
    rasterise,
    seed_grid,
)
from shared.vocabulary import SemanticClass


def test_evidence_for_entropy_inverts_the_one_hot_entropy() -> None:
    w = np.random.default_rng(0).uniform(0.0, 8.0, 50)
    one_hot = np.zeros((w.size, N_CLASSES))
    one_hot[:, 2] = w
    back = evidence_for_entropy(normalised_entropy(one_hot), max_log_evidence=8.0)
    np.testing.assert_allclose(back, w, atol=0.01)


def test_evidence_for_entropy_caps_confident_and_non_finite_cells() -> None:
    assert evidence_for_entropy([0.0, np.nan], max_log_evidence=5.0).tolist() == [5.0, 5.0]


def test_seeded_grid_infers_the_stored_static_labels_on_the_same_cells() -> None:
    c = SemanticClass
    labels = np.array([[c.WALL, c.WALL, c.NONE], [c.RACK, c.FORKLIFT, c.HUMAN], [c.PALLET, c.GATE, c.NONE]], np.uint8)
    entropy = np.where(labels == c.NONE, -1.0, 0.2).astype(np.float32)
    grid = SemanticGrid(resolution_m=0.1)

    seeded = seed_grid(grid, labels, entropy, origin_x_m=-0.3, origin_y_m=0.5)

    layers = rasterise(cells := grid.cells(now_s=0.0), infer_labels(cells), resolution_m=0.1)
    static = np.where(np.isin(labels, [c.FORKLIFT, c.HUMAN]), c.NONE, labels)
    assert seeded == int(np.count_nonzero(static))
    assert (layers.origin_x_m, layers.origin_y_m) == pytest.approx((-0.3, 0.5))
    np.testing.assert_array_equal(layers.labels, static[: layers.labels.shape[0], : layers.labels.shape[1]])
    np.testing.assert_allclose(layers.entropy[layers.labels > 0], 0.2, atol=0.01)


def test_seed_grid_rejects_mismatched_layers() -> None:
    with pytest.raises(SemanticFusionError, match="equal 2-D shapes"):
        seed_grid(SemanticGrid(), np.zeros((2, 2), np.uint8), np.zeros((2, 3)), origin_x_m=0.0, origin_y_m=0.0)

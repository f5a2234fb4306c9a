import numpy as np
import pytest

from services.semantic_fusion import CLASS_COLOURS, SemanticFusionError, render_labels
from shared.vocabulary import SemanticClass


def test_render_labels_colours_cells_with_north_up() -> None:
    labels = np.zeros((2, 3), np.uint8)
    labels[0, 0] = SemanticClass.RACK  # row 0 is the lowest y: bottom of the image
    image = render_labels(labels, scale=2, legend=False)
    assert image.shape == (4, 6, 3) and image.dtype == np.uint8
    assert tuple(image[3, 0]) == CLASS_COLOURS[SemanticClass.RACK]
    assert tuple(image[0, 0]) == CLASS_COLOURS[SemanticClass.NONE]


def test_render_labels_appends_a_legend() -> None:
    labels = np.full((4, 4), SemanticClass.WALL, np.uint8)
    assert render_labels(labels).shape[1] > 4


def test_render_labels_rejects_unknown_codes() -> None:
    with pytest.raises(SemanticFusionError, match="label codes"):
        render_labels(np.full((2, 2), 99, np.uint8))

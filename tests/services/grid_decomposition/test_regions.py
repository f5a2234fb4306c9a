import numpy as np

from services.grid_decomposition.cogency import EdgeCogency
from services.grid_decomposition.regions import road_networks
from services.grid_decomposition.subdivision import Subdivision
from shared.vocabulary import PlaceLabel


def _three_faces_in_a_row() -> tuple[Subdivision, EdgeCogency, np.ndarray, np.ndarray]:
    """A corridor face, a junction face and a corridor face side by side, one component, no doorway."""
    face_image = np.repeat(np.array([[1] * 20 + [2] * 20 + [3] * 20]), 20, axis=0).astype(np.int32)
    sub = Subdivision(face_image, 3, np.zeros((0, 2)), np.zeros((0, 2), dtype=np.int64), np.zeros(0, dtype=np.int64),
                      np.zeros(1, dtype=np.int64), np.zeros((0, 2, 2)), np.zeros(face_image.shape, dtype=bool))
    free = np.zeros(face_image.shape, dtype=bool)
    free[8:12] = True  # a strip 4 cells wide through the three faces
    free_px = np.bincount(face_image[free], minlength=4).astype(np.int64)
    cog = EdgeCogency(np.zeros(4), free_px, np.zeros(0), np.zeros(0, dtype=np.int64), np.zeros(0, dtype=bool))
    labels = np.array([0, PlaceLabel.CORRIDOR.value, PlaceLabel.JUNCTION.value, PlaceLabel.CORRIDOR.value])
    return sub, cog, free, labels


def test_a_road_network_is_floor_between_blocks_not_rays_between_unknown_cells() -> None:
    sub, cog, free, labels = _three_faces_in_a_row()
    component = np.array([0, 1, 1, 1], dtype=np.int64)
    blocks = ~free  # the laser hit the blocks on both sides (else it saw nothing there: unknown)
    none = np.zeros(free.shape, dtype=bool)
    assert road_networks(sub, cog, component, cog.face_free_px, labels)[1]
    # floor between blocks the laser hit
    assert road_networks(sub, cog, component, cog.face_free_px, labels, free=free, occupied=blocks, known=free | blocks,
                         rays=none)[1]
    # rays between blocks the laser hit, floor between unknown cells: still roads
    assert road_networks(sub, cog, component, cog.face_free_px, labels, free=free, occupied=blocks, known=free | blocks,
                         rays=free)[1]
    assert road_networks(sub, cog, component, cog.face_free_px, labels, free=free, occupied=none, known=free,
                         rays=none)[1]
    # rays fanning between unknown cells: no roads
    assert not road_networks(sub, cog, component, cog.face_free_px, labels, free=free, occupied=none, known=free,
                             rays=free)[1]

"""Dominant orientations from the weighted HOG, GMM and CWT peaks."""

from __future__ import annotations

import math

import cv2
import numpy as np

from services.grid_decomposition import dominant_orientations, oriented_gradients


def _angle_error(a: float, b: float) -> float:
    return abs((a - b + math.pi / 2) % math.pi - math.pi / 2)


def test_dominant_orientations_of_axis_aligned_rooms_are_horizontal_and_vertical() -> None:
    occ = np.zeros((200, 300), dtype=bool)
    occ[[10, 100, 190], 10:290] = True
    occ[10:190, [10, 150, 290]] = True
    angles = dominant_orientations(oriented_gradients(occ))
    assert len(angles) == 2
    assert min(_angle_error(a, 0.0) for a in angles) < math.radians(1)
    assert min(_angle_error(a, math.pi / 2) for a in angles) < math.radians(1)


def test_dominant_orientations_follow_a_rotated_building() -> None:
    occ = np.zeros((400, 400), dtype=np.uint8)
    box = cv2.boxPoints(((200.0, 200.0), (250.0, 150.0), 30.0)).astype(np.int32)
    cv2.polylines(occ, [box], True, 1, 2)
    angles = dominant_orientations(oriented_gradients(occ.astype(bool)))
    assert len(angles) == 2
    assert min(_angle_error(a, math.radians(30)) for a in angles) < math.radians(1.5)
    assert min(_angle_error(a, math.radians(120)) for a in angles) < math.radians(1.5)


def test_dominant_orientations_of_a_map_without_edges_is_empty() -> None:
    assert dominant_orientations(oriented_gradients(np.zeros((20, 20), dtype=bool))).size == 0

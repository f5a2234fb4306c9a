"""Face rectangles along the face orientation and obstacles at their corners."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from services.grid_decomposition import DecompositionError, face_geometry


def test_face_geometry_measures_an_axis_aligned_bay_with_uprights_at_its_corners() -> None:
    faces = np.zeros((60, 80), dtype=np.int32)
    faces[10:32, 20:74] = 1  # 1.1 x 2.7 m at 5 cm
    obstacle = np.zeros_like(faces, dtype=bool)
    for r, c in ((8, 18), (8, 75), (33, 18), (33, 75)):
        obstacle[r : r + 2, c : c + 2] = True
    g = face_geometry(faces, 1, obstacle, resolution_m=0.05)
    assert g.short_m[1] == pytest.approx(1.1) and g.long_m[1] == pytest.approx(2.7)
    assert g.corners_on_obstacle[1] == 4
    assert g.walled_fraction[1] < 0.3
    assert g.centroid_px[1] == pytest.approx((46.5, 20.5))


def test_face_geometry_follows_the_given_face_orientation() -> None:
    angle = 0.5
    faces = np.zeros((200, 200), dtype=np.int32)
    box = cv2.boxPoints(((100.0, 100.0), (80.0, 30.0), math.degrees(angle)))
    cv2.fillPoly(faces, [np.rint(box).astype(np.int32)], 1)
    obstacle = np.zeros_like(faces, dtype=bool)
    aligned = face_geometry(faces, 1, obstacle, resolution_m=0.05, face_angle_rad=np.array([0.0, angle]))
    axis = face_geometry(faces, 1, obstacle, resolution_m=0.05)
    assert aligned.long_m[1] == pytest.approx(81 * 0.05, abs=0.1)
    assert aligned.short_m[1] == pytest.approx(31 * 0.05, abs=0.1)
    assert axis.short_m[1] > aligned.short_m[1] + 1.0


def test_face_geometry_rejects_angles_of_the_wrong_length() -> None:
    faces = np.ones((4, 4), dtype=np.int32)
    with pytest.raises(DecompositionError, match="face_angle_rad must have shape"):
        face_geometry(faces, 1, faces == 0, resolution_m=0.05, face_angle_rad=np.zeros(3))


def test_a_bay_is_open_at_the_middle_of_its_short_sides_a_corridor_slice_is_not() -> None:
    """A bay between four uprights vs. a bay-sized slice of a corridor between its two walls."""
    faces = np.zeros((80, 80), dtype=np.int32)
    faces[10:32, 20:74] = 1  # bay: 1.1 x 2.7 m, uprights at the corners
    faces[40:76, 30:52] = 2  # slice of a 1.8 m corridor, 1.1 m long, walls above and below
    faces[4:8, 20:74] = 3  # flue: 0.2 m strip
    obstacle = np.zeros_like(faces, dtype=bool)
    for r, c in ((8, 18), (8, 75), (33, 18), (33, 75)):
        obstacle[r : r + 2, c : c + 2] = True
    obstacle[38:40, 26:56] = True
    obstacle[76:78, 26:56] = True
    g = face_geometry(faces, 3, obstacle, resolution_m=0.05)
    assert g.corners_on_obstacle[1] == 4 and g.ends_on_obstacle[1] == 0
    assert g.corners_on_obstacle[2] == 4 and g.ends_on_obstacle[2] == 2
    assert g.ends_on_obstacle[3] == -1

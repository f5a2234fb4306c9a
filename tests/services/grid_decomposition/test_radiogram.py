"""Radiograms and their Ricker-wavelet peaks."""

from __future__ import annotations

import math

import numpy as np

from services.grid_decomposition import line_offsets, oriented_gradients, radiogram


def test_line_offsets_find_every_wall_of_a_row_of_rooms() -> None:
    occ = np.zeros((120, 400), dtype=bool)
    walls = [20, 110, 200, 290, 380]
    occ[:, walls] = True
    gram = radiogram(oriented_gradients(occ), math.pi / 2)
    lines = line_offsets(gram, resolution_m=0.05)
    found = sorted(-ln.offset_px for ln in lines)  # offset of a vertical line is -x
    assert len(found) == len(walls)
    assert np.allclose(found, walls, atol=1.0)


def test_gradient_filter_ignores_walls_of_the_other_orientation() -> None:
    occ = np.zeros((200, 200), dtype=bool)
    occ[100, :] = True
    gram = radiogram(oriented_gradients(occ), math.pi / 2)  # project along vertical lines
    assert gram.signal.max() < 0.05 * radiogram(oriented_gradients(occ), 0.0).signal.max()


def test_coarse_lines_are_a_subset_of_fine_lines() -> None:
    rng = np.random.default_rng(3)
    occ = rng.random((150, 150)) < 0.02
    occ[:, [30, 90]] = True
    lines = line_offsets(radiogram(oriented_gradients(occ), math.pi / 2), resolution_m=0.05)
    coarse = [ln for ln in lines if ln.coarse]
    assert 2 <= len(coarse) <= len(lines)

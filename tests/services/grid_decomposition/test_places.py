"""Ray-cast place features and their clustering."""

from __future__ import annotations

import numpy as np

from services.grid_decomposition import cast_rays, categorize_places, raycast_features


def test_cast_rays_from_the_centre_of_a_square_room_reach_its_walls() -> None:
    obstacle = np.ones((101, 101), dtype=bool)
    obstacle[1:100, 1:100] = False
    ranges = cast_rays(obstacle, np.array([50]), np.array([50]), n_beams=8, max_range_px=500)
    assert np.allclose(ranges[0, [0, 2, 4, 6]], 49, atol=1.5)
    assert np.allclose(ranges[0, [1, 3, 5, 7]], 49 * np.sqrt(2), atol=2.5)


def test_raycast_features_of_a_circle_scan_are_round() -> None:
    feats = raycast_features(np.full((1, 64), 2.0), gap_threshold=0.5)
    assert feats.shape == (1, 13)
    mean, std, _, _, area, perimeter, _, gaps, _, pc1, pc2, ratio, offset = feats[0]
    assert mean == 2.0 and std == 0.0 and gaps == 0
    assert abs(area - np.pi * 4) < 0.1 and abs(perimeter - 4 * np.pi) < 0.1
    assert abs(ratio - 1.0) < 1e-6 and offset < 1e-9 and abs(pc1 - pc2) < 1e-9


def test_categorize_places_separates_a_corridor_from_a_hall() -> None:
    obstacle = np.ones((120, 240), dtype=bool)
    obstacle[10:110, 10:110] = False  # hall 5 x 5 m
    obstacle[55:65, 110:230] = False  # corridor 0.5 m wide
    _, cols, cat = categorize_places(obstacle, ~obstacle, resolution_m=0.05, n_categories=2, sample_spacing_m=0.25)
    hall = cat[cols < 100]
    corridor = cat[cols > 130]
    assert np.bincount(hall).argmax() != np.bincount(corridor).argmax()

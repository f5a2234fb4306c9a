"""A cut from unknown space to unknown space parts nothing: its two sides join; doorways between seen walls stay."""

from __future__ import annotations

import numpy as np

from services.grid_decomposition.openings import join_unseen_openings, straight_openings

RES = 0.05


def _strip_cut_across() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A 1.5 x 8 m strip of free space (a bundle of laser rays) in unknown space, cut across half-way into two
    segments: segments, obstacles (not free) and occupied cells (none yet)."""
    obstacle = np.ones((200, 60), dtype=bool)
    obstacle[20:180, 15:45] = False
    seg = np.zeros(obstacle.shape, dtype=np.int32)
    seg[20:100, 15:45] = 1
    seg[100:180, 15:45] = 2
    return seg, obstacle, np.zeros(obstacle.shape, dtype=bool)


def test_a_strip_of_rays_cut_between_unknown_edges_is_one_region() -> None:
    seg, obstacle, occupied = _strip_cut_across()
    out = join_unseen_openings(seg, obstacle, occupied, resolution_m=RES)
    assert out[40, 30] == out[160, 30] > 0
    assert np.array_equal(out > 0, seg > 0)
    fixed = np.array([False, True, False])  # a warehouse floor never joins
    assert join_unseen_openings(seg, obstacle, occupied, resolution_m=RES, fixed=fixed).max() == 2


def test_a_doorway_with_a_jamb_the_laser_saw_keeps_its_sides_apart() -> None:
    seg, obstacle, occupied = _strip_cut_across()
    occupied[95:105, 12:15] = True  # the left jamb, hit by the laser
    assert join_unseen_openings(seg, obstacle, occupied, resolution_m=RES).max() == 2
    occupied[:] = False
    occupied[20:180, 45:47] = True  # a wall along the right side (its cells 0.05 m off the cut's end)
    assert join_unseen_openings(seg, obstacle, occupied, resolution_m=RES).max() == 2
    occupied[:] = False
    occupied[20:180, 56] = True  # seen cells 0.6 m beyond the right end: within 0.75 m (a grey wall's specks)
    assert join_unseen_openings(seg, obstacle, occupied, resolution_m=RES).max() == 2


def test_only_straight_borders_are_openings() -> None:
    """Two segments side by side along a crooked border (a staircase) are no cut across an opening."""
    seg, obstacle, _ = _strip_cut_across()
    assert straight_openings(seg, obstacle).width_px.round().tolist() == [29.0]
    seg[20:180, 15:45] = 1
    for k, row in enumerate(range(20, 180, 10)):
        seg[row : row + 10, 15 + k % 2 * 10 : 45] = 2  # a border stepping 0.5 m back and forth down the strip
    assert straight_openings(seg, obstacle).first.size == 0

"""A cut from unknown space to unknown space parts nothing: its two sides join; doorways between seen walls stay."""

from __future__ import annotations

import numpy as np

from services.grid_decomposition.openings import join_unseen_openings, join_unseen_passages, straight_openings

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


def _corridor_with_a_piece() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A 1.5 m wide corridor, 10 m long, between grey (unknown) walls whose occupied cells lie 0.15 m behind the
    floor's edge, cut twice 1.5 m apart: two long pieces and a 1.5 x 1.5 m piece between them (segments 1, 3, 2);
    segments, obstacles, occupied cells."""
    obstacle = np.ones((60, 220), dtype=bool)
    obstacle[15:45, 10:210] = False
    occupied = np.zeros(obstacle.shape, dtype=bool)
    occupied[[11, 48], 10:210] = True  # the walls seen from afar: three grey cells between them and the floor
    seg = np.zeros(obstacle.shape, dtype=np.int32)
    seg[15:45, 10:100] = 1
    seg[15:45, 100:130] = 2
    seg[15:45, 130:210] = 3
    return seg, obstacle, occupied


def test_a_corridor_piece_between_cuts_on_unseen_walls_joins_both_sides() -> None:
    seg, obstacle, occupied = _corridor_with_a_piece()
    out = join_unseen_passages(seg, obstacle, occupied, resolution_m=RES)
    assert out[30, 50] == out[30, 115] == out[30, 170] > 0
    assert np.array_equal(out > 0, seg > 0)
    fixed = np.array([False, False, False, True])  # beside a warehouse floor it stays
    assert join_unseen_passages(seg, obstacle, occupied, resolution_m=RES, fixed=fixed).max() == 3


def test_a_corridor_piece_with_seen_jambs_or_a_third_neighbour_stays() -> None:
    seg, obstacle, occupied = _corridor_with_a_piece()
    seen = occupied.copy()
    seen[14, 100:130] = True  # the wall beside the piece hit by the laser at the floor's edge (1.5 m)
    assert join_unseen_passages(seg, obstacle, seen, resolution_m=RES).max() == 3
    side = seg.copy()
    obstacle[5:15, 105:125] = False
    side[5:15, 105:125] = 4  # a room opening off the piece: a junction, not a piece of corridor
    assert join_unseen_passages(side, obstacle, occupied, resolution_m=RES).max() == 4
    big = seg.copy()
    big[15:45, 70:100] = 2  # a 3 m piece is a room's length, not a strip between two cuts
    assert join_unseen_passages(big, obstacle, occupied, resolution_m=RES).max() == 3

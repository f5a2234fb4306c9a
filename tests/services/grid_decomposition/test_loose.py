"""Pieces of one fan of rays that touch nothing join; a piece touching a room, or behind a wall, does not."""

from __future__ import annotations

import numpy as np

from services.grid_decomposition.loose import join_isolated_pieces


def test_pieces_of_one_fan_that_touch_nothing_join_and_a_piece_touching_a_room_does_not() -> None:
    seg = np.zeros((60, 80), dtype=np.int32)
    occupied = np.zeros(seg.shape, dtype=bool)
    seg[5:55, 2:20] = 1  # a room
    seg[10:30, 30:33] = 2  # three rays of one fan, 3-4 cells apart, unknown between them
    seg[12:32, 36:39] = 3
    seg[10:28, 42:44] = 4
    seg[10:30, 60:63] = 5  # a ray 16 cells off: another fan
    seg[40:50, 20:23] = 6  # a piece touching the room
    out = join_isolated_pieces(seg, occupied, max_area_px=100, gap_px=6)
    assert len({int(out[20, 31]), int(out[20, 37]), int(out[20, 43])}) == 1
    assert out[20, 61] == 5
    assert out[45, 21] == 6 and out[20, 10] == 1


def test_a_wall_between_two_pieces_keeps_them_apart() -> None:
    seg = np.zeros((40, 40), dtype=np.int32)
    occupied = np.zeros(seg.shape, dtype=bool)
    seg[10:30, 10:13] = 1
    seg[10:30, 16:19] = 2
    occupied[:, 14] = True  # a wall in the gap
    out = join_isolated_pieces(seg, occupied, max_area_px=100, gap_px=6)
    assert np.array_equal(out, seg)

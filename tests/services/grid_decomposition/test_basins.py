"""Pieces of one furnished room join; rooms behind a doorway, cubicles off a corridor and floors stay apart."""

from __future__ import annotations

import cv2
import numpy as np

from services.grid_decomposition.basins import _near, join_room_pieces

RES = 0.05


def _room_cut_in_two() -> tuple[np.ndarray, np.ndarray]:
    """A 6 x 4 m room cut at x = 3 m along a gap between two desks (furniture on the cut)."""
    seg = np.zeros((100, 140), dtype=np.int32)
    seg[10:90, 10:70] = 1
    seg[10:90, 70:130] = 2
    desks = np.zeros(seg.shape, dtype=bool)
    desks[20:36, 60:68] = desks[64:80, 72:80] = True
    seg[desks] = 0
    return seg, desks


def test_two_pieces_of_a_furnished_room_join() -> None:
    seg, desks = _room_cut_in_two()
    out = join_room_pieces(seg, desks, resolution_m=RES)
    assert out[50, 30] == out[50, 110] > 0
    assert np.array_equal(out > 0, seg > 0)


def test_rooms_behind_a_doorway_stay_apart() -> None:
    seg, desks = _room_cut_in_two()
    seg[10:90, 68:72] = 0  # a wall between the two halves
    seg[46:54, 68:72] = 1  # with a 0.4 m wide doorway in it
    out = join_room_pieces(seg, desks, resolution_m=RES)
    assert out[50, 30] != out[50, 110]


def test_a_room_opening_onto_a_corridor_stays_apart() -> None:
    """A furnished 3 x 3 m office open over its whole width onto the side of a 2 m x 12 m corridor: an L, not a room."""
    seg = np.zeros((120, 260), dtype=np.int32)
    seg[10:50, 10:250] = 1  # corridor
    seg[50:110, 10:70] = 2  # office below its left end
    desks = np.zeros(seg.shape, dtype=bool)
    desks[56:70, 20:40] = True
    seg[desks] = 0
    out = join_room_pieces(seg, desks, resolution_m=RES)
    assert out[30, 200] != out[90, 40]


def test_bare_pieces_and_fixed_floors_are_not_joined() -> None:
    seg, desks = _room_cut_in_two()
    bare = np.where(seg > 0, seg, np.where(desks, 1, 0)).astype(np.int32)
    out = join_room_pieces(bare, np.zeros(seg.shape, dtype=bool), resolution_m=RES)
    assert out[50, 30] != out[50, 110]  # no furniture near the border: not cut by furniture
    fixed = np.array([False, True, False])
    out = join_room_pieces(seg, desks, resolution_m=RES, fixed=fixed)
    assert out[50, 30] != out[50, 110]


def test_furniture_near_a_border_is_read_as_a_dilation_by_the_disc() -> None:
    """The furniture test at border pixels agrees with ``cv2.dilate`` by the elliptic disc everywhere."""
    rng = np.random.default_rng(3)
    furniture = rng.random((60, 80)) < 0.002
    pixels = np.arange(furniture.size, dtype=np.int64)
    for reach in (1, 4, 9):
        disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * reach + 1, 2 * reach + 1))
        dilated = cv2.dilate(furniture.astype(np.uint8), disc) > 0
        assert np.array_equal(_near(furniture, pixels, reach), dilated.ravel())


def test_a_narrow_office_cut_where_a_cupboard_narrows_it_joins() -> None:
    """A furnished 2.6 x 6 m office, cut across where a cupboard against its wall leaves 1.6 m: one room.

    The cut is a neck (saddle 0.8 m against peaks of 1.3 m), but the union is no less convex than its
    pieces: a room cut in two, not a room beside a corridor.
    """
    seg = np.zeros((140, 80), dtype=np.int32)
    seg[10:70, 10:62] = 1
    seg[70:130, 10:62] = 2
    seg[60:80, 10:30] = 0  # the cupboard against the left wall
    desk = np.zeros(seg.shape, dtype=bool)
    desk[64:76, 44:54] = True
    seg[desk] = 0
    before = join_room_pieces(seg, desk, resolution_m=RES, min_relative_solidity=np.inf)
    assert before[30, 40] != before[110, 40]  # the saddle alone keeps it cut
    out = join_room_pieces(seg, desk, resolution_m=RES)
    assert out[30, 40] == out[110, 40] > 0

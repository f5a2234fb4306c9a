"""Pieces of one furnished room join; rooms behind a doorway, cubicles off a corridor and floors stay apart."""

from __future__ import annotations

import cv2
import numpy as np

from services.grid_decomposition.basins import _near, join_furnished_groups, join_room_pieces

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


def _office_with_cupboards() -> tuple[np.ndarray, np.ndarray]:
    """A 3.2 x 6.5 m office with cupboards along both walls, cut in two beside one of them (a desk near the cut)."""
    seg = np.zeros((150, 90), dtype=np.int32)
    seg[10:75, 10:74] = 1
    seg[75:140, 10:74] = 2
    seg[65:85, 10:32] = 0  # the cupboard beside the cut
    for r0, c0, c1 in ((25, 48, 74), (45, 10, 36), (95, 48, 74), (115, 10, 36)):  # cupboards along the walls
        seg[r0 : r0 + 14, c0:c1] = 0
    desk = np.zeros(seg.shape, dtype=bool)
    desk[70:80, 50:60] = True
    seg[desk] = 0
    return seg, desk


def test_an_office_with_cupboards_along_its_walls_cut_in_two_joins() -> None:
    """Its outline is far from convex (solidity 0.77), but no less convex than either piece: one room."""
    seg, desk = _office_with_cupboards()
    before = join_room_pieces(seg, desk, resolution_m=RES, min_relative_solidity=np.inf)
    assert before[30, 40] != before[110, 40]  # the union's solidity alone keeps it cut
    out = join_room_pieces(seg, desk, resolution_m=RES)
    assert out[30, 40] == out[110, 40] > 0


def test_two_furnished_rooms_side_by_side_behind_a_wide_opening_stay_apart() -> None:
    """Two 3 x 4 m rooms, a 1.8 m opening in the wall between them: both pieces are convex, so their
    convex union is no sign of one room."""
    seg = np.zeros((100, 150), dtype=np.int32)
    seg[10:90, 10:70] = 1
    seg[10:90, 74:134] = 2
    seg[32:68, 70:74] = 1  # the opening
    desks = np.zeros(seg.shape, dtype=bool)
    desks[20:30, 56:66] = desks[70:80, 78:88] = True
    seg[desks] = 0
    out = join_room_pieces(seg, desks, resolution_m=RES)
    assert out[50, 30] != out[50, 110]

def _office_cut_round_a_desk_cluster() -> tuple[np.ndarray, np.ndarray]:
    """A 6 x 4 m office cut in two at x = 3 m from a 1.5 x 1 m desk cluster in its middle to both walls."""
    seg = np.zeros((100, 140), dtype=np.int32)
    seg[10:90, 10:70] = 1
    seg[10:90, 70:130] = 2
    desks = np.zeros(seg.shape, dtype=bool)
    desks[40:60, 55:85] = True
    seg[desks] = 0
    return seg, desks


def test_pieces_only_furniture_separates_join_when_together_they_are_room_shaped() -> None:
    seg, desks = _office_cut_round_a_desk_cluster()
    out = join_furnished_groups(seg, desks)
    assert out[20, 30] == out[80, 110] > 0
    assert np.array_equal(out > 0, seg > 0)
    assert join_furnished_groups(seg, np.zeros_like(desks)).max() == 2  # no furniture: nothing joins


def test_a_doorway_between_walls_keeps_its_pieces_apart_whatever_stands_beside_it() -> None:
    seg, desks = _office_cut_round_a_desk_cluster()
    doors = np.zeros(seg.shape, dtype=bool)
    doors[10:40, 69:71] = True  # the upper cut is a doorway from wall to wall
    out = join_furnished_groups(seg, desks, doors=doors)
    assert out[20, 30] != out[20, 110]


def test_an_office_linked_to_a_corridor_by_furniture_at_its_door_does_not_take_the_corridor() -> None:
    """The office above the left end of a 12 m corridor, open onto it, a chair on the border: a T, not a room."""
    seg = np.zeros((120, 260), dtype=np.int32)
    seg[10:90, 10:70] = 1
    seg[10:90, 70:130] = 2
    seg[90:110, 10:250] = 3
    desks = np.zeros(seg.shape, dtype=bool)
    desks[40:60, 55:85] = True
    desks[86:94, 30:36] = True  # a chair on the office's border with the corridor
    seg[desks] = 0
    out = join_furnished_groups(seg, desks)
    assert out[100, 200] not in (out[20, 30], out[20, 110])
    assert join_furnished_groups(seg, desks, fixed=np.array([False, True, True, True])).max() == 3

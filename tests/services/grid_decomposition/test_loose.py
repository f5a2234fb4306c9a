"""Pieces of one fan of rays that touch nothing join; a room seen alone takes the dots of its rays round it; a dot
between two rays of one region is that region's."""

from __future__ import annotations

import numpy as np

from services.grid_decomposition.loose import (
    _touching,
    fill_between,
    fill_enclosed,
    fill_lone_regions,
    fill_near,
    give_far_pieces,
    join_and_fill_loose,
    join_isolated_pieces,
    join_ray_pieces,
)


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


def test_a_room_seen_alone_takes_the_dots_of_its_rays_and_a_room_with_neighbours_does_not() -> None:
    seg = np.zeros((60, 90), dtype=np.int32)
    occupied = np.zeros(seg.shape, dtype=bool)
    seg[10:30, 10:20] = 1  # a room of rays seen alone: unknown all round it
    seg[10:30, 50:60] = 2  # two rooms side by side
    seg[10:30, 60:70] = 3
    occupied[:, 26] = True  # a wall beside the lone room
    dots = np.zeros(seg.shape, dtype=bool)
    dots[20, 21:26:2] = True  # the lone room's ray dots, up to the wall (within 0.5 m, 10 cells)
    dots[20, 28] = True  # one behind the wall
    dots[35, 12:19:3] = True  # below it
    dots[35, 52:59:3] = True  # below room 2
    out = fill_lone_regions(seg, (seg > 0) | dots, occupied, reach_px=10, min_area_px=50)
    assert np.all(out[20, 21:26:2] == 1) and np.all(out[35, 12:19:3] == 1)
    assert out[20, 28] == 0  # behind the wall
    assert np.all(out[35, 52:59:3] == 0)  # rooms with neighbours take no dots
    assert np.array_equal(out[~dots], seg[~dots])


def test_a_dot_between_two_rays_of_one_fan_is_its_floor_and_one_beyond_the_fan_is_not() -> None:
    seg = np.zeros((60, 80), dtype=np.int32)
    occupied = np.zeros(seg.shape, dtype=bool)
    seg[5:25, 5:30] = 1  # a room with a neighbour (so it is no room seen alone)
    seg[5:25, 30:50] = 2
    rr = np.arange(25, 55)
    seg[rr, 10 + (rr - 25) // 6] = 1  # two rays of room 1's fan, spreading downwards, unknown between them
    seg[rr, 20 + (rr - 25) // 6] = 1
    dots = np.zeros(seg.shape, dtype=bool)
    dots[30, 15] = dots[40, 17] = True  # dots of a third ray between them (4-7 cells from each)
    dots[40, 35] = dots[50, 40] = True  # dots of a ray below room 2, flanked by nothing
    dots[40, 2] = True  # a dot left of the fan: room 1 on one side only
    dots[45, 60] = True  # a dot between two rays of room 1 ...
    seg[42:48, 55] = 1
    seg[42:48, 65] = 1
    occupied[45, 62] = True  # ... with an obstacle between
    out = fill_between(seg, (seg > 0) | dots, occupied, reach_px=10, floor=(seg > 0) | dots)
    assert out[30, 15] == 1 and out[40, 17] == 1
    assert out[40, 35] == 0 and out[50, 40] == 0 and out[40, 2] == 0
    assert out[45, 60] == 0
    assert np.array_equal(out[~dots], seg[~dots])


def test_a_dot_between_two_parts_of_a_pocket_a_region_covers_off_its_floor_is_not_its() -> None:
    """A pocket of unseen space the furniture fill gave region 1 (its cells off the floor) on both sides of a dot:
    no floor of region 1 flanks it; its floor on both sides does."""
    seg = np.zeros((20, 40), dtype=np.int32)
    seg[:, :15] = 1
    seg[:, 22:] = 1
    dots = np.zeros(seg.shape, dtype=bool)
    dots[10, 18] = True
    floor = dots.copy()
    floor[:, :5] = floor[:, 32:] = True  # region 1's floor beyond its pocket, out of reach
    occupied = np.zeros(seg.shape, dtype=bool)
    assert fill_between(seg, floor, occupied, reach_px=10, floor=floor)[10, 18] == 0
    assert fill_between(seg, floor, occupied, reach_px=10, floor=(seg > 0) | dots)[10, 18] == 1


def test_a_dot_between_two_regions_is_neither_s() -> None:
    seg = np.zeros((20, 40), dtype=np.int32)
    seg[:, :15] = 1
    seg[:, 22:] = 2
    dots = np.zeros(seg.shape, dtype=bool)
    dots[10, 18] = True
    out = fill_between(seg, (seg > 0) | dots, np.zeros(seg.shape, dtype=bool), reach_px=10, floor=(seg > 0) | dots)
    assert out[10, 18] == 0


def test_joining_and_filling_at_once_is_the_two_steps_in_turn() -> None:
    """Pieces of a fan that join (the regions found anew after) and scenes where none join (found once)."""
    rng = np.random.default_rng(0)
    for gap in (0, 3, 6):
        seg = np.zeros((60, 90), dtype=np.int32)
        seg[10:30, 10:20] = 1  # a room seen alone
        seg[40:55, 10:13] = 2  # rays of a fan, ``gap`` cells apart
        seg[40:55, 13 + gap : 16 + gap] = 3
        seg[10:30, 50:60] = 4  # two rooms side by side
        seg[10:30, 60:70] = 5
        occupied = rng.random(seg.shape) < 0.01
        free = (seg > 0) | (rng.random(seg.shape) < 0.05) & ~occupied
        kwargs = {"max_area_px": 100, "gap_px": 6}
        expected = fill_lone_regions(join_isolated_pieces(seg, occupied, **kwargs), free, occupied, reach_px=10,
                                     min_area_px=50)
        got = join_and_fill_loose(seg, free, occupied, reach_px=10, min_area_px=50, **kwargs)
        assert np.array_equal(got, expected)


def test_touching_flags_every_region_with_an_8_neighbour_of_another() -> None:
    rng = np.random.default_rng(1)
    seg = rng.integers(0, 12, (30, 40)).astype(np.int32) * (rng.random((30, 40)) < 0.3)
    padded = np.pad(seg, 1)
    expected = np.zeros(12, dtype=bool)
    for r, c in zip(*np.nonzero(seg), strict=True):
        around = padded[r : r + 3, c : c + 3]
        expected[seg[r, c]] |= bool(np.any((around > 0) & (around != seg[r, c])))
    assert np.array_equal(_touching(seg, 12), expected)


def _room_behind_a_door() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A corridor (region 1) below a room whose region (2) is a fan by its door; walls left, right and on top."""
    seg = np.zeros((70, 60), dtype=np.int32)
    occupied = np.zeros(seg.shape, dtype=bool)
    doorways = np.zeros(seg.shape, dtype=bool)
    seg[50:62, 2:58] = 1  # the corridor
    occupied[10:50, 10] = occupied[10:50, 50] = occupied[10, 10:51] = True  # the room's walls
    occupied[49, 10:51] = True  # its wall on the corridor, with a door
    occupied[49, 25:35] = False
    doorways[49, 25:35] = True
    seg[40:49, 22:38] = 2  # the floor seen through the door: 9 x 16 cells
    return seg, occupied, doorways, np.zeros(seg.shape, dtype=bool)


def test_the_dots_beyond_a_fan_inside_the_room_s_walls_are_its_floor_and_those_beyond_its_wall_are_not() -> None:
    seg, occupied, doorways, dots = _room_behind_a_door()
    dots[33, 30] = dots[36, 24] = True  # ray dots beyond the fan's end, inside the walls (4-7 cells)
    dots[5, 30] = True  # beyond the top wall, within reach of nothing
    dots[30, 53] = True  # beyond the right wall, next to it
    seg[28:34, 53:56] = 0
    out = fill_enclosed(seg, (seg > 0) | dots, occupied, doorways, reach_px=20, enclosed_px=100, min_area_px=20,
                         floor=(seg > 0) | dots)
    assert out[33, 30] == 2 and out[36, 24] == 2
    assert out[5, 30] == 0 and out[30, 53] == 0
    assert np.array_equal(out[~dots], seg[~dots])


def test_a_dot_takes_the_floor_it_meets_before_a_pocket_another_region_covers_and_the_pocket_when_alone() -> None:
    seg, occupied, doorways, dots = _room_behind_a_door()
    seg[30:39, 12:23] = 1  # a pocket of unseen space in the room that the corridor's label covers, off the floor
    floor = (seg == 2) | (seg == 1) & ~((np.arange(70)[:, None] < 40) & (np.arange(60)[None, :] < 23))
    dots[36, 24] = True  # the pocket 2 cells left, the room's fan 4 cells below
    dots[27, 14] = True  # the pocket 3 cells below, walls the other ways: no floor in reach
    floor |= dots
    out = fill_enclosed(seg, floor, occupied, doorways, reach_px=20, enclosed_px=100, min_area_px=20, floor=floor)
    assert out[36, 24] == 2
    assert out[27, 14] == 1
    assert np.array_equal(out[~dots], seg[~dots])


def test_a_dot_the_region_reaches_only_round_a_corner_or_a_speck_reaches_is_not_taken() -> None:
    seg, occupied, doorways, dots = _room_behind_a_door()
    dots[38, 40] = True  # diagonal to the fan's corner: the ways along its row and column meet walls, not the fan
    seg[20:23, 15:18] = 3  # a speck of 9 cells in the room's corner
    dots[21, 19] = True  # next to the speck, out of the fan's reach
    out = fill_enclosed(seg, (seg > 0) | dots, occupied, doorways, reach_px=4, enclosed_px=100, min_area_px=20,
                         floor=(seg > 0) | dots)
    assert out[38, 40] == 0
    assert out[21, 19] == 0
    assert np.array_equal(out, seg)


def test_a_dot_in_a_room_behind_a_doorway_line_is_not_the_corridor_s() -> None:
    seg, occupied, doorways, dots = _room_behind_a_door()
    seg[40:49, 22:38] = 0  # the room not seen at all: only the corridor
    dots[45, 30] = True  # a dot in the room, 5 cells above the corridor through the door
    out = fill_enclosed(seg, (seg > 0) | dots, occupied, doorways, reach_px=20, enclosed_px=100, min_area_px=20,
                         floor=(seg > 0) | dots)
    assert out[45, 30] == 0


def test_dots_beside_a_fan_inside_the_room_s_walls_are_its_floor_and_dots_through_its_window_are_not() -> None:
    seg = np.zeros((60, 80), dtype=np.int32)
    occupied = np.zeros(seg.shape, dtype=bool)
    occupied[10, 10:51] = occupied[50, 10:51] = occupied[10:51, 10] = occupied[10:51, 50] = True  # outer walls
    occupied[26:34, 50] = False  # a window in the right wall
    seg[25:35, 20:48] = 1  # the room's floor seen: a fan towards the window
    dots = np.zeros(seg.shape, dtype=bool)
    dots[22, 49] = dots[37, 49] = True  # beside the fan's end, off its rows and columns, inside the walls
    dots[30, 53] = dots[28, 55] = True  # rays through the window, outside the building, as near the fan
    free = (seg > 0) | dots
    doorways = np.zeros(seg.shape, dtype=bool)
    assert np.array_equal(  # no region in line with the dots beside the fan: the line fill leaves them
        fill_enclosed(seg, free, occupied, doorways, reach_px=6, enclosed_px=100, min_area_px=20, floor=free), seg
    )
    out = fill_near(seg, free, occupied, doorways, reach_px=6, enclosed_px=100, min_area_px=20)
    assert out[22, 49] == 1 and out[37, 49] == 1
    assert out[30, 53] == 0 and out[28, 55] == 0  # one way of four closed (the fan, back through the window)
    assert np.array_equal(out[~dots], seg[~dots])


def test_a_dot_inside_walls_is_not_reached_through_a_doorway_line_nor_by_a_speck() -> None:
    seg, occupied, doorways, dots = _room_behind_a_door()
    seg[40:49, 22:38] = 0  # the room not seen at all: only the corridor below its door
    dots[46, 24] = True  # in the room, 3 cells above the doorway line, beside the door
    seg[20:23, 15:18] = 3  # a speck of 9 cells in the room's corner
    dots[24, 19] = True  # beside the speck
    out = fill_near(seg, (seg > 0) | dots, occupied, doorways, reach_px=8, enclosed_px=100, min_area_px=20)
    assert np.array_equal(out, seg)


def _corridor_dots_in_a_room() -> tuple[np.ndarray, np.ndarray]:
    """A corridor (1) along the top, a wall below it with a door, a room (2) behind; dots of the corridor's label
    deep in the room (far from the corridor) and just below the door (near it)."""
    seg = np.zeros((40, 60), dtype=np.int32)
    occupied = np.zeros(seg.shape, dtype=bool)
    seg[0:8, :] = 1
    occupied[9, :] = True
    occupied[9, 28:32] = False  # the door
    seg[10:40, 0:60] = 2
    seg[30:32, 40:43] = 1  # dots 21 rows below the corridor
    seg[11, 29] = 1  # a dot just inside the door
    seg[10, 28:32] = 0
    return seg, occupied


def test_a_piece_of_a_region_far_from_its_body_is_the_room_s_that_reaches_it_and_a_near_one_is_not() -> None:
    seg, occupied = _corridor_dots_in_a_room()
    out = give_far_pieces(seg, occupied, np.zeros_like(occupied), far_px=10, reach_px=20)
    assert (out[30:32, 40:43] == 2).all()
    assert out[11, 29] == 1
    assert (out[seg != 1] == seg[seg != 1]).all() and (out[0:8] == 1).all()


def test_a_far_piece_on_rack_places_keeps_its_region() -> None:
    seg, occupied = _corridor_dots_in_a_room()
    places = np.zeros_like(occupied)
    places[30:32, 40:43] = True
    out = give_far_pieces(seg, occupied, places, far_px=10, reach_px=20)
    assert (out == seg).all()


def _room_and_its_rays() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A room's floor (1) and, beside it, a piece of rays (2) the lines parted from it; no wall between them."""
    seg = np.zeros((40, 40), dtype=np.int32)
    seg[5:35, 2:20] = 1
    seg[5:35, 20:30] = 2
    rays = np.zeros(seg.shape, dtype=bool)
    rays[5:35, 20:30] = True
    occupied = np.zeros(seg.shape, dtype=bool)
    occupied[0, :31] = occupied[39, :31] = True  # walls 5 cells off the border's ends
    occupied[:, 0] = True
    return seg, occupied, rays


def test_a_region_of_rays_joins_the_region_whose_border_with_it_the_laser_saw_through() -> None:
    seg, occupied, rays = _room_and_its_rays()
    joinable = np.ones(3, dtype=bool)
    out = join_ray_pieces(seg, occupied, rays, joinable, seen_px=3, min_border_px=5)
    assert len(np.unique(out[seg > 0])) == 1 and (out[seg == 0] == 0).all()
    # a region of floor, a region off the rooms' floors, or a jamb at the border keep theirs
    assert join_ray_pieces(seg, occupied, np.zeros_like(rays), joinable, seen_px=3, min_border_px=5).max() == 2
    assert join_ray_pieces(seg, occupied, rays, np.array([True, True, False]), seen_px=3, min_border_px=5).max() == 2
    jamb = occupied.copy()
    jamb[20, 19] = True
    assert join_ray_pieces(seg, jamb, rays, joinable, seen_px=3, min_border_px=5).max() == 2


def test_rays_seen_through_a_door_keep_their_region() -> None:
    seg, occupied, rays = _room_and_its_rays()
    occupied[:29, 20] = True  # a wall between them, a door 0.3 m wide at its foot: the rays beyond it
    seg[occupied] = 0
    assert join_ray_pieces(seg, occupied, rays, np.ones(3, dtype=bool), seen_px=3, min_border_px=5).max() == 2

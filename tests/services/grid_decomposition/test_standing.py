"""A border wider than a door that ends on an obstacle standing free on the floor parts nothing: its sides join;
a border between walls, beside a piece of wall between two doors, or ending where the laser saw nothing stays."""

from __future__ import annotations

import numpy as np

from services.grid_decomposition.standing import join_across_open_lines, join_free_standing_ends, seen_walls

RES = 0.05
ROOMS = np.ones(4, dtype=bool)  # every segment a room's region


def _room_parted_at_a_bench(bench: slice = slice(100, 130)) -> tuple[np.ndarray, ...]:
    """A 6 x 9.5 m room walled by hit cells, parted across at row 70 into an upper and a lower segment; a bench
    (1.5 m of hit cells) stands free on the floor on that row, 4.5 m from the left wall and 3.5 m from the right:
    segments, free cells, occupied cells and the wall evidence along the lines (the room's walls)."""
    occupied = np.zeros((140, 215), dtype=bool)
    occupied[8:132, 8:10] = occupied[8:132, 200:202] = True
    occupied[8:10, 8:202] = occupied[130:132, 8:202] = True
    free = np.zeros(occupied.shape, dtype=bool)
    free[10:130, 10:200] = True
    wall = occupied.copy()
    occupied[70, bench] = True
    free[70, bench] = False
    seg = np.zeros(occupied.shape, dtype=np.int32)
    seg[10:70, 10:200] = 1
    seg[70:130, 10:200] = 2
    seg[~free] = 0
    return seg, free, occupied, wall


def test_a_border_ending_on_a_free_standing_bench_is_one_room() -> None:
    seg, free, occupied, wall = _room_parted_at_a_bench()
    out = join_free_standing_ends(seg, free, occupied, wall, resolution_m=RES, joinable=ROOMS)
    assert out[40, 50] == out[100, 50] > 0
    assert np.array_equal(out > 0, seg > 0)
    floor = np.array([False, False, True])  # a warehouse floor (or a piece too small for a room) never joins
    assert join_free_standing_ends(seg, free, occupied, wall, resolution_m=RES, joinable=floor).max() == 2


def test_a_piece_of_wall_between_two_doors_keeps_its_sides_apart() -> None:
    """The same bench in line with a wall that runs on 2 m beyond it either way (two doorways beside it)."""
    seg, free, occupied, wall = _room_parted_at_a_bench()
    for run in (slice(10, 60), slice(170, 200)):
        occupied[69:71, run] = wall[69:71, run] = True
        free[69:71, run] = False
    seg[~free] = 0
    assert join_free_standing_ends(seg, free, occupied, wall, resolution_m=RES, joinable=ROOMS).max() == 2


def test_a_border_ending_on_a_wall_or_where_the_laser_saw_nothing_stays() -> None:
    seg, free, occupied, wall = _room_parted_at_a_bench()
    attached = occupied.copy()
    attached[70, 10:100] = True  # the bench is a wall stub from the left wall: an end on a seen wall
    stub_wall = wall | attached & ~occupied
    free_attached = free & ~attached
    assert join_free_standing_ends(
        np.where(free_attached, seg, 0), free_attached, attached, stub_wall, resolution_m=RES, joinable=ROOMS
    ).max() == 2
    unseen = occupied.copy()
    unseen[70, 100:130] = False  # the bench is unknown space: a jamb the laser never hit
    assert join_free_standing_ends(seg, free, unseen, wall, resolution_m=RES, joinable=ROOMS).max() == 2


def test_a_border_no_wider_than_a_door_stays() -> None:
    """A 1.5 m wide room parted at a free-standing post: the border is a door's width."""
    seg, free, occupied, wall = _room_parted_at_a_bench()
    narrow = np.zeros(seg.shape, dtype=bool)
    narrow[10:130, 10:40] = True
    occupied[70, 10:200] = False
    occupied[70, 24:27] = True  # a post in the middle
    free = narrow & ~occupied
    out = join_free_standing_ends(np.where(free, seg, 0), free, occupied, wall, resolution_m=RES, joinable=ROOMS)
    assert out.max() == 2


def test_seen_walls_are_hits_along_lines_or_faces_of_solid_obstacle() -> None:
    free = np.ones((80, 80), dtype=bool)
    occupied = np.zeros(free.shape, dtype=bool)
    free[10:14, 5:75] = False  # a grey (unknown) band 0.2 m thick: free space on one side of each face only
    free[40, 5:75] = False  # a one-pixel stripe of unknown between two rays: free on both sides
    occupied[60, 5:75] = True  # hit cells along a line
    free[60, 5:75] = False
    wall = ~free
    seen = seen_walls(free, occupied, wall, min_length_px=20)
    assert seen[10, 30] and seen[13, 30]
    assert not seen[40].any()
    assert seen[60, 30]
    short = seen_walls(free, occupied, wall, min_length_px=100)  # no wall that long
    assert not short.any()


def test_an_obstacle_beside_a_seen_wall_is_that_wall_s_end() -> None:
    """A post (0.45 m) on the border 0.2 m from a seen wall's end (not in its line): a jamb, not a bench."""
    seg, free, occupied, wall = _room_parted_at_a_bench(slice(0, 0))
    occupied[66:75, 100:102] = True
    occupied[63:65, 105:141] = wall[63:65, 105:141] = True
    free &= ~occupied
    seg[~free] = 0
    assert join_free_standing_ends(seg, free, occupied, wall, resolution_m=RES, joinable=ROOMS).max() == 2
    occupied[63:65, 105:141] = wall[63:65, 105:141] = False  # the same post alone on the floor
    free[63:65, 105:141] = True
    seg[63:65, 105:141] = 1
    out = join_free_standing_ends(seg, free, occupied, wall, resolution_m=RES, joinable=ROOMS)
    assert out[40, 50] == out[100, 50] > 0


def test_a_bench_on_another_region_s_floor_keeps_the_sides_apart() -> None:
    """The floor round the bench is a third region's (a strip the two sides do not hold)."""
    seg, free, occupied, wall = _room_parted_at_a_bench()
    seg[68:73, 98:133] = 3
    seg[~free] = 0
    assert join_free_standing_ends(seg, free, occupied, wall, resolution_m=RES, joinable=ROOMS).max() == 3


def _cut_room(crossed_row: int) -> tuple[np.ndarray, np.ndarray]:
    """A 6 x 9.5 m room's floor (5 cm pixels) cut across at row 70 into two segments, and a line across open floor
    (a gap ``wall_evidence`` left open: no doors side by side) along ``crossed_row`` over the room's width."""
    seg = np.zeros((140, 215), dtype=np.int32)
    seg[10:70, 10:200] = 1
    seg[70:130, 10:200] = 2
    crossed = np.zeros(seg.shape, dtype=bool)
    crossed[crossed_row - 1 : crossed_row + 2, 10:200] = True
    return seg, crossed


def test_a_cut_along_a_line_across_open_floor_is_no_border() -> None:
    """The room stage's cut 0.4 m beside the line: within the depth the floor was found not to widen, one room."""
    seg, crossed = _cut_room(78)
    out = join_across_open_lines(seg, crossed, joinable=ROOMS, min_border_px=10, reach_px=20)
    assert out.max() == 1 and np.array_equal(out > 0, seg > 0)
    floor = np.array([False, False, True])  # a warehouse floor never joins
    assert join_across_open_lines(seg, crossed, joinable=floor, min_border_px=10, reach_px=20).max() == 2


def test_a_cut_beyond_the_judged_depth_or_mostly_off_the_line_stays() -> None:
    seg, crossed = _cut_room(100)  # 1.5 m off the line: beyond the 1 m judged
    assert join_across_open_lines(seg, crossed, joinable=ROOMS, min_border_px=10, reach_px=20).max() == 2
    seg, crossed = _cut_room(72)
    crossed[:, 60:] = False  # the line spans 2.5 m of the 9.5 m border: most of the border is elsewhere
    assert join_across_open_lines(seg, crossed, joinable=ROOMS, min_border_px=10, reach_px=20).max() == 2
    seg, crossed = _cut_room(72)
    assert join_across_open_lines(seg, np.zeros_like(crossed), joinable=ROOMS, min_border_px=10, reach_px=20).max() == 2

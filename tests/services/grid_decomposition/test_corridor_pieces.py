"""A corridor the room stage cut in pieces is one region again; the rooms that leaked into it part from it."""

from __future__ import annotations

import math

import numpy as np

from services.grid_decomposition.corridor_pieces import join_corridor_pieces
from services.grid_decomposition.radiogram import Line

RESOLUTION_M = 0.05


def _corridor_with_open_room() -> tuple[np.ndarray, list[Line]]:
    """Segments of a 33 m x 2.5 m corridor (rows 100..149) and a 5 m x 5 m room above it (rows 152..250,
    columns 300..399) open onto the corridor over its whole width, as a room stage cut them: the corridor in
    three pieces, the middle one holding the room's lower half too. Walls are the pixels in no region; the
    lines are the walls' (as the decomposition's line search finds them)."""
    segments = np.zeros((260, 700), dtype=np.int32)
    segments[100:150, 20:300] = 1
    segments[100:150, 300:400] = 2
    segments[150:200, 300:400] = 2  # the room's lower half leaked into the corridor's piece, no wall drawn
    segments[200:251, 300:400] = 3
    segments[100:150, 400:680] = 4
    horizontal = [Line(0.0, float(y), 30.0, 0.1, True) for y in (99, 150, 251)]
    vertical = [Line(math.pi / 2, -float(x), 5.0, 0.1, True) for x in (299, 400)]
    return segments, horizontal + vertical


def test_a_corridor_cut_in_pieces_is_one_region_and_the_room_open_onto_it_is_not_in_it() -> None:
    segments, lines = _corridor_with_open_room()
    out, _ = join_corridor_pieces(segments, lines, np.ones(5, dtype=bool), resolution_m=RESOLUTION_M)
    corridor = np.unique(out[101:149, 21:679])
    assert corridor.size == 1 and corridor[0] > 0, "the corridor is one region from end to end"
    room = np.unique(out[155:245, 305:395])
    assert corridor[0] not in room, "the room open onto the corridor does not leak into it"
    assert np.array_equal(out > 0, segments > 0), "every pixel stays in a region"


def test_regions_that_may_not_join_are_left_alone() -> None:
    segments, lines = _corridor_with_open_room()
    out, _ = join_corridor_pieces(segments, lines, np.zeros(5, dtype=bool), resolution_m=RESOLUTION_M)
    assert np.array_equal(out, segments)


def test_an_aisle_beside_a_row_of_desks_in_an_open_office_stays_in_the_office() -> None:
    # a 20 m x 8 m office, one region, with a 1.5 m aisle along its lower wall beside a row of desks (pairs of
    # 1.6 m desks with 0.8 m gaps): the aisle is a walled band, but a small part of the office's region
    segments = np.zeros((180, 420), dtype=np.int32)
    segments[10:170, 10:410] = 1
    for x in range(20, 400, 48):
        segments[40:56, x : x + 32] = 0  # a desk
    lines = [Line(0.0, float(y), 20.0, 0.1, True) for y in (9, 40, 56, 170)]
    lines += [Line(math.pi / 2, -float(x), 8.0, 0.1, True) for x in (9, 410)]
    out, _ = join_corridor_pieces(segments, lines, np.ones(2, dtype=bool), resolution_m=RESOLUTION_M)
    assert np.array_equal(out, segments)


def test_a_corridor_entering_a_hall_does_not_cut_the_hall() -> None:
    # a 20 m x 2 m corridor (rows 100..139, columns 20..419) in two pieces, entering a 12 m x 10 m hall (rows
    # 20..219, columns 420..659): the corridor's lines go on across the hall, whose floor is clear between them
    segments = np.zeros((240, 680), dtype=np.int32)
    segments[100:140, 20:220] = 1
    segments[100:140, 220:420] = 2
    segments[20:220, 420:660] = 3
    lines = [Line(0.0, float(y), 20.0, 0.1, True) for y in (19, 99, 140, 220)]
    lines += [Line(math.pi / 2, -float(x), 10.0, 0.1, True) for x in (19, 419, 660)]
    out, _ = join_corridor_pieces(segments, lines, np.ones(4, dtype=bool), resolution_m=RESOLUTION_M)
    corridor = np.unique(out[101:139, 21:419])
    assert corridor.size == 1, "the corridor is one region"
    hall = np.unique(out[21:219, 425:659])
    assert hall.size == 1 and hall[0] != corridor[0], "the hall is one region of its own"


def test_an_l_shaped_corridor_stays_one_region() -> None:
    # a 30 m x 2.4 m corridor (rows 100..147, columns 20..619) turning down into a 12 m x 2.8 m arm (rows
    # 148..387, columns 564..619) at its end, one region, with a 5 m x 5 m room open onto it (rows 0..99,
    # columns 200..299)
    segments = np.zeros((400, 640), dtype=np.int32)
    segments[100:148, 20:620] = 1
    segments[148:388, 564:620] = 1
    segments[0:100, 200:300] = 1
    lines = [Line(0.0, float(y), 20.0, 0.1, True) for y in (99, 148, 388)]
    lines += [Line(math.pi / 2, -float(x), 10.0, 0.1, True) for x in (19, 199, 300, 563, 620)]
    out, _ = join_corridor_pieces(segments, lines, np.ones(2, dtype=bool), resolution_m=RESOLUTION_M)
    corridor = np.unique(np.r_[out[101:147, 21:619].ravel(), out[149:387, 565:619].ravel()])
    assert corridor.size == 1, "both arms of the corridor are one region"
    room = np.unique(out[5:95, 205:295])
    assert room.size == 1 and room[0] != corridor[0], "the room open onto it is a region of its own"


def test_a_hall_open_along_the_corridor_keeps_the_corridor_in_front_of_it() -> None:
    # a 40 m x 2 m corridor (rows 100..139) in two pieces; along its middle an 8 m x 8 m hall (rows 140..299,
    # columns 300..459) lies open onto it, and the room stage gave the hall the corridor's stretch in front of it
    segments = np.zeros((320, 840), dtype=np.int32)
    segments[100:140, 20:300] = 1
    segments[100:140, 460:820] = 2
    segments[100:300, 300:460] = 3
    lines = [Line(0.0, float(y), 20.0, 0.1, True) for y in (99, 140, 300)]
    lines += [Line(math.pi / 2, -float(x), 10.0, 0.1, True) for x in (19, 299, 460, 820)]
    out, _ = join_corridor_pieces(segments, lines, np.ones(4, dtype=bool), resolution_m=RESOLUTION_M)
    assert np.array_equal(out == out[200, 380], segments == 3), "the hall stays as it was, with its front"


def _corridor_end_beside_an_arm() -> tuple[np.ndarray, list[Line]]:
    """Segments of a 33 m x 2 m corridor (rows 100..139, columns 20..679) whose left end (columns 20..79) meets a
    3 m arm going up (rows 0..99), as a room stage cut them: the arm with the corridor's end, and the rest of the
    corridor. Along its first 7 m the lower wall stands 0.3 m further out (the wall of the room below it, rows
    140..145 free, no line of its own found) than further on."""
    segments = np.zeros((170, 700), dtype=np.int32)
    segments[0:100, 20:80] = 1
    segments[100:146, 20:160] = 1
    segments[100:140, 160:680] = 2
    lines = [Line(0.0, float(y), 30.0, 0.1, True) for y in (99, 140)]
    lines += [Line(math.pi / 2, -float(x), 5.0, 0.1, True) for x in (19, 80, 680)]
    return segments, lines


def test_a_corridor_runs_on_to_its_end_where_one_wall_steps_back_a_little() -> None:
    segments, lines = _corridor_end_beside_an_arm()
    out, _ = join_corridor_pieces(segments, lines, np.ones(3, dtype=bool), resolution_m=RESOLUTION_M)
    corridor = np.unique(out[101:139, 21:679])
    assert corridor.size == 1, "the corridor is one region up to its end below the arm"
    arm = np.unique(out[5:95, 25:75])
    assert arm.size == 1 and arm[0] != corridor[0], "the arm is a region of its own"
    out, _ = join_corridor_pieces(segments, lines, np.ones(3, dtype=bool), resolution_m=RESOLUTION_M, wall_step_m=0)
    assert out[120, 50] == out[50, 50], "without the step the corridor's end, open on both sides, is the arm's"


def _corridor_with_lobby() -> tuple[np.ndarray, list[Line]]:
    """Segments of a 33 m x 2 m corridor (rows 100..139, columns 20..679) widening below its middle into an 8 m x
    2.25 m lobby (rows 140..184, columns 300..459, a post on its front at columns 378..381) in front of two rooms
    (rows 185..280, their walls drawn), as a room stage cut them: the corridor in three pieces, the middle one
    holding the lobby too."""
    segments = np.zeros((300, 700), dtype=np.int32)
    segments[100:140, 20:200] = 1
    segments[100:140, 200:600] = 2
    segments[140:185, 300:460] = 2
    segments[140:146, 378:382] = 0  # the post
    segments[100:140, 600:680] = 3
    segments[190:280, 300:378] = 4
    segments[190:280, 382:460] = 5
    segments[185:190, 320:360] = 4  # their doors
    segments[185:190, 400:440] = 5
    lines = [Line(0.0, float(y), 30.0, 0.1, True) for y in (99, 140, 185, 280)]
    lines += [Line(math.pi / 2, -float(x), 5.0, 0.1, True) for x in (19, 299, 380, 460, 680)]
    return segments, lines


def test_a_lobby_along_the_corridor_in_front_of_doors_is_the_corridors() -> None:
    segments, lines = _corridor_with_lobby()
    out, _ = join_corridor_pieces(segments, lines, np.ones(6, dtype=bool), resolution_m=RESOLUTION_M)
    corridor = np.unique(out[101:139, 21:679])
    assert corridor.size == 1, "the corridor is one region"
    assert np.all(out[147:184, 301:459] == corridor[0]), "the lobby no deeper than a third of its front is in it"
    out, _ = join_corridor_pieces(segments, lines, np.ones(6, dtype=bool), resolution_m=RESOLUTION_M,
                               room_min_depth_ratio=0)
    assert out[160, 380] != out[120, 380], "taken for a room, the lobby is a region of its own"


def _corridor_with_rooms_open_onto_a_widening() -> tuple[np.ndarray, list[Line]]:
    """A 33 m x 2 m corridor (rows 100..139, columns 20..679) widening below its middle by 2.1 m over 5.5 m (rows
    140..181, columns 300..409) into two rooms (rows 182..280) open onto it over their whole width: no wall drawn
    between the widening and the rooms, only the partition between them (columns 353..356), which stops 0.75 m
    short of the corridor's wall line; as a room stage cut them, the corridor in three pieces, the middle one holding
    the widening."""
    segments = np.zeros((300, 700), dtype=np.int32)
    segments[100:140, 20:200] = 1
    segments[100:140, 200:600] = 2
    segments[140:182, 300:410] = 2
    segments[100:140, 600:680] = 3
    segments[182:280, 300:353] = 4
    segments[182:280, 357:410] = 5
    segments[155:280, 353:357] = 0  # the partition's end
    lines = [Line(0.0, float(y), 30.0, 0.1, True) for y in (99, 140, 280)]
    lines += [Line(math.pi / 2, -float(x), 5.0, 0.1, True) for x in (19, 299, 355, 410, 680)]
    return segments, lines


def test_the_floor_beyond_a_wall_step_open_onto_rooms_is_their_mouth_not_the_corridors() -> None:
    segments, lines = _corridor_with_rooms_open_onto_a_widening()
    out, _ = join_corridor_pieces(segments, lines, np.ones(6, dtype=bool), resolution_m=RESOLUTION_M)
    corridor = np.unique(out[101:139, 21:679])
    assert corridor.size == 1, "the corridor is one region"
    assert np.all(out[141:153, 301:409] == corridor[0]), "up to a wall's step beyond its line the floor is its"
    assert np.all(out[160:182, 301:345] == out[200, 320]), "further out, the left room's mouth is the left room's"
    assert np.all(out[160:182, 365:409] == out[200, 390]), "and the right room's the right room's"
    out, _ = join_corridor_pieces(segments, lines, np.ones(6, dtype=bool), resolution_m=RESOLUTION_M,
                                  past_wall_line_to_rooms=False)
    assert np.all(out[141:182, 301:353] == corridor[0]), "without the rule the whole widening is the corridor's"


def _corridor_with_a_room_cut_behind_its_door(depth_px: int) -> tuple[np.ndarray, list[Line]]:
    """A 33 m x 2 m corridor (rows 100..139, columns 20..679) in three pieces, its upper wall drawn (rows 97..99)
    but for a 2 m door (columns 300..339) into a 7.5 m x 3.85 m room above (rows 20..96, columns 250..399); the
    room stage cut the room along the furniture ``depth_px`` beyond the corridor's wall line, so the middle piece
    holds the door and the room's floor behind it up to there."""
    segments = np.zeros((160, 700), dtype=np.int32)
    segments[100:140, 20:200] = 1
    segments[100:140, 200:600] = 2
    segments[100:140, 600:680] = 3
    segments[20:97, 250:400] = 5
    segments[100 - depth_px : 100, 300:340] = 2  # the door, and the room's floor behind it cut with the corridor
    lines = [Line(0.0, float(y), 30.0, 0.1, True) for y in (19, 99, 140)]
    lines += [Line(math.pi / 2, -float(x), 5.0, 0.1, True) for x in (19, 249, 400, 680)]
    return segments, lines


def test_the_floor_behind_a_door_cut_with_the_corridor_is_the_rooms() -> None:
    segments, lines = _corridor_with_a_room_cut_behind_its_door(14)
    out, _ = join_corridor_pieces(segments, lines, np.ones(6, dtype=bool), resolution_m=RESOLUTION_M)
    corridor = np.unique(out[101:139, 21:679])
    assert corridor.size == 1, "the corridor is one region"
    assert np.all(out[86:99, 300:340] == out[50, 320]), "the room's floor 0.7 m past the wall line is the room's"
    out, _ = join_corridor_pieces(segments, lines, np.ones(6, dtype=bool), resolution_m=RESOLUTION_M,
                                  past_wall_line_to_rooms=False)
    assert np.all(out[86:100, 300:340] == corridor[0]), "without the rule it joins the corridor"


def test_a_doorway_no_deeper_than_its_wall_stays_the_corridors() -> None:
    segments, lines = _corridor_with_a_room_cut_behind_its_door(3)
    out, _ = join_corridor_pieces(segments, lines, np.ones(6, dtype=bool), resolution_m=RESOLUTION_M)
    assert np.all(out[97:100, 300:340] == out[120, 320]), "the doorway in the wall's thickness is the corridor's"
    out, _ = join_corridor_pieces(segments, lines, np.ones(6, dtype=bool), resolution_m=RESOLUTION_M,
                                  doorway_depth_m=0)
    assert np.all(out[97:99, 300:340] == out[50, 320]), "taken for the room's floor, it goes to the room"


def _corridor_end_with_small_room() -> tuple[np.ndarray, list[Line]]:
    """A 34 m x 2 m corridor (rows 100..139, columns 20..699) whose west half is in a hall's region (a 10 m x 10 m
    hall below its west end, rows 140..339, columns 20..219, open onto it), its east end a region of its own that
    also holds a 1.6 m x 2 m room above it (rows 60..99, columns 560..591) seen through a gap in the corridor's
    upper wall, and a 3 m x 0.4 m niche in that wall (rows 92..99, columns 440..499)."""
    segments = np.zeros((360, 720), dtype=np.int32)
    segments[100:140, 20:420] = 1
    segments[140:340, 20:220] = 1
    segments[100:140, 420:700] = 2
    segments[60:100, 560:592] = 2
    segments[92:100, 440:500] = 2
    lines = [Line(0.0, float(y), 30.0, 0.1, True) for y in (59, 99, 140, 340)]
    lines += [Line(math.pi / 2, -float(x), 10.0, 0.1, True) for x in (19, 219, 699)]
    return segments, lines


def test_a_small_room_seen_through_a_gap_in_the_corridor_wall_parts_from_the_corridor_end() -> None:
    segments, lines = _corridor_end_with_small_room()
    out, first = join_corridor_pieces(
        segments, lines, np.ones(3, dtype=bool), resolution_m=RESOLUTION_M, beyond_min_area_m2=1.5
    )
    room = np.unique(out[62:98, 562:590])
    corridor = np.unique(out[102:138, 430:690])
    assert room.size == 1 and corridor.size == 1 and room[0] != corridor[0], "the room is a region of its own"
    assert room[0] >= first, "numbered as a room seen beyond the corridor's wall"
    assert np.all(out[93:99, 442:498] == corridor[0]), "the shallow niche is the corridor widening"
    assert np.array_equal(out > 0, segments > 0), "every pixel stays in a region"


def test_without_the_rule_the_small_room_stays_in_the_corridor_end() -> None:
    segments, lines = _corridor_end_with_small_room()
    out, _ = join_corridor_pieces(segments, lines, np.ones(3, dtype=bool), resolution_m=RESOLUTION_M)
    assert np.unique(out[62:138, 562:590]).size == 1

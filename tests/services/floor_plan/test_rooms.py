"""The room level: units joined through open boundaries are one room; a door or a wall keeps rooms apart."""

from __future__ import annotations

import cv2
import numpy as np
import numpy.typing as npt

from services.floor_plan import CellClass, Rect, RoomSettings, UnitType, World, group_rooms, room_keys
from services.floor_plan.rooms import (
    FurnitureSettings,
    cut_off_free,
    fill_free,
    furniture,
    furniture_insides,
    furniture_pockets,
    furniture_reach,
    join_insides,
    label_furniture,
    wall_fringe,
)

RES = 0.05
T = 2  # wall cells


def _walled(shape: tuple[int, int], *rooms: Rect) -> npt.NDArray[np.uint8]:
    """Unknown space with walled rooms: each rectangle's border band (two cells) wall, its inside free."""
    classes = np.full(shape, CellClass.UNKNOWN, np.uint8)
    for r in rooms:
        classes[r.r0 : r.r1 + 1, r.c0 : r.c1 + 1] = CellClass.WALL
    for r in rooms:
        classes[r.r0 + T : r.r1 - T + 1, r.c0 + T : r.c1 - T + 1] = CellClass.FREE
    return classes


def _rooms(world: World, classes: npt.NDArray[np.uint8]) -> list[tuple[int, ...]]:
    types = dict.fromkeys(world.units, UnitType.ROOM)
    return [room.units for room in group_rooms(world, classes, types, wall_cells=T, resolution_m=RES,
                                               settings=RoomSettings())]


def test_an_l_shaped_room_made_of_two_units_is_one_room() -> None:
    leg, foot = Rect(0, 59, 0, 29), Rect(30, 59, 28, 89)  # they share the wall at columns 28-29
    classes = _walled((70, 100), leg, foot)
    classes[32:58, 26:30] = CellClass.FREE  # no wall where the leg meets the foot
    world = World({1: leg, 2: foot}, set(), 3)
    assert _rooms(world, classes) == [(1, 2)]


def test_a_corridor_with_a_bend_made_of_two_units_is_one_room() -> None:
    along, down = Rect(0, 29, 0, 99), Rect(28, 99, 70, 99)  # 1.2 m wide corridor turning down at its end
    classes = _walled((110, 110), along, down)
    classes[26:32, 72:98] = CellClass.FREE
    world = World({1: along, 2: down}, set(), 3)
    assert _rooms(world, classes) == [(1, 2)]


def _two_rooms_with_a_door() -> npt.NDArray[np.uint8]:
    classes = _walled((60, 80), Rect(0, 59, 0, 39), Rect(0, 59, 38, 79))
    classes[22:38, 38:40] = CellClass.FREE  # a 0.8 m door in the 2.8 m wall between them
    return classes


def test_two_rooms_through_a_door_are_two_rooms() -> None:
    world = World({1: Rect(0, 59, 0, 39), 2: Rect(0, 59, 38, 79)}, {Rect(22, 37, 38, 39)}, 3)
    assert _rooms(world, _two_rooms_with_a_door()) == [(1,), (2,)]


def test_a_unit_standing_over_a_wall_with_a_door_is_cut_into_two_rooms() -> None:
    world = World({1: Rect(0, 59, 0, 79)}, set(), 2)  # one unit explains both rooms
    groups = group_rooms(world, _two_rooms_with_a_door(), {1: UnitType.ROOM}, wall_cells=T, resolution_m=RES,
                         settings=RoomSettings())
    assert len(groups) == 2 and all(room.units == (1,) for room in groups)
    lefts = sorted(part.c1 for room in groups for part in room.parts)
    assert lefts[0] < 38 < lefts[1], "the cut runs along the wall"
    assert room_keys(groups) == ["r1", "r1.1"]


def test_speckle_and_clutter_in_a_room_do_not_cut_it_or_close_its_boundaries() -> None:
    rng = np.random.default_rng(3)
    big = Rect(0, 79, 0, 119)
    classes = _walled((80, 120), big)
    inside = classes == CellClass.FREE
    speckle = inside & (rng.random(classes.shape) < 0.08)  # single unknown cells, as real maps have
    classes[speckle] = CellClass.UNKNOWN
    classes[40, 20] = classes[41, 21] = CellClass.WALL  # a clutter dot
    world = World({1: Rect(0, 79, 0, 61), 2: Rect(0, 79, 60, 119)}, set(), 3)  # one room as two units
    assert _rooms(world, classes) == [(1, 2)]


def test_fill_free_gives_unexplained_free_cells_the_label_nearest_through_free_space() -> None:
    free = np.zeros((5, 12), bool)
    free[1:4, 1:11] = True
    free[1:3, 6] = False  # a wall with a gap at row 3
    free[1:4, 9] = False  # a full wall: the last column is cut off
    labels = np.zeros(free.shape, np.int32)
    labels[1, 1] = 7
    labels[1, 7] = 9
    out = fill_free(labels, free)
    assert out[2, 3] == 7 and out[1, 8] == 9 and out[3, 6] == 9
    assert (out[1:4, 10] == 0).all(), "free space no label reaches stays unlabelled"
    assert not out[~free].any()


def test_a_slanted_wall_between_two_rooms_keeps_them_apart() -> None:
    classes = _walled((64, 100), Rect(0, 63, 0, 99))
    cv2.line(classes, (44, 2), (52, 61), int(CellClass.WALL), 1)  # one cell thick, leaning 8 cells over 3 m
    world = World({1: Rect(0, 63, 0, 49), 2: Rect(0, 63, 47, 99)}, set(), 3)  # their free spaces 1 cell apart
    assert _rooms(world, classes) == [(1,), (2,)]
    classes[2:62, 2:98] = CellClass.FREE  # without the wall: one room
    assert _rooms(world, classes) == [(1, 2)]


def _hall_with_a_corridor(corridor: Rect) -> tuple[World, npt.NDArray[np.uint8]]:
    """An 8 m square hall and a 1.2 m wide, 6 m long corridor running off its right side, open over its whole
    width (no wall, no door where it meets the hall); the corridor unit is ``corridor``."""
    hall = Rect(0, 159, 0, 159)
    classes = _walled((160, 280), hall, Rect(40, 65, 158, 279))
    classes[42:64, 156:162] = CellClass.FREE
    return World({1: hall, 2: corridor}, set(), 3), classes


def test_a_corridor_opening_into_a_hall_is_not_part_of_the_hall() -> None:
    world, classes = _hall_with_a_corridor(Rect(40, 65, 158, 279))  # the two units share the wall at 158-159
    assert _rooms(world, classes) == [(1,), (2,)]


def test_a_corridor_unit_reaching_into_the_hall_is_still_a_room_of_its_own() -> None:
    world, classes = _hall_with_a_corridor(Rect(40, 65, 140, 279))  # its rectangle stands 1 m into the hall
    assert _rooms(world, classes) == [(1,), (2,)]


def test_corridor_ends_can_be_turned_off() -> None:
    world, classes = _hall_with_a_corridor(Rect(40, 65, 158, 279))
    groups = group_rooms(world, classes, dict.fromkeys(world.units, UnitType.ROOM), wall_cells=T, resolution_m=RES,
                         settings=RoomSettings(corridor_length_ratio=None))
    assert [room.units for room in groups] == [(1, 2)]


def _room_with_a_sliver() -> tuple[World, npt.NDArray[np.uint8]]:
    """A 3 m room and a 0.3 m x 1 m sliver unit beside it, half walled off (a unit the chain put in a recess)."""
    room, sliver = Rect(0, 59, 0, 59), Rect(10, 33, 58, 67)
    classes = _walled((60, 70), room, sliver)
    classes[12:22, 58:60] = CellClass.FREE  # 0.5 m of the 1 m between them open
    return World({1: room, 2: sliver}, set(), 3), classes


def test_a_sliver_of_a_room_too_small_to_be_one_joins_its_neighbour() -> None:
    world, classes = _room_with_a_sliver()
    assert _rooms(world, classes) == [(1, 2)]


def test_small_rooms_stay_apart_when_the_setting_is_off() -> None:
    world, classes = _room_with_a_sliver()
    groups = group_rooms(world, classes, dict.fromkeys(world.units, UnitType.ROOM), wall_cells=T, resolution_m=RES,
                         settings=RoomSettings(min_room_m2=None))
    assert [room.units for room in groups] == [(1,), (2,)]


def test_the_wall_fringe_of_a_live_map_is_the_less_seen_free_space_against_a_wall_only() -> None:
    occ = np.full((30, 40), 12, np.int8)  # a live map: its clearest free cells read the clamp, 12 %
    occ[:, :2] = 100  # a wall
    occ[:, 2:4] = 18  # seen free fewer times against it
    occ[10:15, 20:25] = 18  # the same, in the open
    occ[20:25, 4:6] = 18  # joined to the wall only through the fringe, 3 and 4 cells from it
    fringe = wall_fringe(occ, occ <= 25, depth_cells=3)
    assert fringe[:, 2:4].all()
    assert not fringe[10:15, 20:25].any(), "less seen floor away from walls is floor"
    assert fringe[20:25, 4].all() and not fringe[20:25, 5].any(), "no deeper than the setting"
    assert not fringe[occ == 12].any() and not fringe[occ == 100].any()
    occ[5:7, 30:32] = 100  # a chair leg
    occ[4:8, 29:33][occ[4:8, 29:33] == 12] = 18  # seen free less often around it
    assert not wall_fringe(occ, occ <= 25, depth_cells=3, min_wall_cells=20)[4:8, 29:33].any(), "furniture is no wall"
    assert wall_fringe(occ, occ <= 25, depth_cells=3, min_wall_cells=20)[:, 2:4].all()


def test_the_inside_of_a_cupboard_drawn_against_a_wall_is_floor_not_fringe() -> None:
    occ = np.zeros((40, 50), np.int8)  # an image's room: clear free cells read 0 %
    occ[:, :2] = occ[:2, :] = occ[:, 48:] = 100  # walls
    occ[2:10, 2:22] = 100  # a cupboard against the walls, drawn as a dark outline ...
    occ[4:8, 4:20] = 18  # ... filled light grey: free, not clearly free
    occ[35:40, 2:48] = -1  # a wall drawn grey, with dark edges ...
    occ[[35, 37], 2:48] = 100
    occ[36, 2:48] = 18  # ... and a light line along it, one cell wide
    free = (occ >= 0) & (occ <= 25)
    fringe = wall_fringe(occ, free, depth_cells=2, inside_max_cells=600)
    assert not fringe[4:8, 4:20].any(), "the cupboard's inside is the room's floor"
    assert fringe[36, 2:48].all(), "the light line inside the grey wall is no furniture's inside"
    assert wall_fringe(occ, free, depth_cells=2)[4:8, 4:20].all(), "without the rule: an edge of the walls"
    assert wall_fringe(occ, free, depth_cells=2, inside_max_cells=50)[4:8, 4:20].all(), "larger: not furniture"


def test_a_cupboards_inside_that_is_a_room_of_its_own_joins_the_room_it_stands_in() -> None:
    free = np.ones((30, 60), np.bool_)
    free[:, [0, 29, 59]] = free[[0, 29], :] = False  # two offices side by side
    free[1:9, 1:13] = False  # a cupboard against the first office's walls ...
    free[3:7, 3:11] = True  # ... whose inside the map shows free
    labels = np.zeros(free.shape, np.int32)
    labels[1:29, 1:29], labels[1:29, 30:59] = 1, 2
    labels[3:7, 3:11] = 3  # the world explains the inside as a room of its own
    labels[~free] = 0
    inside = furniture_insides(free, max_cells=100, min_depth_cells=2)
    assert inside[3:7, 3:11].all() and inside.sum() == 32, "the enclosed free space, nothing else"
    joined = join_insides(labels, furniture_reach(inside, ~free, reach_cells=10))
    assert (joined[3:7, 3:11] == 1).all(), "the office the cupboard stands in"
    assert (joined[labels != 3] == labels[labels != 3]).all()
    labels[3:7, 3:11] = 1
    labels[10:12, 3:6] = 3  # the inside's label holds other cells too: a room, not an inside
    labels[3:7, 3:11] = 3
    assert (join_insides(labels, furniture_reach(inside, ~free, reach_cells=10)) == labels).all()


def test_a_corridor_a_unit_stands_over_stays_one_room_across_the_offices_cross_wall() -> None:
    # one unit explains four offices and the 1 m corridor between them; the 0.5 m wall between the offices
    # cuts the unit across the corridor too, which runs on open through it
    unit = Rect(0, 99, 0, 119)
    classes = _walled((100, 120), unit)
    classes[:, 48:50] = classes[:, 70:72] = CellClass.WALL  # the corridor's sides
    classes[45:55, :50] = classes[45:55, 70:] = CellClass.WALL  # the offices' cross wall
    classes[[0, 1, 98, 99], :] = CellClass.WALL
    classes[:, [0, 1, 118, 119]] = CellClass.WALL
    groups = group_rooms(World({1: unit}, set(), 2), classes, {1: UnitType.ROOM}, wall_cells=T, resolution_m=RES,
                         settings=RoomSettings())
    assert len(groups) == 5, "four offices and the corridor"
    corridor = [room for room in groups if all(p.c0 >= 50 and p.c1 <= 69 for p in room.parts)]
    assert len(corridor) == 1 and len(corridor[0].parts) == 2, "the corridor's two parts are one room"
    assert min(p.r0 for p in corridor[0].parts) < 45 and max(p.r1 for p in corridor[0].parts) > 54


def test_a_corridor_unit_over_the_thick_wall_at_its_side_is_not_cut_into_door_wide_pieces() -> None:
    # a 1.2 m corridor between thick walls (0.5 m below, 0.3 m above), each with a 0.9 m door into a room; the
    # corridor's unit covers 5 cells of the wall below and 2 of the wall above, so each column through both walls is
    # 7 / 31 wall, as much as a cross wall with a door in it; the corridor must not be cut at the doors' jambs into a
    # door-wide piece open over its whole width to the room behind the door
    classes = np.full((120, 120), CellClass.WALL, np.uint8)
    classes[2:32, 50:100] = CellClass.FREE  # the room below
    classes[32:42, 66:84] = CellClass.FREE  # its door
    classes[42:66, 2:118] = CellClass.FREE  # the corridor
    classes[66:72, 30:48] = CellClass.FREE  # the door of the room above
    classes[72:110, 20:60] = CellClass.FREE  # the room above
    world = World({1: Rect(35, 69, 0, 119), 2: Rect(0, 33, 48, 101), 3: Rect(70, 111, 18, 61)}, set(), 4)
    assert _rooms(world, classes) == [(1,), (2,), (3,)]


def test_furniture_in_a_room_takes_its_label_and_a_dotted_wall_stays_unlabelled() -> None:
    classes = _walled((60, 100), Rect(0, 59, 0, 99))
    classes[2:58, 50] = CellClass.FREE  # a dotted wall across the room: dots of 2 cells, gaps of 3
    for r in range(2, 58, 5):
        classes[r : r + 2, 50] = CellClass.WALL
    classes[20:32, 15:27] = CellClass.WALL  # a 0.6 m x 0.6 m desk in the left room
    classes[40:43, 70:73] = CellClass.WALL  # a bin in the right room
    blocked = classes != CellClass.FREE
    found = furniture(blocked, resolution_m=RES, settings=FurnitureSettings())
    assert found[25, 20] and found[41, 71], "the desk and the bin are furniture"
    assert not found[2:58, 50].any(), "a dotted wall's dots are no furniture"
    assert not found[0].any(), "nor is the room's wall"
    labels = np.zeros(classes.shape, np.int32)
    labels[2:58, 2:50] = 1
    labels[2:58, 51:98] = 2
    labels[~(classes == CellClass.FREE)] = 0
    out = label_furniture(labels, found)
    assert (out[20:32, 15:27] == 1).all() and (out[40:43, 70:73] == 2).all()
    assert (out[classes == CellClass.FREE] == labels[classes == CellClass.FREE]).all()


def _two_rooms_parted_by_a_grey_cored_wall() -> npt.NDArray[np.uint8]:
    """A building of two rooms in unseen outside, parted by a wall drawn with two black faces and a grey core 0.2 m
    thick between them (columns 59-62)."""
    classes = np.full((80, 120), CellClass.UNKNOWN, np.uint8)  # the unseen outside
    classes[5:75, 5:115] = CellClass.WALL
    classes[7:73, 7:113] = CellClass.FREE  # a building of two rooms ...
    classes[7:73, 58:64] = CellClass.WALL  # ... parted by a wall drawn with two black faces ...
    classes[7:73, 59:63] = CellClass.UNKNOWN  # ... and a grey core 0.2 m thick between them
    return classes


def test_furniture_drawn_unknown_against_a_wall_takes_its_room_and_a_walls_grey_core_does_not() -> None:
    classes = _two_rooms_parted_by_a_grey_cored_wall()
    classes[7:17, 10:40] = CellClass.UNKNOWN  # a 0.5 m x 1.5 m cupboard drawn grey against the top wall
    classes[62:73, 70:92] = CellClass.WALL  # a cupboard drawn with a dark outline against the bottom wall ...
    classes[63:73, 71:91] = CellClass.UNKNOWN  # ... filled grey
    rows, cols = np.mgrid[0:80, 0:120]
    triangle = (rows >= 55) & (rows < 73) & (cols >= 7) & (cols < 25) & (rows - cols >= 48)
    classes[triangle] = CellClass.UNKNOWN  # unseen space where two walls meet at an angle
    traces = np.zeros(classes.shape, np.bool_)
    pockets = furniture_pockets(classes == CellClass.UNKNOWN, traces, resolution_m=RES, settings=FurnitureSettings())
    assert pockets[7:17, 10:40].all() and pockets[63:73, 71:91].all(), "both cupboards"
    assert not pockets[7:73, 59:63].any(), "the wall's grey core is long and thin: no furniture"
    assert not pockets[triangle].any(), "a triangle is no piece of furniture"
    assert not pockets[:5].any(), "the outside reaches the map's border"
    assert not furniture_pockets(classes == CellClass.UNKNOWN, traces, resolution_m=RES,
                                 settings=FurnitureSettings(pocket_max_m2=0.0)).any(), "0: none"
    labels = np.zeros(classes.shape, np.int32)
    labels[:, :58], labels[:, 64:] = 1, 2
    labels[classes != CellClass.FREE] = 0
    touched = label_furniture(labels, pockets)
    assert (touched[7:17, 10:40] == 1).all(), "the grey cupboard touches its office"
    assert (touched[63:73, 71:91] == 0).all(), "the outlined one touches no room ..."
    near = label_furniture(touched, pockets & (touched == 0), reach_cells=3)
    assert (near[63:73, 71:91] == 2).all(), "... but lies within reach of one"
    assert (near[7:73, 59:63] == 0).all() and (near[triangle] == 0).all()


def test_a_piece_between_two_rooms_takes_no_label() -> None:
    labels = np.zeros((20, 20), np.int32)
    labels[:, :9] = 1
    labels[:, 11:] = 2
    piece = np.zeros((20, 20), np.bool_)
    piece[8:12, 9:11] = True
    assert (label_furniture(labels, piece)[piece] == 0).all()


def test_a_cupboard_joined_to_a_walls_grey_core_is_furniture_and_a_stub_of_that_wall_is_not() -> None:
    classes = _two_rooms_parted_by_a_grey_cored_wall()
    classes[20:40, 63:83] = CellClass.UNKNOWN  # a 1 m x 1 m cupboard drawn grey against it, one piece with its core
    classes[50:73, 56:66] = CellClass.WALL  # a stub of that wall 0.5 m thick above the bottom wall ...
    classes[50:73, 57:65] = CellClass.UNKNOWN  # ... its grey core one piece with the parting wall's
    traces = np.zeros(classes.shape, np.bool_)
    unknown = classes == CellClass.UNKNOWN
    pockets = furniture_pockets(unknown, traces, resolution_m=RES, settings=FurnitureSettings())
    assert pockets[20:40, 63:83].all(), "the cupboard comes apart from the wall's core"
    assert not pockets[50:73].any(), "a stub of wall 0.4 m thick is no furniture"
    assert not furniture_pockets(unknown, traces, resolution_m=RES,
                                 settings=FurnitureSettings(pocket_cut_thickness_m=None))[20:40, 63:83].any(), \
        "without the opening the cupboard is one piece with the wall's core"


def test_a_unit_standing_in_a_doorway_does_not_join_the_two_rooms() -> None:
    left, right = Rect(0, 59, 0, 39), Rect(0, 59, 38, 79)
    door = Rect(20, 39, 36, 41)  # its free inside is the 0.8 m door in the wall at columns 38-39
    world = World({1: left, 2: right, 3: door}, set(), 4)
    types = dict.fromkeys(world.units, UnitType.ROOM)

    def room_of(settings: RoomSettings) -> dict[int, int]:
        rooms = group_rooms(world, _two_rooms_with_a_door(), types, wall_cells=T, resolution_m=RES, settings=settings)
        return {u: k for k, room in enumerate(rooms) for u in room.units}

    assert room_of(RoomSettings())[1] != room_of(RoomSettings())[2]
    off = room_of(RoomSettings(doorway_max_m=None))
    assert off[1] == off[2] == off[3], "without the rule the doorway's unit joins both rooms"


def test_free_space_cut_off_from_its_room_by_a_cell_of_grey_takes_that_room() -> None:
    free = np.zeros((40, 60), bool)
    free[2:20, 2:30] = True  # a room
    free[2:20, 34:58] = True  # another room
    free[22:38, 10:18] = True  # a streak past the first room's wall, one cell of grey between them
    free[30:38, 31:33] = True  # a piece far from both rooms
    free[25, 45] = True  # a speck
    labels = np.zeros(free.shape, np.int32)
    labels[2:20, 2:30] = 1
    labels[2:20, 34:58] = 2
    labels[21, 10:18] = 0
    pieces = cut_off_free(labels, free, min_cells=10)
    assert pieces[22:38, 10:18].all() and not pieces[25, 45], "a speck smaller than min_cells is no piece"
    out = label_furniture(labels, pieces, reach_cells=3)
    assert (out[22:38, 10:18] == 1).all()
    assert (out[30:38, 31:33] == 0).all(), "a piece no room is near stays unlabelled"


def _corridor_above_two_offices_with_cupboards() -> tuple[World, npt.NDArray[np.uint8]]:
    """One unit over a 1.2 m corridor and the two offices below it, behind a 0.5 m wall with a 0.9 m door into each;
    in each office a 0.8 m deep cupboard (drawn in the unknown grey) stands against that wall beside the door."""
    classes = np.full((100, 124), CellClass.WALL, np.uint8)
    classes[70:94, 2:122] = CellClass.FREE  # the corridor
    classes[4:60, 2:60] = CellClass.FREE  # the left office
    classes[4:60, 64:122] = CellClass.FREE  # the right office
    classes[60:70, 20:38] = classes[60:70, 80:98] = CellClass.FREE  # the doors
    classes[44:60, 40:60] = classes[44:60, 100:122] = CellClass.UNKNOWN  # the cupboards
    return World({1: Rect(0, 97, 0, 123)}, set(), 2), classes


def test_a_unit_over_a_corridor_and_offices_is_cut_at_the_wall_the_offices_cupboards_stand_against() -> None:
    # the wall and the cupboards are one band of lines across the unit, 1.3 m thick: thicker than a wall, so without
    # its core the unit is not cut there and the corridor is one room with the offices behind its doors
    world, classes = _corridor_above_two_offices_with_cupboards()

    def corridor(settings: RoomSettings) -> tuple[Rect, ...]:
        groups = group_rooms(world, classes, {1: UnitType.ROOM}, wall_cells=T, resolution_m=RES, settings=settings)
        (room,) = [room for room in groups if any(p.r0 <= 80 <= p.r1 and p.c0 <= 10 for p in room.parts)]
        return room.parts

    assert all(p.r0 >= 60 for p in corridor(RoomSettings())), "the corridor is a room of its own"
    assert any(p.r0 < 44 for p in corridor(RoomSettings(cut_core_share=None))), "no core: one room with the offices"


def test_a_slanted_wall_across_a_unit_is_not_cut_at_its_densest_lines() -> None:
    # the side of a slanted wall running into a unit: each line across the unit is a little more wall than the one
    # before, one band 1.55 m thick that ramps up with no step into a core; no line of it is cut as a wall
    classes = np.full((60, 60), CellClass.FREE, np.uint8)
    for r in range(10, 41):
        classes[r, 2 : 14 + round(0.8 * (r - 10))] = CellClass.WALL
    classes[[0, 1, 58, 59], :] = classes[:, [0, 1, 58, 59]] = CellClass.WALL
    world = World({1: Rect(0, 59, 0, 59)}, set(), 2)

    def parts(settings: RoomSettings) -> list[tuple[Rect, ...]]:
        return [room.parts for room in group_rooms(world, classes, {1: UnitType.ROOM}, wall_cells=T, resolution_m=RES,
                                                   settings=settings)]

    assert parts(RoomSettings()) == parts(RoomSettings(cut_core_share=None))
    assert parts(RoomSettings(cut_core_step=1.0)) != parts(RoomSettings()), "without the step it would be cut"

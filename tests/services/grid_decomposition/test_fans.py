"""A room seen only through its door: a fan of rays off a hall is a region of its own."""

from __future__ import annotations

import numpy as np
from skimage.draw import line

from services.grid_decomposition import decompose
from services.grid_decomposition.change import unchanged_cells
from services.grid_decomposition.continuity import RegionPrior
from services.grid_decomposition.fans import split_fans

RESOLUTION_M = 0.05


def _hall_and_fan(door: tuple[int, int] = (130, 148)) -> tuple[np.ndarray, np.ndarray]:
    """Occupancy (-1 unknown, 0 free, 100 wall) of a 12 m x 5 m hall with a door in its top wall (columns ``door``,
    0.9 m by default), and the fan of laser rays a robot in the hall saw through the door into the small room
    behind it (2.5 m deep, 3.8 m wide, walls round it, unknown but for the rays)."""
    occ = np.full((200, 300), -1, dtype=np.int16)
    occ[20:122, 20:262] = 100
    occ[22:120, 22:260] = 0  # the hall, rows 22..119
    occ[120:122, door[0] : door[1]] = 0  # the door in its top wall
    occ[172:174, 100:176] = occ[122:174, [100, 101, 174, 175]] = 100  # the room's walls
    fan = np.zeros(occ.shape, dtype=bool)
    eye = (100, 139)  # the robot, 1 m below the door
    for end_col in range(60, 220, 3):  # rays to the room's far wall, 2.5 m behind the door
        rows, cols = line(*eye, 172, end_col)  # type: ignore[no-untyped-call]  # skimage is untyped
        # a ray passes the door and goes on into the room: above the wall only if it went through the gap
        through = (rows >= 120) & (rows <= 121)
        if not np.all((cols[through] >= door[0]) & (cols[through] < door[1])):
            continue
        beyond = (rows >= 122) & (rows < 172)
        occ[rows[beyond], cols[beyond]] = 0
        fan[rows[beyond], cols[beyond]] = True
    return occ, fan


def test_a_fan_of_rays_through_a_door_is_a_region_apart_from_the_hall() -> None:
    occ, fan = _hall_and_fan()
    assert fan.sum() * RESOLUTION_M**2 > 1.0  # a room's worth of rays
    segments = decompose(occ, resolution_m=RESOLUTION_M).segments
    hall = np.bincount(segments[50:100, 40:240].ravel()).argmax()
    on_fan = segments[fan & (segments > 0)]
    assert np.mean(on_fan != hall) > 0.8


def test_a_fan_of_rays_through_a_door_wider_than_the_fan_disc_is_a_region_apart_from_the_hall() -> None:
    """The same room behind a 1.5 m door: the 1.2 m disc passes it, and the room stayed the hall's."""
    occ, fan = _hall_and_fan(door=(124, 154))
    segments = decompose(occ, resolution_m=RESOLUTION_M).segments
    hall = np.bincount(segments[50:100, 40:240].ravel()).argmax()
    assert np.mean(segments[fan & (segments > 0)] != hall) > 0.8


def test_a_hall_without_rays_keeps_its_region_whole() -> None:
    occ, _ = _hall_and_fan()
    occ[occ == 0] = -1
    occ[22:120, 22:260] = 0
    occ[120:122, 130:148] = 0
    segments = decompose(occ, resolution_m=RESOLUTION_M).segments
    assert len(np.unique(segments[segments > 0])) == 1


def test_the_floor_right_behind_the_door_goes_with_the_room() -> None:
    """Where the robot saw the room through its door often, the rays near the door are floor as wide as the
    door (no doorway for the room stage: the space does not widen behind it): the room, that floor with it, is
    one region apart from the hall."""
    occ, fan = _hall_and_fan()
    occ[120:122, 128:150] = 0  # a 1.1 m door
    occ[122:146, 128:150] = 0  # 1.2 m deep of floor just behind it, as wide as the door
    fan[122:146, 128:150] = True
    segments = decompose(occ, resolution_m=RESOLUTION_M).segments
    hall = np.bincount(segments[50:100, 40:240].ravel()).argmax()
    on_fan = segments[fan & (segments > 0)]
    room = np.bincount(on_fan).argmax()
    assert room != hall and np.mean(on_fan == room) > 0.8
    assert np.mean(segments[124:144, 130:148] == room) > 0.8


def test_split_fans_parts_a_room_behind_a_neck_and_leaves_rays_out_of_the_building_and_floors_alone() -> None:
    segments = np.zeros((200, 300), dtype=np.int32)
    segments[22:120, 22:260] = 1
    segments[120:170, 134:146] = 1  # a bay 0.6 m wide and 2.5 m deep through the hall's top wall
    hall = np.zeros(segments.shape, dtype=bool)
    hall[[20, 121], 20:262] = hall[20:122, [20, 261]] = True
    room = hall.copy()
    room[170, 100:180] = room[120:170, [120, 160]] = True  # the walls of a room behind the opening
    none_fixed = np.zeros(2, dtype=bool)

    def split(occupied: np.ndarray, fixed: np.ndarray = none_fixed) -> np.ndarray:
        return split_fans(segments, occupied, fixed, resolution_m=RESOLUTION_M)

    fan = split(room)  # seen as rays or as floor: a room behind a 0.6 m neck
    assert len(np.unique(fan[130:170, 134:146])) == 1 and fan[150, 140] != 1
    assert np.array_equal(split(hall), segments)  # no walls beyond: rays out of the building
    assert np.array_equal(split(room, np.array([False, True])), segments)  # a warehouse floor


def test_a_beam_smaller_than_a_room_joins_the_room_it_touches_and_stands_alone_otherwise() -> None:
    """A bay 0.5 m wide and 2.5 m deep off the hall (1.25 m^2, under a room's least area of 1.5 m^2): beside another
    region along its side it is a beam of that region's room; touching nothing but the hall, a room of its own."""
    segments = np.zeros((200, 300), dtype=np.int32)
    segments[22:120, 22:260] = 1
    segments[120:170, 134:144] = 1
    occupied = np.zeros(segments.shape, dtype=bool)
    occupied[[20, 121], 20:262] = occupied[20:122, [20, 261]] = True
    occupied[170, 100:180] = occupied[120:170, [120, 160]] = True

    def split(beside: np.ndarray) -> np.ndarray:
        return split_fans(beside, occupied, np.zeros(3, dtype=bool), resolution_m=RESOLUTION_M, lobe_max_area_m2=1.5)

    alone = split(segments)
    assert len(np.unique(alone[125:170, 134:144])) == 1 and alone[150, 139] not in (0, 1)
    room = segments.copy()
    room[125:170, 144:159] = 2  # the rest of the room behind the opening, another region, along the bay's side
    lobe = split(room)
    assert np.all(lobe[125:170, 134:144] == 2)
    corner = segments.copy()
    corner[169:171, 144:159] = 2  # another region touching the bay at one corner only
    assert split(corner)[150, 139] not in (0, 1, 2)


def test_the_floor_inside_a_closet_door_goes_with_the_room_of_rays_beyond_it() -> None:
    """A closet as wide as its 1 m door: the floor 1.2 m deep just inside the door (dense, seen from the hall) is the
    hall's, and the closet beyond it another region. When that region is laser rays (a room seen only through its
    door) the floor inside the door is its floor; when it is dense floor (a room of its own the robot entered, a bay)
    the hall keeps it."""
    segments = np.zeros((200, 300), dtype=np.int32)
    segments[22:120, 22:260] = 1
    segments[120:144, 134:154] = 1  # the floor inside the door, 1 m wide and 1.2 m deep
    segments[144:184, 120:170] = 2  # the closet beyond it
    occupied = np.zeros(segments.shape, dtype=bool)
    occupied[[20, 120], 20:262] = occupied[20:122, [20, 261]] = True
    occupied[120:144, [133, 154]] = occupied[144:185, [119, 170]] = occupied[184, 119:171] = True
    occupied[120, 134:154] = False  # the door
    rays = np.zeros(segments.shape, dtype=bool)
    rays[144:184:2, 120:170] = True  # every other row of the closet: rays

    def split(thin: np.ndarray | None) -> np.ndarray:
        return split_fans(segments, occupied, np.zeros(3, dtype=bool), resolution_m=RESOLUTION_M, thin=thin,
                          lobe_max_area_m2=1.5)

    assert np.all(split(rays)[128:144, 134:154] == 2)
    assert np.array_equal(split(np.zeros(segments.shape, dtype=bool)), segments)  # a dense room: the hall's floor
    assert np.array_equal(split(None), segments)


def test_a_room_the_previous_decomposition_left_in_the_hall_parts_once_its_walls_are_seen() -> None:
    """A growing map: first the robot saw the rays through the door but none of the room's walls (they could be
    rays out of the building), so the room was the hall's; then it saw the walls, and nothing else changed. With the
    previous decomposition as the prior the hall keeps its unchanged cells, yet the room is a region of its own."""
    after, fan = _hall_and_fan()
    before = after.copy()
    before[172:174, 100:176] = before[122:174, [100, 101, 174, 175]] = -1  # the room's walls not seen yet
    first = decompose(before, resolution_m=RESOLUTION_M).segments
    hall = np.bincount(first[50:100, 40:240].ravel()).argmax()
    assert np.mean(first[fan] == hall) > 0.8  # no walls: the rays are the hall's
    unchanged = unchanged_cells(before, after, resolution_m=RESOLUTION_M)
    segments = decompose(after, resolution_m=RESOLUTION_M, prior=RegionPrior(first, unchanged)).segments
    hall = np.bincount(segments[50:100, 40:240].ravel()).argmax()
    on_fan = segments[fan & (segments > 0)]
    assert np.mean(on_fan != hall) > 0.8
    assert len(np.unique(segments[50:100, 40:240])) == 1  # the hall is one region as before


def test_a_room_loses_a_fan_of_rays_behind_its_door_but_not_its_own_floor_beyond_a_neck() -> None:
    """A 25 m² room (under the hall floor) with a 0.6 m opening in its top wall and a walled space 2.5 m deep behind
    it: the space is a room of its own when the robot saw it only as rays from inside the first room, and the first
    room's own alcove when it is dense floor."""
    segments = np.zeros((200, 300), dtype=np.int32)
    segments[22:120, 80:180] = 1
    segments[120:170, 124:136] = 1
    occupied = np.zeros(segments.shape, dtype=bool)
    occupied[[20, 121], 78:182] = occupied[20:122, [78, 181]] = True
    occupied[170, 100:160] = occupied[120:170, [100, 160]] = True
    rays = np.zeros(segments.shape, dtype=bool)
    rays[120:170, 124:136:2] = True  # every other column of the space behind the opening: laser rays

    def split(thin: np.ndarray | None) -> np.ndarray:
        return split_fans(segments, occupied, np.zeros(2, dtype=bool), resolution_m=RESOLUTION_M, thin=thin)

    fan = split(rays)
    assert len(np.unique(fan[130:170, 124:136])) == 1 and fan[150, 130] != 1
    assert np.all(fan[22:120, 80:180] == 1)
    assert np.array_equal(split(np.zeros(segments.shape, dtype=bool)), segments)  # the room's own floor
    assert np.array_equal(split(None), segments)  # without the rays only halls and corridors lose rooms


def test_a_room_of_rays_behind_a_door_wider_than_the_disc_parts_from_the_hall_at_the_door_line() -> None:
    """A 1.5 m door (wider than the 1.2 m disc, under the 2 m widest door) in a 12 m x 5 m hall's top wall, and a
    room 1.5 m wide and 2.5 m deep behind it, walled: the 1.2 m disc passes the door, so the room stays in the
    hall's core. Seen only as rays it is a room of its own with the wide disc, cut at the door's line (its floor
    by the door with it, the hall whole); as dense floor (a bay of the hall) it stays the hall's."""
    segments = np.zeros((200, 300), dtype=np.int32)
    segments[22:120, 22:260] = 1
    segments[120:170, 125:155] = 1  # the door and the room behind it, as wide as the door
    occupied = np.zeros(segments.shape, dtype=bool)
    occupied[20, 20:262] = occupied[20:122, [20, 261]] = True
    occupied[121, 20:125] = occupied[121, 155:262] = True  # the hall's top wall, with the door in it
    occupied[170, 123:157] = occupied[121:171, [123, 156]] = True  # the room's walls
    rays = np.zeros(segments.shape, dtype=bool)
    rays[120:170, 125:155:2] = True  # every other column of the room: laser rays through the door

    def split(thin: np.ndarray | None, wide_neck_m: float = 2.0) -> np.ndarray:
        return split_fans(segments, occupied, np.zeros(2, dtype=bool), resolution_m=RESOLUTION_M, thin=thin,
                          wide_neck_m=wide_neck_m)

    parted = split(rays)
    room = parted[150, 140]
    # the whole room from the door line: the wide disc bulges 0.35 m through the door, and that floor is the room's
    assert room != 1 and np.mean(parted[120:170, 125:155] == room) > 0.98
    assert np.all(parted[22:120, 22:260] == 1)  # the hall keeps all its floor
    assert np.array_equal(split(rays, wide_neck_m=0.0), segments)  # the 1.2 m disc alone passes the door
    assert np.array_equal(split(np.zeros(segments.shape, dtype=bool)), segments)  # dense floor: a bay of the hall


def test_a_room_whose_side_walls_the_laser_never_hit_parts_from_the_hall_it_is_seen_from() -> None:
    """A bay 0.6 m wide and 2.5 m deep off a 12.7 m hall, with only the room's far wall and the door's jambs hit (its
    side walls and the rest of the hall's wall unseen): a beam from the room's middle back through the door, or
    through the unseen wall into the hall, crosses the building, not the outside. Out of the building (no far wall)
    the rays stay the hall's."""
    segments = np.zeros((200, 300), dtype=np.int32)
    segments[22:120, 22:278] = 1
    segments[120:170, 134:146] = 1
    jambs = np.zeros(segments.shape, dtype=bool)
    jambs[120:122, 110:134] = jambs[120:122, 146:170] = True
    far_wall = jambs.copy()
    far_wall[170, 120:160] = True

    def split(occupied: np.ndarray) -> np.ndarray:
        return split_fans(segments, occupied, np.zeros(2, dtype=bool), resolution_m=RESOLUTION_M)

    room = split(far_wall)
    assert len(np.unique(room[125:170, 134:146])) == 1 and room[150, 140] != 1
    assert np.array_equal(split(jambs), segments)

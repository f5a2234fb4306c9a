"""Rooms: furniture is not a wall, doors split rooms, a corridor and its offices, warehouse floors untouched."""

from __future__ import annotations

import cv2
import numpy as np
import numpy.typing as npt

from services.grid_decomposition import Connection, decompose
from services.grid_decomposition.arrays import components
from services.grid_decomposition.rooms import (
    desk_clusters,
    ends_on_tables,
    free_standing,
    furniture,
    inside_furniture,
    join_furnished_pieces,
    segment_rooms,
)

RES = 0.05


def _office_row() -> np.ndarray:
    """12 x 7 m at 5 cm: a 2 m corridor along the bottom, three 4 x 4.5 m offices above it, each
    with a 0.9 m door from the corridor; 0.15 m walls, unknown outside."""
    occ = np.full((150, 250), -1, dtype=np.int8)
    occ[2:148, 2:248] = 100
    occ[5:145, 5:245] = 0
    occ[45:48, 5:245] = 100  # wall between the corridor (rows 5..44) and the offices
    for x in (85, 165):
        occ[48:145, x : x + 3] = 100
    for x0 in (30, 110, 190):
        occ[45:48, x0 : x0 + 18] = 0  # doors
    return occ


def _furnish(occ: np.ndarray) -> np.ndarray:
    """The offices of :func:`_office_row` with a table on four legs, chairs and a bin against a wall."""
    out = occ.copy()
    for x0 in (15, 95, 175):
        for dx, dy in ((0, 0), (30, 0), (0, 14), (30, 14)):  # table legs, 1.5 x 0.7 m table
            out[90 + dy : 92 + dy, x0 + 20 + dx : x0 + 22 + dx] = 100
        for dx in (18, 28, 38):  # chair legs in a row
            out[80:82, x0 + dx : x0 + dx + 2] = 100
            out[118:120, x0 + dx : x0 + dx + 2] = 100
        cv2.circle(out, (x0 + 55, 140), 5, 100, -1)  # a bin touching the back wall
    return out


def test_furniture_is_small_free_standing_obstacles_not_walls() -> None:
    occ = _furnish(_office_row())
    obstacle = occ != 0
    found = furniture(obstacle, resolution_m=RES)
    assert found[90, 35] and found[80, 33]  # a table leg, a chair leg
    assert not found[46, 60] and not found[100, 86]  # walls
    assert not found[140, 70]  # the bin touches a wall: part of it
    piece = np.zeros_like(obstacle)
    piece[60:62, 20:60] = True  # a 2 m free-standing piece of wall
    assert not furniture(piece, resolution_m=RES)[61, 40]
    dash = np.zeros_like(obstacle)
    dash[60:63, 20:34] = True  # a 0.7 m long, 0.15 m thick dash of a wall with many doors
    assert not furniture(dash, resolution_m=RES)[61, 25]


def test_a_desk_block_is_furniture_a_bent_or_long_piece_of_wall_is_not() -> None:
    canvas = np.zeros((120, 200), dtype=bool)
    desk = canvas.copy()
    desk[40:56, 40:72] = True  # 1.6 x 0.8 m, solid (a desk seen at its top's height)
    assert furniture(desk, resolution_m=RES)[48, 56]
    tee = canvas.copy()
    tee[40:43, 40:84] = True  # a T of 0.15 m walls, 2.2 x 1.9 m
    tee[43:78, 61:64] = True
    assert not furniture(tee, resolution_m=RES)[41, 50]
    pillar = canvas.copy()
    pillar[40:43, 40:84] = True  # a 2.2 m wall, a 0.5 m pillar on it
    cv2.circle(pillar.view(np.uint8), (62, 46), 5, 1, -1)
    assert not furniture(pillar, resolution_m=RES)[41, 45]
    slab = canvas.copy()
    slab[40:50, 40:100] = True  # 3 x 0.5 m: a thick piece of wall, not a desk
    assert not furniture(slab, resolution_m=RES)[45, 70]


def test_a_desk_cluster_is_found_wherever_its_room_lies_in_the_map() -> None:
    floor = np.zeros((120, 200), dtype=bool)
    floor[:, :120] = True  # a room reaching the map's top, left and bottom edges
    floor[50:66, 40:72] = False  # a 1.6 x 0.8 m desk block standing free in it
    floor[0:10, 100:110] = False  # a cupboard at the map's edge: not free-standing
    rule = {"max_extent_px": 60.0, "compact_from_px": 40.0, "max_elongation": 3.0, "min_thickness_px": 8.0}
    found = desk_clusters(~floor, **rule)
    assert found[58, 56] and found.sum() == 16 * 32
    framed = np.zeros((160, 260), dtype=bool)
    framed[20:140, 30:230] = floor  # the same room inside unknown space
    assert np.array_equal(desk_clusters(~framed, **rule)[20:140, 30:230], found)


def test_a_corridor_and_its_offices_are_one_region_each_linked_by_doors() -> None:
    d = decompose(_office_row(), resolution_m=RES)
    corridor = d.segments[25, 120]
    offices = [d.segments[100, 45], d.segments[100, 125], d.segments[100, 205]]
    assert corridor > 0 and len({corridor, *offices}) == 4
    assert set(np.unique(d.segments[5:45, 5:245]).tolist()) == {corridor}
    for office in offices:
        assert d.topology.edges[corridor, office]["connection"] == Connection.DOOR.value


def test_furniture_inside_rooms_does_not_split_them() -> None:
    plain = decompose(_office_row(), resolution_m=RES)
    furnished = _furnish(_office_row())
    d = decompose(furnished, resolution_m=RES)
    assert len(d.regions) == len(plain.regions) == 4
    for x in (45, 125, 205):
        office = d.segments[100, x]
        room = d.segments[48:145, x - 35 : x + 35]
        assert (room[furnished[48:145, x - 35 : x + 35] == 0] == office).all()
    legs = furniture(furnished != 0, resolution_m=RES)
    assert (d.segments[legs] > 0).all()  # a room's area is its floor plan, furniture included
    assert (d.labels[furnished != 0] == 0).all()  # labels stay on free space


def test_segment_rooms_leaves_warehouse_floors_alone() -> None:
    seg = np.zeros((40, 80), dtype=np.int32)
    seg[5:35, 5:40] = 1
    seg[5:35, 40:45] = 2  # a narrow sliver of a floor: a room piece would be merged
    seg[5:35, 45:75] = 3
    floor = np.zeros(seg.shape, dtype=bool)
    floor[5:35, 40:75] = True
    out, _ = segment_rooms(
        seg,
        np.zeros(seg.shape, dtype=bool),
        floor,
        np.zeros(seg.shape, dtype=bool),
        resolution_m=RES,
    )
    assert len(np.unique(out[5:35, 40:75])) == 2
    assert out[10, 42] != out[10, 60]


def test_a_cupboard_against_a_wall_is_in_its_rooms_segment_and_the_wall_is_not() -> None:
    from services.grid_decomposition.rooms import wall_furniture

    occ = np.full((100, 200), -1, dtype=np.int8)
    occ[10:90, 10:190] = 100
    occ[14:86, 14:186] = 0  # 8.6 m x 3.6 m inside 0.2 m walls
    occ[14:86, 98:102] = 100  # a 0.2 m wall between two rooms, a door in it
    occ[44:62, 98:102] = 0
    occ[20:36, 58:98] = 100  # a 2 m x 0.8 m cupboard against that wall, left room
    cupboard = np.zeros(occ.shape, dtype=bool)
    cupboard[20:36, 58:98] = True
    found = wall_furniture(occ != 0, resolution_m=0.05)
    assert found[24:32, 62:94].all()
    assert not found[70:86, 98:102].any() and not found[10:14, 20:180].any()  # walls are thin
    segments = decompose(occ, resolution_m=0.05).segments
    left = np.bincount(segments[20:80, 20:50].ravel()).argmax()
    assert left > 0 and (segments[cupboard] == left).mean() > 0.9
    assert not segments[10:13, :].any()  # the outer wall is in no segment


def _two_furnished_rooms() -> np.ndarray:
    """12 x 6 m at 5 cm: two 6 x 5.6 m rooms side by side joined by a 0.9 m door, each with two
    1.6 x 0.8 m desks (solid blocks, as a lidar at desk height sees them), a cabinet against the
    back wall and chairs; 0.15 m walls, unknown outside."""
    occ = np.full((130, 250), -1, dtype=np.int8)
    occ[2:128, 2:248] = 100
    occ[5:125, 5:245] = 0
    occ[5:125, 124:127] = 100  # the wall between the rooms
    occ[56:74, 124:127] = 0  # the door
    for x0 in (5, 127):
        for dx, dy in ((25, 30), (70, 75)):  # desks
            occ[dy : dy + 16, x0 + dx : x0 + dx + 32] = 100
        occ[105:125, x0 + 40 : x0 + 80] = 100  # a 2 x 1 m cabinet against the back wall
        for dx, dy in ((30, 50), (45, 50), (75, 95), (90, 95), (20, 10)):  # chairs, 0.3 m
            occ[dy : dy + 6, x0 + dx : x0 + dx + 6] = 100
    return occ


def test_two_furnished_rooms_joined_by_a_door_stay_two_rooms_each_in_one_piece() -> None:
    occ = _two_furnished_rooms()
    d = decompose(occ, resolution_m=RES)
    free = occ == 0
    left, right = free.copy(), free.copy()
    left[:, 124:] = False
    right[:, :127] = False
    ids_left = np.unique(d.segments[left])
    ids_right = np.unique(d.segments[right])
    assert ids_left.size == 1 and ids_right.size == 1  # each room one region, furniture or not
    assert ids_left[0] != ids_right[0]  # kept apart at their door
    assert len(d.regions) == 2


def _room_with_a_desk_cluster() -> np.ndarray:
    """7.2 x 5.2 m at 5 cm, 0.15 m walls, unknown outside; in its middle four desks in a cross
    (two 1.8 x 0.6 m bars), too large for furniture, 1.7-2.7 m of floor all round it."""
    occ = np.full((120, 160), -1, dtype=np.int8)
    occ[5:115, 5:155] = 100
    occ[8:112, 8:152] = 0
    occ[54:66, 62:98] = 100
    occ[42:78, 74:86] = 100
    return occ


def test_free_standing_obstacles_are_a_desk_cluster_not_a_wall_or_clutter_at_a_wall() -> None:
    occ = _room_with_a_desk_cluster()
    occ[30:36, 9:20] = 100  # a box 0.05 m from the left wall
    found = free_standing(occ != 0, resolution_m=RES)
    assert found[60, 80] and found[45, 80]  # the desk cluster
    assert not found[32, 15]  # too close to the wall: left to the walls
    assert not found[6, 80] and not found[60, 150]  # walls
    labelled = components(occ != 0)  # the obstacles labelled once, as decompose does: the same answer
    assert np.array_equal(free_standing(occ != 0, resolution_m=RES, labelled=labelled), found)
    assert np.array_equal(
        furniture(occ != 0, resolution_m=RES, labelled=labelled), furniture(occ != 0, resolution_m=RES)
    )


def test_a_room_with_a_desk_cluster_in_its_middle_is_one_segment() -> None:
    occ = _room_with_a_desk_cluster()
    free = occ == 0
    assert np.unique(decompose(occ, resolution_m=RES).segments[free]).size == 1
    # with the cluster as a wall, the lines along its desks close "doorways" to the walls (and without the
    # joining of what only furniture separates, which would make the pieces one room again)
    walled = decompose(occ, resolution_m=RES, island_max_extent_m=0.0, desk_max_extent_m=0.0).segments
    assert np.unique(walled[free]).size > 1


def _corridor_with_offices() -> tuple[np.ndarray, list[int], list[int]]:
    """20.3 x 6.5 m at 5 cm: a 1.6 m corridor along the bottom, four offices (4, 3.8, 3.8 and 1.8 m wide,
    4.5 m deep) above it and a 5.9 x 6.2 m hall at its right end through a 0.9 m door; 0.15 m walls,
    unknown all round. The offices' doors (0.9 m) are in the corridor's side wall right beside the
    partitions, two by two (one each side of a partition), as in a real office floor: beside a door
    the corridor seems to widen.

    Returns the map, the offices' middle columns and the corridor's rows."""
    occ = np.full((170, 446), -1, dtype=np.int8)
    occ[20:150, 20:426] = 100
    occ[23:55, 23:303] = 0  # the corridor, rows 23..54
    occ[58:147, 23:303] = 0  # the offices
    for x in (103, 183, 263):  # partitions
        occ[58:147, x : x + 3] = 100
    occ[23:147, 306:423] = 0  # the hall, 6 m wide, behind a 0.15 m wall
    occ[23:147, 303:306] = 100
    occ[30:48, 303:306] = 0  # the hall's 0.9 m door, narrower than the corridor
    for x in (81, 110, 241, 270):  # doors beside the partitions at 103 and 263
        occ[55:58, x : x + 18] = 0
    return occ, [63, 143, 223, 283], list(range(24, 54))


def test_a_corridor_is_not_cut_beside_the_doors_of_its_offices() -> None:
    occ, office_cols, corridor_rows = _corridor_with_offices()
    d = decompose(occ, resolution_m=RES)
    corridor = np.unique(d.segments[corridor_rows[0] : corridor_rows[-1] + 1, 25:301])
    assert corridor.size == 1 and corridor[0] > 0  # one region from end to end
    rooms = [int(d.segments[100, x]) for x in office_cols] + [int(d.segments[100, 360])]  # offices, hall
    assert len({int(corridor[0]), *rooms}) == len(rooms) + 1  # every office and the hall a region of their own
    for room in rooms:
        assert d.topology.edges[int(corridor[0]), room]["connection"] == Connection.DOOR.value
    # without the rule (and without joining a corridor's pieces) the lines along the partitions close the
    # corridor where its doors make it "widen"
    old = decompose(occ, resolution_m=RES, corridor_length_m=0.0, corridor_pieces=False)
    assert np.unique(old.segments[corridor_rows[0] : corridor_rows[-1] + 1, 25:301]).size > 1


def test_a_corridor_cut_beside_the_doors_of_its_offices_joins_again_and_its_offices_stay_apart() -> None:
    occ, office_cols, corridor_rows = _corridor_with_offices()
    # the room stage cuts the corridor (the rule above off): its pieces lie along one walled band and join
    d = decompose(occ, resolution_m=RES, corridor_length_m=0.0)
    corridor = np.unique(d.segments[corridor_rows[0] : corridor_rows[-1] + 1, 25:301])
    assert corridor.size == 1 and corridor[0] > 0
    rooms = [int(d.segments[100, x]) for x in office_cols] + [int(d.segments[100, 360])]
    assert len({int(corridor[0]), *rooms}) == len(rooms) + 1  # every office and the hall a region of their own


def _open_plan_office() -> np.ndarray:
    """29.2 x 5.5 m at 5 cm, 0.15 m walls, unknown outside: an open-plan office with three desk clusters
    (3.2 x 1.6 m of desks with four chairs along each long side: 3.2 x 2.4 m, too large to be
    furniture or a free-standing obstacle on their own) in a row down its middle, 1.15 m of floor
    between them and the walls, five cupboards (4 x 0.8 m) along the top wall; on the right a
    5.5 m office behind a 0.9 m door."""
    occ = np.full((126, 600), -1, dtype=np.int8)
    occ[5:121, 5:595] = 100
    occ[8:118, 8:592] = 0
    occ[8:118, 480:483] = 100  # the wall to the office
    occ[54:72, 480:483] = 0  # its door
    for x0 in (40, 160, 280):
        occ[47:79, x0 : x0 + 64] = 100  # desks
        for dx in range(4, 64, 16):  # chairs touching them
            occ[39:47, x0 + dx : x0 + dx + 8] = 100
            occ[79:87, x0 + dx : x0 + dx + 8] = 100
    for x0 in range(30, 470, 100):
        occ[8:24, x0 : x0 + 80] = 100  # cupboards against the top wall
    return occ


def test_an_open_plan_office_with_desk_clusters_is_one_room_and_the_office_behind_its_door_another() -> None:
    occ = _open_plan_office()
    free = occ == 0
    hall, office = free.copy(), free.copy()
    hall[:, 480:] = False
    office[:, :483] = False
    d = decompose(occ, resolution_m=RES)
    assert np.unique(d.segments[hall]).size == 1
    assert np.unique(d.segments[office]).size == 1
    assert d.segments[60, 300] != d.segments[60, 540]  # kept apart at their door
    # without joining what only furniture separates, the cuts from the clusters to the walls cut it up
    old = decompose(occ, resolution_m=RES, desk_max_extent_m=0.0)
    assert np.unique(old.segments[hall]).size > 1


def _two_rooms_and_a_table() -> np.ndarray:
    """9 x 4 m at 5 cm: room A (4.2 x 3.7 m) with a 1.5 x 1.5 m table standing 1.1 m from its walls, and
    room B beside it behind a 0.15 m wall with a 0.9 m door; unknown all round."""
    occ = np.full((100, 200), -1, dtype=np.int8)
    occ[10:90, 10:190] = 100
    occ[13:87, 13:97] = 0  # room A
    occ[13:87, 100:187] = 0  # room B
    occ[40:58, 97:100] = 0  # the door
    occ[35:65, 40:70] = 100  # the table
    return occ


def test_a_room_is_not_cut_at_the_gaps_beside_its_table_its_door_stays() -> None:
    occ = _two_rooms_and_a_table()
    free = occ == 0
    none = np.zeros(occ.shape, dtype=bool)

    def rooms(table_min_thickness_m: float, occupied: np.ndarray | None = occ == 100) -> np.ndarray:
        seg, _ = segment_rooms(
            free.astype(np.int32), none, none, none, resolution_m=RES, occupied=occupied, rays=none,
            table_min_thickness_m=table_min_thickness_m, join_saddle_ratio=0.0, desk_max_extent_m=0.0,
        )  # the joins of furnished pieces off: the cuts alone decide
        return seg

    seg = rooms(0.3)
    room_a, room_b = np.unique(seg[13:87, 13:97][free[13:87, 13:97]]), np.unique(seg[13:87, 100:187])
    assert room_a.size == 1 and room_b.size == 1 and room_a[0] != room_b[0]  # A whole, B behind its door
    # taken for a wall (no table test, and no occupied cells to tell a block beside a wall), the table makes the gaps
    # between it and the walls doorways that cut room A
    old = rooms(0.0, None)
    assert np.unique(old[13:87, 13:97][free[13:87, 13:97]]).size > 1


def test_a_cut_ending_beside_a_table_counts_one_beside_a_dash_of_wall_or_between_walls_does_not() -> None:
    blocked = np.zeros((60, 80), dtype=bool)
    blocked[:, :3] = blocked[:, -3:] = True  # walls
    blocked[15:27, 20:32] = True  # a 0.6 m table
    blocked[40:44, 30:60] = True  # a dash of wall, 1.5 m x 0.2 m
    occupied = blocked.copy()
    cuts = np.array([
        [[3.0, 20.0], [18.0, 20.0]],  # wall to table
        [[3.0, 42.0], [29.0, 42.0]],  # wall to the dash
        [[3.0, 52.0], [76.0, 52.0]],  # wall to wall
    ])  # (x, y) ends

    def tables(seen: np.ndarray, c: np.ndarray) -> list[bool]:
        flags = ends_on_tables(
            c, blocked, seen, max_extent_px=60.0, min_thickness_px=6.0, max_elongation=2.5, clearance_px=8
        )
        return [bool(f) for f in flags]

    assert tables(occupied, cuts) == [True, False, False]
    unseen = occupied.copy()
    unseen[15:27, 20:32] = False  # unknown space between rays, not a table the laser hit
    assert tables(unseen, cuts[:1]) == [False]



def test_an_obstacle_standing_in_a_doorway_keeps_the_doorway() -> None:
    occ = _two_rooms_and_a_table()
    occ[35:65, 40:70] = 0  # no table
    occ[40:68, 97:100] = 0  # a 1.4 m door with a 0.5 m bin in its middle: two 0.45 m gaps
    occ[49:59, 95:102] = 100
    free = occ == 0
    none = np.zeros(occ.shape, dtype=bool)
    seg, _ = segment_rooms(
        free.astype(np.int32), none, none, none, resolution_m=RES, occupied=occ == 100, rays=none,
        join_saddle_ratio=0.0, desk_max_extent_m=0.0,
    )
    room_a, room_b = np.unique(seg[13:87, 13:90]), np.unique(seg[13:87, 107:187])
    assert room_a.size == 1 and room_b.size == 1 and room_a[0] != room_b[0]


def _room_with_a_hollow_cupboard() -> np.ndarray:
    """Segments: an 8 x 6 m room (1) with a 1.2 x 0.8 m cupboard standing in it whose inside the laser saw (2), and
    a 1 x 0.8 m closet (3) behind the room's 0.2 m right wall; everything else is wall and unknown (0)."""
    seg = np.zeros((160, 220), dtype=np.int32)
    seg[20:140, 20:180] = 1
    seg[60:76, 80:104] = 0  # the cupboard's sides
    seg[62:74, 82:102] = 2  # its inside
    seg[60:80, 184:204] = 3  # the closet beyond the wall (columns 180..183)
    return seg


def test_the_inside_of_a_hollow_cupboard_is_its_rooms_floor_a_closet_behind_a_wall_is_not() -> None:
    seg = _room_with_a_hollow_cupboard()
    out = inside_furniture(seg, np.zeros(4, dtype=bool), resolution_m=RES)
    assert out[68, 90] == out[100, 50] == 1  # the cupboard's inside joins the room round it
    assert out[70, 194] == 3  # the closet keeps its own segment: the wall round it reaches the unknown outside
    assert np.array_equal(out > 0, seg > 0)
    fixed = np.array([False, False, True, False])
    assert inside_furniture(seg, fixed, resolution_m=RES)[68, 90] == 2  # fixed segments stay


def test_a_large_space_inside_a_block_stays_a_region() -> None:
    """A 2 x 1.5 m store room inside a 2.4 x 1.9 m block standing in the hall is a room, not a cupboard's inside."""
    seg = np.zeros((160, 220), dtype=np.int32)
    seg[20:140, 20:180] = 1
    seg[50:88, 70:118] = 0
    seg[54:84, 74:114] = 2  # 3 m^2 inside
    assert inside_furniture(seg, np.zeros(3, dtype=bool), resolution_m=RES)[70, 90] == 2


def _office_cut_beside_a_corridor() -> tuple[npt.NDArray[np.int32], npt.NDArray[np.bool_]]:
    """A 6 x 4 m office cut in two (segments 2, 3) along a gap between two desks, open along its top onto a
    2 x 16 m corridor (segment 1); the segments and the desks."""
    seg = np.zeros((160, 360), dtype=np.int32)
    seg[10:50, 10:330] = 1  # the corridor
    seg[50:130, 100:160] = 2
    seg[50:130, 160:220] = 3
    desks = np.zeros(seg.shape, dtype=bool)
    desks[60:76, 150:158] = desks[104:120, 162:170] = True
    seg[desks] = 0
    return seg, desks


def test_pieces_of_a_furnished_room_join_again_beside_a_corridor_that_stays_apart() -> None:
    """The office's pieces join (no neck, a convex union, desks at their border), the corridor (a T with them)
    stays apart."""
    seg, desks = _office_cut_beside_a_corridor()
    floor = np.zeros(seg.shape, dtype=bool)
    out = join_furnished_pieces(seg, desks, floor, resolution_m=RES)
    assert out[90, 120] == out[90, 200] != out[30, 40]
    # on a warehouse floor nothing joins
    assert len(np.unique(join_furnished_pieces(seg, desks, seg == 2, resolution_m=RES))) == 4


def test_segments_on_warehouse_floors_stay_as_they_are() -> None:
    """The same pieces all on a warehouse floor, or all but the corridor: every segment keeps its pixels and id."""
    seg, desks = _office_cut_beside_a_corridor()
    for floor in (seg > 0, seg >= 2):
        assert np.array_equal(join_furnished_pieces(seg, desks, floor, resolution_m=RES), seg)


def _room_with_an_arm() -> tuple[np.ndarray, np.ndarray]:
    """Free space at 5 cm of an L-shaped room (a 6 x 4 m body, a 2.2 m wide arm 3 m long off its top left, the arm's
    left wall the body's left wall run on, the arm 0.5 m wider from 0.8 m up) beside a room behind
    0.25 m walls, and the face stage's regions: the arm, the body and the room beside."""
    free = np.zeros((170, 150), dtype=bool)
    free[80:160, 20:140] = True  # the body
    free[20:80, 20:64] = True  # the arm
    free[20:64, 10:20] = True  # the arm wider from 0.8 m up
    free[20:75, 69:140] = True  # the room beside the arm, above the body
    regions = np.where(free, 2, 0).astype(np.int32)
    regions[:80, :64][free[:80, :64]] = 1
    regions[:80, 64:][free[:80, 64:]] = 3
    return free, regions


def test_the_arm_of_an_l_shaped_room_is_the_rooms_even_where_a_line_closed_its_mouth() -> None:
    free, regions = _room_with_an_arm()
    none = np.zeros(free.shape, dtype=bool)
    closed = none.copy()
    closed[79:82, 20:64] = True  # the line across the mouth, closed as a doorway

    def rooms(arm_min_width_m: float) -> np.ndarray:
        seg, _ = segment_rooms(
            regions, none, none, closed, resolution_m=RES, occupied=~free, rays=none, join_saddle_ratio=0.0,
            desk_max_extent_m=0.0, arm_min_width_m=arm_min_width_m, block_max_run_m=0.0,
        )  # the block test off: with every cell round the free space occupied, the arm's corner reads as a block
        return seg

    seg = rooms(2.0)
    arm, body, beside = seg[50, 40], seg[120, 80], seg[50, 100]
    assert arm == body and beside not in (0, body)  # arm and body one room, the room beside another
    seg = rooms(0.0)
    assert seg[50, 40] != seg[120, 80]  # the mouth taken for a doorway: the arm a room of its own



def _room_behind_a_door_with_a_shadow() -> tuple[np.ndarray, np.ndarray]:
    """Free space and occupied cells at 5 cm: a 1.75 m corridor along the top, behind a 0.15 m wall with a 1.5 m door a
    7 x 5.85 m room, whose lower left the laser never saw from the door (a shadow of unknown space from 1.35 m below
    the door's right jamb down to the bottom left)."""
    free = np.zeros((170, 160), dtype=bool)
    occupied = np.zeros(free.shape, dtype=bool)
    free[5:40, 5:155] = True  # the corridor
    occupied[40:43, 5:155] = True  # its wall
    free[43:160, 10:150] = True  # the room
    occupied[40:43, 30:60] = False
    free[40:43, 30:60] = True  # the door
    shadow = np.zeros(free.shape, dtype=np.uint8)
    corners = np.array([[60, 69], [10, 110], [10, 160], [150, 160], [150, 130], [100, 90]], dtype=np.int32)
    cv2.fillPoly(shadow, [corners], 1)
    free &= shadow == 0
    return free, occupied


def test_a_cut_from_a_door_jamb_to_the_lasers_shadow_leaves_the_room_whole_the_door_stays() -> None:
    free, occupied = _room_behind_a_door_with_a_shadow()
    regions = np.where(free, 1, 0).astype(np.int32)
    regions[:40][free[:40]] = 2
    none = np.zeros(free.shape, dtype=bool)

    def rooms(jamb_reach_m: float, seen: np.ndarray) -> np.ndarray:
        seg, _ = segment_rooms(
            regions, none, none, none, resolution_m=RES, occupied=seen, rays=none, join_saddle_ratio=0.0,
            desk_max_extent_m=0.0, jamb_reach_m=jamb_reach_m,
        )
        return seg

    seg = rooms(0.4, occupied)
    corridor, under_door, beside_door = seg[20, 80], seg[50, 40], seg[50, 120]
    assert under_door == beside_door and corridor not in (0, under_door)  # one room behind the corridor's door
    seg = rooms(0.0, occupied)
    assert seg[50, 40] != seg[50, 120]  # the cut from the jamb to the shadow taken for a doorway
    seen = occupied | (~free & (np.arange(free.shape[0])[:, None] > 43))  # the laser hit what stands there
    seg = rooms(0.4, seen)
    assert seg[50, 40] != seg[50, 120]  # a cut from the jamb to something seen is a doorway as before

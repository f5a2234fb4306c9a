"""Doorways found from the free space: cuts across narrow passages between walls, not along corridors."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
from scipy import ndimage

from services.grid_decomposition.doorways import (
    _centre_runs,
    _nearest_walls,
    across_a_corridor,
    block_beside_a_wall,
    bumps_a_strip,
    draw_cuts,
    find_doorways,
    off_a_door_jamb,
    opens_an_arm,
    widens,
)

RES = 0.05


def _two_rooms(door_m: float, *, angle_deg: float = 0.0) -> np.ndarray:
    """Free space of two 4 x 4 m rooms side by side, split by a 0.15 m wall with a door in its middle.

    With ``angle_deg`` the dividing wall is slanted by that much from vertical (no axis-aligned
    line follows it).
    """
    free = np.zeros((100, 200), dtype=np.uint8)
    free[10:90, 10:190] = 1
    half = 40 * math.tan(math.radians(angle_deg))
    top, bottom = (100 + half, 10), (100 - half, 89)
    cv2.line(free, (round(top[0]), top[1]), (round(bottom[0]), bottom[1]), 0, 3)
    door_px = door_m / RES
    mid = ((top[0] + bottom[0]) / 2, 50.0)
    dx, dy = (bottom[0] - top[0]) / 79, 1.0
    norm = math.hypot(dx, dy)
    a = (round(mid[0] - dx / norm * door_px / 2), round(mid[1] - dy / norm * door_px / 2))
    b = (round(mid[0] + dx / norm * door_px / 2), round(mid[1] + dy / norm * door_px / 2))
    cv2.line(free, a, b, 1, 5)
    return free.astype(bool)


def test_find_doorways_cuts_across_the_door_between_two_rooms() -> None:
    free = _two_rooms(0.9)
    cuts = find_doorways(free, resolution_m=RES)
    assert len(cuts) >= 1
    cut_px = draw_cuts(cuts, free.shape) & free
    left, right = cut_px[:, :95], cut_px[:, 106:]
    assert not left.any() and not right.any()
    pieces, _ = cv2.connectedComponents((free & ~draw_cuts(cuts, free.shape)).astype(np.uint8), connectivity=4)
    assert pieces - 1 >= 2


def test_find_doorways_finds_a_door_in_a_slanted_wall() -> None:
    free = _two_rooms(1.0, angle_deg=25.0)
    cuts = find_doorways(free, resolution_m=RES)
    blocked = free & ~draw_cuts(cuts, free.shape)
    _, pieces = cv2.connectedComponents(blocked.astype(np.uint8), connectivity=4)
    assert pieces[50, 30] != pieces[50, 170]


def test_find_doorways_leaves_a_corridor_whole() -> None:
    free = np.zeros((60, 300), dtype=bool)
    free[15:45, 10:290] = True  # 1.5 m wide, 14 m long
    assert len(find_doorways(free, resolution_m=RES)) == 0


def test_find_doorways_leaves_a_room_with_furniture_space_whole() -> None:
    free = np.zeros((100, 140), dtype=bool)
    free[10:90, 10:130] = True
    assert len(find_doorways(free, resolution_m=RES)) == 0


def test_find_doorways_ignores_openings_wider_than_a_door() -> None:
    free = _two_rooms(3.0)
    assert len(find_doorways(free, resolution_m=RES, max_width_m=2.5)) == 0


def test_widens_tells_a_doorway_from_the_mouth_of_a_passage() -> None:
    walls = np.ones((120, 120), dtype=bool)
    walls[10:50, 10:110] = False  # a room above
    walls[50:53, 50:68] = False  # an 18 px doorway in a 3 px wall
    walls[53:110, 10:110] = False  # a room below
    doorway = np.array([[[50.0, 51.0], [67.0, 51.0]]])
    assert widens(walls, doorway, widening_px=6, max_depth_px=20, depth_step_px=5).all()
    walls[53:110, 10:110] = True
    walls[53:110, 50:68] = False  # below the gap a passage as narrow as the gap
    assert not widens(walls, doorway, widening_px=6, max_depth_px=20, depth_step_px=5).any()


def test_a_gap_across_a_corridor_beside_an_office_door_is_no_doorway_a_door_into_a_room_is() -> None:
    walls = np.ones((120, 200), dtype=bool)
    walls[10:40, 10:190] = False  # a 1.5 m corridor
    walls[43:110, 10:190] = False  # offices above its 3 px side wall
    walls[40:43, 104:122] = False  # an office door each side of the line x = 100, right beside it
    walls[40:43, 78:96] = False
    across = np.array([[[100.0, 10.0], [100.0, 39.0]]])  # the gap across the corridor on that line
    # through the doors the corridor "widens" on both sides
    assert widens(walls, across, widening_px=6, max_depth_px=20, depth_step_px=5).all()
    assert across_a_corridor(walls, across, widening_px=6, length_px=40).all()
    assert not widens(walls, across, widening_px=6, max_depth_px=20, depth_step_px=5, corridor_length_px=40).any()
    door = np.array([[[104.0, 41.0], [121.0, 41.0]]])  # the office door itself: corridor below, office above
    assert not across_a_corridor(walls, door, widening_px=6, length_px=40).any()
    assert widens(walls, door, widening_px=6, max_depth_px=20, depth_step_px=5, corridor_length_px=40).all()
    hall = walls.copy()
    hall[10:40, 101:190] = False
    hall[40:110, 101:190] = False  # the corridor ends in a hall at x = 100: not a band on that side
    assert not across_a_corridor(hall, across, widening_px=6, length_px=40).any()
    gaps = np.concatenate([door, across, door])  # each gap's answer is its own, however they are chunked
    assert across_a_corridor(walls, gaps, widening_px=6, length_px=40, chunk=1).tolist() == [False, True, False]


def _strip_with_a_bump() -> np.ndarray:
    """Free space of a 1 m wide, 5 m long dead-end strip with a 0.35 m deep, 0.4 m long cupboard against its right
    wall half-way along it (the strip narrows to 0.65 m there)."""
    free = np.zeros((120, 40), dtype=bool)
    free[10:110, 10:30] = True
    free[56:64, 23:30] = False
    return free


def test_a_strip_narrowed_by_a_cupboard_against_one_wall_is_no_doorway() -> None:
    free = _strip_with_a_bump()
    assert len(find_doorways(free, resolution_m=RES, bump_max_m=0.0)) >= 1  # widens by 0.35 m on both sides
    assert len(find_doorways(free, resolution_m=RES)) == 0
    gap = np.array([[[9.0, 60.0], [23.0, 60.0]]])  # from the left wall to the cupboard
    assert bumps_a_strip(~free, gap, bump_px=12, tolerance_px=2, max_depth_px=20, depth_step_px=5).all()


def _room_beside_a_block(partition: bool) -> np.ndarray:
    """Occupancy (-1 / 0 / 100) of a 4.2 x 7.7 m room whose left wall runs straight, with a 0.15 m wall from its right
    wall ending 1.25 m short of the left one (``partition``), or a hollow 1.2 x 1.1 m table standing 1.25 m from the
    left wall with a cupboard against the right wall beside it (the laser saw their outlines)."""
    occ = np.full((180, 110), -1, dtype=np.int8)
    occ[10:170, 10:100] = 100
    occ[13:167, 13:97] = 0
    if partition:
        occ[88:91, 38:97] = 100
    else:
        occ[70:92, 38:62] = 100
        occ[72:90, 40:60] = -1
        occ[90:106, 55:97] = 100
        occ[92:104, 57:97] = -1
    return occ


def _parted(free: np.ndarray, cuts: np.ndarray) -> bool:
    _, pieces = cv2.connectedComponents((free & ~draw_cuts(cuts, free.shape)).astype(np.uint8), connectivity=4)
    return bool(pieces[40, 50] != pieces[140, 50])


def test_a_passage_between_a_side_wall_and_a_table_is_no_doorway_a_door_in_a_wall_is() -> None:
    furnished = _room_beside_a_block(partition=False)
    free, hit = furnished == 0, furnished == 100
    assert _parted(free, find_doorways(free, resolution_m=RES, block_max_run_m=0.0, hit=hit))  # cut at the table
    assert not _parted(free, find_doorways(free, resolution_m=RES, hit=hit))
    assert _parted(free, find_doorways(free, resolution_m=RES, hit=np.zeros_like(hit)))  # unknown masses: no block
    walled = _room_beside_a_block(partition=True)
    free, hit = walled == 0, walled == 100
    assert _parted(free, find_doorways(free, resolution_m=RES, hit=hit))


def test_a_gap_across_a_corridor_from_the_block_at_a_partitions_end_is_left_to_the_corridor_tests() -> None:
    blocked = np.ones((100, 200), dtype=bool)
    blocked[60:85, 5:195] = False  # a 1.25 m corridor
    blocked[10:60, 5:103] = False  # a room open onto it
    blocked[10:57, 107:195] = False  # the next room, behind a wall
    hit = np.zeros_like(blocked)
    hit[36:60, 95:116] = True  # a hollow block at the end of the partition between the two rooms
    hit[38:58, 97:114] = False
    blocked[36:60, 95:116] = True
    gap = np.array([[[96.0, 60.0], [96.0, 84.0]]])  # from the block across the corridor to its straight far wall

    def block(corridor_length_px: int) -> np.ndarray:
        return block_beside_a_wall(
            blocked, gap, hit=hit, run_px=10, max_thickness_px=12, max_run_px=30, tolerance_px=2, max_depth_px=20,
            depth_step_px=5, widening_px=6, corridor_length_px=corridor_length_px,
        )

    assert block(0).all()  # a block beside a wall that runs straight past
    assert not block(40).any()  # but the corridor goes on


def test_a_door_beside_a_corner_and_a_door_into_a_closet_as_wide_as_its_corridor_stay_doorways() -> None:
    free = np.zeros((100, 200), dtype=bool)
    free[10:90, 10:98] = True  # two 4.4 x 4 m rooms in a row, the 0.15 m wall between them
    free[10:90, 101:190] = True
    free[10:28, 98:101] = True  # a 0.9 m door right beside the top outer wall
    cuts = find_doorways(free, resolution_m=RES)
    _, pieces = cv2.connectedComponents((free & ~draw_cuts(cuts, free.shape)).astype(np.uint8), connectivity=4)
    assert pieces[50, 40] != pieces[50, 150]
    closet = np.zeros((140, 40), dtype=bool)
    closet[10:70, 10:30] = True  # a 1 m corridor
    closet[70:73, 14:26] = True  # a 0.6 m door between 0.2 m jambs in a 0.15 m wall
    closet[73:100, 10:30] = True  # a closet as wide as the corridor behind it
    cuts = find_doorways(closet, resolution_m=RES)
    _, pieces = cv2.connectedComponents((closet & ~draw_cuts(cuts, closet.shape)).astype(np.uint8), connectivity=4)
    assert pieces[30, 20] != pieces[90, 20]


def test_the_mouth_of_a_rooms_arm_is_no_doorway_a_gap_beside_a_partition_and_a_wide_door_are() -> None:
    ell = np.zeros((170, 150), dtype=bool)
    ell[80:160, 20:140] = True  # a 6 x 4 m room
    ell[20:80, 20:64] = True  # its 2.2 m wide arm, the arm's left wall the room's run on
    ell[20:75, 69:140] = True  # a room beside the arm behind 0.25 m walls

    def arm(blocked: np.ndarray, gap: list[list[float]], min_width_px: float = 40.0) -> bool:
        flags = opens_an_arm(blocked, np.array([gap]), min_width_px=min_width_px, from_px=4, to_px=16, share=0.8)
        return bool(flags[0])

    mouth = [[19.0, 80.0], [64.0, 79.0]]  # from the left wall to the corner, (x, y) ends
    assert arm(~ell, mouth)
    assert not arm(~ell, mouth, min_width_px=50.0)  # narrower than the cuts looked at
    two = np.zeros((100, 180), dtype=bool)
    two[10:90, 10:170] = True  # two 4 x 4 m rooms
    two[54:90, 88:91] = False  # the 0.15 m partition between them stops 2.2 m short of the top wall
    assert not arm(~two, [[89.0, 53.0], [89.0, 9.0]])  # the partition's end is free
    assert not arm(~_two_rooms(2.2), [[100.0, 27.0], [100.0, 72.0]])  # a 2.2 m door in a wall between jambs


def test_a_cut_off_a_door_jamb_to_nothing_seen_is_flagged_the_door_and_a_cut_to_a_seen_wall_are_not() -> None:
    space = np.zeros((120, 160), dtype=bool)
    space[5:40, 5:155] = True  # a corridor
    space[43:115, 10:150] = True  # a room behind its 0.15 m wall
    space[40:43, 30:60] = True  # a 1.5 m door
    hit = ~space
    door = [[29.0, 41.0], [60.0, 41.0]]  # (x, y) ends on the jambs, the wall running on beyond both
    down = [[60.0, 42.0], [60.0, 69.0]]  # from the right jamb down into the room, to a point the laser never hit

    def flags(*gaps: list[list[float]], seen: np.ndarray = hit) -> list[bool]:
        out = off_a_door_jamb(np.array(gaps), space, seen, reach_px=8.0, run_px=10, share=0.9, seen_px=2, max_cos=0.5)
        return [bool(f) for f in out]

    assert flags(door, down) == [False, True]
    seen = hit.copy()
    seen[68:71, 58:63] = True  # something the laser hit at the cut's lower end: a doorway as before
    assert flags(door, down, seen=seen) == [False, False]
    assert flags(door) == [False]


def test_distances_to_walls_are_scipys_exact_ones() -> None:
    """The distance to the nearest wall is scipy's Euclidean distance transform (as float32), whole or tiled."""
    rng = np.random.default_rng(5)
    space = rng.random((300, 520)) > 0.01
    for share in (0.0, 1.0):  # one transform; tiles
        dist, wall_x, wall_y = _nearest_walls(space, reach_px=600, max_share=share)
        expected = ndimage.distance_transform_edt(space).astype(np.float32)
        assert np.array_equal(dist, expected)
        rows, cols = np.indices(space.shape)
        assert np.array_equal(np.hypot(wall_x - cols.ravel(), wall_y - rows.ravel()).astype(np.float32), dist.ravel())


def _plain_centre_runs(blocked: np.ndarray, points: np.ndarray, direction: np.ndarray, reach_px: int) -> np.ndarray:
    """The run through each point, walked out one step at a time each way (off the image is blocked)."""
    h, w = blocked.shape
    direction = np.broadcast_to(direction, points.shape)
    out = np.zeros(points.shape[:-1], dtype=np.int64)
    for index in np.ndindex(*points.shape[:-1]):
        (px, py), (dx, dy) = points[index], direction[index]

        def stop(t: float, px: float = px, py: float = py, dx: float = dx, dy: float = dy) -> bool:
            x, y = int(np.rint(px + t * dx)), int(np.rint(py + t * dy))
            return not (0 <= x < w and 0 <= y < h) or bool(blocked[y, x])

        ahead = next((k for k in range(reach_px + 1) if stop(float(k))), reach_px + 1)
        behind = next((k for k in range(reach_px + 1) if stop(float(-k))), reach_px + 1)
        out[index] = max(ahead + behind - 1, 0)
    return out


@pytest.mark.parametrize("seed", range(4))
def test_centre_runs_are_the_runs_walked_out_from_each_point(seed: int) -> None:
    """Runs along any direction, through points inside, on the edge of and off the image, blocked or not."""
    rng = np.random.default_rng(seed)
    blocked = rng.random((int(rng.integers(3, 30)), int(rng.integers(3, 30)))) < rng.uniform(0.05, 0.5)
    h, w = blocked.shape
    points = np.stack([rng.uniform(-3, w + 3, (7, 3)), rng.uniform(-3, h + 3, (7, 3))], axis=-1)
    angle = rng.uniform(0, 2 * math.pi, (7, 1))
    direction = np.stack([np.cos(angle), np.sin(angle)], axis=-1)  # one direction per row, broadcast
    reach = int(rng.integers(1, 12))
    runs = _centre_runs(blocked, points, direction, reach)
    assert runs.dtype == np.int64
    assert np.array_equal(runs, _plain_centre_runs(blocked, points, direction, reach))

"""A wall between two rooms that the map draws only partly: the rooms part along the wall's own line."""

from __future__ import annotations

import math

import numpy as np

from services.grid_decomposition import decompose
from services.grid_decomposition.radiogram import Line
from services.grid_decomposition.short_walls import split_at_short_walls

RESOLUTION_M = 0.05


def _building(partition_rows: slice, corridor: bool = True) -> tuple[np.ndarray, np.ndarray, list[Line]]:
    """Segments, walls and lines of a 14 m x 9 m block: a 2.5 m corridor (rows 10..59, region 2; with
    ``corridor`` False a wall instead) below two 7 m x 6.5 m rooms (rows 60..189, one region 1), and the
    wall between the rooms along column 150 over ``partition_rows``."""
    walls = np.zeros((200, 300), dtype=bool)
    walls[:10, :] = walls[190:, :] = walls[:, :10] = walls[:, 290:] = True
    walls[partition_rows, 148:152] = True
    segments = np.zeros(walls.shape, dtype=np.int32)
    segments[60:190, 10:290] = 1
    if corridor:
        segments[10:60, 10:290] = 2
    else:
        walls[56:60, :] = True
    segments[walls] = 0
    lines = [Line(math.pi / 2, -150.0, 4.5, 0.1, True), Line(0.0, 58.0, 14.0, 0.1, True)]
    return segments, walls, lines


def _regions_over(segments: np.ndarray, rows: slice) -> set[int]:
    return set(np.unique(segments[rows, 10:290]).tolist()) - {0}


def test_two_rooms_whose_wall_stops_short_of_the_corridor_become_two_regions() -> None:
    """The wall runs 6.5 m down from the far wall to 2 m before the corridor: each room is a region."""
    segments, walls, lines = _building(slice(100, 190))
    candidates = np.array([False, True, False])
    out = split_at_short_walls(segments, walls, lines, candidates, resolution_m=RESOLUTION_M)
    left, right = out[150, 80], out[150, 220]
    assert left != right and left > 0 and right > 0
    assert set(np.unique(out[60:190, 10:148]).tolist()) - {0} == {left}
    assert set(np.unique(out[60:190, 152:290]).tolist()) - {0} == {right}
    assert np.array_equal(out[10:60], segments[10:60])  # the corridor is as it was


def test_a_gap_between_the_wall_and_another_wall_is_a_doorway_not_a_missing_wall() -> None:
    """The same wall ending 2 m before a wall (not another region): nothing parts here."""
    segments, walls, lines = _building(slice(100, 190), corridor=False)
    candidates = np.array([False, True])
    out = split_at_short_walls(segments, walls, lines, candidates, resolution_m=RESOLUTION_M)
    assert _regions_over(out, slice(60, 190)) == {1}


def test_a_wall_ending_far_from_the_regions_edge_leaves_one_room() -> None:
    """A 3.5 m stub of wall in a 6.5 m deep room (3 m left open, more than half the stub): one region."""
    segments, walls, lines = _building(slice(120, 190))
    candidates = np.array([False, True, False])
    out = split_at_short_walls(segments, walls, lines, candidates, resolution_m=RESOLUTION_M)
    assert _regions_over(out, slice(60, 190)) == {1}


def test_the_corridor_in_front_of_two_rooms_is_not_cut_on_the_line_of_their_wall() -> None:
    """Rooms below an L of 3.2 m corridor with the 7 m wall between them drawn up to the corridor's side: the wall's
    line goes on across the corridor into the region beyond, but the corridor's pieces (each room-like on
    its own) do not flank that wall; without that test the corridor is cut (the stretch across it allowed
    up to 3.5 m here, so that only the flank test stands in the way)."""
    walls = np.zeros((260, 300), dtype=bool)
    walls[:10, :] = walls[250:, :] = walls[:, :10] = walls[:, 290:] = True
    walls[10:150, 148:152] = True  # the wall between the two lower rooms
    segments = np.zeros(walls.shape, dtype=np.int32)
    walls[10:150, 68:72] = True  # the lower left room's wall to the corridor's arm
    segments[10:150, 72:150] = 1
    segments[10:150, 150:290] = 2
    segments[150:214, 10:290] = 3  # the corridor, with an arm down the left (its box holds the rooms' wall)
    segments[10:150, 10:68] = 3
    segments[214:250, 10:290] = 4
    segments[walls] = 0
    lines = [Line(math.pi / 2, -150.0, 7.0, 0.1, True)]
    candidates = np.array([False, False, False, True, False])
    out = split_at_short_walls(segments, walls, lines, candidates, resolution_m=RESOLUTION_M, gap_max_m=3.5)
    assert np.array_equal(out, segments)
    cut = split_at_short_walls(
        segments, walls, lines, candidates, resolution_m=RESOLUTION_M, gap_max_m=3.5, min_flank_share=0.0
    )
    assert len(set(np.unique(cut[150:214, 10:290]).tolist())) == 2


def _offices_on_a_corridor() -> tuple[np.ndarray, tuple[int, int], tuple[int, int], tuple[int, int]]:
    """Occupancy of a 24 m x 10.5 m building: a 2.5 m corridor along its lower wall, two 12 m x 8 m offices
    above it open onto it over 3 m each (its upper wall not drawn 9-15 m along), and the wall between the
    offices drawn from the far wall to 2 m before the corridor. A point in each office and in the corridor."""
    def px(m: float) -> int:
        return round(m / RESOLUTION_M)

    occ = np.full((px(12.5), px(26)), -1, dtype=np.int8)
    x0, y0, width, depth, t = px(1), px(1), px(24), px(10.5), 4
    occ[y0 - t : y0 + depth + t, x0 - t : x0 + width + t] = 100
    occ[y0 : y0 + depth, x0 : x0 + width] = 0
    side = y0 + px(2.5)  # the corridor's upper side
    occ[side : side + t, x0 : x0 + px(9)] = occ[side : side + t, x0 + px(15) : x0 + width] = 100
    middle = x0 + px(12)
    occ[side + t + px(2.0) : y0 + depth, middle - t // 2 : middle + t // 2] = 100
    return occ, (y0 + px(7), x0 + px(6)), (y0 + px(7), x0 + px(18)), (y0 + px(1.2), middle)


def test_offices_whose_wall_stops_short_of_their_corridor_are_two_regions() -> None:
    occupancy, left, right, corridor = _offices_on_a_corridor()
    seg = decompose(occupancy, resolution_m=RESOLUTION_M).segments
    assert len({int(seg[left]), int(seg[right]), int(seg[corridor])}) == 3
    off = decompose(occupancy, resolution_m=RESOLUTION_M, short_wall_min_m=0).segments
    assert off[left] == off[right] != off[corridor]

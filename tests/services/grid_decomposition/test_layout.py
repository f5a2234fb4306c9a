"""The building's layout: a room that opens onto a corridor where the map never drew its wall is a room."""

from __future__ import annotations

import math

import numpy as np

from services.grid_decomposition.layout import split_by_layout
from services.grid_decomposition.radiogram import Line
from services.grid_decomposition.subdivision import LineGroup

RESOLUTION_M = 0.05


def _corridor_and_room(seen_wall_m: float) -> tuple[np.ndarray, LineGroup]:
    """Walls of a 33 m x 2.5 m corridor (rows 100..149) and a 6 m x 5 m room above it (rows 152..250,
    columns 300..420) that opens onto the corridor over its whole width (6 m, wider than the corridor: no
    neck). The corridor's upper wall is drawn for ``seen_wall_m`` on each side of the opening; the lines
    are the walls' (as the decomposition's line search finds them)."""
    walls = np.zeros((260, 700), dtype=bool)
    walls[98:100, 18:682] = True  # the corridor's lower wall
    walls[100:150, [18, 19, 680, 681]] = True  # its ends
    reach = round(seen_wall_m / RESOLUTION_M)
    walls[150:152, 300 - reach : 300] = walls[150:152, 421 : 421 + reach] = True  # its upper wall, but the opening
    walls[150:253, [298, 299, 421, 422]] = True  # the room's side walls
    walls[251:253, 298:423] = True  # and its far wall
    horizontal = [Line(0.0, float(y), 30.0, 0.1, True) for y in (99, 150, 251)]
    vertical = [Line(math.pi / 2, -float(x), 5.0, 0.1, True) for x in (299, 421)]
    return walls, LineGroup(tuple(horizontal + vertical), None)


def _one_region(walls: np.ndarray) -> np.ndarray:
    segments = np.zeros(walls.shape, dtype=np.int32)
    segments[100:150, 20:680] = 1
    segments[150:251, 300:421] = 1
    segments[walls] = 0
    return segments


def test_a_room_open_onto_a_corridor_where_its_wall_is_missing_is_a_region_of_its_own() -> None:
    walls, lines = _corridor_and_room(seen_wall_m=14.0)
    segments = _one_region(walls)
    out = split_by_layout(segments, walls, [lines], np.array([False, True]), resolution_m=RESOLUTION_M)
    room = np.unique(out[160:245, 305:415])
    corridor = np.unique(out[105:145, 30:670])
    assert room.size == 1 and corridor.size == 1, "the room and the corridor are one region each"
    assert room[0] != corridor[0] and room[0] > 0 and corridor[0] > 0
    assert np.array_equal(out > 0, segments > 0), "every pixel of the region stays in a region"


def test_a_corridor_is_not_cut_across_where_the_walls_of_rooms_beside_it_continue() -> None:
    # the room's side walls continue across the corridor as lines of the layout: the corridor stays one region
    walls, lines = _corridor_and_room(seen_wall_m=14.0)
    out = split_by_layout(_one_region(walls), walls, [lines], np.array([False, True]), resolution_m=RESOLUTION_M)
    assert np.unique(out[105:145, 30:670]).size == 1


def test_a_wall_not_yet_seen_along_its_line_splits_nothing() -> None:
    # a growing map: the corridor's upper wall has been seen for only 1 m on each side of the opening (the robot
    # has not been further): the line is no wall of the layout yet and the region stays whole
    walls, lines = _corridor_and_room(seen_wall_m=1.0)
    segments = _one_region(walls)
    out = split_by_layout(segments, walls, [lines], np.array([False, True]), resolution_m=RESOLUTION_M)
    assert np.array_equal(out, segments)


def test_regions_not_offered_for_a_split_are_left_alone() -> None:
    walls, lines = _corridor_and_room(seen_wall_m=14.0)
    segments = _one_region(walls)
    out = split_by_layout(segments, walls, [lines], np.array([False, False]), resolution_m=RESOLUTION_M)
    assert np.array_equal(out, segments)

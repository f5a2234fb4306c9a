"""The map's straight wall lines (one detector for the slanted walls and the rooms' re-cut); units sharing walls."""

from __future__ import annotations

import math

import cv2
import numpy as np
import numpy.typing as npt

from services.floor_plan.detectors import Evidence, door_candidates, wall_line_segments
from services.floor_plan.likelihood import CellClass, beam_traces
from services.floor_plan.world import Rect, World, shared_band, sharing

# the floor plan's defaults at 0.05 m per cell: 1 m lines, 1.25 m gaps, free space 0.25 m wide
LINES = {"min_length_cells": 20, "max_gap_cells": 25}
SLANTED = math.radians(5.0)


def _building(shape: tuple[int, int] = (160, 200)) -> npt.NDArray[np.uint8]:
    """A walled 7 m x 9 m room in unknown space, walls 0.2 m thick along the grid."""
    cm = np.full(shape, CellClass.UNKNOWN, np.uint8)
    cm[10:150, 10:190] = CellClass.WALL
    cm[14:146, 14:186] = CellClass.FREE
    return cm


def _angles(lines: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Each line's angle to the columns' axis (x), degrees in [0, 180)."""
    out: npt.NDArray[np.float64] = np.degrees(np.arctan2(lines[:, 3] - lines[:, 1], lines[:, 2] - lines[:, 0])) % 180
    return out


def test_a_wall_at_30_degrees_to_the_grid_is_found_along_its_length() -> None:
    cm = _building()
    start, end = (30, 40), (30 + round(100 * math.cos(math.radians(30))), 40 + round(100 * math.sin(math.radians(30))))
    wall = np.zeros(cm.shape, np.uint8)
    cv2.line(wall, start, end, 1, 4)  # (x, y): 30 degrees below the x axis, 5 m long, 0.2 m thick
    cm[wall > 0] = CellClass.WALL
    lines = wall_line_segments(cm, **LINES, min_angle_rad=SLANTED)
    assert len(lines) >= 1
    assert np.all(np.abs(_angles(lines) - 30.0) < 1.0), "every slanted line found is that wall, at its angle"
    assert np.max(np.hypot(lines[:, 2] - lines[:, 0], lines[:, 3] - lines[:, 1])) > 80, "along most of it"
    # the refitted line runs along one face of the wall, within its thickness of the drawn centre line
    x, y = lines[:, 0::2], lines[:, 1::2]
    off = np.abs((x - start[0]) * math.sin(math.radians(30)) - (y - start[1]) * math.cos(math.radians(30)))
    assert np.all(off <= 3.0)


def test_a_dashed_slanted_wall_is_one_line() -> None:
    cm = _building()
    wall = np.zeros(cm.shape, np.uint8)
    cv2.line(wall, (30, 40), (117, 90), 1, 4)
    along = np.hypot(*np.mgrid[0 : cm.shape[0], 0 : cm.shape[1]] - np.array([40, 30])[:, None, None])
    wall[along % 24 >= 12] = 0  # 0.6 m on, 0.6 m off
    cm[wall > 0] = CellClass.WALL
    lines = wall_line_segments(cm, **LINES, min_angle_rad=SLANTED)
    assert len(lines) >= 1 and np.max(np.hypot(lines[:, 2] - lines[:, 0], lines[:, 3] - lines[:, 1])) > 80


def test_walls_along_the_grid_are_no_slanted_lines() -> None:
    cm = _building()
    cm[14:146, 98:102] = CellClass.WALL  # an inner wall with a door
    cm[70:90, 98:102] = CellClass.FREE
    assert len(wall_line_segments(cm, **LINES, min_angle_rad=SLANTED)) == 0
    every = wall_line_segments(cm, **LINES)
    assert len(every) >= 4 and np.all(np.minimum(_angles(every) % 90, 90 - _angles(every) % 90) < 1.0), \
        "without an angle they are the map's wall lines along the grid"


def test_walls_drawn_unknown_are_wall_lines_too() -> None:
    cm = _building()
    wall = np.zeros(cm.shape, np.uint8)
    cv2.line(wall, (30, 40), (117, 90), 1, 4)
    cm[wall > 0] = CellClass.UNKNOWN  # a map that never saw the wall's cells occupied
    assert len(wall_line_segments(cm, **LINES, min_angle_rad=SLANTED)) >= 1


def test_the_edges_of_laser_streaks_through_a_window_are_no_wall_lines_where_beams_read_unknown() -> None:
    cm = np.full((260, 200), CellClass.UNKNOWN, np.uint8)
    cm[10:110, 10:190] = CellClass.WALL
    cm[14:106, 14:186] = CellClass.FREE
    cm[106:110, 80:120] = CellClass.FREE  # a window 2 m wide in the bottom wall
    rays = np.zeros(cm.shape, np.uint8)
    for degrees in range(35, 150, 9):  # beams through it, a cell wide, 7 m into the unknown outside
        a = math.radians(degrees)
        cv2.line(rays, (100, 100), (100 + round(140 * math.cos(a)), 100 + round(140 * math.sin(a))), 1, 1)
    cm[(rays > 0) & (cm != CellClass.FREE)] = CellClass.FREE
    cm[106:110, 14:80] = CellClass.WALL  # the wall either side of the window stays
    cm[106:110, 120:186] = CellClass.WALL
    read = cm.copy()
    read[beam_traces(cm, width_cells=3)] = CellClass.UNKNOWN  # as the floor plan reads them with trace_max_m 0.15
    assert len(wall_line_segments(read, **LINES, min_angle_rad=SLANTED)) == 0, "no beam's edge is a slanted wall"
    assert len(wall_line_segments(cm, **LINES, min_angle_rad=SLANTED)) >= 5, \
        "read free, the beams have an outline, and it runs straight"


def test_units_share_a_wall_with_their_neighbours_in_a_row_or_column_and_not_across_a_corner() -> None:
    t = 2  # a 3 x 3 block of rooms 20 cells a side sharing their walls, and one room standing apart
    rooms = [Rect(18 * i, 18 * i + 19, 18 * j, 18 * j + 19) for i in range(3) for j in range(3)]
    rooms.append(Rect(80, 99, 80, 99))
    boxes = np.array(rooms, np.int64)
    for k, rect in enumerate(rooms):
        found = set(np.flatnonzero(sharing(rect, boxes, t)).tolist())
        expected = {m for m, other in enumerate(rooms) if m != k and shared_band(rect, other, t) is not None}
        assert found == expected
        if k < 9:
            i, j = divmod(k, 3)
            assert found == {3 * a + b for a, b in ((i - 1, j), (i + 1, j), (i, j - 1), (i, j + 1))
                             if 0 <= a < 3 and 0 <= b < 3}
        else:
            assert not found
    # a map open everywhere: one door candidate along each of the 12 shared walls
    doors = door_candidates(World(dict(enumerate(rooms, start=1))), Evidence(np.zeros((100, 100), np.uint8)),
                            wall_cells=t, min_door_cells=4)
    assert len(doors) == 12
    assert all(sum(d.rect.intersects(r) for r in rooms) == 2 for d in doors)

"""Rooms cut along walls that run slanted through the frame: a unit standing over a slanted wall is two rooms."""

from __future__ import annotations

import dataclasses
import math

import cv2
import numpy as np
import numpy.typing as npt

from services.floor_plan import (
    CellClass,
    Rect,
    Room,
    RoomSettings,
    UnitType,
    World,
    group_rooms,
    split_at_slanted_walls,
)
from services.floor_plan.detectors import wall_line_segments
from services.floor_plan.slanted import slanted

RES = 0.05
T = 2  # wall cells
BOX = Rect(0, 99, 0, 139)  # one unit: 5 m x 7 m


def _room_with_slanted_wall(*, dashed: bool, length_share: float = 1.0) -> npt.NDArray[np.uint8]:
    """A walled 5 m x 7 m room with a wall at about 35 degrees across it (dashed: 0.6 m on, 0.6 m off)."""
    classes = np.full((BOX.rows, BOX.cols), CellClass.WALL, np.uint8)
    classes[T:-T, T:-T] = CellClass.FREE
    wall = np.zeros(classes.shape, np.uint8)
    start, end = np.array([T, 20]), np.array([BOX.rows - T - 1, 120])  # (row, col) from the top to the bottom wall
    end = start + (end - start) * length_share
    cv2.line(wall, (int(start[1]), int(start[0])), (int(end[1]), int(end[0])), 1, 2)
    if dashed:
        along = np.hypot(*np.mgrid[0 : BOX.rows, 0 : BOX.cols] - start[:, None, None])
        wall[(along * RES) % 1.2 > 0.6] = 0
    classes[wall > 0] = CellClass.WALL
    return classes


def _lines(classes: npt.NDArray[np.uint8]) -> npt.NDArray[np.float64]:
    """The map's wall lines as the floor plan finds them (``FloorPlanSettings``' defaults at 0.05 m)."""
    return wall_line_segments(classes, min_length_cells=20, max_gap_cells=25)


def _split(classes: npt.NDArray[np.uint8], settings: RoomSettings | None = None
           ) -> tuple[int, npt.NDArray[np.int32]]:
    s = settings or RoomSettings()
    world = World({1: BOX}, set(), 2)
    rooms = group_rooms(world, classes, {1: UnitType.ROOM}, wall_cells=T, resolution_m=RES, settings=s)
    assert len(rooms) == 1, "rectangles alone do not cut a unit along a slanted wall"
    out, cells = split_at_slanted_walls(rooms, world, classes, _lines(classes), resolution_m=RES, reach_m=0.6,
                                        settings=s)
    assert all(room.units == (1,) and room.room_type is UnitType.ROOM for room in out)
    return len(out), cells


def test_a_unit_standing_over_a_slanted_wall_is_two_rooms() -> None:
    n, cells = _split(_room_with_slanted_wall(dashed=False))
    assert n == 2
    left, right = cells[50, 10], cells[50, 130]
    assert left != right and {int(left), int(right)} == {1, 2}, "one room each side of the wall"


def test_a_dashed_slanted_wall_splits_the_room_too() -> None:
    n, cells = _split(_room_with_slanted_wall(dashed=True))
    assert n == 2 and cells[50, 10] != cells[50, 130]


def test_a_slanted_wall_ending_in_the_room_leaves_it_whole() -> None:
    n, cells = _split(_room_with_slanted_wall(dashed=False, length_share=0.5))
    assert n == 1
    free = cells > 0
    assert np.unique(cells[free]).tolist() == [1]


def test_a_room_without_slanted_walls_keeps_its_rectangles() -> None:
    classes = np.full((BOX.rows, BOX.cols), CellClass.WALL, np.uint8)
    classes[T:-T, T:-T] = CellClass.FREE
    classes[T:-T, 69:71] = CellClass.WALL  # a straight wall along the frame: the units' own cut, not this one
    classes[40:60, 69:71] = CellClass.FREE  # with a door
    assert not len(slanted(_lines(classes), math.radians(15.0)))


def test_slanted_cuts_can_be_turned_off() -> None:
    n, _ = _split(_room_with_slanted_wall(dashed=False), dataclasses.replace(RoomSettings(), slant_min_angle_rad=None))
    assert n == 1


def _two_units_over_a_slanted_wall(settings: RoomSettings) -> npt.NDArray[np.int32]:
    """Two units side by side, kept apart as two rooms, where a slanted wall cuts the first one only: the space
    right of the wall lies in both."""
    classes = _room_with_slanted_wall(dashed=False)
    world = World({1: Rect(0, 99, 0, 101), 2: Rect(0, 99, 100, 139)}, set(), 3)
    rooms = [Room((1,), (Rect(T, 99 - T, T, 101 - T),), UnitType.ROOM, 20.0),
             Room((2,), (Rect(T, 99 - T, 100 + T, 139 - T),), UnitType.ROOM, 8.0)]
    _, cells = split_at_slanted_walls(rooms, world, classes, _lines(classes), resolution_m=RES, reach_m=0.6,
                                      settings=settings)
    return cells


def test_the_space_between_slanted_walls_two_units_hold_is_one_room() -> None:
    cells = _two_units_over_a_slanted_wall(RoomSettings())
    left, right_of_wall, second_unit = cells[80, 10], cells[20, 80], cells[20, 130]
    assert right_of_wall == second_unit, "no wall between the two units' pieces right of the slanted wall"
    assert left != right_of_wall, "the slanted wall still parts the rooms"


def test_rooms_that_share_space_between_slanted_walls_stay_apart_without_the_join() -> None:
    cells = _two_units_over_a_slanted_wall(dataclasses.replace(RoomSettings(), slant_join_max_m2=None))
    assert cells[20, 80] != cells[20, 130]

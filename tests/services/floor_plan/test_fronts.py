"""Rooms cut along open fronts: offices whose side walls both end at a corridor are rooms of their own, a stretch of
corridor between two doors facing each other and an alcove are not."""

from __future__ import annotations

import dataclasses

import numpy as np
import numpy.typing as npt

from services.floor_plan import CellClass, Rect, RoomSettings, UnitType, World, group_rooms
from services.floor_plan.fronts import open_fronts, split_at_fronts
from services.floor_plan.slanted import room_cells

RES = 0.05
T = 2  # wall cells


def _offices() -> npt.NDArray[np.uint8]:
    """A 2 m corridor (rows 102..141) along three offices 5 m deep and 3 m wide (rows 2..101) whose walls between
    them end at the corridor: each office's front is open over its whole width."""
    classes = np.full((144, 6 * 20 + 4 + 60), CellClass.WALL, np.uint8)
    classes[T:-T, T:-T] = CellClass.FREE
    for c in (62, 122):
        classes[T:102, c : c + 2] = CellClass.WALL
    return classes


def test_offices_open_onto_a_corridor_have_fronts_and_a_unit_over_office_and_corridor_is_two_rooms() -> None:
    classes = _offices()
    free = classes == CellClass.FREE
    fronts = open_fronts(free, resolution_m=RES, settings=RoomSettings())
    assert fronts[101, 70:120].all(), "the middle office's front, from wall end to wall end"
    assert not fronts[:101].any() and not fronts[103:].any()
    world = World({1: Rect(0, 143, 60, 126)}, set(), 2)  # the middle office and the corridor in front of it
    s = RoomSettings()
    rooms = group_rooms(world, classes, {1: UnitType.ROOM}, wall_cells=T, resolution_m=RES, settings=s)
    assert len(rooms) == 1
    out, cells = split_at_fronts(rooms, room_cells(rooms, classes.shape) * free, world, free, fronts,
                                 resolution_m=RES, settings=s)
    assert len(out) == 2
    assert cells[50, 90] != cells[120, 90], "the office is not one room with the corridor"
    assert all(room.units == (1,) for room in out)
    off = dataclasses.replace(s, front_max_m=None)
    assert not open_fronts(free, resolution_m=RES, settings=off).any()


def _corridor_with_doors() -> npt.NDArray[np.uint8]:
    """A 2 m corridor, 20 m long, between rooms; each of its two walls has a 1.5 m door facing the other's."""
    classes = np.full((404, 80), CellClass.FREE, np.uint8)
    classes[:T], classes[-T:] = CellClass.WALL, CellClass.WALL
    classes[:, 18:20] = classes[:, 60:62] = CellClass.WALL
    classes[200:230, 18:20] = classes[200:230, 60:62] = CellClass.FREE
    return classes


def _alcove() -> npt.NDArray[np.uint8]:
    """A room with an alcove 3 m wide and 2.5 m deep in its lower wall, another room below."""
    classes = np.full((304, 204), CellClass.FREE, np.uint8)
    classes[:T], classes[-T:], classes[:, :T], classes[:, -T:] = (CellClass.WALL,) * 4
    classes[150:152, 20:70] = classes[150:152, 130:184] = CellClass.WALL  # the room's lower wall, passages at its ends
    classes[150:202, 68:70] = classes[150:202, 130:132] = CellClass.WALL  # the alcove's sides
    classes[200:202, 68:132] = CellClass.WALL  # its back
    return classes


def test_a_corridor_between_doors_facing_each_other_and_an_alcove_have_no_front() -> None:
    s = RoomSettings()
    corridor, alcove = (c == CellClass.FREE for c in (_corridor_with_doors(), _alcove()))
    assert not open_fronts(corridor, resolution_m=RES, settings=s).any(), "no wall across its back nearby"
    assert not open_fronts(alcove, resolution_m=RES, settings=s).any(), "its side walls turn along the room's wall"
    # what keeps them apart: a corridor stretch up to 10 widths deep is an office, a wall running on for 10 m a cap
    assert open_fronts(corridor, resolution_m=RES, settings=dataclasses.replace(s, corridor_length_ratio=10.0)).any()
    assert open_fronts(alcove, resolution_m=RES, settings=dataclasses.replace(s, front_corner_m=10.0)).any()

"""Clutter inside units: furniture drawn as obstacles where it pays, specks and unexplored space left alone."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from pydantic import ValidationError

from services.floor_plan import CellClass, ChainSettings, FloorPlanSettings, explain_clutter, floor_plan
from services.floor_plan.likelihood import log_sensor_table
from shared.settings import FloorPlanStageSettings

RES = 0.05
TABLE = log_sensor_table()


def _room_with_desk() -> np.ndarray:
    """A 4 m x 3 m room (walls two cells thick), a desk seen from one side (its front row occupied, the rest
    unknown: the laser never saw behind it) and a speck of unknown in the free space."""
    occ = np.full((80, 100), -1, np.int8)
    occ[10:70, 10:90] = 100
    occ[12:68, 12:88] = 0
    occ[30:46, 40:56] = -1  # the desk, 0.8 m x 0.8 m
    occ[30, 40:56] = 100
    occ[56, 70] = -1  # a speck
    return occ


def test_a_desk_in_a_room_is_an_obstacle_of_the_world_and_a_speck_is_not() -> None:
    settings = FloorPlanSettings(chain=ChainSettings(iterations=1500, seed=1))
    plan = floor_plan(_room_with_desk(), resolution_m=RES, settings=settings)
    assert len(plan.units) == 1
    assert plan.clutter == 1
    assert np.all(plan.classes_world[31:46, 40:56] == CellClass.UNKNOWN), "the unseen desk is drawn unexplained"
    assert plan.classes_world[56, 70] == CellClass.FREE, "one cell is not worth an obstacle"
    assert plan.k > plan.k_units
    off = floor_plan(_room_with_desk(), resolution_m=RES, settings=replace(settings, clutter_max_m2=None))
    assert off.clutter == 0 and off.k == off.k_units == pytest.approx(plan.k_units)
    assert off.classes_world[35, 45] == CellClass.FREE, "without clutter obstacles the seed's world draws it free"


def test_a_blob_is_drawn_in_the_class_that_explains_it_best() -> None:
    cm = np.zeros((12, 20), np.uint8)
    cm[2:6, 2:6] = CellClass.WALL  # furniture drawn black
    cm[2:6, 10:14] = CellClass.UNKNOWN  # the space behind furniture
    cm[2, 10] = CellClass.WALL
    out = explain_clutter(cm, np.zeros_like(cm), TABLE, max_cells=100, log_cost=5.0)
    assert out.drawn == 2 and out.drawn_occupied == 1
    assert np.all(out.classes_world[2:6, 2:6] == CellClass.WALL)
    assert np.all(out.classes_world[2:6, 10:14] == CellClass.UNKNOWN)
    assert set(np.unique(out.obstacles)) == {0, 1, 2}


def test_unexplored_space_larger_than_furniture_and_cells_the_world_does_not_draw_free_are_left_alone() -> None:
    cm = np.zeros((30, 30), np.uint8)
    cm[5:20, 5:20] = CellClass.UNKNOWN  # 225 cells: a unit stretched over unexplored space
    cw = np.zeros_like(cm)
    cm[25:28, 25:28] = CellClass.WALL
    cw[25:28, 25:28] = CellClass.UNKNOWN  # outside every unit: not clutter in a unit
    out = explain_clutter(cm, cw, TABLE, max_cells=100, log_cost=5.0)
    assert out.drawn == 0
    assert np.array_equal(out.classes_world, cw)


def test_bad_arguments_are_refused() -> None:
    cm = np.zeros((5, 5), np.uint8)
    with pytest.raises(ValueError, match="differ in shape"):
        explain_clutter(cm, np.zeros((4, 5), np.uint8), TABLE, max_cells=10, log_cost=1.0)
    with pytest.raises(ValueError, match="max_cells"):
        explain_clutter(cm, cm, TABLE, max_cells=0, log_cost=1.0)


def test_the_worker_settings_take_clutter_obstacles_off_and_refuse_a_nonsense_size() -> None:
    assert FloorPlanStageSettings(clutter_max_m2=None).clutter_max_m2 is None
    with pytest.raises(ValidationError, match="clutter_max_m2"):
        FloorPlanStageSettings(clutter_max_m2=0.0)
    with pytest.raises(ValidationError, match="clutter_log_cost"):
        FloorPlanStageSettings(clutter_log_cost=-1.0)

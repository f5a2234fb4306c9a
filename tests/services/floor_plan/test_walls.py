"""Walls as the map draws them: each unit wall fitted in segments, doors kept open, exterior obstacles outside."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import numpy.typing as npt
import pytest
from pydantic import ValidationError

from services.floor_plan import CellClass, ChainSettings, FloorPlanSettings, Rect, World, floor_plan, render
from services.floor_plan.clutter import explain_exterior
from services.floor_plan.detectors import wall_line_segments
from services.floor_plan.likelihood import log_sensor_table
from services.floor_plan.walls import Walls, fit_walls
from shared.settings import FloorPlanStageSettings

RES = 0.05
TABLE = log_sensor_table()


def _fit(world: World, cm: npt.NDArray[np.uint8], *, t: int, log_cost: float = 10.0) -> Walls:
    return fit_walls(world, cm, TABLE, wall_cells=t, fixed=np.zeros(cm.shape, bool), max_shift=3, max_thickness=t + 3,
                     log_cost=log_cost, segment_cells=5)


def _room(shape: tuple[int, int], r0: int, r1: int, c0: int, c1: int, t: int) -> npt.NDArray[np.uint8]:
    cm = np.full(shape, CellClass.UNKNOWN, np.uint8)
    cm[r0 : r1 + 1, c0 : c1 + 1] = CellClass.WALL
    cm[r0 + t : r1 - t + 1, c0 + t : c1 - t + 1] = CellClass.FREE
    return cm


def test_a_wall_drawn_thicker_and_off_the_band_is_drawn_as_the_map_draws_it() -> None:
    cm = _room((60, 80), 10, 49, 10, 69, 2)
    cm[10:15, 10:70] = CellClass.WALL  # the top wall is five cells thick, reaching into the room
    world = World({1: Rect(10, 49, 10, 69)})
    out = _fit(world, cm, t=2)
    top = out.segments[1][0]
    assert any(s.thickness == 5 and s.shift == 3 for s in top), top
    assert np.all(out.classes_world[10:15, 12:68] == CellClass.WALL)
    assert np.all(out.classes_world[15:48, 12:68] == CellClass.FREE)
    assert all(s.shift == 0 and s.thickness == 2 for side in out.segments[1][1:] for s in side), "the rest is the band"


def test_a_gap_in_a_wall_onto_free_space_is_an_opening_and_a_speck_is_not_worth_a_segment() -> None:
    cm = _room((60, 80), 10, 49, 10, 69, 2)
    cm[5:12, 30:45] = CellClass.FREE  # the top wall open over 0.75 m onto free space no unit explains
    cm[49, 60] = CellClass.FREE  # one cell missing from the bottom wall
    out = _fit(World({1: Rect(10, 49, 10, 69)}), cm, t=2)
    assert np.all(out.classes_world[10:12, 30:45] == CellClass.FREE), "the unit's free space runs through the gap"
    assert any(s.thickness == 0 for s in out.segments[1][0])
    assert out.classes_world[49, 60] == CellClass.WALL
    assert out.segments[1][1] == out.segments[1][1][:1] and out.segments[1][1][0].thickness == 2


def test_a_door_stays_open_through_a_shared_wall_drawn_thicker() -> None:
    cm = np.full((60, 110), CellClass.UNKNOWN, np.uint8)
    cm[10:50, 10:100] = CellClass.WALL
    cm[12:48, 12:53] = CellClass.FREE
    cm[12:48, 57:98] = CellClass.FREE  # the shared wall is four cells thick (columns 53..56)
    cm[25:35, 53:57] = CellClass.FREE  # the doorway through it
    door = Rect(25, 34, 54, 55)
    world = World({1: Rect(10, 49, 10, 55), 2: Rect(10, 49, 54, 99)}, {door})
    assert world.door_units(door, 2) == [1, 2]
    out = _fit(world, cm, t=2)
    assert np.all(out.classes_world[25:35, 53:57] == CellClass.FREE)
    assert np.all(out.classes_world[12:25, 53:57] == CellClass.WALL)
    assert np.all(out.classes_world[35:48, 53:57] == CellClass.WALL)


def test_walls_the_map_draws_as_the_band_give_back_the_seeds_world() -> None:
    rng = np.random.default_rng(3)
    cm = rng.integers(0, 3, (50, 70)).astype(np.uint8)  # nothing to fit: no segment pays its cost
    world = World({1: Rect(5, 30, 5, 40), 2: Rect(29, 45, 5, 40), 3: Rect(5, 45, 39, 65)}, {Rect(29, 30, 15, 25)})
    out = _fit(world, cm, t=2, log_cost=1e6)
    assert out.fitted == 0
    assert np.array_equal(out.classes_world, render(world, cm.shape, wall_cells=2))


def test_exterior_obstacles_are_blobs_against_a_wall_and_not_objects_further_out() -> None:
    cm = np.full((40, 60), CellClass.UNKNOWN, np.uint8)
    cw = cm.copy()
    cw[20:, :] = CellClass.WALL  # a wall the world draws (rows 20..)
    cm[20:, :] = CellClass.WALL
    cm[17:20, 10:30] = CellClass.WALL  # the wall's ragged outside, three cells more
    cm[5:8, 40:50] = CellClass.WALL  # something seen through a window, far from any wall
    cm[19, 55] = CellClass.WALL  # a speck against the wall: not worth an obstacle
    out = explain_exterior(cm, cw, TABLE, max_cells=400, log_cost=10.0)
    assert out.drawn == 1
    assert np.all(out.classes_world[17:20, 10:30] == CellClass.WALL)
    assert np.all(out.classes_world[5:8, 40:50] == CellClass.UNKNOWN)
    assert out.classes_world[19, 55] == CellClass.UNKNOWN
    assert explain_exterior(cm, cw, TABLE, max_cells=50, log_cost=10.0).drawn == 0, "larger than the cap"


def _rooms_with_a_thick_wall() -> npt.NDArray[np.int8]:
    occ = np.full((80, 120), -1, np.int8)
    for r0, r1, c0, c1 in ((10, 69, 10, 60), (10, 69, 59, 109)):  # walls two cells thick
        occ[r0 : r1 + 1, c0 : c1 + 1] = 100
        occ[r0 + 2 : r1 - 1, c0 + 2 : c1 - 1] = 0
    occ[12:15, 12:59] = 100  # the first room's top wall is five cells thick
    occ[35:48, 59:61] = 0  # the door
    return occ


def test_fitted_walls_explain_more_of_the_map_and_leave_units_doors_and_rooms_alone() -> None:
    settings = FloorPlanSettings(chain=ChainSettings(iterations=1500, seed=1), clutter_max_m2=None)
    plan = floor_plan(_rooms_with_a_thick_wall(), resolution_m=RES, settings=settings)
    seed = floor_plan(_rooms_with_a_thick_wall(), resolution_m=RES, settings=replace(settings, wall_shift_m=None))
    assert plan.world == seed.world and plan.rooms == seed.rooms
    assert seed.walls == {} and seed.wall_segments == 0
    assert plan.k_units == seed.k_units == seed.k, "k_units is the seed's world either way"
    assert plan.k > plan.k_units and plan.wall_segments >= 1
    thick = (slice(10, 15), slice(14, 57))
    assert np.all(plan.classes_world[thick] == CellClass.WALL), "the thick wall is drawn thick"
    assert not np.all(seed.classes_world[thick] == CellClass.WALL), "the seed's band is thinner"


def test_the_worker_settings_take_fitted_walls_off_and_refuse_a_nonsense_shift() -> None:
    assert FloorPlanStageSettings(wall_shift_m=None).wall_shift_m is None
    with pytest.raises(ValidationError, match="wall_shift_m"):
        FloorPlanStageSettings(wall_shift_m=0.0)
    with pytest.raises(ValueError, match="segment_cells"):
        fit_walls(World(), np.zeros((5, 5), np.uint8), TABLE, wall_cells=1, fixed=np.zeros((5, 5), bool),
                  max_shift=1, max_thickness=2, log_cost=1.0, segment_cells=0)


def _slanted_room(shape: tuple[int, int] = (60, 80)) -> npt.NDArray[np.uint8]:
    """A room whose right wall leans 0.4 cells outwards per row (about 22 degrees off the columns), one-cell walls,
    unknown outside: no axis-parallel rectangle fits it."""
    cm = np.full(shape, CellClass.UNKNOWN, np.uint8)
    for r in range(10, 50):
        right = round(50 + 0.4 * (r - 10))
        cm[r, 10 : right + 1] = CellClass.WALL if r in (10, 49) else CellClass.FREE
        cm[r, 10] = cm[r, right] = CellClass.WALL
    return cm


def test_a_unit_over_a_slanted_wall_is_cut_along_it_and_gives_up_the_corner_beyond() -> None:
    cm = _slanted_room()
    world = World({1: Rect(10, 49, 10, 66)})  # the room's bounding box, as an axis-parallel unit stands over it
    lines = wall_line_segments(cm, min_length_cells=20, max_gap_cells=25, min_angle_rad=0.09)
    out = fit_walls(world, cm, TABLE, wall_cells=1, fixed=np.zeros(cm.shape, bool), max_shift=3, max_thickness=4,
                    log_cost=10.0, segment_cells=5, lines=lines)
    seed = _fit(world, cm, t=1)
    assert seed.slants == {1: ()} and seed.classes_world[15, 62] == CellClass.FREE, "without lines: a rectangle"
    (cut,) = out.slants[1]
    assert abs(cut.normal_row) > 0.3 and abs(cut.normal_col) > 0.8, "the wall leans, its normal is not an axis"
    corner = (cm == CellClass.UNKNOWN)[10:50, 10:67]
    assert np.mean(out.classes_world[10:50, 10:67][corner] == CellClass.UNKNOWN) > 0.9, "the corner is given up"
    slanted = np.zeros(cm.shape, bool)
    for r in range(12, 48):
        slanted[r, round(50 + 0.4 * (r - 10))] = True
    assert np.mean(out.classes_world[slanted] == CellClass.WALL) > 0.8, "the wall is drawn along the slanted line"
    assert np.all(out.classes_world[12:48, 12:48] == CellClass.FREE), "the room's free space stays"
    k = [float(np.mean(w.classes_world == cm)) for w in (seed, out)]
    assert k[1] > k[0]


def test_a_slanted_wall_keeps_the_units_door_and_pays_its_cost() -> None:
    cm = _slanted_room()
    world = World({1: Rect(10, 49, 10, 66)})
    lines = wall_line_segments(cm, min_length_cells=20, max_gap_cells=25, min_angle_rad=0.09)
    dear = fit_walls(world, cm, TABLE, wall_cells=1, fixed=np.zeros(cm.shape, bool), max_shift=3, max_thickness=4,
                     log_cost=1e6, segment_cells=5, lines=lines)
    assert dear.slants == {1: ()}, "a cut that does not pay its cost is not drawn"
    cm[0:11, 55:71] = CellClass.WALL  # a room beyond the corner, a door in the top wall to it
    cm[1:10, 56:70] = CellClass.FREE
    cm[10, 60:66] = CellClass.FREE
    world = World({1: Rect(10, 49, 10, 66), 2: Rect(0, 10, 55, 70)}, {Rect(10, 10, 60, 65)})
    assert world.door_units(Rect(10, 10, 60, 65), 1) == [1, 2]
    out = fit_walls(world, cm, TABLE, wall_cells=1, fixed=np.zeros(cm.shape, bool), max_shift=3, max_thickness=4,
                    log_cost=10.0, segment_cells=5, lines=lines)
    assert np.all(out.classes_world[10, 60:66] == CellClass.FREE), "the door stays open"
    for cut in out.slants[1]:
        d = (10 - cut.row0) * cut.normal_row + (np.arange(60, 66) - cut.col0) * cut.normal_col
        assert np.all(d < -cut.thickness), "no cut gives up the cells of the unit's door"


def test_a_plan_of_a_slanted_room_draws_the_slanted_wall_and_leaves_the_units_alone() -> None:
    occ = np.where(_slanted_room() == CellClass.FREE, 0, np.where(_slanted_room() == CellClass.WALL, 100, -1))
    settings = FloorPlanSettings(chain=ChainSettings(iterations=1500, seed=1))
    plan = floor_plan(occ.astype(np.int8), resolution_m=RES, settings=settings)
    flat = floor_plan(occ.astype(np.int8), resolution_m=RES, settings=replace(settings, slant_min_angle_rad=None))
    assert plan.world == flat.world and plan.rooms == flat.rooms and plan.k_units == flat.k_units
    assert flat.slanted_walls == 0 and plan.slanted_walls >= 1
    assert plan.k > flat.k

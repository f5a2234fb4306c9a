"""The floor plan of small drawn maps: units where rooms are, doors where they open, types from shape."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt
import pytest

from services.floor_plan import (
    SEED_SCHEDULE,
    CellClass,
    ChainSettings,
    FloorPlan,
    FloorPlanError,
    FloorPlanSettings,
    Phase,
    Rect,
    UnitType,
    World,
    floor_plan,
    room_labels,
    unit_labels,
)
from services.floor_plan.detectors import Evidence, fsu_candidates
from services.floor_plan.likelihood import classify_map
from services.floor_plan.mapfile import floor_plan_map_file, read_map
from shared.mapfiles import write_map_yaml

RES = 0.05


def _box(occ: npt.NDArray[np.int8], r0: int, r1: int, c0: int, c1: int) -> None:
    """A walled room (walls two cells thick) with free space inside."""
    occ[r0 : r1 + 1, c0 : c1 + 1] = 100
    occ[r0 + 2 : r1 - 1, c0 + 2 : c1 - 1] = 0


def _two_rooms() -> npt.NDArray[np.int8]:
    occ = np.full((80, 120), -1, np.int8)
    _box(occ, 10, 69, 10, 60)
    _box(occ, 10, 69, 59, 109)
    occ[35:48, 59:61] = 0  # the door
    return occ


# table 3.2's phases, four times shorter: small maps settle sooner
SHORT = tuple(Phase(None if p.until is None else p.until // 4, p.probabilities) for p in SEED_SCHEDULE)


def _settings(iterations: int = 2000, seed: int = 1) -> FloorPlanSettings:
    return FloorPlanSettings(chain=ChainSettings(iterations=iterations, seed=seed, schedule=SHORT),
                             warm_start_iteration=1001)


def test_two_rooms_joined_by_a_door_give_two_units_and_one_door() -> None:
    plan = floor_plan(_two_rooms(), resolution_m=RES, settings=_settings())
    assert len(plan.units) == 2
    assert len(plan.doors) == 1
    assert set(plan.doors[0].units) == {u.id for u in plan.units}
    assert plan.adjacency == [tuple(sorted(u.id for u in plan.units))]
    assert all(u.unit_type is UnitType.ROOM for u in plan.units)
    # the world explains the map better than an empty one does
    assert plan.k > float(np.mean(plan.classes_map == CellClass.UNKNOWN))


def test_a_long_unit_with_several_doors_is_a_corridor() -> None:
    occ = np.full((90, 200), -1, np.int8)
    _box(occ, 60, 85, 5, 194)  # corridor 1.3 m x 9.5 m
    for c0 in (5, 70, 135):
        _box(occ, 5, 61, c0, c0 + 60)
        occ[60:62, c0 + 20 : c0 + 35] = 0  # door from the room into the corridor
    plan = floor_plan(occ, resolution_m=RES, settings=_settings(3000))
    corridor = max(plan.units, key=lambda u: u.rect.cols / u.rect.rows)
    assert corridor.unit_type is UnitType.CORRIDOR
    assert len([d for d in plan.doors if corridor.id in d.units]) >= 2


def test_solid_blocks_are_obstacles_the_world_draws_as_walls() -> None:
    occ = np.full((80, 120), 100, np.int8)  # the outside filled, as some maps draw it
    _box(occ, 10, 69, 10, 109)
    occ[30:50, 40:80] = 100  # a solid block (a rack drawn solid) in the middle of the room
    plan = floor_plan(occ, resolution_m=RES, settings=_settings())
    assert np.all(plan.classes_world[:5] == CellClass.WALL)
    assert np.all(plan.classes_world[33:47, 43:77] == CellClass.WALL)
    assert plan.k > float(np.mean(plan.classes_map == CellClass.WALL))
    # reported as obstacles in map metres: the block (2 m x 1 m at x 2..4 m, y 1.5..2.5 m) is one of them
    block = [poly for poly in plan.obstacles if all(1.9 <= x <= 4.1 and 1.4 <= y <= 2.6 for x, y in poly[0])]
    assert len(block) == 1
    outside = [poly for poly in plan.obstacles if len(poly) == 2]  # the filled outside, the room its hole
    assert len(outside) == 1
    assert not plan.standing[plan.obstacles.index(outside[0])], "the filled outside is no block in the building"
    assert plan.standing[plan.obstacles.index(block[0])]


def test_a_hall_with_racks_drawn_solid_is_one_unit_around_them_and_the_racks_are_obstacles() -> None:
    occ = np.full((160, 260), -1, np.int8)
    _box(occ, 10, 149, 10, 249)  # a 12 m x 7 m hall
    racks = ((40, 55), (75, 90), (110, 125))
    for r0, r1 in racks:
        occ[r0 : r1 + 1, 40:220] = 100  # rack rows drawn solid, 0.8 m deep
    plan = floor_plan(occ, resolution_m=RES, settings=_settings(3000))
    assert len(plan.units) == 1, "the racks stand in one unit; they do not cut the hall into aisles"
    for r0, r1 in racks:
        assert np.all(plan.classes_world[r0 : r1 + 1, 40:220] == CellClass.WALL)
        assert not unit_labels(plan)[r0 : r1 + 1, 40:220].any(), "no rack cell is a unit's free space"
        y0, y1 = r0 * RES, (r1 + 1) * RES
        found = [poly for poly in plan.obstacles
                 if all(1.9 <= x <= 11.1 and y0 - 0.1 <= y <= y1 + 0.1 for x, y in poly[0])]
        assert len(found) == 1, "each rack row is reported as an obstacle"
        assert plan.standing[plan.obstacles.index(found[0])], "a rack stands in the hall"


def test_units_png_labels_only_free_cells_one_id_per_unit() -> None:
    plan = floor_plan(_two_rooms(), resolution_m=RES, settings=_settings())
    labels = unit_labels(plan)
    assert set(np.unique(labels)) == {0} | {u.id for u in plan.units}
    assert not labels[plan.classes_map != CellClass.FREE].any()
    assert labels[plan.classes_map == CellClass.FREE].all(), "every free cell is some unit's, as in segments.png"


def test_two_rooms_through_a_door_are_two_rooms_and_an_l_shaped_room_is_one() -> None:
    plan = floor_plan(_two_rooms(), resolution_m=RES, settings=_settings())
    assert len(plan.rooms) == 2
    rooms = room_labels(plan)
    left, right = rooms[40, 30], rooms[40, 85]
    assert left and right and left != right
    occ = np.full((90, 110), -1, np.int8)
    occ[5:85, 5:45] = 100
    occ[50:85, 5:105] = 100
    occ[7:83, 7:43] = 0
    occ[52:83, 7:103] = 0  # an L: a leg 1.8 m wide and a foot 4.8 m long, no wall between them
    plan = floor_plan(occ, resolution_m=RES, settings=_settings(3000))
    rooms = room_labels(plan)
    assert len(set(np.unique(rooms[occ == 0]))) == 1, "one room over all of the L's free space"


def test_a_warm_start_keeps_the_ids_of_units_that_still_exist() -> None:
    occ = _two_rooms()
    first = floor_plan(occ, resolution_m=RES, settings=_settings())
    grown = np.full((80, 170), -1, np.int8)
    grown[:, :120] = occ
    _box(grown, 10, 69, 108, 160)
    grown[30:40, 108:110] = 0
    second = floor_plan(grown, resolution_m=RES, settings=_settings(1000), start=first.world)
    before = {u.rect: u.id for u in first.units}
    kept = [u for u in second.units if u.rect in before]
    assert kept and all(before[u.rect] == u.id for u in kept)
    assert len(second.units) >= 3


def test_independent_chains_keep_the_world_of_the_highest_posterior() -> None:
    def fit(restarts: int, start: World | None = None) -> FloorPlan:
        settings = _settings(400)
        settings = replace(settings, chain=replace(settings.chain, restarts=restarts))
        return floor_plan(_two_rooms(), resolution_m=RES, settings=settings, start=start)

    one, three = fit(1), fit(3)
    assert three.iterations == 3 * one.iterations  # the first chain is the one chain of restarts=1
    assert three.log_posterior >= one.log_posterior
    # a warm start carries its world on in one chain
    assert fit(3, start=three.world).iterations == 400


def test_the_chain_stops_at_its_iteration_and_time_bounds() -> None:
    plan = floor_plan(_two_rooms(), resolution_m=RES, settings=_settings(iterations=40))
    assert plan.iterations == 40 * ChainSettings().restarts  # every chain of a cold start
    timed = FloorPlanSettings(chain=ChainSettings(iterations=10**9, max_seconds=0.2))
    assert floor_plan(_two_rooms(), resolution_m=RES, settings=timed).iterations < 10**9


@pytest.mark.parametrize(
    ("occ", "match"),
    [
        (np.full((50, 50), -1, np.int8), "no free cell"),
        (np.zeros((1, 1), np.int8), "at least 3x3"),
        (np.zeros((0, 10), np.int8), "at least 3x3"),
        (np.zeros((4, 4, 4), np.int8), "2-D"),
    ],
)
def test_maps_without_anything_to_explain_are_refused(occ: npt.NDArray[np.int8], match: str) -> None:
    with pytest.raises(FloorPlanError, match=match):
        floor_plan(occ, resolution_m=RES)


def test_bad_map_files_give_clear_errors(tmp_path: Path) -> None:
    (tmp_path / "notes.txt").write_text("hello")
    with pytest.raises(FloorPlanError, match="neither a map_server YAML nor an image"):
        read_map(tmp_path / "notes.txt")
    (tmp_path / "fake.png").write_text("not a png")
    with pytest.raises(FloorPlanError, match="not a readable image"):
        read_map(tmp_path / "fake.png", resolution_m=RES)
    with pytest.raises(FloorPlanError, match="give its resolution"):
        read_map(tmp_path / "fake.png")
    (tmp_path / "bad.yaml").write_text("image: map.pgm\nresolution: fast\norigin: [0, 0, 0]\n")
    with pytest.raises(FloorPlanError, match="bad resolution"):
        read_map(tmp_path / "bad.yaml")
    with pytest.raises(FloorPlanError, match="does not exist"):
        read_map(tmp_path / "missing.yaml")


def test_map_file_outputs_agree_with_the_plan(tmp_path: Path) -> None:
    yaml_path = tmp_path / "map" / "occupancy.yaml"
    write_map_yaml(yaml_path, _two_rooms(), resolution_m=RES, origin_x_m=-1.0, origin_y_m=2.0)
    plan = floor_plan_map_file(yaml_path, tmp_path / "out", settings=_settings())
    collection = json.loads((tmp_path / "out" / "floor_plan.geojson").read_text())
    kinds = [f["properties"]["kind"] for f in collection["features"]]
    assert kinds.count("unit") == len(plan.units) and kinds.count("door") == len(plan.doors)
    xs = [p[0] for f in collection["features"] if f["properties"]["kind"] == "unit"
          for p in f["geometry"]["coordinates"][0]]
    assert min(xs) > -1.0  # in map coordinates: right of the origin
    units = cv2.imread(str(tmp_path / "out" / "units.png"), cv2.IMREAD_UNCHANGED)
    assert units is not None and units.shape == plan.classes_map.shape and units.dtype == np.uint16
    rooms = cv2.imread(str(tmp_path / "out" / "rooms.png"), cv2.IMREAD_UNCHANGED)
    assert rooms is not None and rooms.shape == plan.classes_map.shape and rooms.dtype == np.uint16
    assert set(np.unique(rooms)) == {0} | set(range(1, len(plan.rooms) + 1))
    assert all(f["properties"]["rooms"] for f in collection["features"] if f["properties"]["kind"] == "unit")
    assert (tmp_path / "out" / "overview.png").is_file()


def test_robot_positions_seed_candidates_where_the_robot_passed() -> None:
    occ = np.full((80, 160), -1, np.int8)
    _box(occ, 5, 74, 5, 94)  # a big room: the deepest free space
    _box(occ, 20, 59, 93, 140)  # a smaller one beside it
    classes = classify_map(occ)
    unexplained = np.full(classes.shape, CellClass.UNKNOWN, np.uint8)
    evidence = Evidence(classes)
    only_deepest = fsu_candidates(classes, unexplained, evidence, wall_cells=2, min_inner_cells=10, max_candidates=1)
    assert all(c.rect.c1 <= 96 for c in only_deepest), "without positions the one candidate is the big room"
    passed = fsu_candidates(classes, unexplained, evidence, wall_cells=2, min_inner_cells=10, max_candidates=1,
                            positions_rc=np.array([[40, 120]]))

    def small_room(rect: Rect) -> bool:
        return rect.c0 >= 93 and rect.r0 <= 22 and rect.r1 >= 57

    assert any(small_room(c.rect) for c in passed), "the room the robot passed gets its own candidate"
    plan = floor_plan(occ, resolution_m=RES, settings=_settings(1500), trajectory_xy_m=np.array([[6.0, 2.0]]))
    assert any(small_room(u.rect) for u in plan.units)


def test_units_take_the_wall_thickness_the_map_is_drawn_with() -> None:
    occ = np.full((80, 120), -1, np.int8)
    for r0, r1, c0, c1 in ((10, 69, 10, 60), (10, 69, 60, 109)):  # walls one cell thick, one shared
        occ[r0 : r1 + 1, c0 : c1 + 1] = 100
        occ[r0 + 1 : r1, c0 + 1 : c1] = 0
    occ[35:48, 60] = 0  # the door
    thin = floor_plan(occ, resolution_m=RES, settings=_settings())
    thick = floor_plan(occ, resolution_m=RES, settings=replace(_settings(), wall_m=0.1))
    assert len(thin.units) == 2
    drawn = thin.classes_world == CellClass.WALL
    # every wall the world draws is a wall of the map, and it predicts more cells than two-cell walls do
    assert np.all(thin.classes_map[drawn] == CellClass.WALL)
    assert thin.k > thick.k


def test_floor_plan_reads_a_bare_image_with_its_own_unknown_grey(tmp_path: Path) -> None:
    from PIL import Image

    grey = np.full((80, 120), 230, np.uint8)  # unknown drawn light grey (map_server's thresholds call it free)
    occ = _two_rooms()[::-1]
    grey[occ == 0] = 255
    grey[occ == 100] = 0
    Image.fromarray(grey).save(tmp_path / "map.png")
    read, _, _ = read_map(tmp_path / "map.png", resolution_m=RES)
    assert np.array_equal(read, _two_rooms())


def test_walls_drawn_light_grey_are_walls_of_the_floor_plan_and_no_room_lies_on_them(tmp_path: Path) -> None:
    from PIL import Image

    grey = np.full((80, 120), 180, np.uint8)  # unknown
    occ = _two_rooms()[::-1]
    grey[occ == 0] = 255
    grey[occ == 100] = 211  # walls filled light grey (map_server's thresholds call it free), as ipa's Freiburg52
    Image.fromarray(grey).save(tmp_path / "map.png")
    read, _, _ = read_map(tmp_path / "map.png", resolution_m=RES)
    drawn = _two_rooms()
    assert np.all(read[drawn == 100] == 100) and np.all(read[drawn == 0] == 0)
    plan = floor_plan(read, resolution_m=RES, settings=_settings())
    rooms = room_labels(plan)
    assert not rooms[drawn == 100].any()
    assert len(np.unique(rooms[20:60, 15:55])) == len(np.unique(rooms[20:60, 65:105])) == 1
    assert rooms[40, 30] != rooms[40, 80]


def _room_with_beams_through_a_window() -> npt.NDArray[np.int8]:
    """A 4 m x 6 m room seen from inside, a window 1.5 m wide in its bottom wall, and the laser's beams through it:
    a cell wide, 4 m into the unknown outside; two desks 0.1 m apart inside (drawn occupied)."""
    occ = np.full((200, 160), -1, np.int8)
    _box(occ, 10, 90, 20, 140)
    occ[89:91, 65:95] = 0
    rays = np.zeros(occ.shape, np.uint8)
    for degrees in range(40, 141, 10):
        a = np.radians(degrees)
        cv2.line(rays, (80, 80), (80 + round(110 * np.cos(a)), 80 + round(110 * np.sin(a))), 1, 1)
    occ[(rays > 0) & (occ == -1)] = 0
    occ[30:50, 40:60] = 100  # two desks with a gap two cells wide between them
    occ[30:50, 62:82] = 100
    return occ


def test_laser_beams_through_a_window_read_unknown_and_the_rooms_free_space_stays_free() -> None:
    occ = _room_with_beams_through_a_window()
    plan = floor_plan(occ, resolution_m=RES, settings=replace(_settings(), trace_max_m=0.15))
    seen = floor_plan(occ, resolution_m=RES, settings=replace(_settings(), trace_max_m=None))
    outside = np.zeros(occ.shape, bool)
    outside[115:, :] = True  # beyond the fan by the window, where the beams have drawn apart
    beams = outside & (occ == 0)
    assert np.all(seen.classes_map[beams] == CellClass.FREE)
    assert np.mean(plan.classes_map[beams] == CellClass.UNKNOWN) > 0.9, "a beam's trace is not space seen free"
    inside = occ[12:89, 22:139] == 0
    assert np.array_equal(plan.classes_map[12:89, 22:139][inside], seen.classes_map[12:89, 22:139][inside]), \
        "the room's floor, the window and the gap between the desks stay free"
    assert plan.k > seen.k


def test_a_room_whose_floor_reads_as_beam_traces_in_part_stays_one_room_with_every_free_cell_labelled() -> None:
    """A laser map's room with a band of clutter dots across its floor (unknown specks two cells apart: the free cells
    between them are narrow runs beside unknown, as the traces of beams are): the traces' reading must not cut the
    room at the band, and the room's label covers the band's free cells as the map draws them."""
    occ = np.full((80, 120), -1, np.int8)
    _box(occ, 10, 69, 10, 109)
    band = np.zeros(occ.shape, bool)
    band[38:43, 12:108] = True
    dots = band & (np.arange(80)[:, None] % 2 == 0) & (np.arange(120)[None, :] % 2 == 0)
    occ[dots] = -1
    plan = floor_plan(occ, resolution_m=RES, settings=replace(_settings(), trace_max_m=0.15))
    assert (plan.classes_map[band & (occ == 0)] == CellClass.UNKNOWN).mean() > 0.8, "the band reads as traces"
    rooms = room_labels(plan)
    assert len(plan.rooms) == 1
    assert (rooms[band & (occ == 0)] > 0).all()
    assert len(np.unique(rooms[occ == 0])) == 1


def _grey_edged(tmp_path: Path) -> tuple[npt.NDArray[np.int8], npt.NDArray[np.bool_]]:
    """The two rooms drawn as an image whose walls have a one-pixel light-grey edge on the room side (antialiasing),
    and a light-grey patch in the middle of the left room; read back, with the edge (GridLayer order)."""
    from PIL import Image

    occ = _two_rooms()
    free = occ == 0
    wall = cv2.dilate((occ == 100).astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    edge = free & wall
    grey = np.full(occ.shape, 180, np.uint8)
    grey[free] = 255
    grey[edge] = 235
    grey[35:45, 30:40] = 240  # floor seen free less often, away from every wall
    grey[occ == 100] = 0
    Image.fromarray(grey[::-1].copy()).save(tmp_path / "map.png")
    read, _, _ = read_map(tmp_path / "map.png", resolution_m=RES)
    return read, edge


def test_the_label_images_leave_out_the_grey_edge_along_walls_and_keep_the_floor(tmp_path: Path) -> None:
    read, edge = _grey_edged(tmp_path)
    plan = floor_plan(read, resolution_m=RES, settings=_settings())
    assert np.array_equal(plan.classes_map == CellClass.FREE, _two_rooms() == 0), "the edge still reads free"
    for labels in (unit_labels(plan), room_labels(plan)):
        assert not labels[edge].any(), "the grey edge of a wall is no room's (the ipa ground truth's convention)"
        assert labels[(_two_rooms() == 0) & ~edge].all(), "clear floor and a grey patch away from walls are labelled"
    assert room_labels(plan)[40, 35] == room_labels(plan)[20, 20], "the grey patch belongs to its room"


def test_the_wall_edge_changes_no_unit_and_no_k_and_can_be_turned_off(tmp_path: Path) -> None:
    read, _ = _grey_edged(tmp_path)
    plain = floor_plan(_two_rooms(), resolution_m=RES, settings=_settings())
    edged = floor_plan(read, resolution_m=RES, settings=_settings())
    assert edged.world.units == plain.world.units and edged.k == plain.k
    every = floor_plan(read, resolution_m=RES, settings=replace(_settings(), fringe_m=None))
    assert room_labels(every)[_two_rooms() == 0].all(), "with the setting off every free cell is labelled"

"""The whole decomposition on literal offices and seeded synthetic warehouses."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from services.grid_decomposition import Connection, Decomposition, DecompositionError, Resolution, decompose
from shared.vocabulary import PlaceLabel
from tests.api.warehouse_map import warehouse
from tests.services.grid_decomposition.warehouse import Warehouse, cell_labels, synthetic_warehouse


def _two_rooms_and_a_door() -> np.ndarray:
    """8 x 4 m at 5 cm: two rooms split by a wall with a 0.9 m door; unknown border."""
    occ = np.full((100, 180), -1, dtype=np.int8)
    occ[5:95, 5:175] = 100
    occ[8:92, 8:172] = 0
    occ[8:92, 88:91] = 100
    occ[40:58, 88:91] = 0
    return occ


def test_decompose_splits_two_rooms_at_their_door() -> None:
    d = decompose(_two_rooms_and_a_door(), resolution_m=0.05)
    assert len(d.regions) == 2
    left, right = d.segments[50, 40], d.segments[50, 140]
    assert left > 0 and right > 0 and left != right
    assert d.topology.edges[left, right]["connection"] == Connection.DOOR.value
    assert {info.label for info in d.regions.values()} == {PlaceLabel.ROOM}


def test_a_region_under_a_rooms_least_area_is_never_a_room() -> None:
    d = decompose(_two_rooms_and_a_door(), resolution_m=0.05, room_min_area_m2=40.0)  # 34 m² of floor in all
    assert d.regions and all(info.label is not PlaceLabel.ROOM for info in d.regions.values())


def test_two_doors_with_a_post_between_them_keep_two_rooms() -> None:
    # 10 x 13 m at 5 cm, a wall down the middle opened 3 m wide: two 1.4 m doors and a 0.2 m
    # post, drawn as a speck (a real map's door frame), too wide as one doorway
    occ = np.full((200, 260), -1, dtype=np.int8)
    occ[5:195, 5:255] = 100
    occ[8:192, 8:252] = 0
    occ[8:192, 128:131] = 100
    occ[70:130, 128:131] = 0
    occ[98:102, 128:131] = 100
    d = decompose(occ, resolution_m=0.05)
    left, right = d.segments[40, 60], d.segments[160, 200]
    assert left > 0 and right > 0 and left != right
    assert len(d.regions) == 2


def test_segments_and_labels_cover_exactly_the_free_space() -> None:
    occ = _two_rooms_and_a_door()
    d = decompose(occ, resolution_m=0.05, origin_xy_m=(-2.0, 3.0))
    free = occ == 0
    assert ((d.segments > 0) == free).all()
    assert ((d.labels > 0) == free).all()
    assert d.segments.shape == d.labels.shape == occ.shape


def _check_warehouse(wh: Warehouse, d: Decomposition) -> None:
    """Every cross-aisle junction found, no pallet cell labelled corridor, 95 % of free space right."""
    missed = [(x, y) for x, y in wh.junctions_px if d.labels[round(y), round(x)] != PlaceLabel.JUNCTION.value]
    assert not missed
    cells = cell_labels(d.labels, wh)
    assert not (cells == PlaceLabel.CORRIDOR.value).any()
    assert (cells == PlaceLabel.STORAGE.value).mean() > 0.95
    free = wh.occupancy == 0
    assert (d.labels[free] == wh.truth[free]).mean() >= 0.95


@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize(
    "options",
    [{}, {"aisle_width_m": (1.8, 2.2)}, {"aisle_width_m": (3.5, 4.5)}, {"rotation_rad": 0.6}],
    ids=["plain", "narrow", "wide", "turned"],
)
def test_every_cross_aisle_is_a_junction_and_no_pallet_cell_a_corridor(seed: int, options: dict[str, Any]) -> None:
    wh = synthetic_warehouse(seed, n_double_rows=3, n_sections=2, bays_per_section=5, **options)
    _check_warehouse(wh, decompose(wh.occupancy, resolution_m=wh.resolution_m))


def test_a_second_building_at_another_angle_is_decomposed_along_its_own_lines() -> None:
    wh = synthetic_warehouse(1, n_double_rows=2, n_sections=2, bays_per_section=4, rotated_block_rad=0.5)
    d = decompose(wh.occupancy, resolution_m=wh.resolution_m)
    assert d.texture_regions.max() == 1
    angles = [{round(math.degrees(ln.angle_rad)) % 90 for ln in g.lines} for g in d.line_groups]
    assert sorted(angles, key=min) == [{0}, {61}]
    _check_warehouse(wh, d)


def test_warehouse_regions_are_aisles_junctions_and_pallet_cells() -> None:
    wh = synthetic_warehouse(4, n_double_rows=2, n_sections=2, bays_per_section=4)
    d = decompose(wh.occupancy, resolution_m=wh.resolution_m)
    labels = [info.label for info in d.regions.values()]
    assert labels.count(PlaceLabel.STORAGE) > labels.count(PlaceLabel.CORRIDOR) > 1
    assert PlaceLabel.JUNCTION in labels
    kinds = {data["connection"] for _, _, data in d.topology.edges(data=True)}
    assert Connection.STORAGE_ACCESS.value in kinds


def test_fine_resolution_has_at_least_as_many_faces_as_coarse() -> None:
    wh = synthetic_warehouse(5, n_double_rows=2, n_sections=1, bays_per_section=4)
    coarse = decompose(wh.occupancy, resolution_m=wh.resolution_m, resolution=Resolution.COARSE)
    fine = decompose(wh.occupancy, resolution_m=wh.resolution_m, resolution=Resolution.FINE)
    assert fine.subdivision.n_faces >= coarse.subdivision.n_faces


def test_label_overrides_relabel_a_category() -> None:
    occ = _two_rooms_and_a_door()
    auto = decompose(occ, resolution_m=0.05, n_categories=3)
    category = int(auto.face_labels.category[auto.subdivision.face_image[50, 40]])
    forced = decompose(occ, resolution_m=0.05, n_categories=3, label_overrides={category: PlaceLabel.STORAGE})
    assert forced.labels[50, 40] == PlaceLabel.STORAGE.value
    assert forced.face_labels.category_labels[category] is PlaceLabel.STORAGE


@pytest.mark.parametrize("label", [PlaceLabel.ROOM, PlaceLabel.UNIDENTIFIED])
def test_overriding_a_storage_category_renames_its_places_and_keeps_every_region(label: PlaceLabel) -> None:
    wh = synthetic_warehouse(4, n_double_rows=2, n_sections=2, bays_per_section=4)
    auto = decompose(wh.occupancy, resolution_m=wh.resolution_m)
    storage = [c for c, lab in auto.face_labels.category_labels.items() if lab is PlaceLabel.STORAGE]
    assert storage
    forced = decompose(wh.occupancy, resolution_m=wh.resolution_m, label_overrides=dict.fromkeys(storage, label))
    assert len(forced.regions) == len(auto.regions)
    assert (forced.segments == auto.segments).all()
    in_face = (auto.subdivision.face_image > 0) & (auto.labels > 0)
    renamed = np.isin(auto.face_labels.category[auto.subdivision.face_image], storage) & in_face
    assert renamed.any() and (forced.labels[renamed] == label.value).all()
    assert (forced.labels[in_face & ~renamed] == auto.labels[in_face & ~renamed]).all()
    assert sum(info.label is label for info in forced.regions.values()) >= sum(
        info.label is PlaceLabel.STORAGE for info in auto.regions.values()
    ) // 2


@pytest.mark.parametrize(
    ("occupancy", "message"),
    [
        (np.zeros((0, 0), np.int8), "at least 2 x 2"),
        (np.zeros((1, 1), np.int8), "at least 2 x 2"),
        (np.full((20, 20), -1, np.int8), "no free cell"),
        (np.full((20, 20), 100, np.int8), "no free cell"),
        (np.full((20, 20), 120, np.int16), "values must be"),
        (np.zeros((4, 4), np.float32), "integer"),
    ],
)
def test_bad_grids_raise_decomposition_error(occupancy: np.ndarray, message: str) -> None:
    with pytest.raises(DecompositionError, match=message):
        decompose(occupancy, resolution_m=0.05)


def test_bad_resolution_raises_decomposition_error() -> None:
    with pytest.raises(DecompositionError, match="resolution_m"):
        decompose(_two_rooms_and_a_door(), resolution_m=0.0)


def test_rack_uprights_do_not_split_an_axis_aligned_warehouse_into_texture_regions() -> None:
    wh = synthetic_warehouse(0)
    d = decompose(wh.occupancy, resolution_m=wh.resolution_m)
    assert d.texture_regions.max() == 0


def test_a_cross_aisle_one_bay_wide_is_corridor_not_storage() -> None:
    """The simulator's hall: 2.7 m bays, 3.0 m cross and end aisles (a bay-sized rectangle between uprights)."""
    wh = warehouse()
    free = wh.grids.occupancy == 0
    aisle = free & np.isin(wh.grids.labels, [PlaceLabel.CORRIDOR.value, PlaceLabel.JUNCTION.value])
    storage = free & (wh.grids.labels == PlaceLabel.STORAGE.value)
    assert (wh.decomposition.labels[aisle] == PlaceLabel.STORAGE.value).mean() < 0.01
    assert (wh.decomposition.labels[storage] == PlaceLabel.STORAGE.value).mean() > 0.9
    kinds = {info.label for info in wh.decomposition.regions.values()}
    assert {PlaceLabel.CORRIDOR, PlaceLabel.JUNCTION, PlaceLabel.STORAGE} <= kinds



def _road_grid() -> np.ndarray:
    """Roads 0.75 m wide between 2.25 m square solid blocks, 3 x 3 blocks (5 cm, unknown outside)."""
    occ = np.full((200, 200), -1, dtype=np.int8)
    occ[10:190, 10:190] = 100
    occ[15:185, 15:185] = 0
    for r in range(30, 170, 60):
        for c in range(30, 170, 60):
            occ[r : r + 45, c : c + 45] = 100
    return occ


def test_a_grid_of_roads_is_split_into_corridors_and_junctions_linked_in_the_topology() -> None:
    d = decompose(_road_grid(), resolution_m=0.05)
    kinds = {info.label for info in d.regions.values()}
    assert kinds == {PlaceLabel.CORRIDOR, PlaceLabel.JUNCTION}
    junctions = [r for r, info in d.regions.items() if info.label is PlaceLabel.JUNCTION]
    assert len(junctions) >= 4  # the four crossings inside the grid
    for r in junctions:
        corridors = [n for n in d.topology.neighbors(r) if d.regions[n].label is PlaceLabel.CORRIDOR]
        assert len(corridors) >= 2
        assert all(d.topology.edges[r, n]["connection"] == Connection.CONNECTED.value for n in corridors)
    # road pieces are linked through the crossings, not to each other
    assert not [(a, b) for a, b in d.topology.edges if d.regions[a].label is d.regions[b].label is PlaceLabel.CORRIDOR]


def test_open_floor_of_a_real_home_map_is_never_storage() -> None:
    """ROSE\u00b2 ``no_gt/EX2`` (a real map at an odd angle, no racks): a few rectangles between its
    walls look like pallet cells, yet no region or pixel is storage."""
    from pathlib import Path

    from services.grid_decomposition.mapfile import read_map_file

    path = Path(__file__).resolve().parents[4] / "shared" / "data" / "maps" / "rose2" / "no_gt" / "EX2.png"
    if not path.exists():
        pytest.skip(f"{path} is absent: the ROSE2 maps are not on this machine")
    occ, _, _ = read_map_file(path, resolution_m=0.05)
    d = decompose(occ, resolution_m=0.05)
    assert len(d.rack_rows_px) == 0
    assert not (d.labels == PlaceLabel.STORAGE.value).any()
    assert all(r.label is not PlaceLabel.STORAGE for r in d.regions.values())
    assert len(d.regions) > 3  # and it is not one region


@pytest.mark.parametrize("rotation_rad", [0.0, 0.3])
def test_a_rack_hall_skips_the_room_stage_with_the_same_regions(
    monkeypatch: pytest.MonkeyPatch, rotation_rad: float
) -> None:
    """Every region of a rack hall lies on its warehouse floors: the room stage and the steps after it that leave such
    regions alone are not run, and the decomposition is the same as with them run."""
    from services.grid_decomposition import pipeline
    from services.simulator.rackmaps import RackStyle, rack_hall_map

    hall = rack_hall_map(
        0, style=RackStyle.PALLET_HEIGHT, rotation_rad=rotation_rad, n_double_rows=2, bays_per_section=4
    )
    called: list[str] = []

    def spy(name: str, step: Any) -> Any:
        def run(*args: Any, **kwargs: Any) -> Any:
            called.append(name)
            return step(*args, **kwargs)
        return run

    steps = ("segment_rooms", "split_at_short_walls", "join_furnished_pieces", "split_fans", "merge_passages")
    for name in (*steps, "wall_furniture"):
        monkeypatch.setattr(pipeline, name, spy(name, getattr(pipeline, name)))
    skipped = decompose(hall.occupancy, resolution_m=hall.resolution_m)
    assert called == []
    monkeypatch.setattr(pipeline, "_on_floors_only", lambda segments, floor: False)  # the room stage run
    run = decompose(hall.occupancy, resolution_m=hall.resolution_m)
    assert {"segment_rooms", "split_fans", "wall_furniture"} <= set(called)
    assert np.array_equal(skipped.segments, run.segments)
    assert np.array_equal(skipped.labels, run.labels)
    assert skipped.regions == run.regions
    assert sorted(skipped.topology.edges(data=True)) == sorted(run.topology.edges(data=True))

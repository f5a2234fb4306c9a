"""Racks however a map draws them (solid blocks, upright dots, pallet faces) are rack rows and storage; the
strips between them aisles with a junction at each end; pallets standing on open floor are no rooms."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from services.grid_decomposition import decompose
from services.grid_decomposition.arrays import components
from services.grid_decomposition.racks import (
    RackLayout,
    _interval_image,
    _transposed,
    _turn,
    face_places,
    find_racks,
    floor_objects,
)
from services.simulator import ground_truth_grids, load_world
from services.simulator.rackmaps import RackMap, RackStyle, rack_hall_map
from shared.vocabulary import PlaceLabel
from tests.services.grid_decomposition.test_rooms import RES, _furnish, _office_row


def _small(style: RackStyle, seed: int = 0, rotation_rad: float = 0.0) -> RackMap:
    return rack_hall_map(seed, style=style, rotation_rad=rotation_rad, n_double_rows=2, bays_per_section=4)


def _box(mask: np.ndarray) -> tuple[int, int, int, int]:
    rows, cols = np.nonzero(mask)
    return int(rows.min()), int(rows.max()) + 1, int(cols.min()), int(cols.max()) + 1


def test_the_strip_between_two_solid_racks_is_one_corridor_region_with_a_junction_at_each_end() -> None:
    hall = _small(RackStyle.SOLID)
    d = decompose(hall.occupancy, resolution_m=hall.resolution_m)
    free = hall.occupancy == 0
    # the aisle between the two double rows: between the end cross aisle's and the middle cross aisle's junctions
    boxes = [_box(hall.junctions == k) for k in range(1, int(hall.junctions.max()) + 1)]
    r0, r1 = sorted({(b[0], b[1]) for b in boxes})[1]  # the middle aisle band (the others are perimeter aisles)
    left, middle = sorted((b for b in boxes if (b[0], b[1]) == (r0, r1)), key=lambda b: b[2])[:2]
    strip = np.zeros(free.shape, dtype=bool)
    strip[r0:r1, left[3] : middle[2]] = True
    strip &= free
    ids, counts = np.unique(d.segments[strip], return_counts=True)
    aisle = int(ids[np.argmax(counts)])
    assert counts.max() == strip.sum()  # one region
    assert d.regions[aisle].label is PlaceLabel.CORRIDOR
    for end in (left, middle):
        inside = np.zeros(free.shape, dtype=bool)
        inside[end[0] : end[1], end[2] : end[3]] = True
        junction = int(np.bincount(d.segments[inside & free]).argmax())
        assert d.regions[junction].label is PlaceLabel.JUNCTION
        assert d.topology.has_edge(aisle, junction)


@pytest.mark.parametrize("rotation_rad", [0.0, 0.35])
def test_every_solid_rack_is_a_rack_row(rotation_rad: float) -> None:
    hall = _small(RackStyle.SOLID, seed=1, rotation_rad=rotation_rad)
    d = decompose(hall.occupancy, resolution_m=hall.resolution_m)
    assert len(d.rack_rows_px) == len(hall.racks_px)
    for truth in hall.racks_px:
        centre = truth.mean(axis=0)
        inside = [
            cv2.pointPolygonTest(row.astype(np.float32), (float(centre[0]), float(centre[1])), False) >= 0
            for row in d.rack_rows_px
        ]
        assert sum(inside) == 1
    assert not any(r.label is PlaceLabel.ROOM for r in d.regions.values())


@pytest.mark.parametrize("style", [RackStyle.UPRIGHTS, RackStyle.PALLET_HEIGHT])
def test_rows_of_upright_dots_and_pallet_faces_with_unknown_behind_are_racks(style: RackStyle) -> None:
    hall = _small(style, seed=2, rotation_rad=math.radians(20))
    d = decompose(hall.occupancy, resolution_m=hall.resolution_m)
    free = hall.occupancy == 0
    storage = free & (hall.truth == PlaceLabel.STORAGE.value)
    assert (d.labels[storage] == PlaceLabel.STORAGE.value).mean() > 0.9
    assert (d.labels[storage] == PlaceLabel.CORRIDOR.value).mean() < 0.05
    for k in range(1, int(hall.junctions.max()) + 1):  # every cross aisle is a junction region
        seg = d.segments[(hall.junctions == k) & free]
        assert d.regions[int(np.bincount(seg).argmax())].label is PlaceLabel.JUNCTION


def test_a_pallet_on_open_floor_is_no_room_and_open_floor_is_no_storage() -> None:
    hall = rack_hall_map(0, style=RackStyle.DEPOT, rotation_rad=0.2)
    assert len(hall.pallets_px) > 0
    d = decompose(hall.occupancy, resolution_m=hall.resolution_m)
    free = hall.occupancy == 0
    assert not any(r.label is PlaceLabel.ROOM for r in d.regions.values())
    assert not (d.labels[free] == PlaceLabel.STORAGE.value).any()
    assert len(d.rack_rows_px) == 0


def test_the_pallets_on_open_floor_are_floor_objects_however_the_occupied_cells_are_labelled() -> None:
    hall = rack_hall_map(0, style=RackStyle.DEPOT, rotation_rad=0.2)
    occupied, known = hall.occupancy > 65, hall.occupancy >= 0
    objects = floor_objects(occupied, known, resolution_m=hall.resolution_m)
    assert objects.any()
    shared = floor_objects(occupied, known, resolution_m=hall.resolution_m, labelled=components(occupied))
    assert np.array_equal(objects, shared)


def test_an_office_has_no_racks() -> None:
    occ = _furnish(_office_row())
    layout = find_racks(occ == 100, occ >= 0, resolution_m=RES, angles_rad=[0.0])
    assert not layout.cells.any() and len(layout.rows_px) == 0


@pytest.mark.parametrize("style", [RackStyle.PALLET_HEIGHT, RackStyle.MIXED])
def test_a_hall_explored_up_to_its_racks_ends_keeps_its_racks(style: RackStyle) -> None:
    # the robot has seen the first section only: everything right of the middle cross aisle is unknown
    hall = _small(style)
    boxes = [_box(hall.junctions == k) for k in range(1, int(hall.junctions.max()) + 1)]
    columns = sorted({(b[2] + b[3]) // 2 for b in boxes})
    cut = columns[len(columns) // 2]
    occ = hall.occupancy.copy()
    occ[:, cut:] = -1
    d = decompose(occ, resolution_m=hall.resolution_m)
    free = occ == 0
    storage = free & (hall.truth == PlaceLabel.STORAGE.value)
    assert len(d.rack_rows_px) > 0
    assert (d.labels[storage] == PlaceLabel.STORAGE.value).mean() > 0.9
    assert (d.labels[storage] == PlaceLabel.CORRIDOR.value).mean() < 0.05
    seen = [k for k, b in enumerate(boxes, start=1) if b[3] < cut]
    for k in seen:  # every cross aisle seen whole is a junction region of its own
        seg = d.segments[(hall.junctions == k) & free]
        assert d.regions[int(np.bincount(seg).argmax())].label is PlaceLabel.JUNCTION
    assert len(d.regions) > len(seen)


@pytest.mark.parametrize("angle", [0.0, 1e-12, 0.3, -0.3, math.pi / 4, -math.pi / 4])
def test_rack_places_rasterise_as_a_search_per_pixel_would(angle: float) -> None:
    rng = np.random.default_rng(7)
    matrix, _ = _turn((37, 53), angle)
    cols, rows = np.arange(53, dtype=np.float64), np.arange(37, dtype=np.float64)
    u = (matrix[0, 0] * cols, matrix[0, 1] * rows + matrix[0, 2])
    v = (matrix[1, 0] * cols, matrix[1, 1] * rows + matrix[1, 2])
    u_px, v_px = u[0][None, :] + u[1][:, None], v[0][None, :] + v[1][:, None]
    # edges between pixels and exactly on some
    xs = np.sort(np.r_[rng.uniform(u_px.min() - 2, u_px.max() + 2, 6), u_px[5, 7], u_px[20, 40]])
    ys = np.sort(np.r_[rng.uniform(v_px.min() - 2, v_px.max() + 2, 6), v_px[3, 3]])
    ids = rng.integers(0, 50, (ys.size + 1, xs.size + 1)).astype(np.int32)
    expected = ids[np.searchsorted(ys, v_px, side="right"), np.searchsorted(xs, u_px, side="right")]
    assert np.array_equal(_interval_image(xs, ys, u, v, ids), expected)


def test_a_cross_aisle_one_bay_wide_between_loaded_racks_is_no_row_of_pallet_cells() -> None:
    """The demo warehouse (2.7 m bays, 70 % loaded, a 3.0 m cross aisle between its two sections): closed along
    the rows over a bay, the racks ran through the cross aisle, which became storage; a person's faint trace
    left across it (uncertain cells) does not hide it."""
    world = load_world("demo")
    grids = ground_truth_grids(world)
    occupancy = grids.occupancy.copy()
    origin = np.array([grids.origin_x_m, grids.origin_y_m])
    col = int((20.5 - origin[0]) / grids.resolution_m)  # the person walked the middle cross aisle
    for y0_m, y1_m in ((10.9, 11.9), (16.0, 17.0)):  # between the back-to-back rows, every other cell
        rows = slice(int((y0_m - origin[1]) / grids.resolution_m), int((y1_m - origin[1]) / grids.resolution_m), 2)
        occupancy[rows, col] = np.where(occupancy[rows, col] == 0, 40, occupancy[rows, col])
    d = decompose(occupancy, resolution_m=grids.resolution_m, origin_xy_m=tuple(origin))
    free = occupancy == 0

    def cells(polygon: np.ndarray) -> np.ndarray:
        mask = np.zeros(free.shape, np.uint8)
        cv2.fillPoly(mask, [np.round((polygon - origin) / grids.resolution_m - 0.5).astype(np.int32)], 1)
        inside: np.ndarray = (mask > 0) & free
        return inside

    for area in world.areas:
        if area.detail.get("corridor_kind") == "cross_aisle":
            assert (d.labels[cells(area.polygon)] == PlaceLabel.STORAGE.value).mean() < 0.05, area.id
        if area.kind.name == "JUNCTION":  # every crossing of an aisle and a cross aisle
            assert d.regions[int(np.bincount(d.segments[cells(area.polygon)]).argmax())].label is (
                PlaceLabel.JUNCTION), area.id


def test_a_turned_image_is_transposed_as_numpy_transposes_it() -> None:
    rng = np.random.default_rng(0)
    image = rng.random((37, 53)) < 0.3
    for mask in (image, image[3:, ::2]):
        out = _transposed(mask)
        assert out.dtype == np.bool_ and out.flags.c_contiguous
        assert np.array_equal(out, np.ascontiguousarray(mask.T))
    codes = image.astype(np.uint8) * 3
    turned = _transposed(codes)
    assert turned.dtype == np.uint8 and np.array_equal(turned, np.ascontiguousarray(codes.T))


@pytest.mark.parametrize("seed", range(3))
def test_face_places_is_the_majority_place_label_of_each_faces_free_pixels(seed: int) -> None:
    """Counted from runs, the votes are those of a bincount over every free pixel (faces cut across places)."""
    rng = np.random.default_rng(seed)
    h, w, n_faces, n_places = 60, 90, 12, 7
    faces = np.kron(rng.integers(0, n_faces + 1, (6, 9)), np.ones((10, 10), np.int64)).astype(np.int32)
    cells = np.kron(rng.integers(0, n_places + 1, (4, 5)), np.ones((15, 18), np.int64)).astype(np.int32)
    cells[rng.random((h, w)) < 0.05] = 0
    free = rng.random((h, w)) < 0.8
    labels = np.r_[0, rng.choice([PlaceLabel.STORAGE.value, PlaceLabel.CORRIDOR.value], n_places)].astype(np.int64)
    layout = RackLayout(cells, labels, np.zeros((h, w), dtype=bool), np.zeros((0, 4, 2)))
    n_lab = len(PlaceLabel)
    votes = np.bincount(
        faces[free].astype(np.int64) * n_lab + labels[cells[free]], minlength=(n_faces + 1) * n_lab
    ).reshape(n_faces + 1, n_lab)
    best = votes[:, 1:].argmax(axis=1) + 1
    want = np.where(votes[np.arange(n_faces + 1), best] > 0.5 * votes.sum(axis=1), best, 0)
    want[0] = 0
    assert np.array_equal(face_places(faces, n_faces, layout, free), want)

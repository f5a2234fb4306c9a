"""Racks the pillar stage knows as places of the decomposition, and the rack rows the decomposition writes."""

from __future__ import annotations

import dataclasses
import functools
from pathlib import Path

import cv2
import numpy as np
import pytest

from services.grid_decomposition import DecompositionError, decompose
from services.grid_decomposition.known_racks import (
    KnownRacks,
    aisle_crossings,
    aisle_regions,
    footprint_mask,
    footprints,
    known_layout,
)
from services.grid_decomposition.records import RACK_ROW_SOURCE, decomposition_features, rack_row_features
from services.simulator.rackmaps import RackStyle
from shared.store import Feature, GridLayer, MapStore, RevisionWrite
from shared.vocabulary import FeatureKind, PlaceLabel
from tests.api.warehouse_map import bin_features, warehouse
from tests.services.grid_decomposition.warehouse import styled_warehouse


def _aisles() -> list[np.ndarray]:
    """The nav-test world's aisle sections (its ``aisle`` corridors), polygons in metres."""
    return [np.asarray(a.polygon, dtype=np.float64) for a in warehouse().world.areas
            if a.kind.name == "CORRIDOR" and isinstance(a.detail.get("aisle"), int)]


@functools.cache
def _racks_unseen() -> tuple[np.ndarray, GridLayer]:
    """The nav-test world's occupancy with its racks invisible (a lidar under the beams that missed the uprights),
    and its ground-truth grid as a layer."""
    grids = warehouse().grids
    layer = GridLayer("occupancy", grids.occupancy, grids.resolution_m, grids.origin_x_m, grids.origin_y_m)
    bins = footprints(bin_features(warehouse().world), FeatureKind.BIN)
    hidden = footprint_mask(bins, shape=grids.occupancy.shape, resolution_m=grids.resolution_m,
                            origin_xy_m=(grids.origin_x_m, grids.origin_y_m))
    return np.where(hidden, 0, grids.occupancy).astype(np.int8), layer


def _spanning_aisles() -> list[np.ndarray]:
    """The nav-test world's aisles as the pillar stage spans them: from the first bin to the last, through the
    cross aisle between the two sections."""
    out = []
    for number in sorted({a.detail["aisle"] for a in warehouse().world.areas if "aisle" in a.detail}):
        xy = np.vstack([a.polygon for a in warehouse().world.areas if a.detail.get("aisle") == number])
        (x0, y0), (x1, y1) = xy.min(axis=0), xy.max(axis=0)
        out.append(np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]]))
    return out


def test_bins_on_several_levels_share_one_footprint() -> None:
    features = bin_features(warehouse().world)
    assert len({tuple(map(tuple, f)) for f in footprints(features, FeatureKind.BIN)}) == len(
        footprints(features, FeatureKind.BIN)) < len(features)
    assert footprints(features, FeatureKind.CORRIDOR) == []


def test_known_racks_make_storage_and_aisles_where_the_grid_shows_no_rack() -> None:
    occupancy, layer = _racks_unseen()
    origin = (layer.origin_x_m, layer.origin_y_m)
    bins = footprints(bin_features(warehouse().world), FeatureKind.BIN)
    alone = decompose(occupancy, resolution_m=layer.resolution_m, origin_xy_m=origin)
    assert PlaceLabel.STORAGE not in {r.label for r in alone.regions.values()}, "nothing shows a rack"
    known = known_layout(bins, _aisles(), shape=occupancy.shape, resolution_m=layer.resolution_m, origin_xy_m=origin)
    result = decompose(occupancy, resolution_m=layer.resolution_m, origin_xy_m=origin, known_places=known)
    regions = set()
    for ring in bins:  # every pallet cell is storage, a region of its own
        cell = footprint_mask([ring], shape=occupancy.shape, resolution_m=layer.resolution_m, origin_xy_m=origin)
        ids, counts = np.unique(result.segments[cell], return_counts=True)
        main = int(ids[counts.argmax()])
        assert counts.max() > 0.8 * counts.sum() and result.regions[main].label is PlaceLabel.STORAGE
        regions.add(main)
    assert len(regions) == len(bins)
    for ring in _aisles():  # every aisle section is mostly one corridor region
        strip = footprint_mask([ring], shape=occupancy.shape, resolution_m=layer.resolution_m, origin_xy_m=origin)
        ids, counts = np.unique(result.segments[strip], return_counts=True)
        assert counts.max() > 0.8 * counts.sum() and result.regions[int(ids[counts.argmax()])].label is (
            PlaceLabel.CORRIDOR)
    assert PlaceLabel.ROOM not in {r.label for r in result.regions.values()}
    racks = footprint_mask(bins, shape=occupancy.shape, resolution_m=layer.resolution_m, origin_xy_m=origin)
    near = cv2.dilate(racks.astype(np.uint8), np.ones((21, 21), np.uint8)) > 0  # 0.5 m round the bins
    assert not np.any((result.labels == PlaceLabel.STORAGE.value) & ~near), "open floor is never storage"
    floor = (result.labels == PlaceLabel.OPEN_AREA.value).sum() * layer.resolution_m**2
    assert floor > 100.0, "the hall's floor round the racks stays open area"


def test_a_known_layout_refuses_another_grid() -> None:
    occupancy, layer = _racks_unseen()
    with pytest.raises(DecompositionError, match="positive"):
        known_layout([], [], shape=(3, 3), resolution_m=0.0, origin_xy_m=(0.0, 0.0))
    other = known_layout([], [], shape=(5, 5), resolution_m=layer.resolution_m, origin_xy_m=(0.0, 0.0))
    with pytest.raises(DecompositionError, match="known places"):
        decompose(occupancy, resolution_m=layer.resolution_m, known_places=other)


def test_solid_racks_found_in_the_grid_become_rack_row_features() -> None:
    hall = styled_warehouse(0, style=RackStyle.SOLID)
    result = decompose(hall.occupancy, resolution_m=hall.resolution_m, origin_xy_m=(2.0, -1.0))
    rows = decomposition_features(result)[FeatureKind.RACK_ROW]
    assert len(rows) == len(result.rack_rows_px) > 0
    assert len({row.key for row in rows}) == len(rows)
    racks = hall.truth == PlaceLabel.STORAGE.value
    for row in rows:
        assert row.properties["source"] == RACK_ROW_SOURCE and row.properties["length_m"] >= row.properties[
            "depth_m"] > 0
        ring = np.asarray(row.geometry["coordinates"][0][:4])
        inside = footprint_mask([ring], shape=racks.shape, resolution_m=hall.resolution_m, origin_xy_m=(2.0, -1.0))
        assert inside.any() and np.mean(racks[inside] | (hall.occupancy[inside] > 50)) > 0.8, row.key
    # the rows the pillar stage knows are left to it
    known = footprint_mask([np.asarray(r.geometry["coordinates"][0][:4]) for r in rows[:2]], shape=racks.shape,
                           resolution_m=hall.resolution_m, origin_xy_m=(2.0, -1.0))
    assert [r.key for r in rack_row_features(result, known_racks=known)] == [r.key for r in rows[: len(rows) - 2]]


def test_known_racks_are_read_again_only_when_the_pillar_stage_changes_them(tmp_path: Path) -> None:
    store = MapStore(f"sqlite:///{tmp_path / 'aisle.db'}")
    store.upgrade()
    map_id = store.ensure_map("site").id
    racks = KnownRacks()
    assert not racks.refresh(store, map_id) and racks.on_grid(warehouse_layer()) is None
    bins = bin_features(warehouse().world)

    def write(stage: str, features: list[Feature]) -> bool:
        store.write_revision(map_id, RevisionWrite(stage, features={"bin": features}))
        return racks.note(store.revisions(map_id, limit=1000)[-1:])

    assert write("pillar_mapping", bins) and racks.refresh(store, map_id)
    assert len(racks.bins) == len(footprints(bins, FeatureKind.BIN)) and not racks.refresh(store, map_id)
    assert not write("pillar_mapping", bins), "the same bins again change nothing"
    assert not write("ground_truth", bins[:3]), "only the pillar stage's bins count"
    top = max(b.properties["level"] for b in bins)
    lower = [b for b in bins if b.properties["level"] != top]
    assert write("pillar_mapping", lower) and not racks.refresh(store, map_id), "a level less: the same footprints"
    jittered = [dataclasses.replace(b, geometry={"type": "Polygon", "coordinates": [
        [[x + 0.01, y - 0.01] for x, y in b.geometry["coordinates"][0]]]}) for b in reversed(lower)]
    assert write("pillar_mapping", jittered) and not racks.refresh(store, map_id), "a refit's centimetre is no change"
    layout = racks.on_grid(warehouse_layer())
    assert layout is not None and np.count_nonzero(layout.cell_labels == PlaceLabel.STORAGE.value) == len(racks.bins)
    store.close()


def warehouse_layer() -> GridLayer:
    return _racks_unseen()[1]


def test_feature_footprints_skip_what_is_not_a_polygon() -> None:
    point = Feature("bin", "x", {"type": "Point", "coordinates": [1.0, 2.0]}, {})
    bad = Feature("bin", "y", {"type": "Polygon", "coordinates": [[[0, 0], [1, 1]]]}, {})
    assert footprints([point, bad], FeatureKind.BIN) == []


def test_an_aisle_known_over_its_sections_is_a_junction_where_a_cross_aisle_crosses_it() -> None:
    """The pillar stage spans an aisle from its first bin to its last, through the cross aisle between sections:
    there no bin faces it, and that crossing is a junction between one corridor region per section."""
    occupancy, layer = _racks_unseen()
    origin = (layer.origin_x_m, layer.origin_y_m)
    bins = footprints(bin_features(warehouse().world), FeatureKind.BIN)
    sections = _aisles()
    spanning = list(zip([f"aisle-{n:02d}" for n in (1, 2)], _spanning_aisles(), strict=True))
    assert all(len(aisle_crossings(ring, bins)) == 1 for _, ring in spanning)
    known = known_layout(bins, [ring for _, ring in spanning], shape=occupancy.shape,
                         resolution_m=layer.resolution_m, origin_xy_m=origin)
    result = decompose(occupancy, resolution_m=layer.resolution_m, origin_xy_m=origin, known_places=known)
    names = aisle_regions(result, spanning)

    def main_region(polygon: np.ndarray) -> int:
        cells = footprint_mask([polygon], shape=occupancy.shape, resolution_m=layer.resolution_m, origin_xy_m=origin)
        return int(np.bincount(result.segments[cells & (result.segments > 0)]).argmax())

    corridors = {main_region(ring) for ring in sections}
    assert len(corridors) == len(sections) and all(result.regions[r].label is PlaceLabel.CORRIDOR for r in corridors)
    assert sorted(names[r] for r in corridors) == sorted(key for key, _ in spanning for _ in range(2))
    for area in warehouse().world.areas:
        if area.kind.name == "JUNCTION":
            assert result.regions[main_region(np.asarray(area.polygon))].label is PlaceLabel.JUNCTION, area.id


def test_the_cross_aisles_beside_an_aisles_ends_and_crossings_are_corridor_places() -> None:
    """What the rack finder makes of the racks' ends (a pallet left there is closed into the rack) does not
    decide the cross aisle the pillar stage's bins leave there: it is a corridor place, not storage."""
    occupancy, layer = _racks_unseen()
    origin = (layer.origin_x_m, layer.origin_y_m)
    bins = footprints(bin_features(warehouse().world), FeatureKind.BIN)
    known = known_layout(bins, _spanning_aisles(), shape=occupancy.shape, resolution_m=layer.resolution_m,
                         origin_xy_m=origin)
    for area in warehouse().world.areas:
        if area.detail.get("corridor_kind") == "cross_aisle":
            inside = footprint_mask([np.asarray(area.polygon)], shape=occupancy.shape,
                                    resolution_m=layer.resolution_m, origin_xy_m=origin)
            labels = known.cell_labels[known.cells[inside]]
            assert (labels == PlaceLabel.CORRIDOR.value).mean() > 0.8, area.id

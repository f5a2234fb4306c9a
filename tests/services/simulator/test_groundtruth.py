"""Ground truth: GeoJSON features, occupancy grid and label image agree with the world."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from services.simulator import (
    demo_layout,
    ground_truth_features,
    ground_truth_grids,
    read_layout,
    world_from_layout,
    write_ground_truth,
)
from services.simulator.world import AreaKind
from shared.mapfiles import read_map_yaml
from shared.store.records import FEATURE_KINDS


def _cell(grids, xy: np.ndarray) -> tuple[int, int]:  # type: ignore[no-untyped-def]
    col, row = np.floor((xy - (grids.origin_x_m, grids.origin_y_m)) / grids.resolution_m).astype(int)
    return int(row), int(col)


def test_uprights_are_occupied_and_aisle_centres_are_corridor() -> None:
    world = world_from_layout(demo_layout())
    grids = ground_truth_grids(world, resolution_m=0.05)
    assert grids.occupancy.shape == grids.labels.shape
    for xy in world.uprights.xy:
        assert grids.occupancy[_cell(grids, xy)] == 100
        assert grids.labels[_cell(grids, xy)] == 0
    for area in world.areas:
        if area.kind in (AreaKind.CORRIDOR, AreaKind.JUNCTION):
            assert grids.labels[_cell(grids, area.polygon.mean(axis=0))] == area.kind.value


def test_geojson_has_every_bin_upright_and_only_store_kinds() -> None:
    world = world_from_layout(demo_layout())
    features = ground_truth_features(world)["features"]
    kinds = {f["properties"]["kind"] for f in features}
    assert kinds <= FEATURE_KINDS
    assert {"wall", "corridor", "junction", "rack_row", "bin", "pillar", "dock", "gate", "charger", "object",
            "open_area"} <= kinds
    assert sum(f["properties"]["kind"] == "bin" for f in features) == len(world.bins)
    assert sum(f["properties"]["kind"] == "pillar" for f in features) == len(world.uprights.ids)


def test_written_ground_truth_rebuilds_the_world_and_images_match_pixel_for_pixel(tmp_path: Path) -> None:
    world = world_from_layout(demo_layout())
    files = write_ground_truth(world, tmp_path / "truth", resolution_m=0.1)
    again = world_from_layout(read_layout(files["layout"]))
    np.testing.assert_allclose(again.uprights.xy, world.uprights.xy)
    occupancy = read_map_yaml(files["occupancy"]).occupancy
    image = cv2.imread(str(files["labels"]), cv2.IMREAD_UNCHANGED)
    assert image is not None
    labels = image[::-1]
    assert labels.shape == occupancy.shape
    assert not np.any((occupancy == 100) & (labels != 0))
    assert set(np.unique(labels)) <= set(range(7))

"""Worlds from layouts: racks, uprights, bins and areas agree with the layout; bad layouts are refused."""

from __future__ import annotations

import math
import re

import cv2
import numpy as np
import pytest

from services.simulator import SimulatorError, demo_layout, random_layout, world_from_layout
from services.simulator.world import AreaKind


def _inside(polygon: np.ndarray, point: np.ndarray) -> bool:
    return cv2.pointPolygonTest(polygon.astype(np.float32), (float(point[0]), float(point[1])), True) >= -1e-4


def test_block_has_two_rows_per_aisle_and_uprights_at_every_frame() -> None:
    layout = demo_layout()
    block = layout["blocks"][0]
    world = world_from_layout(layout)
    assert len(world.rows) == 2 * block["aisles"]
    segments = math.ceil(block["bays"] / block["cross_aisle_every"])
    frames_per_row = block["bays"] + segments
    assert len(world.uprights.ids) == len(world.rows) * frames_per_row * 2
    assert len(set(world.uprights.ids)) == len(world.uprights.ids)


def test_bins_have_wms_ids_one_per_bay_and_level() -> None:
    layout = demo_layout()
    world = world_from_layout(layout)
    block = layout["blocks"][0]
    assert len(world.bins) == len(world.rows) * block["bays"] * block["levels"]
    ids = [b.id for b in world.bins]
    assert len(set(ids)) == len(ids)
    assert all(re.fullmatch(r"\d{2}-\d{3}-\d{2}", i) for i in ids)
    left_bays = {b.bay % 2 for b in world.bins if b.row.endswith("L")}
    assert left_bays == {1}


def test_bin_access_pose_lies_in_its_aisle_and_faces_the_bin() -> None:
    world = world_from_layout(random_layout(3, rotated_region=True))
    aisles = [a for a in world.areas if a.kind is AreaKind.CORRIDOR and "aisle" in a.detail]
    for b in world.bins[::7]:
        x, y, yaw = b.access_pose
        mine = [a for a in aisles if a.detail["aisle"] == b.aisle]
        assert any(_inside(a.polygon, np.array([x, y])) for a in mine), b.id
        centre = b.polygon.mean(axis=0)
        to_bin = math.atan2(centre[1] - y, centre[0] - x)
        assert abs(math.remainder(to_bin - yaw, 2 * math.pi)) < 1e-6


@pytest.mark.parametrize("seed", range(4))
def test_random_worlds_keep_uprights_inside_their_rows_and_rows_off_aisles(seed: int) -> None:
    world = world_from_layout(random_layout(seed))
    for xy, row in zip(world.uprights.xy, world.uprights.row, strict=True):
        assert _inside(world.rows[int(row)].polygon, xy)
    aisles = [a for a in world.areas if a.kind is AreaKind.CORRIDOR]
    for row in world.rows:
        centre = row.polygon.mean(axis=0)
        assert not any(_inside(a.polygon, centre) for a in aisles)


def test_rotated_region_has_rows_at_its_angle() -> None:
    layout = random_layout(5, rotated_region=True)
    yaw = layout["blocks"][1]["yaw_rad"]
    world = world_from_layout(layout)
    yaws = {round(math.remainder(r.front_yaw_rad - yaw, math.pi / 2), 6) for r in world.rows}
    assert 0.0 in yaws or -0.0 in yaws


def test_block_outside_the_hall_is_refused() -> None:
    layout = demo_layout()
    layout["blocks"][0]["origin_m"] = [30.0, 5.0]
    with pytest.raises(SimulatorError, match="outside the hall"):
        world_from_layout(layout)


@pytest.mark.parametrize(("patch", "message"), [
    ({"hall": None}, "hall"),
    ({"gates": [{"id": "G", "kind": "window", "offset_m": 1}]}, "kind must be"),
    ({"gates": [{"id": "G", "edge": "south", "offset_m": 39, "width_m": 3}]}, "runs past"),
    ({"actors": [{"id": "A", "kind": "robot", "path": [[1, 1]]}]}, "kind must be"),
    ({"blocks": [{"id": "B", "aisle_width_m": -1}]}, "aisle_width_m"),
])
def test_bad_layouts_are_refused_with_the_offending_entry(patch: dict[str, object], message: str) -> None:
    layout = demo_layout()
    layout.update(patch)
    with pytest.raises(SimulatorError, match=message):
        world_from_layout(layout)

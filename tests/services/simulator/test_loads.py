"""Loaded racks: every occupied bin holds pallets with loads that rest on what the ground truth says, seeded, and a
rack-facing camera sees them; blocks without the option are built as before."""

from __future__ import annotations

import math
from collections import Counter

import cv2
import numpy as np
import numpy.typing as npt
import pytest

from services.simulator import (
    RgbdModel,
    SimulatorError,
    demo_layout,
    loaded_layout,
    rack_rgbd_mount,
    rack_view,
    render_boxes,
    world_from_layout,
)
from services.simulator.cameras import RGBD_MOUNT
from services.simulator.loads import bin_records
from services.simulator.world import LoadTruth, ObjectClass, World


@pytest.fixture(scope="module")
def worlds() -> list[World]:
    return [world_from_layout(loaded_layout(seed, deep=deep)) for seed in (1, 2) for deep in (1, 2)]


def _top(world: World, truth: LoadTruth) -> float:
    return float(world.boxes.z_m[truth.box, 1])


def _footprint(world: World, truth: LoadTruth) -> npt.NDArray[np.float32]:
    return np.asarray(world.boxes.take(np.array([truth.box])).corners_xy()[0], dtype=np.float32)


def _overlap(a: npt.NDArray[np.float32], b: npt.NDArray[np.float32]) -> float:
    area, _ = cv2.intersectConvexConvex(a, b)
    return float(area)


def _contains(polygon: npt.NDArray[np.float32], point: npt.NDArray[np.float32]) -> bool:
    return cv2.pointPolygonTest(polygon.reshape(-1, 1, 2), (float(point[0]), float(point[1])), False) > 0


def test_occupied_bins_hold_a_pallet_and_empty_bins_nothing(worlds: list[World]) -> None:
    for world in worlds:
        pallets = Counter(t.bin_id for t in world.loads if t.kind == ObjectClass.PALLET)
        holding = {t.bin_id for t in world.loads}
        for b in world.bins:
            assert (pallets[b.id] > 0) == b.occupied
            assert (b.id in holding) == b.occupied
        assert any(not b.occupied for b in world.bins)


def test_every_object_rests_on_its_support(worlds: list[World]) -> None:
    for world in worlds:
        by_id = {t.id: t for t in world.loads}
        z_of_bin = {b.id: b.z_m for b in world.bins}
        for truth in world.loads:
            bottom = float(world.boxes.z_m[truth.box, 0])
            if truth.kind == ObjectClass.PALLET:
                assert truth.support == ("floor" if z_of_bin[truth.bin_id] == 0 else "beam")
                assert bottom == pytest.approx(z_of_bin[truth.bin_id])
            else:
                below = by_id[truth.support]
                assert below.bin_id == truth.bin_id
                assert bottom == pytest.approx(_top(world, below))
                assert _overlap(_footprint(world, truth), _footprint(world, below)) > 0.0


def test_stable_loads_stand_over_their_support_and_leaning_ones_do_not(worlds: list[World]) -> None:
    by_world = [(world, {t.id: t for t in world.loads}) for world in worlds]
    kinds: Counter[str] = Counter()
    for world, by_id in by_world:
        for truth in world.loads:
            if truth.kind != ObjectClass.LOAD:
                continue
            centre = world.boxes.centre_xy[truth.box]
            assert _contains(_footprint(world, by_id[truth.support]), centre) == truth.stable
            kinds["overhang" if truth.overhang else "flush"] += 1
            kinds["leaning" if not truth.stable else "stable"] += 1
    assert kinds["leaning"] > 0 and kinds["overhang"] > kinds["leaning"]


def test_objects_of_a_bin_do_not_intersect(worlds: list[World]) -> None:
    for world in worlds:
        objects = list(world.loads)
        for i, a in enumerate(objects):
            za = world.boxes.z_m[a.box]
            for b in objects[i + 1:]:
                zb = world.boxes.z_m[b.box]
                if a.bin_id != b.bin_id or min(za[1], zb[1]) - max(za[0], zb[0]) <= 1e-9:
                    continue
                assert _overlap(_footprint(world, a), _footprint(world, b)) < 1e-6, (a.id, b.id)


def test_double_deep_racks_hide_back_pallets_behind_front_ones(worlds: list[World]) -> None:
    for world in worlds:
        deep = world.layout["blocks"][0]["loads"]["deep"]
        slots = {(t.bin_id, t.slot, t.deep_slot) for t in world.loads if t.kind == ObjectClass.PALLET}
        behind = [t for t in world.loads if t.behind]
        assert bool(behind) == (deep == 2)
        for t in behind:
            assert (t.bin_id, t.slot, 0) in slots


def test_loads_are_seeded() -> None:
    a, b = (world_from_layout(loaded_layout(5)) for _ in range(2))
    c = world_from_layout(loaded_layout(6))
    assert a.loads == b.loads
    assert np.array_equal(a.boxes.z_m, b.boxes.z_m)
    assert a.loads != c.loads


def test_a_layout_without_loads_has_no_load_truth_and_its_usual_pallets() -> None:
    world = world_from_layout(demo_layout())
    assert world.loads == ()
    assert (world.boxes.kind == ObjectClass.PALLET).sum() == 2 * sum(b.occupied for b in world.bins)


@pytest.mark.parametrize("loads", [{"deep": 3}, {"stacked": 1.5}, {"colour": 1}, "many",
                                   {"bare": 0.5, "stacked": 0.4, "pair": 0.3}])
def test_bad_load_options_are_refused_by_name(loads: object) -> None:
    layout = loaded_layout(1)
    layout["blocks"][0]["loads"] = loads
    with pytest.raises(SimulatorError, match="loads"):
        world_from_layout(layout)


def test_the_rack_mount_at_one_metre_level_is_the_usual_rgbd_mount() -> None:
    assert np.allclose(rack_rgbd_mount(height_m=1.0), RGBD_MOUNT)
    up = rack_rgbd_mount(height_m=1.5, pitch_up_rad=0.3)
    assert up[2, 3] == 1.5
    assert up[2, 2] == pytest.approx(math.sin(0.3))  # the optical axis points up by the pitch


def test_a_rack_view_sees_the_bins_objects_and_the_bin_records_face_the_aisle(worlds: list[World]) -> None:
    world = worlds[0]
    camera = RgbdModel().camera()
    target = next(b for b in world.bins if b.occupied and b.level == 1)
    pose = rack_view(world, target.id, standoff_m=2.8, height_m=0.6, pitch_up_rad=0.2)
    rendered = render_boxes(world.boxes, pose, camera, far_m=8.0)
    shown = set(np.unique(rendered.box).tolist())
    assert {t.box for t in world.loads if t.bin_id == target.id and t.deep_slot == 0} <= shown
    record = next(r for r in bin_records(world) if r.id == target.id)
    assert record.level == 0 and record.footprint is not None
    left, right = np.array(record.footprint[0]), np.array(record.footprint[1])
    seen = (pose[:3, :3].T @ (np.array([*left, 0.0]) - pose[:3, 3]))[0], \
        (pose[:3, :3].T @ (np.array([*right, 0.0]) - pose[:3, 3]))[0]
    assert seen[0] < 0 < seen[1]  # front edge first, left to right as the camera sees it
    with pytest.raises(SimulatorError, match="no bin"):
        rack_view(world, "99-999-99", standoff_m=2.0, height_m=1.0)

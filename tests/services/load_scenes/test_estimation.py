"""Box estimation at rack faces: simulated RGB-D views of loaded racks give the pallets, loads and beams the ground
truth holds, in the right bay and level; empty bays and hidden back pallets give none; bad input is refused."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
import numpy.typing as npt
import pytest

from services.load_scenes.errors import LoadScenesError
from services.load_scenes.estimation import (
    BEHIND_M,
    RackView,
    bays_from_bins,
    camera_moved,
    estimate_boxes,
    merge_views,
)
from services.load_scenes.frames import Intrinsics, decode_depth, intrinsics_from_camera_info
from services.load_scenes.model import Bay, BoxEstimate, ObjectKind
from services.simulator import RgbdModel, depth_image_mm, loaded_layout, rack_view, render_boxes, world_from_layout
from services.simulator.loads import RACK_CAMERAS, bin_records, seen_whole
from services.simulator.render import Rendered
from services.simulator.world import LoadTruth, ObjectClass, World
from shared.bins import Bin
from shared.settings import RackProfileSettings

MODEL = RgbdModel()
CAMERA = MODEL.camera()
INTRINSICS = Intrinsics(CAMERA.fx, CAMERA.fy, CAMERA.cx, CAMERA.cy, CAMERA.width, CAMERA.height)
KINDS = {ObjectClass.PALLET: ObjectKind.PALLET, ObjectClass.LOAD: ObjectKind.LOAD}


class Frame(NamedTuple):
    pose: npt.NDArray[np.float64]
    rendered: Rendered
    depth: npt.NDArray[np.uint16]
    view: RackView


class Scene(NamedTuple):
    world: World
    bays: list[Bay]
    by_bin: dict[str, Bay]


def _scene(seed: int, deep: int) -> Scene:
    world = world_from_layout(loaded_layout(seed, deep=deep, aisles=1, bays=5))
    bays = bays_from_bins(bin_records(world))
    return Scene(world, bays, {b: bay for bay in bays for b in bay.bin_ids})


def _frame(scene: Scene, bin_id: str, camera: int, seed: int = 0, *, along_m: float = 0.0) -> Frame:
    height, pitch = RACK_CAMERAS[camera]
    pose = rack_view(scene.world, bin_id, standoff_m=2.8, height_m=height, pitch_up_rad=pitch, along_m=along_m)
    rendered = render_boxes(scene.world.boxes, pose, CAMERA, far_m=8.0)
    depth = depth_image_mm(rendered.depth_m, MODEL, np.random.default_rng(seed))
    return Frame(pose, rendered, depth, estimate_boxes(depth, INTRINSICS, pose, scene.bays, stamp_ns=7))


@pytest.fixture(scope="module")
def single() -> Scene:
    return _scene(1, 1)


@pytest.fixture(scope="module")
def double() -> Scene:
    return _scene(2, 2)  # bays 3 to 5 show back pallets both hidden and, behind an empty position, whole


@pytest.fixture(scope="module")
def single_frames(single: Scene) -> list[Frame]:
    return [_frame(single, bay.bin_ids[0], camera, k) for k, bay in enumerate(single.bays[:3]) for camera in (0, 1)]


def _bay_uv(bay: Bay, xy: tuple[float, float]) -> tuple[float, float]:
    dx, dy = xy[0] - bay.origin[0], xy[1] - bay.origin[1]
    c, s = math.cos(bay.yaw_rad), math.sin(bay.yaw_rad)
    return dx * s - dy * c, dx * c + dy * s


def _matches(scene: Scene, truth: LoadTruth, est: BoxEstimate, *, tol_m: float = 0.1) -> bool:
    """Same kind and bin, centre within ``tol_m`` across and up and 0.3 m into the rack, size within 0.12 m."""
    bay = scene.by_bin[truth.bin_id]
    if est.kind is not KINDS[truth.kind] or est.bay != bay.key or est.level is None:
        return False
    boxes = scene.world.boxes
    u, v = _bay_uv(bay, (float(boxes.centre_xy[truth.box, 0]), float(boxes.centre_xy[truth.box, 1])))
    eu, ev = _bay_uv(bay, (est.centre[0], est.centre[1]))
    z0, z1 = boxes.z_m[truth.box]
    return (bay.bin_ids[est.level] == truth.bin_id and abs(eu - u) <= tol_m and abs(ev - v) <= 0.3
            and abs(est.centre[2] - 0.5 * (z0 + z1)) <= tol_m and abs(est.size[2] - (z1 - z0)) <= 0.12
            and abs(est.size[0] - boxes.size_xy[truth.box, 0]) <= 0.12)


def test_estimates_match_the_ground_truth_boxes_a_view_shows(single: Scene, single_frames: list[Frame]) -> None:
    seen: dict[ObjectClass, int] = {ObjectClass.PALLET: 0, ObjectClass.LOAD: 0}
    found = dict(seen)
    estimates = right = 0
    for frame in single_frames:
        objects = [e for e in frame.view.boxes if e.kind is not ObjectKind.BEAM]
        for truth in seen_whole(single.world, frame.rendered, frame.pose, CAMERA):
            seen[truth.kind] += 1
            found[truth.kind] += any(_matches(single, truth, e) for e in objects)
        for est in objects:
            estimates += 1
            right += any(_matches(single, t, est) for t in single.world.loads if t.bin_id in single.by_bin)
            assert est.stamp_ns == 7 and 0.0 < est.score <= 1.0
            assert all(0.0 < s < 0.2 for s in est.sigma)
    assert seen[ObjectClass.PALLET] >= 5 and seen[ObjectClass.LOAD] >= 5
    assert found[ObjectClass.PALLET] == seen[ObjectClass.PALLET]
    assert found[ObjectClass.LOAD] >= 0.9 * seen[ObjectClass.LOAD]
    assert right >= 0.95 * estimates


def test_beams_are_found_at_their_levels(single: Scene, single_frames: list[Frame]) -> None:
    for frame, bay in zip(single_frames[::2], single.bays, strict=False):
        beams = [e for e in frame.view.boxes if e.kind is ObjectKind.BEAM and e.bay == bay.key]
        assert [e.level for e in beams] == [1]  # the low camera sees level 1's beam whole, level 2's cut
        top = beams[0].centre[2] + 0.5 * beams[0].size[2]
        assert top == pytest.approx(bay.levels_z_m[1], abs=0.03)


def test_an_empty_bin_yields_no_pallet_nor_load(single: Scene) -> None:
    empty = next(b for b in single.world.bins if not b.occupied and b.level <= 2)
    frame = _frame(single, empty.id, 0)
    bay = single.by_bin[empty.id]
    level = bay.bin_ids.index(empty.id)
    assert frame.view.evidence[bay.key].points.shape[0] > 100
    assert not [e for e in frame.view.boxes if e.bay == bay.key and e.level == level and e.kind is not ObjectKind.BEAM]


def test_a_back_pallet_hidden_behind_a_front_one_is_not_seen(double: Scene) -> None:
    hidden_checked = seen_checked = 0
    for bay in double.bays[2:5]:
        frame = _frame(double, bay.bin_ids[0], 0)
        in_image = {t.id for t in seen_whole(double.world, frame.rendered, frame.pose, CAMERA, min_fraction=0.0)}
        glimpsed = {t.id for t in seen_whole(double.world, frame.rendered, frame.pose, CAMERA, min_fraction=0.25)}
        whole = {t.id for t in seen_whole(double.world, frame.rendered, frame.pose, CAMERA)}
        objects = [e for e in frame.view.boxes if e.kind is ObjectKind.PALLET]
        for truth in double.world.loads:
            if truth.kind != ObjectClass.PALLET or truth.deep_slot != 1 or double.by_bin[truth.bin_id] != bay:
                continue
            near = [e for e in objects if _matches(double, truth, e, tol_m=0.5)]
            if truth.behind and truth.id in in_image and truth.id not in glimpsed:  # under a quarter of it shows
                hidden_checked += 1
                assert not near, truth.id
            elif truth.id in whole:
                seen_checked += 1
                assert near, truth.id
    assert hidden_checked > 0 and seen_checked > 0


def test_depth_evidence_holds_the_points_in_each_bay_and_the_camera_origin(single: Scene,
                                                                         single_frames: list[Frame]) -> None:
    frame = single_frames[0]
    assert frame.view.evidence
    for key, evidence in frame.view.evidence.items():
        bay = next(b for b in single.bays if b.key == key)
        assert evidence.origin == pytest.approx(tuple(frame.pose[:3, 3]))
        uv = _bay_uv(bay, (evidence.points[:, 0], evidence.points[:, 1]))  # type: ignore[arg-type]
        u, v = np.asarray(uv[0]), np.asarray(uv[1])
        behind = v > bay.depth_m + 1e-9  # rays through the bay that met nothing in it: a point just behind
        assert np.all(np.abs(u[~behind]) <= 0.5 * bay.width_m + 1e-9)
        assert np.all(v[behind] == pytest.approx(bay.depth_m + BEHIND_M))
        assert np.all(evidence.points[:, 2] >= 0.0)
    target = single.bays[0]
    assert target.key in frame.view.evidence
    assert {key.split("/")[0] for key in frame.view.evidence} == {target.row}  # the row behind the camera: none


def test_float_metres_give_the_same_boxes_as_millimetres(single: Scene, single_frames: list[Frame]) -> None:
    frame = single_frames[1]
    metres = frame.depth.astype(np.float32) / 1000.0
    again = estimate_boxes(metres, INTRINSICS, frame.pose, single.bays, stamp_ns=7)
    assert [(e.id, e.kind) for e in again.boxes] == [(e.id, e.kind) for e in frame.view.boxes]


@pytest.mark.parametrize(("change", "message"), [
    ("nan", "NaN"), ("size", "does not match"), ("zeros", "no depth"), ("dtype", "uint16 millimetres or float"),
    ("negative", "negative"), ("no_bays", "no bays"), ("pose", "not orthonormal"), ("pose_shape", "4x4"),
    ("stride", "stride"),
])
def test_bad_input_is_refused_with_a_clear_error(single: Scene, single_frames: list[Frame], change: str,
                                                 message: str) -> None:
    frame = single_frames[0]
    depth: npt.NDArray[np.generic] = frame.depth.astype(np.float32) / 1000.0
    pose: npt.NDArray[np.float64] = frame.pose.copy()
    bays: list[Bay] = single.bays
    intrinsics = INTRINSICS
    stride = 2
    if change == "nan":
        depth[10, 10] = np.nan
    elif change == "size":
        depth = depth[:-1]
    elif change == "zeros":
        depth = np.zeros_like(frame.depth)
    elif change == "dtype":
        depth = frame.depth.astype(np.int32)
    elif change == "negative":
        depth[5, 5] = -1.0
    elif change == "no_bays":
        bays = []
    elif change == "pose":
        pose[:3, :3] *= 2.0
    elif change == "pose_shape":
        pose = pose[:3]
    else:
        stride = 0
    with pytest.raises(LoadScenesError, match=message):
        estimate_boxes(depth, intrinsics, pose, bays, stamp_ns=0, stride=stride)


def test_bays_from_bins_groups_levels_and_knows_double_deep(single: Scene, double: Scene) -> None:
    assert len(single.bays) == len({(b.row, b.bay) for b in single.world.bins})
    for bay in single.bays:
        assert bay.levels_z_m == (0.0, 1.3, 2.6) and bay.deep == 1
        assert bay.key == f"{bay.row}/{bay.bay:03d}"
        assert bay.width_m == pytest.approx(2.7) and bay.depth_m == pytest.approx(1.1)
        assert [int(i[-2:]) for i in bay.bin_ids] == [1, 2, 3]
    assert all(bay.deep == 2 for bay in double.bays)
    # the bay's yaw points into the rack: its origin is on the aisle side of the bins' centres
    record = next(r for r in bin_records(single.world) if r.id == single.bays[0].bin_ids[0])
    u, v = _bay_uv(single.bays[0], record.centre)
    assert abs(u) < 1e-6 and v == pytest.approx(0.55)


def test_bays_from_bins_takes_levels_from_profiles_and_skips_what_it_cannot_place() -> None:
    footprint = ((0.0, 0.0), (2.7, 0.0), (2.7, 1.1), (0.0, 1.1), (0.0, 0.0))
    cells = [Bin(id="01-001", centre=(1.35, 0.55), aisle=1, bay=1, footprint=footprint, row="R01L"),
             Bin(id="01-003", centre=(4.0, 0.55), aisle=1, bay=3),  # no footprint
             Bin(id="01-005", centre=(9.0, 0.55), aisle=1, bay=5, footprint=footprint, row="R01L")]
    profiles = [RackProfileSettings(levels_m=[0.0, 1.5], area=[(-1.0, -1.0), (5.0, -1.0), (5.0, 5.0), (-1.0, 5.0)]),
                RackProfileSettings(levels_m=[0.0, 1.2, 2.4])]  # elsewhere: bin 01-005
    bays = bays_from_bins(cells, profiles=profiles)
    assert [(b.key, b.bin_ids, b.levels_z_m) for b in bays] == [
        ("R01L/001", ("01-001-01", "01-001-02"), (0.0, 1.5)),
        ("R01L/005", ("01-005-01", "01-005-02", "01-005-03"), (0.0, 1.2, 2.4))]
    assert bays[0].yaw_rad == pytest.approx(math.pi / 2)
    flat = Bin(id="01-007-01", centre=(0.0, 0.0), aisle=1, bay=7, level=0, z_m=0.0,
               footprint=((0.0, 0.0), (0.0, 0.0), (0.0, 1.0), (0.0, 0.0)))
    with pytest.raises(LoadScenesError, match="front edge"):
        bays_from_bins([flat])


def test_views_of_one_object_merge_into_one_estimate_and_others_stay_apart(single: Scene,
                                                                           single_frames: list[Frame]) -> None:
    frames = [single_frames[0], _frame(single, single.bays[0].bin_ids[0], 0, along_m=0.2)]  # a step further
    boxes = [e for f in frames for e in f.view.boxes if e.kind is not ObjectKind.BEAM]
    merged = merge_views(boxes)
    assert len(merged) < len(boxes)
    for a in merged:
        for b in merged:
            if a is not b and a.kind is b.kind and a.bay == b.bay and a.level == b.level:
                assert math.dist(a.centre, b.centre) > 0.25
    again = [m for m in merged if sum(math.dist(m.centre, e.centre) <= 0.25 and e.kind is m.kind for e in boxes) > 1]
    assert again and all(m.sigma[0] < 0.2 for m in again)
    for m in again:
        views = [e for e in boxes if e.kind is m.kind and e.bay == m.bay and math.dist(m.centre, e.centre) <= 0.25]
        assert m.score >= max(e.score for e in views)


def test_camera_info_and_depth_messages_are_read_and_bad_ones_refused() -> None:
    from services.simulator import rosmsgs

    _, info = rosmsgs.camera_info(5, "cam", width=CAMERA.width, height=CAMERA.height, k=CAMERA.k())
    assert intrinsics_from_camera_info(info) == INTRINSICS
    depth = np.arange(12, dtype=np.uint16).reshape(3, 4)
    _, image = rosmsgs.image(5, "cam", depth)
    assert np.array_equal(decode_depth(image), depth)
    _, flat = rosmsgs.camera_info(5, "cam", width=4, height=3, k=np.zeros((3, 3)))
    with pytest.raises(LoadScenesError, match="not usable"):
        intrinsics_from_camera_info(flat)
    _, colour = rosmsgs.image(5, "cam", np.zeros((3, 4, 3), np.uint8))
    with pytest.raises(LoadScenesError, match="16UC1"):
        decode_depth(colour)


def test_a_frame_from_where_the_last_one_was_taken_is_told_apart_from_one_that_moved() -> None:
    world = world_from_layout(loaded_layout(1))
    bin_id = world.bins[0].id
    here = rack_view(world, bin_id, standoff_m=2.8, height_m=0.6)
    nudged = rack_view(world, bin_id, standoff_m=2.8, height_m=0.6, along_m=0.05)
    driven = rack_view(world, bin_id, standoff_m=2.8, height_m=0.6, along_m=0.5)
    turned = rack_view(world, bin_id, standoff_m=2.8, height_m=0.6, pitch_up_rad=0.3)
    kw = {"min_move_m": 0.2, "min_turn_rad": 0.1}
    assert not camera_moved(here, here, **kw) and not camera_moved(here, nudged, **kw)
    assert camera_moved(here, driven, **kw) and camera_moved(here, turned, **kw)

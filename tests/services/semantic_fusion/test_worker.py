"""The semantic-fusion stage as deployed: annotated scans on a real zenoh bus, a real SQLite store, the API."""

from __future__ import annotations

import io
import threading
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
from fastapi.testclient import TestClient

from api import create_app
from services.semantic_fusion import (
    CLASS_COLOURS,
    DYNAMIC_CLASSES,
    RangeScan,
    ScanObservation,
    SemanticLayers,
    label_accuracy,
    se2,
)
from services.semantic_fusion.synthetic import (
    CLASS_NAMES,
    SimulatedRun,
    Warehouse,
    make_warehouse,
    simulate_run,
    truth_labels,
)
from services.semantic_fusion.worker import FusionStage, fusion_stage
from services.simulator.rosmsgs import tf_message, transform_stamped
from shared import messages
from shared.bus import Bus, Publisher
from shared.settings import SemanticFusionSettings, Settings, ZenohSettings
from shared.store import MapStore, Revision
from shared.transforms import quaternion_from_yaw
from shared.vocabulary import SemanticClass
from shared.worker import StageFactory, run_stage
from tests.helpers import wait_for

STAGE = "semantic_fusion"
RESOLUTION_M = 0.05


def _stage(**settings: Any) -> StageFactory:
    """The stage built from its settings section with ``settings`` changed from the defaults."""
    return lambda context: FusionStage(context, SemanticFusionSettings(**settings))


FAST_STORE = _stage(store_period_s=0.2)
"""The stage with its defaults except a short store period."""


def _message(scan: ScanObservation, *, stamp_ns: int | None = None, **override: Any) -> Any:
    """An aisle_msgs/AnnotatedScan carrying ``scan`` (labels = distribution columns = CLASS_NAMES indices)."""
    cls = messages.message_class
    x, y, yaw = scan.camera_pose
    q = quaternion_from_yaw(float(yaw))
    fields = {
        "bearings": np.arctan2(scan.points_xy[:, 1], scan.points_xy[:, 0]).astype(np.float32),
        "ranges": np.hypot(scan.points_xy[:, 0], scan.points_xy[:, 1]).astype(np.float32),
        "heights": scan.heights.astype(np.float32),
        "labels": scan.columns.astype(np.uint8),
        "confidences": scan.confidences.astype(np.float32),
    } | override
    stamp_ns = scan.stamp_ns if stamp_ns is None else stamp_ns
    return cls(messages.ANNOTATED_SCAN)(
        header=cls("std_msgs/msg/Header")(
            stamp=cls("builtin_interfaces/msg/Time")(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9), frame_id="map"),
        camera_pose=cls("geometry_msgs/msg/Pose")(
            position=cls("geometry_msgs/msg/Point")(x=float(x), y=float(y), z=1.0),
            orientation=cls("geometry_msgs/msg/Quaternion")(x=float(q[0]), y=float(q[1]), z=float(q[2]),
                                                            w=float(q[3]))),
        class_names=list(CLASS_NAMES),
        **fields,
    )


@contextmanager
def running_stage(zenoh_listen: ZenohSettings, store: MapStore,
                  factory: StageFactory = FAST_STORE) -> Iterator[tuple[Bus, Bus]]:
    """The stage on its own bus; yields a second, connected bus to publish from, and the stage's."""
    settings = Settings(database_url=store.url, zenoh=zenoh_listen)
    stop = threading.Event()
    with ExitStack() as stack:
        bus = stack.enter_context(Bus.open(zenoh_listen, domain_id=0))
        robots = stack.enter_context(Bus.open(ZenohSettings(listen=[], connect=zenoh_listen.listen), domain_id=0))
        thread = threading.Thread(target=run_stage, args=(STAGE, factory),
                                  kwargs={"bus": bus, "store": store, "settings": settings, "stop": stop})
        thread.start()
        try:
            wait_for(lambda: robots.alive_workers() == [STAGE], what="the worker to come up")
            yield robots, bus
        finally:
            stop.set()
            thread.join(timeout=60)
            assert not thread.is_alive()


def _publisher(bus: Bus, namespace: str) -> Publisher:
    return bus.publisher("annotated_scan", messages.ANNOTATED_SCAN, namespace=namespace)


def _newest_revision(store: MapStore) -> Revision | None:
    map_id = store.ensure_map("site").id
    newest, page = None, store.revisions(map_id)
    while page:
        newest = page[-1]
        page = store.revisions(map_id, after_id=newest.id)
    return newest


def _wait_for_input(store: MapStore, stamp_ns: int, *, timeout_s: float = 60.0) -> None:
    wait_for(lambda: (r := _newest_revision(store)) is not None and r.input_end_ns == stamp_ns,
             timeout_s=timeout_s, what=f"a revision with input up to {stamp_ns} ns")


def _stored_layers(store: MapStore) -> SemanticLayers:
    map_id = store.ensure_map("site").id
    labels, entropy = store.layer(map_id, "semantic_label"), store.layer(map_id, "semantic_entropy")
    assert labels is not None and entropy is not None and labels.revision_id == entropy.revision_id
    layer = labels.layer
    return SemanticLayers(layer.data, entropy.layer.data, layer.resolution_m, layer.origin_x_m, layer.origin_y_m)


def _accuracy(layers: SemanticLayers, warehouse: Warehouse) -> float:
    truth = truth_labels(warehouse, resolution_m=RESOLUTION_M)
    return label_accuracy(layers, truth, exclude=frozenset(DYNAMIC_CLASSES)).fraction


def _counters(store: MapStore) -> dict[str, int]:
    return dict({w.name: w for w in store.workers()}[STAGE].counters)


@pytest.fixture
def sqlite_store(tmp_path: Path) -> Iterator[MapStore]:
    store = MapStore(f"sqlite:///{tmp_path / 'aisle.db'}")
    store.upgrade()
    yield store
    store.close()


@pytest.mark.slow
def test_noisy_annotated_scans_become_a_correct_label_layer_served_in_colour(
        zenoh_listen: ZenohSettings, sqlite_store: MapStore) -> None:
    warehouse = make_warehouse(length_m=40.0, width_m=26.0, seed=3)
    run = simulate_run(warehouse, seed=3)
    with running_stage(zenoh_listen, sqlite_store) as (robots, _):
        publisher = _publisher(robots, "robot1")
        for scan in run.scans:
            publisher.publish(_message(scan))
        _wait_for_input(sqlite_store, run.scans[-1].stamp_ns, timeout_s=120.0)

    layers = _stored_layers(sqlite_store)
    assert _accuracy(layers, warehouse) >= 0.97
    counters = _counters(sqlite_store)
    assert counters[f"{STAGE}.scans_integrated"] == len(run.scans)
    assert counters.get(f"{STAGE}.bad_scans", 0) == 0

    client = TestClient(create_app(store=sqlite_store, settings=Settings(database_url=sqlite_store.url)))
    with client:
        png = client.get("/v1/maps/site/layers/semantic_label.png")
        values = client.get("/v1/maps/site/layers/semantic_label/values")
    assert png.status_code == 200 and png.headers["content-type"] == "image/png"
    decoded = cv2.imdecode(np.frombuffer(png.content, np.uint8), cv2.IMREAD_COLOR)
    assert decoded is not None
    image = cv2.cvtColor(decoded, cv2.COLOR_BGR2RGB)
    rows, cols = layers.labels.shape
    assert image.shape[0] >= rows and image.shape[1] > cols  # the legend sits right of the map
    r, c = np.argwhere(layers.labels == SemanticClass.RACK)[0]
    assert tuple(image[rows - 1 - r, c]) == CLASS_COLOURS[SemanticClass.RACK]
    legend = image[:, cols:].reshape(-1, 3)
    assert (legend == CLASS_COLOURS[SemanticClass.RACK]).all(axis=1).any()
    np.testing.assert_array_equal(np.load(io.BytesIO(values.content), allow_pickle=False),
                                  layers.labels)


def test_bad_annotated_scans_are_counted_and_skipped_while_good_ones_flow(
        zenoh_listen: ZenohSettings, sqlite_store: MapStore) -> None:
    warehouse = make_warehouse(length_m=30.0, width_m=20.0, seed=1)
    scans = simulate_run(warehouse, seed=1, max_scans=120).scans

    template = max(scans, key=lambda s: s.points_xy.shape[0])
    n = template.points_xy.shape[0]

    def bad(after: ScanObservation, kind: int) -> Any:
        stamp_ns = after.stamp_ns + 1  # in order: only the content is bad
        return [
            _message(template, stamp_ns=stamp_ns, ranges=np.ones(n + 3, np.float32)),  # arrays differ in length
            _message(template, stamp_ns=stamp_ns, heights=np.full(n, np.nan, np.float32)),  # NaN
            _message(template, stamp_ns=stamp_ns, labels=np.full(n, len(CLASS_NAMES) + 4, np.uint8)),  # unknown ids
        ][kind % 3]

    with running_stage(zenoh_listen, sqlite_store, factory=fusion_stage) as (robots, stage_bus):
        publisher = _publisher(robots, "robot1")
        for i, scan in enumerate(scans):
            publisher.publish(_message(scan))
            if i % 30 == 10:
                publisher.publish(bad(scan, i // 30))
            if i == 50:
                publisher.publish(_message(scans[40]))  # out of order
        sent = len(scans) + len(range(10, len(scans), 30)) + 1
        wait_for(lambda: stage_bus.counters.snapshot().get(f"{STAGE}.annotated_scan.received", 0) == sent,
                 what="every scan to reach the stage")
    counters = _counters(sqlite_store)  # the final heartbeat, after the stop drained every queued scan
    assert counters[f"{STAGE}.scans_integrated"] == len(scans)
    assert counters[f"{STAGE}.bad_scans"] == sum(1 for i in range(len(scans)) if i % 30 == 10)
    assert counters[f"{STAGE}.scans_out_of_order"] == 1
    layers = _stored_layers(sqlite_store)  # the stop committed what was fused
    assert np.count_nonzero(layers.labels) > 0
    assert _accuracy(layers, warehouse) >= 0.9


def test_robots_share_one_grid_and_a_restart_keeps_the_map(
        zenoh_listen: ZenohSettings, sqlite_store: MapStore) -> None:
    warehouse = make_warehouse(length_m=30.0, width_m=20.0, seed=2)
    scans = simulate_run(warehouse, seed=2).scans
    half = len(scans) // 2
    with running_stage(zenoh_listen, sqlite_store) as (robots, _):
        first, second = _publisher(robots, "robot1"), _publisher(robots, "robot2")
        for a, b in zip(scans[:half], scans[half: 2 * half], strict=True):
            first.publish(_message(a))
            second.publish(_message(b))
        _wait_for_input(sqlite_store, scans[2 * half - 1].stamp_ns)
    both = _stored_layers(sqlite_store)
    assert _counters(sqlite_store)[f"{STAGE}.robots"] == 2
    assert _accuracy(both, warehouse) >= 0.97

    with running_stage(zenoh_listen, sqlite_store) as (robots, _):
        publisher = _publisher(robots, "robot3")
        for scan in scans[:5]:
            publisher.publish(_message(scan, stamp_ns=scan.stamp_ns + 10**12))
        _wait_for_input(sqlite_store, scans[4].stamp_ns + 10**12)
    after = _stored_layers(sqlite_store)
    kept = _world_cells(after) & _world_cells(both)
    assert len(kept) >= 0.95 * len(_world_cells(both))


def _world_cells(layers: SemanticLayers) -> set[tuple[int, int, int]]:
    """(row, col, label) of every labelled static cell on the world lattice."""
    dr, dc = round(layers.origin_y_m / RESOLUTION_M), round(layers.origin_x_m / RESOLUTION_M)
    static = ~np.isin(layers.labels, [0, *(int(c) for c in DYNAMIC_CLASSES)])
    rows, cols = np.nonzero(static)
    return set(zip((rows + dr).tolist(), (cols + dc).tolist(), layers.labels[rows, cols].tolist(), strict=True))


MOUNT = np.array([0.3, 0.0, 0.5])
"""The synthetic camera's floor frame in the robot base frame (x, y metres, yaw radians)."""


def _pose_message(base: np.ndarray, stamp_ns: int) -> Any:
    cls = messages.message_class
    q = quaternion_from_yaw(float(base[2]))
    return cls(messages.POSE_STAMPED)(
        header=cls("std_msgs/msg/Header")(
            stamp=cls("builtin_interfaces/msg/Time")(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9), frame_id="map"),
        pose=cls("geometry_msgs/msg/Pose")(
            position=cls("geometry_msgs/msg/Point")(x=float(base[0]), y=float(base[1]), z=0.0),
            orientation=cls("geometry_msgs/msg/Quaternion")(x=float(q[0]), y=float(q[1]), z=float(q[2]),
                                                            w=float(q[3]))))


def test_corrected_poses_pull_a_drifting_robot_onto_the_map(
        zenoh_listen: ZenohSettings, sqlite_store: MapStore) -> None:
    warehouse = make_warehouse(length_m=30.0, width_m=20.0, seed=4)
    run = simulate_run(warehouse, seed=4, odometry_yaw_bias_per_m=0.01)
    factory = _stage(store_period_s=0.2, pose_topic="localization_pose",
                     pose_correction_period_s=0.0, detect_loops=False,
                     camera_x_in_base_m=MOUNT[0], camera_y_in_base_m=MOUNT[1],
                     camera_yaw_in_base_rad=MOUNT[2])
    base = se2.compose(run.true_poses, se2.inverse(MOUNT))
    with running_stage(zenoh_listen, sqlite_store, factory=factory) as (robots, _):
        scans = _publisher(robots, "robot1")
        poses = robots.publisher("localization_pose", messages.POSE_STAMPED, namespace="robot1")
        for i, scan in enumerate(run.scans):
            if i % 10 == 5:
                poses.publish(_pose_message(base[i - 2], run.scans[i - 2].stamp_ns))
            scans.publish(_message(scan))
        _wait_for_input(sqlite_store, run.scans[-1].stamp_ns)
    counters = _counters(sqlite_store)
    assert counters[f"{STAGE}.pose_corrections"] >= 1
    assert _accuracy(_stored_layers(sqlite_store), warehouse) >= 0.97


def _laser_message(scan: RangeScan, *, fov_rad: float, beams: int, frame_id: str, yaw_rad: float = 0.0) -> Any:
    """sensor_msgs/LaserScan with ``scan``'s returns in their beams (the others +inf), as a lidar in the same
    place turned ``yaw_rad`` left of the synthetic one sees them."""
    cls = messages.message_class
    increment = fov_rad / (beams - 1)
    ranges = np.full(beams, np.inf, dtype=np.float32)
    bearings = np.arctan2(scan.points_xy[:, 1], scan.points_xy[:, 0])
    ranges[np.round((bearings + fov_rad / 2) / increment).astype(int)] = np.hypot(*scan.points_xy.T)
    stamp = cls("builtin_interfaces/msg/Time")(sec=scan.stamp_ns // 10**9, nanosec=scan.stamp_ns % 10**9)
    return cls(messages.LASER_SCAN)(
        header=cls("std_msgs/msg/Header")(stamp=stamp, frame_id=frame_id), angle_min=-fov_rad / 2 - yaw_rad,
        angle_max=fov_rad / 2 - yaw_rad, angle_increment=increment, time_increment=0.0, scan_time=0.1,
        range_min=0.05, range_max=20.0, ranges=ranges, intensities=np.zeros(0, dtype=np.float32))


def _publish_drive(robots: Bus, stage_bus: Bus, namespace: str, run: SimulatedRun, *, beams: int, laser_frame: str,
                   laser_yaw_rad: float, base_frame: str | None) -> None:
    """Publish ``run``'s annotated scans and lidar (ahead of them, as a labeller's latency makes it) under
    ``namespace``, the lidar turned ``laser_yaw_rad`` in its place 0.3 m ahead of the base; unless ``base_frame``
    is None its mount in that frame goes out first on tf_static, as the simulator sends it."""
    if base_frame is not None:
        mount = transform_stamped(run.scans[0].stamp_ns, base_frame, laser_frame, (0.3, 0.0, 0.2),
                                  quaternion_from_yaw(laser_yaw_rad))
        sent = stage_bus.counters.snapshot().get(f"{STAGE}.tf_static.received", 0) + 1
        robots.publisher("tf_static", messages.TF_MESSAGE, namespace=namespace).publish(tf_message([mount])[1])
        wait_for(lambda: stage_bus.counters.snapshot().get(f"{STAGE}.tf_static.received", 0) == sent,
                 what="the lidar's mount to reach the stage")
    ranges = {r.stamp_ns: r for r in run.range_scans}
    scans = _publisher(robots, namespace)
    lidar = robots.publisher("scan", messages.LASER_SCAN, namespace=namespace)
    lag = 5  # the labeller's latency: raw lidar scans are half a second ahead of the annotated ones
    for i, scan in enumerate(run.scans):
        ahead = run.scans[min(i + lag, len(run.scans) - 1)].stamp_ns if i else -1
        for stamp in [s for s in ranges if s <= ahead or i == len(run.scans) - 1]:
            lidar.publish(_laser_message(ranges.pop(stamp), fov_rad=1.5 * np.pi, beams=beams, frame_id=laser_frame,
                                         yaw_rad=laser_yaw_rad))
        scans.publish(_message(scan))


def test_the_robots_lidar_mounted_as_its_tf_says_keeps_a_drifting_robots_map_straight(
        zenoh_listen: ZenohSettings, sqlite_store: MapStore) -> None:
    warehouse = make_warehouse(length_m=30.0, width_m=18.0, seed=0)
    beams = 541
    run = simulate_run(warehouse, seed=100, odometry_yaw_bias_per_m=0.002, lidar_beams=beams)
    # the lidar is on by default; its mount settings (the base origin) are wrong for this robot (on them this
    # run labels 95.8 % right): tf has it
    factory = _stage(store_period_s=0.2, camera_x_in_base_m=MOUNT[0],
                     camera_y_in_base_m=MOUNT[1], camera_yaw_in_base_rad=MOUNT[2])
    with running_stage(zenoh_listen, sqlite_store, factory=factory) as (robots, stage_bus):
        _publish_drive(robots, stage_bus, "robot1", run, beams=beams, laser_frame="robot1/laser", laser_yaw_rad=0.1,
                       base_frame="robot1/base_link")
        _wait_for_input(sqlite_store, run.scans[-1].stamp_ns)
    counters = _counters(sqlite_store)
    assert counters[f"{STAGE}.range_scans_attached"] > 100
    assert counters.get(f"{STAGE}.range_scans_mount_from_settings", 0) == 0
    assert counters.get(f"{STAGE}.bad_range_scans", 0) == 0
    assert _accuracy(_stored_layers(sqlite_store), warehouse) >= 0.97


def test_each_robot_has_its_own_lidar_mount_from_its_tf_or_else_the_settings(
        zenoh_listen: ZenohSettings, sqlite_store: MapStore) -> None:
    warehouse = make_warehouse(length_m=30.0, width_m=18.0, seed=0)
    beams = 541
    run = simulate_run(warehouse, seed=100, lidar_beams=beams, max_scans=150)
    factory = _stage(store_period_s=0.2, camera_x_in_base_m=MOUNT[0],
                     camera_y_in_base_m=MOUNT[1], camera_yaw_in_base_rad=MOUNT[2], lidar_x_in_base_m=0.3)
    with running_stage(zenoh_listen, sqlite_store, factory=factory) as (robots, stage_bus):
        # same frame names (not prefixed), different lidars: robot1's is turned, and tf says so; robot2 sends no tf
        _publish_drive(robots, stage_bus, "robot1", run, beams=beams, laser_frame="laser", laser_yaw_rad=0.1,
                       base_frame="base_link")
        _publish_drive(robots, stage_bus, "robot2", run, beams=beams, laser_frame="laser", laser_yaw_rad=0.0,
                       base_frame=None)
        received = {"annotated_scan": 2 * len(run.scans), "scan": 2 * len(run.range_scans)}
        wait_for(lambda: all(stage_bus.counters.snapshot().get(f"{STAGE}.{topic}.received", 0) == n
                             for topic, n in received.items()), what="both robots' scans to reach the stage")
    counters = _counters(sqlite_store)  # the final heartbeat, after the stop drained every queued scan
    assert counters[f"{STAGE}.robots"] == 2
    # at most one range scan per keyframe: more than half the keyframes (the robots drove the same route) is both
    assert counters[f"{STAGE}.range_scans_attached"] > counters[f"{STAGE}.keyframes"] / 2
    assert 0 < counters[f"{STAGE}.range_scans_mount_from_settings"] <= len(run.range_scans)  # robot2's only
    assert _accuracy(_stored_layers(sqlite_store), warehouse) >= 0.97

"""The object-labelling stage as deployed: real zenoh, a real SQLite store, simulated RGB-D traffic."""

from __future__ import annotations

import logging
import math
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from services.cli import main
from services.object_labelling import ObjectLabellingError
from services.object_labelling.worker import LabellingStage
from services.simulator import Output, robot_specs, simulate
from services.simulator.live import publish_live
from shared import messages
from shared.bus import Bus
from shared.settings import LabellingSettings, Settings, ZenohSettings
from shared.store import MapStore
from shared.transforms import yaw_from_quaternion
from shared.worker import StageContext, run_stage
from tests.helpers import wait_for
from tests.services.object_labelling.sim_scenes import (
    ROI_OF_KIND,
    cone_truth,
    labelling_hall,
    robot_waypoints,
)

log = logging.getLogger(__name__)

START_NS = 1_700_000_000_000_000_000
ROI_CLASSES = sorted(set(ROI_OF_KIND.values()))
TOPICS = ("tf", "tf_static", "rgbd/color/image_raw", "rgbd/depth/image_raw", "rgbd/camera_info")


@pytest.fixture(scope="session")
def sim_model(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A classifier trained by `aisle train-classifier` in ~20 s on 40 renders of scatter halls (not the test
    hall; no real photos), at 96 px CNN input."""
    path = tmp_path_factory.mktemp("model") / "sim.npz"
    assert main(["train-classifier", "--sim-views", "40", "--input-size", "96", "--out", str(path)]) == 0
    return path


@pytest.fixture(scope="session")
def sim_traffic() -> list[Output]:
    """One robot driving past a forklift, a person and a pallet: TF and RGB-D messages only."""
    world = labelling_hall()
    specs = robot_specs(world, waypoints=robot_waypoints(), cameras=["rgbd"], speed_mps=1.5)
    return [o for o in simulate(world, specs, start_ns=START_NS) if o.topic in TOPICS]


@contextmanager
def running_stage(settings: Settings, store: MapStore, factory: Callable[[StageContext], LabellingStage]
                  ) -> Iterator[Bus]:
    """The stage under ``run_stage`` on a listening bus; yields a second bus connected to it (the robot)."""
    stop = threading.Event()
    robot_side = ZenohSettings(listen=[], connect=settings.zenoh.listen)
    with Bus.open(settings.zenoh, domain_id=0) as bus, Bus.open(robot_side, domain_id=0) as robot_bus:
        thread = threading.Thread(target=run_stage, args=("object_labelling", factory),
                                  kwargs={"bus": bus, "store": store, "settings": settings, "stop": stop})
        thread.start()
        try:
            wait_for(lambda: bus.alive_workers() == ["object_labelling"], timeout_s=30, what="the worker to come up")
            yield robot_bus
        finally:
            stop.set()
            thread.join(timeout=30)
            assert not thread.is_alive()


def _store(tmp_path: Path) -> MapStore:
    store = MapStore(f"sqlite:///{tmp_path / 'aisle.db'}")
    store.upgrade()
    return store


def _factory(model: Path, weights: Path, **params: Any) -> Callable[[StageContext], LabellingStage]:
    settings = LabellingSettings(model_path=model, weights_path=weights, **params)
    return lambda context: LabellingStage(context, settings)


def _publish(bus: Bus, outputs: list[Output], *, rate: float) -> None:
    publish_live(bus, outputs, threading.Event(), start_ns=outputs[0].stamp_ns, rate=rate)


def _agreement(scans: list[Any]) -> tuple[float, float, int]:
    """Share of object-labelled cones whose ray hits that class first, share of object-hitting cones
    labelled with their class, and the number of object-labelled cones."""
    world = labelling_hall()
    labelled = correct = truth_objects = found = 0
    for scan in scans:
        stamp_ns = scan.header.stamp.sec * 10**9 + scan.header.stamp.nanosec
        p, q = scan.camera_pose.position, scan.camera_pose.orientation
        yaw = yaw_from_quaternion((q.x, q.y, q.z, q.w))
        bearings = yaw + np.asarray(scan.bearings, dtype=np.float64)
        truth = cone_truth(world, (stamp_ns - START_NS) / 1e9, np.array([p.x, p.y]), bearings,
                           np.asarray(scan.heights, dtype=np.float64))
        names = [scan.class_names[i] for i in scan.labels]
        for name, true in zip(names, truth, strict=True):
            if name in ROI_CLASSES:
                labelled += 1
                correct += name == true
            if true in ROI_CLASSES:
                truth_objects += 1
                found += name == true
    return correct / max(labelled, 1), found / max(truth_objects, 1), labelled


@pytest.mark.slow
def test_annotated_scans_of_simulated_traffic_label_the_objects_the_cones_hit(
    zenoh_listen: ZenohSettings, tmp_path: Path, sim_model: Path, weights_path: Path, sim_traffic: list[Output]
) -> None:
    store = _store(tmp_path)
    settings = Settings(database_url=store.url, zenoh=zenoh_listen)
    with running_stage(settings, store, _factory(sim_model, weights_path, commit_period_s=0.5)) as robot_bus:
        received = robot_bus.subscribe("annotated_scan", messages.ANNOTATED_SCAN, namespaces=["robot1"],
                                       maxsize=1000, name="test.annotated")
        _publish(robot_bus, sim_traffic, rate=1.0)
        frames = sum(o.topic == "rgbd/color/image_raw" for o in sim_traffic)
        wait_for(lambda: received.pending() >= frames // 3, timeout_s=30, what="annotated scans")
        site = store.ensure_map(settings.map_name)
        wait_for(lambda: store.features(site.id, kinds=["object"]), timeout_s=10, what="committed objects")
        scans = []
        while (item := received.receive(0.5)) is not None:
            scans.append(item.message)
    precision, recall, labelled = _agreement(scans)
    log.info("annotated scans %d of %d frames; object cones %d; agreement with ray truth %.3f, recall %.3f",
             len(scans), frames, labelled, precision, recall)
    print(f"annotated_scans {len(scans)} of {frames} frames, object cones {labelled}, "
          f"label agreement {precision:.3f}, recall {recall:.3f}")
    assert scans[0].class_names[0] == "unknown" and set(ROI_CLASSES) <= set(scans[0].class_names)
    assert precision >= 0.85  # the object labels published are right
    # and most cones that see an object carry its class (objects cut by the image too); which frames a loaded
    # machine lets the stage label (a newer pair overtakes one waiting) moves this share by about 0.1
    assert recall > 0.5
    site_id = store.ensure_map(settings.map_name).id
    stored = {f.feature.key: f.feature for revision in store.revisions(site_id, limit=1000)
              for f in store.features(site_id, kinds=["object"], revision=revision.id)}
    objects = list(stored.values())  # every object the stage stored (each is dropped once unseen for 10 s)
    for feature in objects:
        assert feature.properties["robot"] == "robot1"
        assert feature.properties["first_seen_ns"] <= feature.properties["last_seen_ns"]
        print("object", feature.properties["class"], np.round(feature.geometry["coordinates"], 2), feature.confidence)
    for actor in labelling_hall().actors:  # each object stored once, near where it stands
        label = {"person": "human"}.get(actor.kind.value, actor.kind.value)
        near = [f for f in objects if f.properties["class"] == label
                and math.dist(f.geometry["coordinates"], actor.path.mean(axis=0)) < 2.5]
        assert len(near) == 1, (label, [f.geometry["coordinates"] for f in objects])
    assert len(objects) == len(labelling_hall().actors)


def test_missing_model_file_fails_at_start_with_how_to_train_one(tmp_path: Path, weights_path: Path) -> None:
    context = StageContext("object_labelling", None, None, Settings(), None, None)  # type: ignore[arg-type]
    with pytest.raises(ObjectLabellingError, match=r"does not exist.*aisle train-classifier"):
        LabellingStage(context, LabellingSettings(model_path=tmp_path / "absent.npz", weights_path=weights_path))


def test_corrupt_model_file_fails_at_start_with_how_to_train_one(tmp_path: Path, weights_path: Path) -> None:
    model = tmp_path / "broken.npz"
    model.write_bytes(b"PK\x03\x04 not really a zip")
    context = StageContext("object_labelling", None, None, Settings(), None, None)  # type: ignore[arg-type]
    with pytest.raises(ObjectLabellingError, match=r"corrupt.*aisle train-classifier"):
        LabellingStage(context, LabellingSettings(model_path=model, weights_path=weights_path))


def _corrupt_pairs(traffic: list[Output]) -> list[Output]:
    """Traffic with a bad pair 100 ms after three good frames: wrong encoding, size mismatch, all-zero depth."""
    out = []
    colours = {o.stamp_ns: o for o in traffic if o.topic == "rgbd/color/image_raw"}
    depths = {o.stamp_ns: o for o in traffic if o.topic == "rgbd/depth/image_raw"}
    stamps = sorted(colours)
    breakers = {stamps[3]: "encoding", stamps[6]: "size", stamps[9]: "zero"}
    for output in traffic:
        out.append(output)
        if output.topic != "rgbd/depth/image_raw" or output.stamp_ns not in breakers:
            continue
        stamp_ns = output.stamp_ns + 100_000_000
        colour, depth = colours[output.stamp_ns].message, depths[output.stamp_ns].message
        header = type(colour.header)(stamp=type(colour.header.stamp)(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9),
                                     frame_id=colour.header.frame_id)
        kind = breakers[output.stamp_ns]
        bad_colour = type(colour)(header=header, height=colour.height, width=colour.width,
                                  encoding="mono8" if kind == "encoding" else colour.encoding,
                                  is_bigendian=0, step=colour.step, data=colour.data)
        if kind == "size":
            half = np.asarray(depth.data).view(np.uint16).reshape(depth.height, depth.width)[::2, ::2].copy()
            bad_depth = type(depth)(header=header, height=half.shape[0], width=half.shape[1], encoding="16UC1",
                                    is_bigendian=0, step=half.shape[1] * 2, data=half.view(np.uint8).ravel())
        else:
            data = np.zeros_like(depth.data) if kind == "zero" else depth.data
            bad_depth = type(depth)(header=header, height=depth.height, width=depth.width, encoding=depth.encoding,
                                    is_bigendian=0, step=depth.step, data=data)
        out.append(Output(stamp_ns, output.namespace, "rgbd/color/image_raw", messages.IMAGE, bad_colour))
        out.append(Output(stamp_ns, output.namespace, "rgbd/depth/image_raw", messages.IMAGE, bad_depth))
    return out


@pytest.mark.slow
def test_corrupt_frames_are_counted_and_skipped_while_good_frames_flow(
    zenoh_listen: ZenohSettings, tmp_path: Path, sim_model: Path, weights_path: Path, sim_traffic: list[Output]
) -> None:
    first_seconds = [o for o in sim_traffic if o.stamp_ns < START_NS + 3_000_000_000]
    traffic = _corrupt_pairs(first_seconds)
    good = sum(o.topic == "rgbd/color/image_raw" for o in first_seconds)
    store = _store(tmp_path)
    settings = Settings(database_url=store.url, zenoh=zenoh_listen)
    with running_stage(settings, store, _factory(sim_model, weights_path)) as robot_bus:
        received = robot_bus.subscribe("annotated_scan", messages.ANNOTATED_SCAN, namespaces=["robot1"],
                                       maxsize=1000, name="test.annotated")
        _publish(robot_bus, traffic, rate=0.5)
        wait_for(lambda: received.pending() >= good // 2, timeout_s=30, what="annotated scans of the good frames")
    counters = {w.name: w for w in store.workers()}["object_labelling"].counters
    # Each bad pair is either labelled corrupt or, on a loaded machine, overtaken by the next good pair while it
    # waits for its pose (counted as skipped): none passes silently, and the checks themselves do run.
    assert counters["object_labelling.corrupt_frames"] >= 1
    assert counters["object_labelling.corrupt_frames"] + counters.get("object_labelling.pairs_skipped", 0) >= 3
    assert counters["object_labelling.frames_labelled"] >= good // 2
    assert counters.get("object_labelling.crashes", 0) == 0

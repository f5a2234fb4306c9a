"""The load-scene stage as deployed: real zenoh, a real SQLite store, a simulated robot whose rack-facing RGB-D
camera looks at loaded racks while it drives down the aisle."""

from __future__ import annotations

import math
import threading
from pathlib import Path

import numpy as np
import pytest

from services.load_scenes.worker import load_scenes_stage
from services.simulator import RobotSpec, loaded_layout, rack_rgbd_mount, rgbd_sensor, simulate, world_from_layout
from services.simulator.lidar import LidarModel
from services.simulator.live import publish_live
from services.simulator.loads import bin_records
from services.simulator.stream import Output
from shared.bus import Bus
from shared.loads import occupancy_from_feature
from shared.settings import LoadScenesStageSettings, Settings, ZenohSettings
from shared.store import MapStore, RevisionWrite
from shared.vocabulary import FeatureKind
from shared.worker import run_stage
from tests.helpers import wait_for

TOPICS = ("tf", "tf_static", "rgbd/depth/image_raw", "rgbd/camera_info")


@pytest.mark.slow
def test_a_robot_driving_past_loaded_racks_stores_bin_states_that_match_them(zenoh_listen: ZenohSettings,
                                                                             tmp_path: Path) -> None:
    world = world_from_layout(loaded_layout(4, aisles=1, bays=3))
    row = next(r for r in world.rows if r.id == "R01L")  # faces +y; the robot drives -x with the camera on its left
    face_y = float(row.polygon[:, 1].max())
    x0, x1 = float(row.polygon[:, 0].min()), float(row.polygon[:, 0].max())
    route = np.array([[x1 - 0.3, face_y + 2.65], [x0 + 0.3, face_y + 2.65]])
    camera = rgbd_sensor(rate_hz=2.0, photos=False, mount=rack_rgbd_mount(height_m=0.6, pitch_up_rad=0.2))
    spec = RobotSpec("robot1", route, speed_mps=2.0, cameras=(camera,), lidar=LidarModel(rate_hz=1.0))
    outputs: list[Output] = [o for o in simulate(world, [spec]) if o.topic in TOPICS]

    store = MapStore(f"sqlite:///{tmp_path / 'aisle.db'}")
    store.upgrade()
    settings = Settings(database_url=store.url, zenoh=zenoh_listen,
                        load_scenes=LoadScenesStageSettings(commit_period_s=0.5))
    site = store.ensure_map(settings.map_name)
    bins = [b.feature() for b in bin_records(world)]
    store.write_revision(site.id, RevisionWrite("pillar_mapping", features={FeatureKind.BIN: bins}))

    stop = threading.Event()
    robot_side = ZenohSettings(listen=[], connect=settings.zenoh.listen)
    with Bus.open(settings.zenoh, domain_id=0) as bus, Bus.open(robot_side, domain_id=0) as robot_bus:
        thread = threading.Thread(target=run_stage, args=("load_scenes", load_scenes_stage),
                                  kwargs={"bus": bus, "store": store, "settings": settings, "stop": stop})
        thread.start()
        try:
            wait_for(lambda: bus.alive_workers() == ["load_scenes"], timeout_s=30, what="the worker to come up")
            publish_live(robot_bus, outputs, threading.Event(), start_ns=outputs[0].stamp_ns, rate=3.0)
            wait_for(lambda: store.features(site.id, kinds=[FeatureKind.BIN_STATE]), timeout_s=20,
                     what="stored bin states")
        finally:
            stop.set()
            thread.join(timeout=30)
        assert not thread.is_alive()
        assert store.features(site.id, kinds=[FeatureKind.LOAD_SCENE])
    states = {s.bin_id: s for s in (occupancy_from_feature(item.feature)
                                    for item in store.features(site.id, kinds=[FeatureKind.BIN_STATE]))}
    truth = {b.id: b.occupied for b in world.bins}
    decided = {k: s for k, s in states.items() if s.state.value != "unknown"}
    assert len(decided) >= 3
    for bin_id, state in decided.items():
        assert (state.state.value == "occupied") == truth[bin_id], (bin_id, state)
        assert state.last_seen_ns is not None and state.views >= 1
    assert all(math.isfinite(s.confidence) for s in states.values())



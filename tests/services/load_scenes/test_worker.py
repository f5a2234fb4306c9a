"""The load-scene stage as deployed: real zenoh, a real SQLite store, a simulated robot whose rack-facing RGB-D
camera looks at loaded racks while it drives down the aisle; then the WMS imports a stock list with planted errors
through the HTTP API and asks for the discrepancies.

One survey serves every test here (module fixture): the stage runs over the drive, is stopped, and a new stage on
the same store runs over a second drive past the same racks, so what the second run stores rests on both."""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient

from api import create_app
from services.load_scenes.worker import load_scenes_stage
from services.simulator import RobotSpec, loaded_layout, rack_rgbd_mount, rgbd_sensor, simulate, world_from_layout
from services.simulator.lidar import LidarModel
from services.simulator.live import publish_live
from services.simulator.loads import bin_records
from services.simulator.stream import Output
from services.simulator.world import World
from shared.bus import Bus
from shared.loads import BinOccupancy, Occupancy, occupancy_from_feature
from shared.settings import LoadScenesStageSettings, Settings, ZenohSettings
from shared.store import MapStore, RevisionWrite
from shared.store.keys import Role, create_key
from shared.vocabulary import FeatureKind
from shared.worker import run_stage
from tests.helpers import free_port, wait_for

pytestmark = pytest.mark.slow

TOPICS = ("tf", "tf_static", "rgbd/depth/image_raw", "rgbd/camera_info")
URL = "/v1/maps/site"


@dataclass(frozen=True)
class Survey:
    world: World
    store: MapStore
    map_id: int
    first: dict[str, BinOccupancy]
    """Bin states stored after the first run of the stage."""
    second: dict[str, BinOccupancy]
    """Bin states stored after the second run (a new stage on the same store)."""


def _states(store: MapStore, map_id: int) -> dict[str, BinOccupancy]:
    return {s.bin_id: s for s in (occupancy_from_feature(item.feature)
                                  for item in store.features(map_id, kinds=[FeatureKind.BIN_STATE]))}


def _drive(world: World) -> list[Output]:
    """A robot with the low rack camera driving down the aisle past row R01L."""
    row = next(r for r in world.rows if r.id == "R01L")  # faces +y; the robot drives -x with the camera on its left
    face_y = float(row.polygon[:, 1].max())
    x0, x1 = float(row.polygon[:, 0].min()), float(row.polygon[:, 0].max())
    route = np.array([[x1 - 0.3, face_y + 2.65], [x0 + 0.3, face_y + 2.65]])
    camera = rgbd_sensor(rate_hz=2.0, photos=False, mount=rack_rgbd_mount(height_m=0.6, pitch_up_rad=0.2))
    spec = RobotSpec("robot1", route, speed_mps=2.0, cameras=(camera,), lidar=LidarModel(rate_hz=1.0))
    return [o for o in simulate(world, [spec]) if o.topic in TOPICS]


def _settled(read: Callable[[], object], *, quiet_s: float = 1.5) -> Callable[[], bool]:
    """A condition: ``read()`` is truthy and has not changed for ``quiet_s`` (the stage has caught up)."""
    seen: object = None
    since = time.monotonic()

    def condition() -> bool:
        nonlocal seen, since
        value = read()
        if value != seen:
            seen, since = value, time.monotonic()
            return False
        return bool(value) and time.monotonic() - since >= quiet_s

    return condition


def _run_stage(settings: Settings, store: MapStore, outputs: list[Output], done: Callable[[], object]) -> None:
    """One run of the stage (its own thread) over the drive, until ``done()`` holds; then it is stopped."""
    stop = threading.Event()
    robot_side = ZenohSettings(listen=[], connect=settings.zenoh.listen)
    with Bus.open(settings.zenoh, domain_id=0) as bus, Bus.open(robot_side, domain_id=0) as robot_bus:
        thread = threading.Thread(target=run_stage, args=("load_scenes", load_scenes_stage),
                                  kwargs={"bus": bus, "store": store, "settings": settings, "stop": stop})
        thread.start()
        try:
            wait_for(lambda: bus.alive_workers() == ["load_scenes"], timeout_s=30, what="the worker to come up")
            publish_live(robot_bus, outputs, threading.Event(), start_ns=outputs[0].stamp_ns, rate=3.0)
            wait_for(done, timeout_s=20, what="stored bin states")
        finally:
            stop.set()
            thread.join(timeout=30)
        assert not thread.is_alive()


@pytest.fixture(scope="module")
def survey(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Survey]:
    world = world_from_layout(loaded_layout(4, aisles=1, bays=3))
    outputs = _drive(world)
    store = MapStore(f"sqlite:///{tmp_path_factory.mktemp('loads') / 'aisle.db'}")
    store.upgrade()
    settings = Settings(database_url=store.url, zenoh=ZenohSettings(listen=[f"tcp/127.0.0.1:{free_port()}"]),
                        load_scenes=LoadScenesStageSettings(commit_period_s=0.5))
    site = store.ensure_map(settings.map_name)
    bins = [b.feature() for b in bin_records(world)]  # as the pillar stage stores them
    store.write_revision(site.id, RevisionWrite("pillar_mapping", features={FeatureKind.BIN: bins}))

    def views() -> int:
        return sum(s.views for s in _states(store, site.id).values())

    _run_stage(settings, store, outputs, _settled(views))
    first = _states(store, site.id)
    assert store.features(site.id, kinds=[FeatureKind.LOAD_SCENE])
    seen_first = views()
    _run_stage(settings, store, outputs, _settled(lambda: (n := views()) > seen_first and n))
    yield Survey(world, store, site.id, first, _states(store, site.id))
    store.close()


def test_a_robot_driving_past_loaded_racks_stores_bin_states_that_match_them(survey: Survey) -> None:
    truth = {b.id: b.occupied for b in survey.world.bins}
    for states in (survey.first, survey.second):
        decided = {k: s for k, s in states.items() if s.state is not Occupancy.UNKNOWN}
        assert len(decided) >= 3
        for bin_id, state in decided.items():
            assert (state.state is Occupancy.OCCUPIED) == truth[bin_id], (bin_id, state)
            assert state.last_seen_ns is not None and state.views >= 1
        assert all(math.isfinite(s.confidence) for s in states.values())


def test_a_restarted_stage_fuses_onto_the_states_stored_before(survey: Survey) -> None:
    seen = [bin_id for bin_id, state in survey.first.items() if state.views]
    assert seen
    for bin_id in seen:  # the second drive passed the same bins: its views were added to the stored ones
        before, after = survey.first[bin_id], survey.second[bin_id]
        assert after.views > before.views or after == before, (before, after)
    assert sum(survey.second[k].views for k in seen) > sum(survey.first[k].views for k in seen) * 1.5
    # older views are discounted (history_weight) so a rack that changes is followed; a restart must not flip
    # what the robots saw before
    decided = [k for k in seen if Occupancy.UNKNOWN not in (survey.first[k].state, survey.second[k].state)]
    assert decided and all(survey.first[k].state is survey.second[k].state for k in decided)


def test_the_wms_learns_through_the_api_where_its_stock_list_is_wrong(survey: Survey, tmp_path: Path) -> None:
    truth = {b.id: b.occupied for b in survey.world.bins}
    ids = sorted(truth)
    planted = set(ids[::3])  # every third bin booked wrongly: stock where the rack is empty, none where it holds some
    stock = [{"id": bin_id, "holds_stock": truth[bin_id] != (bin_id in planted)} for bin_id in ids]
    well_seen = {k for k, s in survey.second.items() if s.state is not Occupancy.UNKNOWN and s.views >= 2}
    expected = planted & well_seen
    assert {truth[k] for k in expected} == {True, False}, "errors of both kinds among the bins seen twice"

    settings = Settings(data_dir=tmp_path, database_url=survey.store.url)
    key = create_key(survey.store, role=Role.WRITE, name="wms")[1]
    with TestClient(create_app(store=survey.store, settings=settings)) as client:
        put = client.put(f"{URL}/wms-stock", json={"bins": stock}, headers={"X-API-Key": key})
        assert put.status_code == 200, put.text
        answer = client.get(f"{URL}/wms-stock/discrepancies", params={"min_views": 2})
    assert answer.status_code == 200, answer.text
    body = answer.json()
    assert {item["bin_id"] for item in body["discrepancies"]} == expected
    for item in body["discrepancies"]:
        assert item["robots_saw"] == ("occupied" if truth[item["bin_id"]] else "empty")
        assert item["views"] >= 2 and item["last_seen"] is not None
        assert len(item["evidence"]) == len(item["occupancy"]["objects"]), "the objects seen, as 3D boxes"
    assert body["counts"]["listed"] == len(ids)

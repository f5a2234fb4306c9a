"""The occupancy stage as deployed: real zenoh, a real store, a robot in another process."""

from __future__ import annotations

import math
import subprocess
import sys
from functools import partial
from pathlib import Path

import numpy as np
import pytest

from services.occupancy_mapping.worker import occupancy_stage
from shared import messages
from shared.keyexpr import Attachment, topic_key
from shared.robots import Robot
from shared.settings import Settings, ZenohSettings
from shared.store import MapStore
from tests import stages
from tests.helpers import wait_for

TALKER = Path(__file__).resolve().parents[2] / "rmw_zenoh_talker.py"


running_stage = partial(stages.running_stage, "occupancy_mapping", occupancy_stage)


def _settings(zenoh_listen: ZenohSettings, url: str) -> Settings:
    return Settings(database_url=url, zenoh=zenoh_listen,
                    occupancy={"store_period_s": 0.3, "publish_period_s": 0.3, "resolution_m": 0.1})


def _talk(zenoh_listen: ZenohSettings, *, scans: int = 40, namespace: str = "robot1") -> None:
    subprocess.run([sys.executable, str(TALKER), "--connect", zenoh_listen.listen[0], "--scans", str(scans),
                    "--namespace", namespace], check=True, timeout=60)


def _cell(layer_data: np.ndarray, x: float, y: float, origin: tuple[float, float], res: float) -> int:
    return int(layer_data[int((y - origin[1]) / res), int((x - origin[0]) / res)])


def test_scans_from_a_separate_rmw_zenoh_process_build_the_map_and_track_the_robot(
        zenoh_listen: ZenohSettings, store: MapStore) -> None:
    settings = _settings(zenoh_listen, store.url)
    with running_stage(settings, store):
        _talk(zenoh_listen)
        site = store.ensure_map(settings.map_name)
        wait_for(lambda: (layer := store.layer(site.id, "occupancy")) is not None
                 and int((layer.layer.data > 50).sum()) > 200, what="walls in the stored occupancy layer")
    stored = store.layer(site.id, "occupancy")
    assert stored is not None
    grid = stored.layer
    origin, res = (grid.origin_x_m, grid.origin_y_m), grid.resolution_m
    for wall_point in [(4.0, 0.0), (-4.0, 1.0), (0.5, 4.0), (1.0, -4.0)]:
        values = [_cell(grid.data, wall_point[0] + dx, wall_point[1] + dy, origin, res)
                  for dx in (-0.1, 0.0, 0.1) for dy in (-0.1, 0.0, 0.1)]
        assert max(values) > 50, f"wall at {wall_point} not occupied"
    assert 0 <= _cell(grid.data, 0.0, 0.0, origin, res) < 50  # the room's middle is free
    assert _cell(grid.data, 5.5, 5.5, origin, res) == -1  # behind the walls nothing is known
    worker = {w.name: w for w in store.workers()}["occupancy_mapping"]
    assert worker.counters["occupancy_mapping.scans_integrated"] >= 35
    stored_robot = store.feature(site.id, "robot", "robot1")
    assert stored_robot is not None and stored_robot.revision_id == stored.revision_id
    robot = Robot.from_feature(stored_robot.feature)
    assert robot.robot == "robot1" and robot.track[-1] == robot.pose
    assert len(robot.track) >= 5  # several seconds of driving, thinned
    # the lidar (0.2 m ahead of the base) went round the 1.5 m circle the robot drove
    assert all(1.1 < math.hypot(p.x_m, p.y_m) < 2.1 for p in robot.track)
    stamps = [p.stamp_ns for p in robot.track]
    assert stamps == sorted(stamps)


def test_bad_input_is_counted_and_the_worker_keeps_mapping(zenoh_listen: ZenohSettings, tmp_path: Path) -> None:
    store = MapStore(f"sqlite:///{tmp_path / 'a.db'}")
    store.upgrade()
    settings = _settings(zenoh_listen, store.url)
    with running_stage(settings, store) as bus:
        scan_key = topic_key(0, "robot1", "scan", messages.LASER_SCAN)
        attachment = Attachment(1, 0, bytes(16)).encode()
        cls = messages.message_class
        bad_scan = cls(messages.LASER_SCAN)(
            header=cls("std_msgs/msg/Header")(stamp=cls("builtin_interfaces/msg/Time")(sec=1, nanosec=0),
                                              frame_id="laser"),
            angle_min=-1.0, angle_max=1.0, angle_increment=0.5, time_increment=0.0, scan_time=0.1,
            range_min=0.1, range_max=10.0, ranges=np.full(100, np.nan, np.float32), intensities=np.zeros(0, np.float32))
        bus.session.put(scan_key, b"\x00\x01\x00\x00not a scan", attachment=attachment)
        bus.session.put(scan_key, messages.serialize(bad_scan, messages.LASER_SCAN), attachment=attachment)
        _talk(zenoh_listen)
        site = store.ensure_map(settings.map_name)
        wait_for(lambda: (layer := store.layer(site.id, "occupancy")) is not None
                 and int((layer.layer.data > 50).sum()) > 200, what="a map despite the bad input")
        counters = bus.counters.snapshot()
    assert counters["occupancy_mapping.scan.malformed"] >= 1
    worker = {w.name: w for w in store.workers()}["occupancy_mapping"]
    assert worker.counters["occupancy_mapping.malformed_scans"] >= 1


def test_restart_resumes_from_the_stored_layer(zenoh_listen: ZenohSettings, tmp_path: Path) -> None:
    store = MapStore(f"sqlite:///{tmp_path / 'a.db'}")
    store.upgrade()
    settings = _settings(zenoh_listen, store.url)
    site = store.ensure_map(settings.map_name)
    with running_stage(settings, store):
        _talk(zenoh_listen, scans=20)
        wait_for(lambda: store.layer(site.id, "occupancy") is not None, what="a first layer")
    before = store.layer(site.id, "occupancy")
    assert before is not None
    with running_stage(settings, store):
        _talk(zenoh_listen, scans=5, namespace="robot2")
        wait_for(lambda: (s := store.layer(site.id, "occupancy")) is not None and s.revision_id > before.revision_id,
                 what="a revision after the restart")
    after = store.layer(site.id, "occupancy")
    assert after is not None
    known_before = int((before.layer.data >= 0).sum())
    assert int((after.layer.data >= 0).sum()) >= known_before
    assert int((after.layer.data > 50).sum()) >= int((before.layer.data > 50).sum()) * 0.9


@pytest.mark.postgres
def test_database_outage_is_survived(zenoh_listen: ZenohSettings, postgres_url: str) -> None:
    from sqlalchemy import make_url

    from tests.tcp_proxy import TcpProxy

    target = make_url(postgres_url)
    with TcpProxy(target.host or "127.0.0.1", target.port or 5432) as proxy:
        url = target.set(host="127.0.0.1", port=proxy.port).render_as_string(hide_password=False)
        store = MapStore(url)
        store.upgrade()
        settings = _settings(zenoh_listen, url)
        site = store.ensure_map(settings.map_name)
        with running_stage(settings, store):
            _talk(zenoh_listen, scans=10)
            wait_for(lambda: store.layer(site.id, "occupancy") is not None, what="a first revision")
            first = len(store.revisions(site.id))
            proxy.cut()
            _talk(zenoh_listen, scans=10, namespace="robot2")
            wait_for(lambda: proxy.refused > 2, what="the worker to hit the outage")
            proxy.restore()
            _talk(zenoh_listen, scans=10, namespace="robot3")
            wait_for(lambda: len(store.revisions(site.id)) > first, timeout_s=30, what="writes after the outage")
        worker = {w.name: w for w in store.workers()}["occupancy_mapping"]
        assert worker.counters.get("occupancy_mapping.store_unavailable", 0) >= 1
        assert len(store.revisions(site.id)) > first
        store.close()


def test_map_and_map_events_are_published_for_ros_tools(zenoh_listen: ZenohSettings, tmp_path: Path) -> None:
    from shared.grids import layer_from_occupancy_grid

    store = MapStore(f"sqlite:///{tmp_path / 'a.db'}")
    store.upgrade()
    settings = _settings(zenoh_listen, store.url)
    with running_stage(settings, store) as bus:
        grids = bus.subscribe("map", messages.OCCUPANCY_GRID, namespaces=["aisle"], name="test.map")
        events = bus.subscribe("map_events", messages.MAP_EVENT, namespaces=["aisle"], name="test.events")
        _talk(zenoh_listen)
        wait_for(lambda: grids.pending() > 0 and events.pending() > 0, what="a map and a map event")
        grid, event = grids.receive(1.0), events.receive(1.0)
    assert grid is not None and event is not None
    layer = layer_from_occupancy_grid(grid.message, name="occupancy")
    assert grid.message.header.frame_id == "map" and int((layer.data > 50).sum()) > 0
    assert event.message.map_name == "site" and event.message.stage == "occupancy_mapping"
    assert list(event.message.layers_updated) == ["occupancy"]
    assert store.revisions(store.ensure_map("site").id)[0].id == event.message.revision_id

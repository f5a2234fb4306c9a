"""The whole stack as a user starts it: ``aisle run`` in its own process, asked over HTTP."""

from __future__ import annotations

import io
import signal
from pathlib import Path

import cv2
import numpy as np
import pytest

from services.occupancy_mapping import wall_agreement
from shared.mapfiles import read_map_yaml
from shared.settings import Settings
from shared.store import GridLayer, MapStore
from tests.helpers import data_path, wait_for
from tests.stack import POLL_S, aisle_run, counter, health

pytestmark = pytest.mark.slow


def test_demo_stack_reports_healthy_and_builds_a_map(tmp_path: Path) -> None:
    with aisle_run(tmp_path, "--demo", "--demo-rate", "3") as client:
        wait_for(lambda: health(client)["status"] == "ok", timeout_s=60, what="a healthy stack")
        status = health(client)
        assert status["database"]["ok"] and status["bus"]["ok"]
        assert {w["name"] for w in status["workers"] if w["alive"]} == set(Settings().stages)
        wait_for(lambda: client.get("/v1/maps/site/layers/occupancy.png").status_code == 200, timeout_s=60,
                 interval_s=POLL_S, what="an occupancy layer")
        png = client.get("/v1/maps/site/layers/occupancy.png")
        image = cv2.imdecode(np.frombuffer(png.content, np.uint8), cv2.IMREAD_UNCHANGED)
        assert image is not None and (image == 0).sum() > 100  # walls drawn black
        revisions_seen = client.get("/v1/maps/site/revisions").json()
    store = MapStore(f"sqlite:///{tmp_path / 'var' / 'aisle.db'}")
    site = store.get_map("site")
    assert site is not None
    stored = store.revisions(site.id, limit=1000)
    assert len(stored) >= len(revisions_seen["revisions"])  # the final write on shutdown kept everything
    store.close()


@pytest.mark.parametrize(("stop_signal", "grace_s"), [(signal.SIGTERM, None), (signal.SIGINT, "0")],
                         ids=["sigterm", "sigint-no-grace"])
def test_a_signal_stops_the_stack_and_leaves_a_store_that_opens(tmp_path: Path, stop_signal: signal.Signals,
                                                                grace_s: str | None) -> None:
    # with no grace the stages are stopped in the middle of their work: the process still exits with 0
    env = {} if grace_s is None else {"AISLE_SHUTDOWN_GRACE_S": grace_s}
    with aisle_run(tmp_path, "--demo", "--demo-rate", "3", stop_signal=stop_signal, env=env) as client:
        wait_for(lambda: client.get("/v1/maps/site/layers/occupancy").status_code == 200, timeout_s=60,
                 interval_s=POLL_S, what="an occupancy layer")
    # aisle_run asserted the exit code 0 (within its hang guard)
    store = MapStore(f"sqlite:///{tmp_path / 'var' / 'aisle.db'}")
    assert store.upgrade() is False  # the schema as the process left it
    with store.engine.connect() as connection:
        assert connection.exec_driver_sql("PRAGMA integrity_check").scalar() == "ok"
    site = store.get_map("site")
    assert site is not None
    stored = store.layer(site.id, "occupancy")
    assert stored is not None and (stored.layer.data >= 0).any()  # the map built before the stop reads back
    store.close()


def test_replayed_mac_bag_lines_up_with_its_own_map(tmp_path: Path) -> None:
    bag = data_path("bags", "mac_first_floor", "bag")
    reference = read_map_yaml(data_path("bags", "mac_first_floor", "mac_1st_floor_final.yaml"))
    with aisle_run(tmp_path, "--replay", str(bag), "--rate", "4") as client:
        wait_for(lambda: counter(client, "occupancy_mapping", "scans_integrated") >= 340, timeout_s=120,
                 interval_s=POLL_S, what="every scan integrated")
        png = client.get("/v1/maps/site/layers/occupancy.png")
        assert png.status_code == 200 and png.headers["content-type"] == "image/png"
        values = client.get("/v1/maps/site/layers/occupancy/values", params={"format": "npy"})
        meta = client.get("/v1/maps/site/layers/occupancy").json()
    occupancy = np.load(io.BytesIO(values.content), allow_pickle=False)
    ours = GridLayer("ours", occupancy, meta["resolution_m"], meta["origin"]["x_m"], meta["origin"]["y_m"])
    agreement = wall_agreement(ours, GridLayer("reference", reference.occupancy, reference.resolution_m,
                                               reference.origin_x_m, reference.origin_y_m))
    # most of what we call a wall is a wall of the floor's own map, and about half of the walls in the
    # part of the floor the bag saw are found (the bag is 46 s of one corridor loop; figures in the README)
    assert agreement.precision > 0.5
    assert agreement.fraction_in_view > 0.4

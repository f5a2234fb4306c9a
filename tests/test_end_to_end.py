"""The whole stack as a user starts it: ``aisle run`` in its own process, asked over HTTP."""

from __future__ import annotations

import io
import os
import signal
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import cv2
import httpx2 as httpx
import numpy as np
import pytest

from services.occupancy_mapping import read_map_yaml, wall_agreement
from shared.settings import Settings
from shared.store import GridLayer, MapStore
from tests.helpers import data_path, free_port, wait_for

pytestmark = pytest.mark.slow


@contextmanager
def aisle_run(tmp_path: Path, *args: str) -> Iterator[httpx.Client]:
    """``aisle run ARGS`` on free ports with its own data folder; stopped with SIGINT, which must be clean."""
    port = free_port()
    env = {**os.environ, "AISLE_DATA_DIR": str(tmp_path / "var"), "AISLE_API_PORT": str(port),
           "AISLE_ZENOH__LISTEN": f'["tcp/127.0.0.1:{free_port()}"]', "AISLE_OCCUPANCY__STORE_PERIOD_S": "1"}
    log = (tmp_path / "aisle.log").open("w")
    process = subprocess.Popen([sys.executable, "-m", "services.cli", "run", *args], env=env, stdout=log,
                               stderr=subprocess.STDOUT)
    try:
        with httpx.Client(base_url=f"http://127.0.0.1:{port}", timeout=5.0) as client:
            wait_for(lambda: _answers(client), timeout_s=60, what="the API to answer")
            yield client
        process.send_signal(signal.SIGINT)
        assert process.wait(timeout=60) == 0, (tmp_path / "aisle.log").read_text()[-3000:]
    finally:
        if process.poll() is None:
            process.kill()
        log.close()


def _answers(client: httpx.Client) -> bool:
    try:
        client.get("/v1/health")
    except httpx.TransportError:
        return False
    return True


def _health(client: httpx.Client) -> dict[str, Any]:
    body: dict[str, Any] = client.get("/v1/health").json()
    return body


def _counter(client: httpx.Client, worker: str, name: str) -> int:
    workers = {w["name"]: w for w in _health(client)["workers"]}
    return int(workers.get(worker, {}).get("counters", {}).get(f"{worker}.{name}", 0))


def test_demo_stack_reports_healthy_and_builds_a_map(tmp_path: Path) -> None:
    with aisle_run(tmp_path, "--demo", "--demo-rate", "3") as client:
        wait_for(lambda: _health(client)["status"] == "ok", timeout_s=60, what="a healthy stack")
        health = _health(client)
        assert health["database"]["ok"] and health["bus"]["ok"]
        assert {w["name"] for w in health["workers"] if w["alive"]} == set(Settings().stages)
        wait_for(lambda: client.get("/v1/maps/site/layers/occupancy.png").status_code == 200, timeout_s=60,
                 what="an occupancy layer")
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


def test_replayed_mac_bag_lines_up_with_its_own_map(tmp_path: Path) -> None:
    bag = data_path("bags", "mac_first_floor", "bag")
    reference = read_map_yaml(data_path("bags", "mac_first_floor", "mac_1st_floor_final.yaml"))
    with aisle_run(tmp_path, "--replay", str(bag), "--rate", "4") as client:
        wait_for(lambda: _counter(client, "occupancy_mapping", "scans_integrated") >= 340, timeout_s=120,
                 what="every scan integrated")
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

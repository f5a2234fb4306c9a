"""The real deployment's shape, as processes: it keeps mapping through a killed worker and a database outage.

docker-compose.yml runs a zenoh router, PostgreSQL, one ``aisle worker`` per stage and the API. Here the same
commands and variables run as processes (:mod:`tests.deployment`), with two API instances behind one database,
while two simulated robots' survey is replayed from a rosbag2: the pillar worker is SIGKILLed mid-stream and
restarted, then the database is cut for 10 s. The map must end with the world's bins, and every revision
committed before the kill must still read as it did. (The object-labelling and semantic-fusion workers need
an RGB-D camera and a trained model; this survey carries a lidar and a fisheye only.)
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import httpx2 as httpx
import numpy as np
import pytest
from scipy.spatial import cKDTree

from services.simulator import ground_truth_features, sim_run, world_from_layout
from tests.conftest import POSTGRES_URL_ENV
from tests.deployment import Deployment, dedicated_database, deployment, serve_env, stages_env
from tests.helpers import free_port, wait_for
from tests.stack import POLL_S, answers, health

pytestmark = pytest.mark.slow

MAP = "/v1/maps/site"
STAGES = ("occupancy_mapping", "grid_decomposition", "pillar_mapping")
KILLED = "pillar_mapping"
OUTAGE_S = 10.0
BIN_TOLERANCE_M = 0.15
TWO_AISLES = {
    "name": "two-aisles",
    "hall": {"length_m": 20.0, "width_m": 17.0},
    "blocks": [
        {"id": "A", "origin_m": [3.0, 3.0], "aisles": 2, "bays": 4, "aisle_width_m": 3.0, "bay_pitch_m": 2.7,
         "rack_depth_m": 1.1, "levels": 2, "level_pitch_m": 1.5, "fill": 0.5, "end_corridor_m": 2.5},
    ],
    "seed": 0,
}
"""Two aisles, so each robot surveys both, one after the other: what the killed worker misses of the first,
the other robot shows it again later."""
SETTINGS = {
    "AISLE_OCCUPANCY__STORE_PERIOD_S": "2", "AISLE_PILLARS__STORE_PERIOD_S": "2",
    "AISLE_DECOMPOSITION__MIN_PERIOD_S": "3", "AISLE_PILLARS__RACK_PROFILES": '[{"levels_m": [0.0, 1.5]}]',
    "AISLE_PILLARS__LOCALISATION_SIGMA_M": "0.01", "AISLE_PILLARS__LOCALISATION_SIGMA_RAD": "0.002",
    **stages_env(STAGES),
}
"""The compose services' settings, with store periods short enough for a 36 s survey."""


@pytest.fixture
def database() -> Iterator[str]:
    base = os.environ.get(POSTGRES_URL_ENV)
    if not base:
        pytest.skip(f"the scale-out run needs PostgreSQL (a deployment's database): set {POSTGRES_URL_ENV}, e.g. "
                    "postgresql+psycopg://postgres@127.0.0.1:5432/test (a database of its own is created beside it)")
    with dedicated_database(base) as url:
        yield url


def _revisions(client: httpx.Client) -> list[dict[str, Any]]:
    page: list[dict[str, Any]] = client.get(f"{MAP}/revisions", params={"limit": 1000}).json()["revisions"]
    return page


def _newest(client: httpx.Client) -> int | None:
    latest = client.get(MAP).json()["latest_revision"]
    return None if latest is None else int(latest["id"])


def _bins(client: httpx.Client, revision: int) -> list[dict[str, Any]]:
    """The bins of the map as of ``revision``."""
    response = client.get(f"{MAP}/bins", params={"limit": 1000, "revision": revision})
    assert response.status_code == 200, response.text
    bins: list[dict[str, Any]] = response.json()["bins"]
    return bins


def _centres(bins: list[dict[str, Any]]) -> np.ndarray:
    return np.array([b["centre"] for b in bins], dtype=np.float64).reshape(-1, 2)


def _truth(world_layout: dict[str, Any]) -> tuple[np.ndarray, list[str]]:
    """The simulator's bins: centres (B, 2), metres, and ids (aisle-bay-level)."""
    truth = [f for f in ground_truth_features(world_from_layout(world_layout))["features"]
             if f["properties"]["kind"] == "bin"]
    centres = [np.asarray(f["geometry"]["coordinates"][0][:-1], dtype=np.float64).mean(axis=0) for f in truth]
    return np.array(centres), [f["properties"]["id"] for f in truth]


def _settled(client: httpx.Client, quiet_s: float) -> Callable[[], bool]:
    """A condition: the stored map has had no new revision for ``quiet_s``."""
    seen: dict[str, Any] = {"newest": None, "since": time.monotonic()}

    def check() -> bool:
        newest = _newest(client)
        if newest != seen["newest"]:
            seen.update(newest=newest, since=time.monotonic())
        return bool(time.monotonic() - seen["since"] >= quiet_s)

    return check


def _degraded_names(client: httpx.Client) -> list[str]:
    body = client.get("/v1/health").json()
    return list(body["missing_workers"])


def _during_outage(clients: list[httpx.Client], seconds: float) -> set[int]:
    """Ask both APIs for the map while the database is away; the status codes they answered."""
    codes: set[int] = set()
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        for client in clients:
            codes.add(client.get(f"{MAP}/revisions", params={"limit": 1}).status_code)
        time.sleep(0.5)
    return codes


def test_deployment_maps_through_a_killed_worker_and_a_database_outage(tmp_path: Path, database: str) -> None:
    ports = [free_port(), free_port()]
    with deployment(tmp_path, database, settings=SETTINGS) as stack:
        try:
            _run(stack, tmp_path, ports)
        except BaseException:
            print(stack.logs())
            raise


def _run(stack: Deployment, tmp_path: Path, ports: list[int]) -> None:
    assert stack.start("migrate", "db", "upgrade").wait(timeout=60) == 0
    for stage in STAGES:
        stack.start(stage, "worker", stage)
    for k, port in enumerate(ports):
        stack.start(f"api{k}", "serve", env=serve_env(port))
    bag = tmp_path / "survey"  # written while the processes start
    sim_run(world_from_layout(TWO_AISLES), bag, robots=2, cameras=["fisheye"], fisheye_rate_hz=2.0)
    with httpx.Client(base_url=f"http://127.0.0.1:{ports[0]}", timeout=10) as one, \
            httpx.Client(base_url=f"http://127.0.0.1:{ports[1]}", timeout=10) as two:
        wait_for(lambda: answers(one) and answers(two), timeout_s=60, what="both APIs to answer")
        wait_for(lambda: health(one)["status"] == "ok" and health(two)["status"] == "ok", timeout_s=60,
                 what="every worker alive, seen by both APIs")
        robots = stack.start("robots", "replay", str(bag))

        # SIGKILL the pillar worker once it has committed bins, mid-survey; both APIs see it missing
        wait_for(lambda: (newest := _newest(one)) is not None and _bins(one, newest), timeout_s=60,
                 interval_s=POLL_S, what="the first bins")
        before_kill = _revisions(one)
        pillar_revision = max(r["id"] for r in before_kill if r["stage"] == KILLED)
        bins_then = _bins(two, pillar_revision)
        assert robots.poll() is None, "the survey ended before the kill; it must be mid-stream"
        assert stack.kill(KILLED) == -9
        wait_for(lambda: KILLED in _degraded_names(one) and KILLED in _degraded_names(two), timeout_s=20,
                 what="both APIs to report the killed worker missing")
        stack.start(KILLED, "worker", KILLED)
        wait_for(lambda: health(one)["status"] == "ok", timeout_s=60, what="the worker back")

        # the database goes away for 10 s and comes back; both APIs say so (503) rather than hang or fail
        stack.proxy.cut()
        codes = _during_outage([one, two], OUTAGE_S)
        stack.proxy.restore()
        assert codes == {503}, codes
        assert robots.wait(timeout=120) == 0, stack.log("robots")

        wait_for(_settled(one, quiet_s=6.0), timeout_s=90, interval_s=POLL_S,
                 what="the map to stop changing after the survey")
        revision = _newest(one)
        assert revision is not None
        final = _bins(one, revision)
        assert _bins(two, revision) == final, "the two APIs read the same revision differently"

        # the map converged to the world's bins: each where a true bin is, under its id; most of them found
        # (the pillar stage can leave out a rack face it saw too little of, with or without a kill or an outage)
        truth, truth_ids = _truth(TWO_AISLES)
        to_truth, nearest = cKDTree(truth).query(_centres(final))
        assert np.all(to_truth <= BIN_TOLERANCE_M), f"bins off the true ones by {np.sort(to_truth)[-5:]} m"
        same_place = [b["id"][:-3] == truth_ids[k][:-3] for b, k in zip(final, nearest, strict=True)]
        assert all(same_place), "a bin's aisle-bay is not the simulator's at its place"
        assert {b["level"] for b in final} == {0, 1}  # the site's two levels (a level's bins share a centre)
        assert {b["aisle"] for b in final} == {1, 2}
        assert len(final) >= len(truth) / 2, f"{len(final)} of {len(truth)} bins: {sorted(b['id'] for b in final)}"

        # nothing committed before the kill is lost: every revision reads as it did, through either API
        for client in (one, two):
            assert [client.get(f"{MAP}/revisions/{r['id']}").json() for r in before_kill] == before_kill
        assert _bins(one, pillar_revision) == bins_then
        after = {r["id"] for r in _revisions(two)}
        assert {r["id"] for r in before_kill} <= after and max(after) > pillar_revision
        stages_committed = {r["stage"] for r in _revisions(one) if r["id"] > pillar_revision}
        assert {"occupancy_mapping", KILLED} <= stages_committed, stages_committed
        counters = {w["name"]: w["counters"] for w in health(one)["workers"]}
        for stage in STAGES:  # each felt the outage (a heartbeat every 5 s at least), counted it and went on
            felt = sum(counters[stage].get(f"{stage}.{what}", 0)
                       for what in ("store_unavailable", "heartbeat_failures"))
            assert felt >= 1, counters[stage]

    for name in (*STAGES, "api0", "api1", "router"):
        assert stack.stop(name) == 0, f"{name} did not stop cleanly:\n{stack.log(name)}"

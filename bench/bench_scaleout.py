"""Scale-out: what each process of the deployment costs per robot, and how many robots one machine carries.

Run: ``PYTHONPATH=. .venv/bin/python bench/bench_scaleout.py [--rates 1,3,6] [--postgres-url URL]
[--connections 4]``. Needs PostgreSQL (default ``$AISLE_TEST_POSTGRES_URL``; a database of its own is created and
dropped) and Linux (CPU times come from ``/proc``).

It starts what docker-compose.yml runs, as processes (:mod:`tests.deployment`): a zenoh router, ``aisle worker``
for ``occupancy_mapping``, ``grid_decomposition`` and ``pillar_mapping``, and ``aisle serve`` twice, all on one
PostgreSQL database (connected directly, not through the test's cuttable proxy), with the compose file's store
periods. A two-robot survey of a small two-aisle hall (per
robot: lidar 10 Hz, odometry and tf 20 Hz, fisheye 2 Hz) is replayed by ``aisle replay`` at each ``--rates`` R:
R times real time is the traffic of 2R robots, each rate on a deployment of its own. Meanwhile
``--connections`` HTTP connections per API instance ask for bins by id and the first page of the bin list (half
each), back to back.

Per rate it prints ``name value unit`` lines: for each stage the messages it took per second (scans integrated,
fisheye frames mapped, decompositions), what it dropped, the cores it used and its CPU per second of one robot's
traffic; revisions committed per second; the API's requests per second and p99 latency (both instances); the
router's and PostgreSQL's cores; and the replay's lag (wall time over the bag's duration / R: a stage that holds
the sender, as scans do, shows here). Then ``capacity.*``, from the highest rate: each process's CPU per second of
one robot's traffic (for the occupancy and pillar stages, their CPU per scan or frame taken times the scans or
frames a robot sends a second, so frames a saturated stage dropped are still counted as work to do); the robots
one stage process carries (it works on one core); how many robots one machine of ``os.cpu_count()`` cores carries
with every process of the map on it (the robots' own replay and the API, whose load is the WMS's, not the
robots', left out); which process is heaviest, what the first machine carries once it runs on a second one, and
what the two machines carry together. CPU time is what a process used whatever else
competes for the cores; wall rates depend on the machine's load (printed with ``uptime``).
"""

from __future__ import annotations

import argparse
import asyncio
import os
import random
import resource
import shutil
import subprocess
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import httpx2 as httpx
import numpy as np
import sqlalchemy as sa

from bench.bench_api_load import Load, _cpu_s, _drive
from services.simulator import sim_run, world_from_layout
from shared.store import MapStore
from shared.store.keys import Role, create_key
from tests.deployment import Deployment, dedicated_database, deployment, serve_env, stages_env
from tests.helpers import free_port, wait_for
from tests.test_scaleout import TWO_AISLES

DEFAULT_POSTGRES_URL = "postgresql+psycopg://postgres@127.0.0.1:5432/test"
STAGES = ("occupancy_mapping", "grid_decomposition", "pillar_mapping")
ROBOTS_IN_BAG = 2
FISHEYE_HZ = 2.0
API_WARMUP_S = 2.0
SETTINGS = {
    "AISLE_OCCUPANCY__STORE_PERIOD_S": "5", "AISLE_PILLARS__STORE_PERIOD_S": "10", "AISLE_FUSION__STORE_PERIOD_S": "5",
    "AISLE_DECOMPOSITION__MIN_PERIOD_S": "10", "AISLE_PILLARS__RACK_PROFILES": '[{"levels_m": [0.0, 1.5]}]',
    "AISLE_PILLARS__LOCALISATION_SIGMA_M": "0.01", "AISLE_PILLARS__LOCALISATION_SIGMA_RAD": "0.002",
    # the load's one client address must not be refused: the limit still runs on every request
    "AISLE_API_RATE_LIMIT_PER_S": "1000000", "AISLE_API_RATE_LIMIT_BURST": "1000000",
    **stages_env(STAGES),
}
"""docker-compose.yml's store periods."""
TAKEN = {"occupancy_mapping": "occupancy_mapping.scans_integrated", "pillar_mapping": "pillar_mapping.frames",
         "grid_decomposition": "grid_decomposition.decompositions"}
DROPPED = {"pillar_mapping": ("pillar_mapping.fisheye/image_raw.dropped", "pillar_mapping.frames_superseded"),
           "occupancy_mapping": ("occupancy_mapping.scan.dropped",)}


def _emit(name: str, value: float, unit: str) -> None:
    print(f"{name} {value:.4g} {unit}", flush=True)


def _counters(client: httpx.Client) -> dict[str, dict[str, int]]:
    return {w["name"]: w["counters"] for w in client.get("/v1/health").json()["workers"]}


def _postgres_cpu_s(url: str) -> dict[int, float]:
    """CPU so far of each PostgreSQL backend serving ``url``'s database, by pid (the server runs here)."""
    engine = sa.create_engine(url)
    try:
        with engine.connect() as connection:
            pids = connection.execute(sa.text(
                "SELECT pid FROM pg_stat_activity WHERE datname = current_database() AND pid <> pg_backend_pid()"
            )).scalars().all()
    finally:
        engine.dispose()
    return {int(pid): _cpu_s(int(pid)) for pid in pids}


def _api_paths(client: httpx.Client, seed: int) -> Callable[[], str]:
    """Requests a WMS makes while the map grows: half a bin by id (ids re-read every 100 requests), half the
    first page of the bin list."""
    rng = random.Random(seed)
    ids: list[str] = []
    made = 0

    def path() -> str:
        nonlocal made
        if made % 100 == 0:
            ids[:] = [b["id"] for b in client.get("/v1/maps/site/bins", params={"limit": 1000}).json()["bins"]]
        made += 1
        if ids and rng.random() < 0.5:
            return f"/v1/maps/site/bins/{rng.choice(ids)}"
        return "/v1/maps/site/bins?limit=50"

    return path


async def _load(ports: list[int], key: str, paths: list[Callable[[], str]], *, connections: int,
                duration_s: float) -> list[Load]:
    return list(await asyncio.gather(*(
        _drive(port, key, path, connections=connections, warmup_s=API_WARMUP_S, duration_s=duration_s - API_WARMUP_S)
        for port, path in zip(ports, paths, strict=True))))


def _children_cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def _step(stack: Deployment, bag: Path, rate: float, *, clients: list[httpx.Client], ports: list[int], key: str,
          database: str, connections: int, bag_s: float, offered: dict[str, float]) -> dict[str, float]:
    """Replay at ``rate`` with the API under load; prints the step's figures, returns each process's CPU s per
    robot-second (``offered``: messages a robot sends a second, by stage, for the per-message stages)."""
    before = _counters(clients[0])
    cpu_before = {name: _cpu_s(p.pid) for name, p in stack.processes.items() if p.poll() is None}
    postgres_before = _postgres_cpu_s(database)
    revisions_before = len(clients[0].get("/v1/maps/site/revisions", params={"limit": 1000}).json()["revisions"])
    reaped = _children_cpu_s()
    started = time.perf_counter()
    robots = stack.start("robots", "replay", str(bag), "--rate", str(rate))
    paths = [_api_paths(client, seed) for seed, client in enumerate(clients)]
    loads = asyncio.run(_load(ports, key, paths, connections=connections, duration_s=bag_s / rate))
    robots.wait(timeout=600)
    replay_s = time.perf_counter() - started
    robots_cpu = _children_cpu_s() - reaped
    time.sleep(7.0)  # the stages take in what is queued and heartbeat their counters (every 5 s)
    elapsed = time.perf_counter() - started
    after = _counters(clients[0])
    cpu = {name: _cpu_s(stack.processes[name].pid) - was for name, was in cpu_before.items()}
    cpu["robots"] = robots_cpu
    postgres_after = _postgres_cpu_s(database)
    cpu["postgresql"] = sum(now - postgres_before.get(pid, 0.0) for pid, now in postgres_after.items())
    revisions = len(clients[0].get("/v1/maps/site/revisions", params={"limit": 1000}).json()["revisions"])
    robots_now = ROBOTS_IN_BAG * rate
    robot_s = ROBOTS_IN_BAG * bag_s  # seconds of one robot's traffic replayed
    prefix = f"rate{rate:g}"
    _emit(f"{prefix}.robots_equivalent", robots_now, "robots")
    _emit(f"{prefix}.replay_lag", replay_s / (bag_s / rate), "x")
    per_robot_s = {name: seconds / robot_s for name, seconds in cpu.items()}
    for stage in STAGES:
        stage_counters, was = after.get(stage, {}), before.get(stage, {})
        taken = stage_counters.get(TAKEN[stage], 0) - was.get(TAKEN[stage], 0)
        _emit(f"{prefix}.{stage}.taken_per_s", taken / replay_s, "msg/s")
        for counter in DROPPED.get(stage, ()):
            _emit(f"{prefix}.{counter}", stage_counters.get(counter, 0) - was.get(counter, 0), "msgs")
        if stage in offered and taken:
            _emit(f"{prefix}.{stage}.cpu_per_msg", 1000 * cpu[stage] / taken, "ms")
            per_robot_s[stage] = cpu[stage] / taken * offered[stage]
    for name, seconds in sorted(cpu.items()):
        _emit(f"{prefix}.{name}.cores", seconds / elapsed, "cores")
        _emit(f"{prefix}.{name}.cpu_per_robot_s", 1000 * per_robot_s[name], "ms")
    _emit(f"{prefix}.revisions_per_s", (revisions - revisions_before) / elapsed, "rev/s")
    for k, load in enumerate(loads):
        latencies = np.asarray(load.latencies_s)
        _emit(f"{prefix}.api{k}.req_per_s", len(latencies) / (bag_s / rate - API_WARMUP_S), "req/s")
        _emit(f"{prefix}.api{k}.p99", 1000 * float(np.percentile(latencies, 99)) if len(latencies) else float("nan"),
              "ms")
        _emit(f"{prefix}.api{k}.errors", load.errors, "answers")
    return {name: cost for name, cost in per_robot_s.items() if name != "robots"}


def _capacity(cost: dict[str, float]) -> None:
    """Robots one machine carries from the CPU per robot-second of each process; the heaviest moved off.

    A stage is one process whose work runs on one core (Python), so it carries at most 1 / its cost robots
    whatever the machine; the machine carries at most its cores over the sum of the costs.
    """
    cores = os.cpu_count() or 1
    mapping = {name: c for name, c in cost.items() if not name.startswith("api")}
    for name, c in sorted(mapping.items()):
        _emit(f"capacity.{name}.cpu_per_robot_s", 1000 * c, "ms")
        if name in STAGES:
            _emit(f"capacity.{name}.robots_per_process", 1 / c, "robots")
    stage_limit = min(1 / mapping[name] for name in STAGES if name in mapping)
    total = sum(mapping.values())
    heaviest = max(mapping, key=mapping.__getitem__)
    _emit("capacity.cores", cores, "cores")
    _emit("capacity.robots_one_machine", min(cores / total, stage_limit), "robots")
    print(f"capacity.heaviest {heaviest} -", flush=True)
    _emit("capacity.second_machine.rest.robots", cores / (total - mapping[heaviest]), "robots")
    _emit("capacity.two_machines.robots", min(cores / (total - mapping[heaviest]), stage_limit), "robots")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--rates", default="1,3,6", help="replay speed factors (R x real time = 2R robots)")
    parser.add_argument("--postgres-url", default=os.environ.get("AISLE_TEST_POSTGRES_URL", DEFAULT_POSTGRES_URL))
    parser.add_argument("--connections", type=int, default=4, help="HTTP connections per API instance")
    args = parser.parse_args()
    folder = Path(tempfile.mkdtemp(prefix="aisle-scaleout-"))
    _uptime()
    try:
        bag = folder / "survey"
        counts = sim_run(world_from_layout(TWO_AISLES), bag, robots=ROBOTS_IN_BAG, cameras=["fisheye"],
                         fisheye_rate_hz=FISHEYE_HZ)
        bag_s = counts["/robot1/odom"] / 20.0
        _emit("bag.duration", bag_s, "s")
        offered = {"occupancy_mapping": counts["/robot1/scan"] / bag_s,
                   "pillar_mapping": counts["/robot1/fisheye/image_raw"] / bag_s}
        cost: dict[str, float] = {}
        for rate in (float(r) for r in args.rates.split(",")):
            cost = _fresh_deployment_step(folder / f"rate{rate:g}", bag, rate, postgres_url=args.postgres_url,
                                          connections=args.connections, bag_s=bag_s, offered=offered)
        _capacity(cost)
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    _uptime()


def _fresh_deployment_step(folder: Path, bag: Path, rate: float, *, postgres_url: str, connections: int,
                           bag_s: float, offered: dict[str, float]) -> dict[str, float]:
    """One :func:`_step` on a deployment of its own (a new database, new workers: the bag's stamps replayed
    again into running workers would be old news to them)."""
    folder.mkdir()
    ports = [free_port(), free_port()]
    with dedicated_database(postgres_url) as database, \
            deployment(folder, database, settings={**SETTINGS, "AISLE_DATABASE_URL": database}) as stack:
        if stack.start("migrate", "db", "upgrade").wait(timeout=120) != 0:
            raise SystemExit(stack.logs())
        for stage in STAGES:
            stack.start(stage, "worker", stage)
        for k, port in enumerate(ports):
            stack.start(f"api{k}", "serve", env=serve_env(port))
        clients = [httpx.Client(base_url=f"http://127.0.0.1:{port}", timeout=10) for port in ports]
        try:
            wait_for(lambda: all(_healthy(c) for c in clients), timeout_s=180, what="the deployment to be up")
            store = MapStore(database)
            key = create_key(store, role=Role.READ, name="bench")[1]
            store.close()
            return _step(stack, bag, rate, clients=clients, ports=ports, key=key, database=database,
                         connections=connections, bag_s=bag_s, offered=offered)
        finally:
            for client in clients:
                client.close()


def _uptime() -> None:
    load = subprocess.run(["uptime"], capture_output=True, text=True, check=True).stdout.strip()
    print(f"uptime {load}", flush=True)


def _healthy(client: httpx.Client) -> bool:
    try:
        return bool(client.get("/v1/health").json()["status"] == "ok")
    except httpx.TransportError:
        return False


if __name__ == "__main__":
    main()

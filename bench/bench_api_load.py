"""REST API under load while a stage writes: bin lookups by id and GeoJSON bounding-box queries.

Run: ``PYTHONPATH=. .venv/bin/python bench/bench_api_load.py [--duration-s 10] [--connections 16]
[--backends sqlite,postgresql] [--workers 1] [--writer-period-s 0.5]``. Prints one ``name value unit``
line per figure, per database and query type, each query type measured on its own:

* ``<db>.bin.*``: ``GET /v1/maps/site/bins/<id>`` for a random one of the hall's 8,910 bins;
* ``<db>.bbox.*``: ``GET /v1/maps/site/features?bbox=...`` for a random 10 m x 10 m window of the hall
  (GeoJSON of the walls, places, rack rows, uprights and bins it touches: about 110 features, 45 kB);
* ``rate`` (answered requests/s over the measured time), ``p50``/``p95``/``p99`` latency, ``errors``
  (answers other than 200); ``cpu.server``/``writer``/``client``/``other`` (cores busy on average:
  ``other`` is PostgreSQL and anything else running on the machine) and ``server_cpu_per_request``,
  which says what the API costs whatever else competes for the cores;
* ``<db>.writer.*``: revisions the writer stored meanwhile and how long each took.

Three processes on loopback, as deployed:

1. the API, started as ``aisle serve`` (uvicorn, one process) on a free port, configured like a network
   deployment: reads need a key (``AISLE_API_REQUIRE_KEYS_FOR_READS=true``) and keys are rate limited,
   with the limit raised to 1,000,000 requests/s so the one bench key is never refused (a WMS that makes
   this many requests gets its limit raised the same way; the limiter still runs on every request).
   ``--workers N`` (N > 1) runs the same app in N uvicorn worker processes instead (``_api_server.py``);
2. ``_api_writer.py``, which stores the simulated 250 m x 72 m hall (8,910 bins, 3,696 uprights, places,
   walls, docks) and then, every ``--writer-period-s``, a revision as the stages do: alternately the 5 cm
   occupancy layer (7.6 M cells) and every rack row, upright and bin of the pillar stage;
3. this process, the load: ``--connections`` keep-alive HTTP/1.1 connections (raw asyncio, so the client
   spends little of the machine's two cores), each sending its next request when the last answer is in.

SQLite is a file in a temporary directory; PostgreSQL is a fresh schema in ``--postgres-url`` (default
``$AISLE_TEST_POSTGRES_URL``), dropped afterwards. Each query type is measured for ``--duration-s`` after
``--warmup-s`` of the same load. Linux only (CPU figures come from ``/proc``).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import random
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import uuid
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np
import sqlalchemy as sa

from shared.store import MapStore
from shared.store.keys import Role, create_key

WRITER = Path(__file__).with_name("_api_writer.py")
ROOT = Path(__file__).resolve().parents[1]
HALL_M = (250.0, 72.0)
WINDOW_M = 10.0
RATE_LIMIT_PER_S = 1_000_000
DEFAULT_POSTGRES_URL = "postgresql+psycopg://postgres@127.0.0.1:5432/test"


@dataclass
class Load:
    """What one query type measured: latencies (s) of answered requests, and answers other than 200."""

    latencies_s: list[float] = field(default_factory=list)
    errors: int = 0


def _cpu_s(pid: int, *, children: bool = False) -> float:
    """CPU time (user + system) process ``pid`` (and its child processes) used so far, seconds (Linux ``/proc``)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rpartition(")")[2].split()
        kids = [int(kid) for task in Path(f"/proc/{pid}/task").iterdir()
                for kid in (task / "children").read_text().split()] if children else []
    except FileNotFoundError:  # ended meanwhile
        return 0.0
    own = (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    return own + sum(_cpu_s(kid, children=True) for kid in kids)


def _busy_s() -> float:
    """CPU time the whole machine has been busy so far (all cores), seconds (Linux ``/proc``)."""
    ticks = [int(value) for value in Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:9]]
    return (sum(ticks) - ticks[3] - ticks[4]) / os.sysconf("SC_CLK_TCK")


class CpuShare(NamedTuple):
    """Cores used on average by each side during a measurement (1.0 = one core busy all the time)."""

    server: float
    writer: float
    client: float
    other: float
    """Everything else on the machine: PostgreSQL, and whatever else runs."""


@contextmanager
def cpu_share(server_pid: int, writer_pid: int, into: list[CpuShare]) -> Iterator[None]:
    """Append the CPU share of the server, the writer, this process and the rest over the block to ``into``."""
    def now() -> list[float]:  # the server with its worker processes; the others are single processes
        return [_cpu_s(server_pid, children=True), _cpu_s(writer_pid), _cpu_s(os.getpid())]

    before, busy, started = now(), _busy_s(), time.perf_counter()
    yield
    elapsed = time.perf_counter() - started
    used = [(after - was) / elapsed for after, was in zip(now(), before, strict=True)]
    into.append(CpuShare(used[0], used[1], used[2], (_busy_s() - busy) / elapsed - sum(used)))


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


@contextmanager
def database(backend: str, postgres_url: str) -> Iterator[str]:
    """A URL to an empty database of ``backend``; removed afterwards."""
    if backend == "sqlite":
        folder = Path(tempfile.mkdtemp(prefix="aisle-bench-"))
        try:
            yield f"sqlite:///{folder / 'aisle.db'}"
        finally:
            shutil.rmtree(folder)
        return
    schema = f"aisle_bench_{uuid.uuid4().hex[:12]}"
    admin = sa.create_engine(postgres_url)
    with admin.begin() as connection:
        connection.execute(sa.text(f'CREATE SCHEMA "{schema}"'))
    separator = "&" if "?" in postgres_url else "?"
    try:
        yield f"{postgres_url}{separator}options=-csearch_path%3D{schema}"
    finally:
        with admin.begin() as connection:
            connection.execute(sa.text(f'DROP SCHEMA "{schema}" CASCADE'))
        admin.dispose()


@contextmanager
def writer(url: str, *, period_s: float) -> Iterator[subprocess.Popen[str]]:
    """The writer process, once it has stored the hall; killed if still running on exit."""
    command = [sys.executable, str(WRITER), "--database-url", url, "--period-s", str(period_s)]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    with subprocess.Popen(command, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env) as process:
        try:
            assert process.stdout is not None
            if not (line := process.stdout.readline().strip()).startswith("ready"):
                raise RuntimeError(f"writer did not start (said {line!r}, exit code {process.poll()})")
            yield process
        finally:
            if process.poll() is None:
                process.kill()


@contextmanager
def server(url: str, port: int, *, workers: int) -> Iterator[subprocess.Popen[bytes]]:
    """The API on 127.0.0.1:``port`` over ``url``, once it answers; stopped with SIGINT on exit.

    One worker is ``aisle serve``; more are uvicorn worker processes of ``_api_server.app``, the same app.
    """
    env = {**os.environ, "AISLE_DATABASE_URL": url, "AISLE_API_HOST": "127.0.0.1", "AISLE_API_PORT": str(port),
           "AISLE_API_REQUIRE_KEYS_FOR_READS": "true", "AISLE_API_RATE_LIMIT_PER_S": str(RATE_LIMIT_PER_S),
           "AISLE_ZENOH__LISTEN": json.dumps([f"tcp/127.0.0.1:{_free_port()}"]), "AISLE_LOG_LEVEL": "WARNING",
           "AISLE_DATA_DIR": tempfile.gettempdir(), "PYTHONPATH": str(ROOT)}
    command = [sys.executable, "-m", "services.cli", "serve"]
    if workers > 1:
        command = [sys.executable, "-m", "uvicorn", "--factory", "bench._api_server:app", "--host", "127.0.0.1",
                   "--port", str(port), "--workers", str(workers), "--log-level", "warning", "--no-access-log"]
    with subprocess.Popen(command, env=env, cwd=ROOT) as process:
        try:
            deadline = time.monotonic() + 60.0
            while not _answers(port):
                if process.poll() is not None or time.monotonic() > deadline:
                    raise RuntimeError(f"aisle serve did not answer on port {port} (exit code {process.poll()})")
                time.sleep(0.1)
            yield process
        finally:
            if process.poll() is None:
                process.send_signal(signal.SIGINT)
                try:
                    process.wait(timeout=20)
                except subprocess.TimeoutExpired:
                    process.kill()


def _answers(port: int) -> bool:
    try:
        with socket.create_connection(("127.0.0.1", port), timeout=1.0) as sock:
            sock.sendall(b"GET /v1/health HTTP/1.1\r\nHost: bench\r\nConnection: close\r\n\r\n")
            return sock.recv(12).startswith(b"HTTP/1.1")
    except OSError:
        return False


async def _read_response(reader: asyncio.StreamReader) -> int:
    """Read one HTTP/1.1 response (Content-Length or chunked); returns its status code."""
    head = await reader.readuntil(b"\r\n\r\n")
    status = int(head[9:12])
    headers = head.lower()
    if b"transfer-encoding: chunked" in headers:
        while True:
            size = int((await reader.readuntil(b"\r\n")).strip(), 16)
            await reader.readexactly(size + 2)
            if size == 0:
                return status
    start = headers.index(b"content-length:") + len(b"content-length:")
    await reader.readexactly(int(headers[start:headers.index(b"\r\n", start)]))
    return status


async def _connection(port: int, key: str, next_path: Callable[[], str], *, warmup_until: float, stop_at: float,
                      load: Load) -> None:
    """One keep-alive connection sending requests back to back; records those started after the warm-up."""
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    try:
        while (started := time.perf_counter()) < stop_at:
            writer.write(f"GET {next_path()} HTTP/1.1\r\nHost: bench\r\nX-API-Key: {key}\r\n\r\n".encode())
            status = await _read_response(reader)
            if started >= warmup_until:
                load.latencies_s.append(time.perf_counter() - started)
                load.errors += status != 200
    finally:
        writer.close()


async def _drive(port: int, key: str, next_path: Callable[[], str], *, connections: int, warmup_s: float,
                 duration_s: float) -> Load:
    """``connections`` connections sending ``next_path()`` requests for ``warmup_s`` + ``duration_s``."""
    now = time.perf_counter()
    load = Load()
    await asyncio.gather(*(
        _connection(port, key, next_path, warmup_until=now + warmup_s, stop_at=now + warmup_s + duration_s,
                    load=load)
        for _ in range(connections)))
    return load


def _paths(bin_ids: list[str], *, seed: int) -> dict[str, Callable[[], str]]:
    rng = random.Random(seed)

    def bin_path() -> str:
        return f"/v1/maps/site/bins/{rng.choice(bin_ids)}"

    def bbox_path() -> str:
        x = rng.uniform(0.0, HALL_M[0] - WINDOW_M)
        y = rng.uniform(0.0, HALL_M[1] - WINDOW_M)
        return f"/v1/maps/site/features?bbox={x:.2f},{y:.2f},{x + WINDOW_M:.2f},{y + WINDOW_M:.2f}"

    return {"bin": bin_path, "bbox": bbox_path}


def run_backend(backend: str, args: argparse.Namespace) -> None:
    with database(backend, args.postgres_url) as url:
        store = MapStore(url)
        store.upgrade()
        create_key(store, role=Role.ADMIN, name="bench-admin")  # so the server prints no first admin key
        key = create_key(store, role=Role.READ, name="bench")[1]
        with writer(url, period_s=args.writer_period_s) as stage:
            assert stage.stdin is not None and stage.stdout is not None
            map_info = store.get_map("site")
            assert map_info is not None
            bin_ids = [item.feature.key for item in store.features(map_info.id, kinds=["bin"])]
            store.close()
            port = _free_port()
            with server(url, port, workers=args.workers) as api:
                stage.stdin.write("go\n")
                stage.stdin.flush()
                loads: dict[str, Load] = {}
                shares: list[CpuShare] = []
                for name, next_path in _paths(bin_ids, seed=args.seed).items():
                    with cpu_share(api.pid, stage.pid, shares):
                        loads[name] = asyncio.run(_drive(port, key, next_path, connections=args.connections,
                                                         warmup_s=args.warmup_s, duration_s=args.duration_s))
                stage.stdin.write("stop\n")
                stage.stdin.flush()
                written = json.loads(stage.stdout.readline())
    for (name, load), share in zip(loads.items(), shares, strict=True):
        latencies_ms = np.asarray(load.latencies_s) * 1000.0
        p50, p95, p99 = np.percentile(latencies_ms, [50, 95, 99]) if len(latencies_ms) else (np.nan,) * 3
        print(f"{backend}.{name}.rate {len(latencies_ms) / args.duration_s:.0f} req/s")
        print(f"{backend}.{name}.p50 {p50:.1f} ms")
        print(f"{backend}.{name}.p95 {p95:.1f} ms")
        print(f"{backend}.{name}.p99 {p99:.1f} ms")
        print(f"{backend}.{name}.errors {load.errors} requests")
        for side, cores in share._asdict().items():
            print(f"{backend}.{name}.cpu.{side} {cores:.2f} cores")
        if len(latencies_ms):
            cpu_per_request_ms = share.server / (len(latencies_ms) / args.duration_s) * 1000.0
            print(f"{backend}.{name}.server_cpu_per_request {cpu_per_request_ms:.2f} ms")
    write_s = np.asarray(written["write_s"])
    print(f"{backend}.writer.revisions {written['revisions']} revisions")
    if len(write_s):
        print(f"{backend}.writer.write_p50 {np.percentile(write_s, 50) * 1000:.0f} ms")
        print(f"{backend}.writer.write_max {write_s.max() * 1000:.0f} ms", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--duration-s", type=float, default=10.0, help="measured time per database")
    parser.add_argument("--warmup-s", type=float, default=2.0, help="load before measuring")
    parser.add_argument("--connections", type=int, default=16, help="concurrent connections")
    parser.add_argument("--writer-period-s", type=float, default=0.5, help="time between two stage revisions")
    parser.add_argument("--workers", type=int, default=1,
                        help="API processes: 1 is `aisle serve`; more run the same app under uvicorn --workers")
    parser.add_argument("--backends", default="sqlite,postgresql", help="comma-separated: sqlite, postgresql")
    parser.add_argument("--postgres-url", default=os.environ.get("AISLE_TEST_POSTGRES_URL", DEFAULT_POSTGRES_URL))
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    for backend in args.backends.split(","):
        if backend == "postgresql" and not _reachable(args.postgres_url):
            print(f"postgresql.skipped 1 (no database at {sa.make_url(args.postgres_url).render_as_string()})")
            continue
        run_backend(backend, args)


def _reachable(url: str) -> bool:
    engine = sa.create_engine(url)
    try:
        with engine.connect():
            return True
    except sa.exc.OperationalError:
        return False
    finally:
        engine.dispose()


if __name__ == "__main__":
    main()

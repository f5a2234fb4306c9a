"""Bin-by-id read latency while the WMS imports a large bin list (``PUT …/wms-bins``), and what the import leaves
in the server's memory.

The API runs as ``aisle serve`` (one uvicorn process, as deployed; reads need a key) over a store holding the
simulated 250 m x 72 m hall (8,910 bins). One client thread reads bins by id on a keep-alive connection,
``--rate`` a second, each timed from when it was due (so a stall of the server counts for every read it held up,
not once); after ``--quiet-s`` of that, another thread PUTs a WMS list of ``--bins`` bins (about 35 bytes of
JSON each, ids ``W-000001``..., positions spread over the hall), and the reads go on until the import is
answered. Printed as one JSON line: read latency p50/p99/max before and during the import, how many reads were
answered during it, the import's wall time, the server's CPU seconds during it, and its resident memory
(VmRSS) before, right after and ``--settle-s`` after the import; plus the load average and this process's CPU.

    PYTHONPATH=. .venv/bin/python bench/bench_import_latency.py --bins 200000
"""

from __future__ import annotations

import argparse
import http.client
import json
import os
import random
import threading
import time
from pathlib import Path

import numpy as np

from bench._api_writer import MAP_NAME, hall_features
from bench.bench_api_load import DEFAULT_POSTGRES_URL, _cpu_s, _free_port, database, server
from shared.store import MapStore, RevisionWrite
from shared.store.keys import Role, create_key


def _rss_mb(pid: int) -> float:
    """Resident memory of process ``pid``, MB (Linux ``/proc``)."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def _percentiles_ms(latencies_s: list[float]) -> dict[str, float]:
    if not latencies_s:
        return {"p50_ms": float("nan"), "p99_ms": float("nan"), "max_ms": float("nan"), "n": 0}
    values = np.asarray(latencies_s) * 1000
    return {"p50_ms": round(float(np.percentile(values, 50)), 2), "p99_ms": round(float(np.percentile(values, 99)), 2),
            "max_ms": round(float(values.max()), 1), "n": len(latencies_s)}


def wms_list(count: int, *, rng: np.random.Generator) -> bytes:
    """A WMS list of ``count`` bins with positions in the hall, as JSON."""
    xy = rng.uniform((0.0, 0.0), (250.0, 72.0), size=(count, 2)).round(3)
    bins = [{"id": f"W-{i:06d}", "x_m": float(x), "y_m": float(y)} for i, (x, y) in enumerate(xy, start=1)]
    return json.dumps({"bins": bins, "tolerance_m": 0.5}).encode()


def _reads(port: int, key: str, bin_ids: list[str], *, rate_per_s: float, until: list[float],
           into: list[tuple[float, float]]) -> None:
    """Read random bins by id, one every 1/``rate_per_s`` s, until one falls due after ``until[0]`` (once the
    caller has set it); (due time, latency) of each into ``into``. A read is timed from when it was due, and
    every read due before the end is made, so a stall counts once for every read it held up."""
    connection = http.client.HTTPConnection("127.0.0.1", port, timeout=600)
    rng = random.Random(0)
    due = time.perf_counter()
    try:
        while not until or due <= until[0]:
            due += 1.0 / rate_per_s
            time.sleep(max(0.0, due - time.perf_counter()))
            connection.request("GET", f"/v1/maps/{MAP_NAME}/bins/{rng.choice(bin_ids)}", headers={"X-API-Key": key})
            response = connection.getresponse()
            response.read()
            if response.status != 200:
                raise RuntimeError(f"bin read answered {response.status}")
            into.append((due, time.perf_counter() - due))
    finally:
        connection.close()


def _warm_up(port: int, key: str, bin_ids: list[str], *, timeout_s: float = 120.0) -> None:
    """Read bins until 20 reads in a row take under 20 ms each (the live state is built, the server settled)."""
    connection = http.client.HTTPConnection("127.0.0.1", port, timeout=600)
    fast, deadline = 0, time.monotonic() + timeout_s
    try:
        while fast < 20 and time.monotonic() < deadline:
            started = time.perf_counter()
            connection.request("GET", f"/v1/maps/{MAP_NAME}/bins/{bin_ids[fast]}", headers={"X-API-Key": key})
            connection.getresponse().read()
            fast = fast + 1 if time.perf_counter() - started < 0.02 else 0
    finally:
        connection.close()


def run(url: str, *, bins: int, rate_per_s: float, quiet_s: float, settle_s: float, seed: int) -> dict[str, object]:
    """Store the hall at ``url``, serve it, and measure reads before and during one import of ``bins`` bins."""
    store = MapStore(url)
    store.upgrade()
    features = hall_features(seed=seed)
    map_id = store.ensure_map(MAP_NAME).id
    store.write_revision(map_id, RevisionWrite("pillar_mapping", features={"bin": features["bin"]}))
    reader = create_key(store, role=Role.READ, name="bench-reader")[1]
    writer = create_key(store, role=Role.WRITE, name="bench-wms")[1]
    store.close()
    bin_ids = [item.key for item in features["bin"]]
    body = wms_list(bins, rng=np.random.default_rng(seed))
    port = _free_port()
    with server(url, port, workers=1) as process:
        _warm_up(port, reader, bin_ids)
        latencies: list[tuple[float, float]] = []
        until: list[float] = []
        thread = threading.Thread(target=_reads, args=(port, reader, bin_ids),
                                  kwargs={"rate_per_s": rate_per_s, "until": until, "into": latencies})
        thread.start()
        try:
            time.sleep(quiet_s)
            rss_before = _rss_mb(process.pid)
            cpu_before = _cpu_s(process.pid)
            connection = http.client.HTTPConnection("127.0.0.1", port, timeout=600)
            import_started = time.perf_counter()
            connection.request("PUT", f"/v1/maps/{MAP_NAME}/wms-bins", body=body,
                               headers={"X-API-Key": writer, "Content-Type": "application/json"})
            response = connection.getresponse()
            answer = response.read()
            import_ended = time.perf_counter()
            connection.close()
            cpu_import = _cpu_s(process.pid) - cpu_before
            rss_after = _rss_mb(process.pid)
        finally:
            until.append(time.perf_counter())
            thread.join()
        time.sleep(settle_s)
        rss_settled = _rss_mb(process.pid)
    if response.status != 200:
        raise RuntimeError(f"import answered {response.status}: {answer[:300]!r}")
    before = [lat for start, lat in latencies if start < import_started]
    during = [lat for start, lat in latencies if import_started <= start < import_ended]
    return {"bins": bins, "read_rate_per_s": rate_per_s, "body_mb": round(len(body) / 1e6, 1),
            "import_s": round(import_ended - import_started, 2),
            "server_cpu_import_s": round(cpu_import, 2), "reads_before": _percentiles_ms(before),
            "reads_during": _percentiles_ms(during),
            "rss_mb": {"before": round(rss_before), "after": round(rss_after), "settled": round(rss_settled)}}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--bins", type=int, default=200_000, help="bins in the imported WMS list")
    parser.add_argument("--rate", type=float, default=200.0, help="bin reads a second (one connection)")
    parser.add_argument("--quiet-s", type=float, default=3.0, help="reads alone before the import starts")
    parser.add_argument("--settle-s", type=float, default=5.0, help="wait after the import before the last RSS")
    parser.add_argument("--backend", choices=["sqlite", "postgresql"], default="sqlite")
    parser.add_argument("--postgres-url", default=os.environ.get("AISLE_TEST_POSTGRES_URL", DEFAULT_POSTGRES_URL))
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    cpu_started, started = time.process_time(), time.perf_counter()
    with database(args.backend, args.postgres_url) as url:
        figures = run(url, bins=args.bins, rate_per_s=args.rate, quiet_s=args.quiet_s, settle_s=args.settle_s,
                      seed=args.seed)
    figures.update(backend=args.backend, bench_cpu_s=round(time.process_time() - cpu_started, 1),
                   bench_wall_s=round(time.perf_counter() - started, 1),
                   load_avg=[round(value, 2) for value in os.getloadavg()])
    print(json.dumps(figures))


if __name__ == "__main__":
    main()

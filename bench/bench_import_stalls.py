"""Where a large WMS import holds the GIL for long: stalls of a helper thread during one import, in process.

A helper thread sleeps 1 ms at a time while the app (in this process, through FastAPI's test client) answers
``PUT …/wms-bins`` with a list of ``--bins`` bins for the simulated hall (8,910 bins; SQLite file or
PostgreSQL schema); whenever it wakes more than ``--stall-ms`` late, the GIL (or the machine) held it up that
long, and the event loop answering reads would have waited as well. Printed as one JSON line: the stalls
(start after the import began and length, ms), the cyclic garbage collector's runs longer than 10 ms among
them (generation, start, length), the import's wall and CPU time (this process: the import, the test client
and the helper thread), the load average. ``bench_import_latency.py`` measures what reads see.

    PYTHONPATH=. .venv/bin/python bench/bench_import_stalls.py --bins 200000 [--backend postgresql]
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
from fastapi.testclient import TestClient

from api import create_app
from bench._api_writer import MAP_NAME, hall_features
from bench.bench_api_load import DEFAULT_POSTGRES_URL, database
from bench.bench_import_latency import wms_list
from shared.settings import Settings
from shared.store import MapStore, RevisionWrite
from shared.store.keys import Role, create_key


def _watch(stall_s: float, stop: threading.Event, into: list[tuple[float, float]]) -> None:
    """(start, length) into ``into`` of every 1 ms sleep that ended more than ``stall_s`` late, until ``stop``."""
    last = time.perf_counter()
    while not stop.is_set():
        time.sleep(0.001)
        now = time.perf_counter()
        if now - last > stall_s:
            into.append((last, now - last))
        last = now


def run(url: str, data_dir: Path, *, bins: int, stall_ms: float, seed: int) -> dict[str, Any]:
    store = MapStore(url)
    store.upgrade()
    features = hall_features(seed=seed)
    site = store.ensure_map(MAP_NAME)
    store.write_revision(site.id, RevisionWrite("pillar_mapping", features={"bin": features["bin"]}))
    writer = create_key(store, role=Role.WRITE, name="bench-wms")[1]
    app = create_app(store=store, settings=Settings(data_dir=data_dir, database_url=url), rate_limit_per_s=None)
    body = wms_list(bins, rng=np.random.default_rng(seed))
    collections: list[list[float]] = []

    def timed(phase: str, info: dict[str, int]) -> None:
        if phase == "start":
            collections.append([info["generation"], time.perf_counter()])
        else:
            collections[-1].append(time.perf_counter() - collections[-1][1])

    stalls: list[tuple[float, float]] = []
    stop = threading.Event()
    watcher = threading.Thread(target=_watch, args=(stall_ms / 1000, stop, stalls))
    with TestClient(app) as client:
        gc.callbacks.append(timed)
        watcher.start()
        try:
            time.sleep(0.1)
            cpu_started, started = time.process_time(), time.perf_counter()
            answer = client.put(f"/v1/maps/{MAP_NAME}/wms-bins", content=body,
                                headers={"X-API-Key": writer, "Content-Type": "application/json"})
            wall_s, cpu_s = time.perf_counter() - started, time.process_time() - cpu_started
        finally:
            stop.set()
            watcher.join()
            gc.callbacks.remove(timed)
    store.close()
    if answer.status_code != 200:
        raise RuntimeError(f"import answered {answer.status_code}: {answer.text[:300]}")
    return {"bins": bins, "import_wall_s": round(wall_s, 2), "import_cpu_s": round(cpu_s, 2),
            f"stalls_over_{stall_ms:g}_ms": [[round((s - started) * 1000), round(length * 1000, 1)]
                                              for s, length in stalls if s >= started - 0.01],
            "gc_over_10_ms": [[int(c[0]), round((c[1] - started) * 1000), round(c[2] * 1000, 1)]
                              for c in collections if len(c) == 3 and c[2] > 0.01 and c[1] >= started]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--bins", type=int, default=200_000, help="bins in the imported WMS list")
    parser.add_argument("--stall-ms", type=float, default=15.0, help="report helper-thread stalls longer than this")
    parser.add_argument("--backend", choices=["sqlite", "postgresql"], default="sqlite")
    parser.add_argument("--postgres-url", default=os.environ.get("AISLE_TEST_POSTGRES_URL", DEFAULT_POSTGRES_URL))
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    with database(args.backend, args.postgres_url) as url, tempfile.TemporaryDirectory() as folder:
        figures = run(url, Path(folder), bins=args.bins, stall_ms=args.stall_ms, seed=args.seed)
    figures.update(backend=args.backend, load_avg=[round(value, 2) for value in os.getloadavg()])
    print(json.dumps(figures))


if __name__ == "__main__":
    main()

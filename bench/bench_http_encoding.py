"""What gzip and ETags cost and save, on the 250 m x 72 m simulated hall (about 12,800 features).

Run: ``PYTHONPATH=. .venv/bin/python bench/bench_http_encoding.py``. Prints ``name value unit`` lines:

* ``layout.bytes_identity`` / ``layout.bytes_gzip``: ``GET /v1/maps/site/layout`` as sent without and with
  ``Accept-Encoding: gzip``; ``layout.cpu_ms_*``: CPU time of one such request in this process (best of 5), and of a
  ``304`` answer to ``If-None-Match`` (the route still builds the answer: the tag is its hash);
* ``bin.cpu_us_*``: CPU time of one ``GET /v1/maps/site/bins/{id}`` through the whole ASGI app (the fast path), with
  the gzip and ETag middleware (:class:`api.conditional.ConditionalReads`) and without it, called directly (no HTTP
  client), mean of 5,000.
"""

from __future__ import annotations

import asyncio
import tempfile
import time
from collections.abc import Callable, MutableMapping
from functools import partial
from pathlib import Path
from typing import Any

from fastapi import FastAPI
from fastapi.testclient import TestClient

from api import create_app
from bench.bench_layout import _hall_store
from shared.settings import Settings

REPEATS = 5
BIN_CALLS = 5000


def _best_cpu_s(work: Callable[[], object]) -> float:
    times = []
    for _ in range(REPEATS):
        start = time.process_time()
        work()
        times.append(time.process_time() - start)
    return min(times)


async def _call(app: FastAPI, path: str, calls: int) -> float:
    """Mean CPU seconds of one GET of ``path`` through ``app`` (ASGI, no client)."""
    scope: dict[str, Any] = {"type": "http", "asgi": {"version": "3.0"}, "http_version": "1.1", "method": "GET",
                             "scheme": "http", "path": path, "raw_path": path.encode(), "query_string": b"",
                             "root_path": "", "headers": [(b"host", b"bench"), (b"accept-encoding", b"gzip")],
                             "client": ("127.0.0.1", 5000), "server": ("127.0.0.1", 8000), "state": {}}

    async def receive() -> dict[str, Any]:
        return {"type": "http.request", "body": b"", "more_body": False}

    statuses: list[int] = []

    async def send(message: MutableMapping[str, Any]) -> None:
        if message["type"] == "http.response.start":
            statuses.append(message["status"])

    for _ in range(100):  # warm: the live state is loaded on the first read
        await app(scope, receive, send)
    start = time.process_time()
    for _ in range(calls):
        await app(scope, receive, send)
    spent = time.process_time() - start
    assert set(statuses) == {200}, statuses[:5]
    return spent / calls


def main() -> None:
    with tempfile.TemporaryDirectory() as folder:
        store = _hall_store(f"sqlite:///{Path(folder) / 'hall.db'}")
        settings = Settings(data_dir=Path(folder), database_url=store.url)
        apps = {}
        for name in ("with", "without"):
            app = create_app(store=store, settings=settings, rate_limit_per_s=None)
            if name == "without":
                app.user_middleware = [m for m in app.user_middleware  # api.conditional.ConditionalReads
                                       if getattr(m.cls, "__name__", "") != "ConditionalReads"]
            apps[name] = app
        with TestClient(apps["with"]) as client:
            path = "/v1/maps/site/layout"
            plain = client.get(path, headers={"Accept-Encoding": "identity"})
            zipped = client.get(path, headers={"Accept-Encoding": "gzip"})
            print(f"layout.bytes_identity {len(plain.content)} B")
            print(f"layout.bytes_gzip {zipped.headers['content-length']} B")
            tag = {"If-None-Match": plain.headers["etag"]}
            for name, headers in (("identity", {"Accept-Encoding": "identity"}),
                                  ("gzip", {"Accept-Encoding": "gzip"}), ("304", tag)):
                spent_s = _best_cpu_s(partial(client.get, path, headers=headers))
                print(f"layout.cpu_ms_{name} {1000 * spent_s:.1f} ms")
            bin_id = client.get("/v1/maps/site/bins", params={"limit": 1}).json()["bins"][0]["id"]
        for name, app in apps.items():
            mean_s = asyncio.run(_call(app, f"/v1/maps/site/bins/{bin_id}", BIN_CALLS))
            print(f"bin.cpu_us_{name}_middleware {1e6 * mean_s:.1f} us")
            app.state.context.live.close()
        store.close()


if __name__ == "__main__":
    main()

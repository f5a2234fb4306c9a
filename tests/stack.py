"""The whole stack as a user starts it: ``aisle run`` in its own process, spoken to over HTTP."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import httpx2 as httpx

from tests.helpers import free_port, wait_for

POLL_S = 0.25
"""How often a test asks a running stack over HTTP whether what it waits for has happened: often enough, and
seldom enough to leave the CPU to the stages it waits on (a read of the bins or revisions is not free)."""


@contextmanager
def aisle_run(tmp_path: Path, *args: str, stop_signal: signal.Signals = signal.SIGINT,
              env: dict[str, str] | None = None) -> Iterator[httpx.Client]:
    """``aisle run ARGS`` on free ports with its own data folder (and ``env``, ``AISLE_*`` variables); stopped with
    ``stop_signal``, which must be clean (exit code 0)."""
    port = free_port()
    env = {**os.environ, "AISLE_DATA_DIR": str(tmp_path / "var"), "AISLE_API_PORT": str(port),
           "AISLE_ZENOH__LISTEN": f'["tcp/127.0.0.1:{free_port()}"]', "AISLE_OCCUPANCY__STORE_PERIOD_S": "1",
           **(env or {})}
    log = (tmp_path / "aisle.log").open("w")
    process = subprocess.Popen([sys.executable, "-m", "services.cli", "run", *args], env=env, stdout=log,
                               stderr=subprocess.STDOUT)
    try:
        # a request may wait behind the stages on a loaded 2-core machine (a 5 s limit timed out a /bins at load 25);
        # how long the run may take is bounded by each wait_for, not by one request
        with httpx.Client(base_url=f"http://127.0.0.1:{port}", timeout=30.0) as client:
            wait_for(lambda: answers(client), timeout_s=60, what="the API to answer")
            yield client
        process.send_signal(stop_signal)
        assert process.wait(timeout=60) == 0, (tmp_path / "aisle.log").read_text()[-3000:]
    finally:
        if process.poll() is None:
            process.kill()
            process.wait(timeout=30)  # reaped, so a failed run reports its failure, not a ResourceWarning
        log.close()


def answers(client: httpx.Client) -> bool:
    try:
        client.get("/v1/health")
    except httpx.TransportError:
        return False
    return True


def health(client: httpx.Client) -> dict[str, Any]:
    body: dict[str, Any] = client.get("/v1/health").json()
    return body


def counter(client: httpx.Client, worker: str, name: str) -> int:
    workers = {w["name"]: w for w in health(client)["workers"]}
    return int(workers.get(worker, {}).get("counters", {}).get(f"{worker}.{name}", 0))



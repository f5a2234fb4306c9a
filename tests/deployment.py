"""docker-compose.yml's shape as real processes, without a docker engine.

A zenoh router (:mod:`tests.zenoh_router`, as the ``eclipse/zenoh`` container runs), a PostgreSQL database of
its own reached through a :class:`~tests.tcp_proxy.TcpProxy` (so a test can cut it), the migration job, one
``aisle worker STAGE`` per stage and ``aisle serve`` instances, every one a client of the router configured
only through ``AISLE_*`` variables, like the compose services. Robots are ``aisle replay`` processes.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import uuid
from collections.abc import Iterator, Mapping, Sequence
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO

import sqlalchemy as sa

from tests.helpers import free_port, wait_for
from tests.tcp_proxy import TcpProxy

ROOT = Path(__file__).resolve().parents[1]


@contextmanager
def dedicated_database(base_url: str) -> Iterator[str]:
    """A new, empty PostgreSQL database on the server of ``base_url``; dropped afterwards (connections too)."""
    name = f"aisle_scaleout_{uuid.uuid4().hex[:10]}"
    admin = sa.create_engine(base_url, isolation_level="AUTOCOMMIT")
    with admin.connect() as connection:
        connection.execute(sa.text(f'CREATE DATABASE "{name}"'))
    try:
        yield sa.make_url(base_url).set(database=name).render_as_string(hide_password=False)
    finally:
        with admin.connect() as connection:
            connection.execute(sa.text(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)'))
        admin.dispose()


@dataclass
class Deployment:
    """The running processes by name (the router is ``router``), their logs in ``folder``."""

    folder: Path
    proxy: TcpProxy
    environment: dict[str, str]
    processes: dict[str, subprocess.Popen[bytes]] = field(default_factory=dict)
    _logs: list[IO[bytes]] = field(default_factory=list)

    def start(self, name: str, *command: str, env: Mapping[str, str] | None = None,
              module: str = "services.cli") -> subprocess.Popen[bytes]:
        """``aisle COMMAND`` (or ``python -m MODULE COMMAND``) as process ``name``, replacing a dead one so named."""
        previous = self.processes.get(name)
        if previous is not None and previous.poll() is None:
            raise RuntimeError(f"{name} is still running")
        log = (self.folder / f"{name}.log").open("ab")
        self._logs.append(log)
        process = subprocess.Popen([sys.executable, "-m", module, *command], cwd=ROOT,
                                   env={**self.environment, **(env or {})}, stdout=log, stderr=subprocess.STDOUT)
        self.processes[name] = process
        return process

    def kill(self, name: str) -> int:
        """SIGKILL process ``name``; its exit code (-9)."""
        process = self.processes[name]
        process.send_signal(signal.SIGKILL)
        return process.wait(timeout=30)

    def stop(self, name: str, *, timeout_s: float = 60.0) -> int:
        """SIGINT process ``name`` (as ``docker stop`` would SIGTERM it) and its exit code."""
        process = self.processes[name]
        if process.poll() is None:
            process.send_signal(signal.SIGINT)
        return process.wait(timeout=timeout_s)

    def log(self, name: str, *, tail_chars: int = 3000) -> str:
        return (self.folder / f"{name}.log").read_text(errors="replace")[-tail_chars:]

    def logs(self) -> str:
        """The end of every process's log, for a failure message."""
        return "\n".join(f"--- {name} (exit {p.poll()}) ---\n{self.log(name)}" for name, p in self.processes.items())

    def _close(self) -> None:
        for process in self.processes.values():
            if process.poll() is None:
                process.kill()
                process.wait(timeout=30)
        for log in self._logs:
            log.close()


@contextmanager
def deployment(folder: Path, database_url: str, *, settings: Mapping[str, str] | None = None
               ) -> Iterator[Deployment]:
    """A router, a TCP proxy in front of ``database_url`` and the compose services' common environment.

    ``settings`` are extra ``AISLE_*`` variables every process gets. Processes still running on exit are killed.
    """
    router_port = free_port()
    router = f"tcp/127.0.0.1:{router_port}"
    target = sa.make_url(database_url)
    with ExitStack() as stack:
        proxy = stack.enter_context(TcpProxy(target.host or "127.0.0.1", target.port or 5432))
        through_proxy = target.set(host="127.0.0.1", port=proxy.port).render_as_string(hide_password=False)
        environment = {key: value for key, value in os.environ.items() if not key.startswith("AISLE_")}
        environment.update({
            "AISLE_DATABASE_URL": through_proxy, "AISLE_DATA_DIR": str(folder / "var"),
            "AISLE_ZENOH__MODE": "client", "AISLE_ZENOH__CONNECT": f'["{router}"]', "AISLE_ZENOH__LISTEN": "[]",
            "AISLE_ROBOT_NAMESPACES": '["*"]', "AISLE_MAP_NAME": "site", "AISLE_LOG_LEVEL": "INFO",
            **(settings or {}),
        })
        running = Deployment(folder, proxy, environment)
        stack.callback(running._close)
        running.start("router", router, module="tests.zenoh_router")
        wait_for(lambda: _listens(router_port), timeout_s=30, what="the zenoh router to listen")
        yield running


def _listens(port: int) -> bool:
    try:
        socket.create_connection(("127.0.0.1", port), timeout=1.0).close()
    except OSError:
        return False
    return True


def serve_env(port: int) -> dict[str, str]:
    """The environment of one ``aisle serve`` on loopback ``port``."""
    return {"AISLE_API_HOST": "127.0.0.1", "AISLE_API_PORT": str(port)}


def stages_env(stages: Sequence[str]) -> dict[str, str]:
    """``AISLE_STAGES`` naming the workers the deployment runs (what ``aisle serve`` expects to be alive)."""
    return {"AISLE_STAGES": "[" + ", ".join(f'"{stage}"' for stage in stages) + "]"}

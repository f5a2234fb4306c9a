"""CPU of `aisle run` per stage and thread: idle (no robot traffic) and, with ``--mapping``, while the demo robot maps.

Run: ``PYTHONPATH=. .venv/bin/python bench/bench_idle.py [--seconds 30] [--warmup-s 10] [--mapping]``. Runs what
`aisle run` runs (every default stage, the API, a zenoh peer, SQLite in a temporary folder) in this process, waits
``--warmup-s``, then reads each thread's CPU time from ``/proc/self/task`` over ``--seconds``. Prints
``<mode>.cpu.<thread> value %`` lines (percent of one core; Python threads by name, a stage's heartbeat under its
stage, the zenoh runtime's threads by their name) and ``<mode>.cpu.total``. ``--mapping`` adds the demo robot
(its own thread, ``mapping.cpu.job``) and reports the stages while they map; ``--streams N`` holds N event streams
(SSE) open on the API meanwhile. Linux only.
"""

from __future__ import annotations

import argparse
import os
import re
import socket
import tempfile
import threading
import time
from collections import defaultdict
from pathlib import Path

from services import runtime
from services.cli import _demo_job, _demo_settings
from shared.settings import Settings, ZenohSettings

_CLOCK_TICKS = os.sysconf("SC_CLK_TCK")


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def _thread_cpu_s() -> dict[int, tuple[str, float]]:
    """Native thread id -> (kernel name, CPU seconds) of every thread of this process."""
    found = {}
    for task in Path("/proc/self/task").iterdir():
        try:
            stat = (task / "stat").read_text()
        except FileNotFoundError:  # ended meanwhile
            continue
        name = stat[stat.index("(") + 1:stat.rindex(")")]
        fields = stat[stat.rindex(")") + 2:].split()
        found[int(task.name)] = (name, (int(fields[11]) + int(fields[12])) / _CLOCK_TICKS)
    return found


def _groups(threads: dict[int, tuple[str, float]]) -> dict[int, str]:
    """Native thread id -> group: a Python thread's name up to its first '-' (a stage's heartbeat counts for the
    stage), else the kernel's name without digits (zenoh's runtime threads)."""
    python = {t.native_id: "main" if t is threading.main_thread() else t.name.split("-")[0]
              for t in threading.enumerate()}
    return {tid: python.get(tid) or re.sub(r"[-_:]?\d+$", "", name) or name for tid, (name, _) in threads.items()}


def _open_streams(port: int, count: int) -> list[socket.socket]:
    """``count`` event streams of map ``site`` held open (their heartbeats left unread in the socket buffers)."""
    streams = []
    for _ in range(count):
        stream = socket.create_connection(("127.0.0.1", port))
        stream.sendall(b"GET /v1/maps/site/events HTTP/1.1\r\nHost: bench\r\nAccept: text/event-stream\r\n\r\n")
        streams.append(stream)
    return streams


def measure(*, seconds: float, warmup_s: float, mapping: bool, streams: int = 0) -> dict[str, float]:
    with tempfile.TemporaryDirectory() as folder:
        settings = Settings(data_dir=Path(folder), api_port=_free_port(), log_level="WARNING",
                            zenoh=ZenohSettings(listen=[f"tcp/127.0.0.1:{_free_port()}"]))
        extra = []
        if mapping:
            settings = _demo_settings(settings)
            extra.append(_demo_job("fisheye", rate=1.0))
        stop = threading.Event()
        worker = threading.Thread(target=runtime.run, name="runtime", kwargs={
            "settings": settings, "stages": list(settings.stages), "api": True, "stop": stop, "extra": extra,
            "compact": True})
        worker.start()
        try:
            time.sleep(warmup_s)
            clients = _open_streams(settings.api_port, streams)
            time.sleep(1.0)
            before, wall = _thread_cpu_s(), time.monotonic()
            time.sleep(seconds)
            after, wall = _thread_cpu_s(), time.monotonic() - wall
            groups = _groups(after)
            for client in clients:
                client.close()
        finally:
            stop.set()
            worker.join(timeout=60)
    per_group: dict[str, float] = defaultdict(float)
    for native_id, (name, cpu) in after.items():
        per_group[groups[native_id]] += cpu - before.get(native_id, (name, 0.0))[1]
    figures = {name: 100 * cpu / wall for name, cpu in sorted(per_group.items())}
    figures["total"] = sum(figures.values())
    return figures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=30.0)
    parser.add_argument("--warmup-s", type=float, default=25.0)
    parser.add_argument("--mapping", action="store_true", help="with the demo robot driving and mapping")
    parser.add_argument("--streams", type=int, default=0, help="event streams (SSE) held open meanwhile")
    args = parser.parse_args()
    mode = ("mapping" if args.mapping else "idle") + (f"_{args.streams}_streams" if args.streams else "")
    for name, percent in measure(seconds=args.seconds, warmup_s=args.warmup_s, mapping=args.mapping,
                                 streams=args.streams).items():
        print(f"{mode}.cpu.{name} {percent:.2f} %")
    print(f"load {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()

"""Bus throughput between two processes, and CDR serialisation cost, for a scan and a depth image.

Run: ``.venv/bin/python bench/bench_bus.py [--duration-s 3]``. Prints one ``name value unit``
line per figure. This process publishes on a loopback zenoh peer; a second process
(``_bus_peer.py``) connects to it over TCP (shared memory is off in ``shared.bus.zenoh_config``)
and subscribes. For each message:

* ``raw``: pre-serialised CDR through ``Publisher.publish_raw``; the peer copies each payload
  out of zenoh in the subscriber callback.
* ``typed``: ``Publisher.publish(message)`` (serialise + put) into a bus subscription whose
  ``receive`` parses key and attachment and deserialises.

Rates count from the first put until the peer has received every message, so a receiver that
falls behind shows up as a lower rate. ``serialize`` and ``deserialize`` are timed in-process.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import socket
import subprocess
import sys
import time
import timeit
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Literal, NamedTuple

import numpy as np

from shared import messages
from shared.bus import Bus
from shared.keyexpr import topic_key
from shared.settings import ZenohSettings

log = logging.getLogger("bench.bench_bus")

PEER = Path(__file__).with_name("_bus_peer.py")


class Case(NamedTuple):
    """One message to push through the bus."""

    name: str
    topic: str
    msgtype: str
    message: Any


def laser_scan(*, beams: int, seed: int) -> Any:
    """A 360 degree scan of ``beams`` ranges and intensities (float32)."""
    rng = np.random.default_rng(seed)
    cls = messages.message_class
    header = cls("std_msgs/msg/Header")(stamp=cls("builtin_interfaces/msg/Time")(sec=1, nanosec=0),
                                        frame_id="laser")
    return cls(messages.LASER_SCAN)(
        header=header, angle_min=-math.pi, angle_max=math.pi, angle_increment=2 * math.pi / beams,
        time_increment=0.0, scan_time=0.1, range_min=0.1, range_max=30.0,
        ranges=rng.uniform(0.1, 30.0, beams).astype(np.float32),
        intensities=rng.uniform(0.0, 1.0, beams).astype(np.float32))


def depth_image(*, width: int, height: int, seed: int) -> Any:
    """A 16UC1 depth image (millimetres), ``width`` x ``height`` pixels."""
    rng = np.random.default_rng(seed)
    cls = messages.message_class
    header = cls("std_msgs/msg/Header")(stamp=cls("builtin_interfaces/msg/Time")(sec=1, nanosec=0),
                                        frame_id="depth")
    pixels = rng.integers(300, 10_000, size=(height, width), dtype=np.uint16)
    return cls(messages.IMAGE)(header=header, height=height, width=width, encoding="16UC1",
                               is_bigendian=0, step=2 * width, data=pixels.view(np.uint8).ravel())


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


@contextmanager
def _peer(endpoint: str, case: Case, mode: Literal["raw", "typed"]) -> Iterator[subprocess.Popen[str]]:
    """The subscriber process, once it says it is subscribed; killed if still running on exit."""
    command = [sys.executable, str(PEER), "--connect", endpoint, "--mode", mode,
               "--topic", case.topic, "--msgtype", case.msgtype]
    with subprocess.Popen(command, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True) as process:
        try:
            assert process.stdout is not None
            if (line := process.stdout.readline().strip()) != "ready":
                raise RuntimeError(f"bus peer did not start (said {line!r}, exit code {process.poll()})")
            yield process
        finally:
            if process.poll() is None:
                process.kill()


def _wait_matched(bus: Bus, case: Case, *, timeout_s: float) -> None:
    """Block until ``bus`` has seen the peer's subscription for ``case`` (declarations travel)."""
    with bus.session.declare_publisher(topic_key(bus.domain_id, "", case.topic, case.msgtype)) as probe:
        deadline = time.monotonic() + timeout_s
        # zenoh's stub says matching_status is a bool; at run time it is a MatchingStatus
        while not probe.matching_status.matching:  # type: ignore[attr-defined]
            if time.monotonic() > deadline:
                raise TimeoutError(f"no subscriber for {case.topic} after {timeout_s} s")
            time.sleep(0.01)


def throughput(bus: Bus, endpoint: str, case: Case, mode: Literal["raw", "typed"], *,
               duration_s: float) -> dict[str, float]:
    """Messages/s, MB/s and drops for ``duration_s`` of publishing ``case`` to a peer process."""
    payload = messages.serialize(case.message, case.msgtype)
    publisher = bus.publisher(case.topic, case.msgtype)
    try:
        with _peer(endpoint, case, mode) as peer:
            assert peer.stdin is not None and peer.stdout is not None
            _wait_matched(bus, case, timeout_s=10.0)
            sent = 0
            started = time.perf_counter()
            stop_at = started + duration_s
            while time.perf_counter() < stop_at:
                if mode == "raw":
                    publisher.publish_raw(payload)
                else:
                    publisher.publish(case.message)
                sent += 1
            peer.stdin.write(f"expect {sent}\n")
            peer.stdin.flush()
            report = json.loads(peer.stdout.readline())
            elapsed_s = time.perf_counter() - started
    finally:
        publisher.close()
    if report["received"] != sent:
        log.warning("%s %s: sent %d, peer received %d", case.name, mode, sent, report["received"])
    return {"msgs_per_s": report["received"] / elapsed_s,
            "mb_per_s": report["received"] * len(payload) / 1e6 / elapsed_s,
            "lost": sent - report["received"],
            "dropped": report["dropped"]}


def serde_cost_us(case: Case, *, repeat: int) -> tuple[float, float]:
    """Microseconds per serialise and per deserialise of ``case``'s message (best of 5 runs)."""
    payload = messages.serialize(case.message, case.msgtype)
    ser = min(timeit.repeat(lambda: messages.serialize(case.message, case.msgtype), number=repeat, repeat=5))
    de = min(timeit.repeat(lambda: messages.deserialize(payload, case.msgtype), number=repeat, repeat=5))
    return ser / repeat * 1e6, de / repeat * 1e6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--duration-s", type=float, default=3.0, help="publishing time per measurement")
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    cases = [Case("scan720", "scan", messages.LASER_SCAN, laser_scan(beams=720, seed=0)),
             Case("depth640x480", "depth", messages.IMAGE, depth_image(width=640, height=480, seed=0))]
    endpoint = f"tcp/127.0.0.1:{_free_port()}"
    with Bus.open(ZenohSettings(listen=[endpoint]), domain_id=0) as bus:
        for case in cases:
            payload_bytes = len(messages.serialize(case.message, case.msgtype))
            ser_us, de_us = serde_cost_us(case, repeat=2000 if payload_bytes < 100_000 else 100)
            print(f"{case.name}.payload {payload_bytes} B")
            print(f"{case.name}.serialize {ser_us:.1f} us/msg")
            print(f"{case.name}.deserialize {de_us:.1f} us/msg")
            for mode in ("raw", "typed"):
                figures = throughput(bus, endpoint, case, mode, duration_s=args.duration_s)
                print(f"{case.name}.{mode}.rate {figures['msgs_per_s']:.0f} msg/s")
                print(f"{case.name}.{mode}.throughput {figures['mb_per_s']:.1f} MB/s")
                print(f"{case.name}.{mode}.lost {figures['lost']:.0f} msg")
                print(f"{case.name}.{mode}.dropped {figures['dropped']:.0f} msg", flush=True)


if __name__ == "__main__":
    main()

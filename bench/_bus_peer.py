"""The receiving side of ``bench_bus.py``, run in its own process.

Protocol on stdin/stdout, one line each: the peer prints ``ready`` once subscribed; the
bench writes ``expect <n>`` when it has sent ``n`` messages; the peer prints a JSON line
``{"received": ..., "payload_bytes": ...}`` as soon as it has received them all (or after
``--timeout-s``) and exits.

Modes: ``raw`` counts samples and copies their payload out of zenoh in the callback, as
:class:`shared.bus.Subscription` does; ``typed`` goes through a bus subscription, so every
message is queued, its key and attachment parsed and its CDR deserialised.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import threading

import zenoh

from shared.bus import Bus
from shared.keyexpr import topic_selector
from shared.settings import ZenohSettings

log = logging.getLogger("bench._bus_peer")


class _Tally:
    """Samples and payload bytes received, shared between zenoh's thread and ours."""

    def __init__(self) -> None:
        self.received = 0
        self.payload_bytes = 0
        self.changed = threading.Condition()

    def add(self, payload_bytes: int) -> None:
        with self.changed:
            self.received += 1
            self.payload_bytes += payload_bytes
            self.changed.notify()


def _expected_count() -> int:
    line = sys.stdin.readline().split()
    if len(line) != 2 or line[0] != "expect":
        raise SystemExit(f"expected 'expect <n>' on stdin, got {line!r}")
    return int(line[1])


def _wait_for_expected(tally: _Tally, *, timeout_s: float) -> None:
    expected = _expected_count()
    with tally.changed:
        tally.changed.wait_for(lambda: tally.received >= expected, timeout=timeout_s)


def _run_raw(bus: Bus, selector: str, *, timeout_s: float) -> _Tally:
    tally = _Tally()

    def on_sample(sample: zenoh.Sample) -> None:
        tally.add(len(sample.payload.to_bytes()))

    with bus.session.declare_subscriber(selector, on_sample):
        print("ready", flush=True)
        _wait_for_expected(tally, timeout_s=timeout_s)
    return tally


def _run_typed(bus: Bus, topic: str, msgtype: str, *, timeout_s: float) -> _Tally:
    tally = _Tally()
    subscription = bus.subscribe(topic, msgtype, maxsize=10_000)
    stop = threading.Event()

    def pump() -> None:
        while not stop.is_set():
            if subscription.receive(0.05) is not None:
                tally.add(0)

    receiver = threading.Thread(target=pump, name="typed-receiver")
    receiver.start()
    print("ready", flush=True)
    try:
        _wait_for_expected(tally, timeout_s=timeout_s)
    finally:
        stop.set()
        receiver.join()
    return tally


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--connect", required=True, help="zenoh endpoint, e.g. tcp/127.0.0.1:7447")
    parser.add_argument("--mode", choices=("raw", "typed"), required=True)
    parser.add_argument("--topic", required=True)
    parser.add_argument("--msgtype", required=True)
    parser.add_argument("--timeout-s", type=float, default=30.0,
                        help="how long to wait for the last message once told how many to expect")
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    settings = ZenohSettings(listen=[], connect=[args.connect])
    with Bus.open(settings, domain_id=0) as bus:
        if args.mode == "raw":
            selector = topic_selector(bus.domain_id, "*", args.topic, args.msgtype)
            tally = _run_raw(bus, selector, timeout_s=args.timeout_s)
        else:
            tally = _run_typed(bus, args.topic, args.msgtype, timeout_s=args.timeout_s)
        dropped = bus.counters.get(f"{args.topic}.dropped")
    print(json.dumps({"received": tally.received, "payload_bytes": tally.payload_bytes, "dropped": dropped}),
          flush=True)


if __name__ == "__main__":
    main()

"""Publish simulated messages onto the bus in real time, and the built-in live demo."""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter
from collections.abc import Iterable

import numpy as np

from services.simulator.layout import world_from_layout
from services.simulator.presets import demo_layout
from services.simulator.route import survey_route, waypoint_route
from services.simulator.stream import CameraSensor, Output, RobotSpec, simulate
from shared.bus import Bus, Publisher

log = logging.getLogger(__name__)

_CAMERA_TOPICS = ("image_raw", "depth/image_raw")


def publish_live(bus: Bus, outputs: Iterable[Output], stop: threading.Event, *, start_ns: int,
                 rate: float = 1.0) -> Counter[str]:
    """Publish ``outputs`` onto ``bus``, each when the wall clock reaches its stamp.

    ``start_ns`` is the stamp that corresponds to the moment this is called; ``rate`` > 1 runs
    faster than real time. Camera images are dropped under congestion, everything else blocks.
    Returns messages published per ``/<namespace>/<topic>``; stops early when ``stop`` is set.
    """
    if rate <= 0:
        raise ValueError(f"rate must be positive, got {rate}")
    publishers: dict[tuple[str, str, str], Publisher] = {}
    published: Counter[str] = Counter()
    wall_start = time.monotonic()
    try:
        for output in outputs:
            due = wall_start + (output.stamp_ns - start_ns) / 1e9 / rate
            delay = due - time.monotonic()
            if (delay > 0 and stop.wait(delay)) or stop.is_set():
                break
            key = (output.namespace, output.topic, output.msgtype)
            publisher = publishers.get(key)
            if publisher is None:
                publisher = publishers[key] = bus.publisher(
                    output.topic, output.msgtype, namespace=output.namespace,
                    drop_when_congested=output.topic.endswith(_CAMERA_TOPICS))
            publisher.publish(output.message)
            published["/" + "/".join(p for p in (output.namespace, output.topic) if p)] += 1
    finally:
        for publisher in publishers.values():
            publisher.close()
    return published


def run_demo(bus: Bus, stop: threading.Event, *, seed: int = 0, namespace: str = "robot1", speed_mps: float = 1.2,
             rate: float = 1.0, cameras: tuple[CameraSensor, ...] = ()) -> None:
    """Drive a simulated robot round the built-in 40 m x 25 m demo warehouse until ``stop`` is set.

    The robot surveys every aisle and returns to its start, over and over, publishing scans,
    odometry, TF (static transforms every 2 s) and its true pose under ``namespace`` in real time
    (``rate`` > 1 runs faster), so the occupancy stage fills in the map within about a minute.
    ``cameras`` ride along, e.g. ``(fisheye_sensor(rate_hz=2.0),)`` for the pillar stage (a 2 Hz fisheye
    renders in about 0.45 s per simulated second on one core, so it keeps up at ``rate`` 1).
    """
    layout = demo_layout()
    layout["seed"] = seed
    world = world_from_layout(layout)
    survey = survey_route(world)
    loop = np.vstack([survey, waypoint_route(world, [survey[-1], survey[0]])[1:]])
    rounds = 0
    while not stop.is_set():
        start_ns = time.time_ns()
        robot = RobotSpec(namespace, loop, speed_mps=speed_mps, seed=seed + rounds, cameras=cameras)
        published = publish_live(bus, simulate(world, [robot], start_ns=start_ns), stop, start_ns=start_ns,
                                 rate=rate)
        rounds += 1
        log.info("demo round %d done: %d messages", rounds, published.total())

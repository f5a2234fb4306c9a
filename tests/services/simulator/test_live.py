"""Live publishing: the demo robot's scans, odometry and transforms arrive on the bus under its namespace."""

from __future__ import annotations

import threading

from services.simulator import run_demo
from shared import messages
from shared.bus import Bus
from tests.helpers import wait_for


def test_demo_publishes_scans_odometry_and_static_transforms(bus_pair: tuple[Bus, Bus]) -> None:
    listener, talker = bus_pair
    scans = listener.subscribe("scan", messages.LASER_SCAN)
    static = listener.subscribe("tf_static", messages.TF_MESSAGE)
    odometry = listener.subscribe("odom", messages.ODOMETRY)
    stop = threading.Event()
    demo = threading.Thread(target=run_demo, args=(talker, stop), kwargs={"seed": 1, "rate": 4.0})
    demo.start()
    try:
        wait_for(lambda: scans.pending() >= 3 and static.pending() >= 1 and odometry.pending() >= 3,
                 timeout_s=30.0, what="demo traffic")
    finally:
        stop.set()
        demo.join(timeout=10.0)
    scan = scans.receive(1.0)
    assert scan is not None and scan.namespace == "robot1"
    assert scan.message.header.frame_id == "robot1/laser"
    assert not demo.is_alive()

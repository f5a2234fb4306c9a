"""Typed publish/subscribe over real zenoh sessions on loopback."""

from __future__ import annotations

import time
from typing import Any

import numpy as np
import pytest

from shared import messages
from shared.bus import Bus, DropPolicy, Publisher, Subscription
from shared.keyexpr import Attachment, topic_key
from tests.helpers import wait_for


def _scan(stamp_s: int, n: int = 360) -> Any:
    cls = messages.message_class
    return cls(messages.LASER_SCAN)(
        header=cls("std_msgs/msg/Header")(stamp=cls("builtin_interfaces/msg/Time")(sec=stamp_s, nanosec=0),
                                          frame_id="laser"),
        angle_min=-np.pi, angle_max=np.pi, angle_increment=2 * np.pi / n, time_increment=0.0, scan_time=0.1,
        range_min=0.1, range_max=20.0, ranges=np.full(n, 3.0, np.float32), intensities=np.zeros(0, np.float32))


def _publish_and_receive(pub: Publisher, sub: Subscription) -> bool:
    pub.publish(_scan(0))
    return sub.receive(0.05) is not None


def _publish_and_count(pub: Publisher, sub: Subscription) -> bool:
    pub.publish(_scan(0))
    time.sleep(0.02)
    return sub.pending() > 0


def test_subscriber_receives_every_robot_and_knows_which(bus_pair: tuple[Bus, Bus]) -> None:
    listener, talker = bus_pair
    sub = listener.subscribe("scan", messages.LASER_SCAN)
    publishers = {ns: talker.publisher("scan", messages.LASER_SCAN, namespace=ns) for ns in ("robot1", "robot2", "")}
    received: list[Any] = []

    def publish_until_heard() -> bool:
        for ns, pub in publishers.items():
            if ns not in {r.namespace for r in received}:
                pub.publish(_scan(1))
        while (item := sub.receive(0.05)) is not None:
            received.append(item)
        return {r.namespace for r in received} == set(publishers)

    wait_for(publish_until_heard, what="scans from three namespaces")
    first = received[0]
    assert first.topic == "scan" and first.msgtype == messages.LASER_SCAN
    assert first.attachment is not None and len(first.attachment.gid) == 16
    np.testing.assert_array_equal(first.message.ranges, np.full(360, 3.0, np.float32))


def test_sequence_numbers_count_up_from_one(bus_pair: tuple[Bus, Bus]) -> None:
    listener, talker = bus_pair
    sub = listener.subscribe("odom_seq", messages.LASER_SCAN)
    pub = talker.publisher("odom_seq", messages.LASER_SCAN)
    wait_for(lambda: _publish_and_receive(pub, sub), what="first message")
    for stamp in range(1, 6):
        pub.publish(_scan(stamp))
    got = [sub.receive(2.0) for _ in range(5)]
    seqs = [r.attachment.sequence_number for r in got if r is not None and r.attachment is not None]
    assert seqs == sorted(seqs) and len(seqs) == 5 and seqs[-1] - seqs[0] == 4
    assert [r.message.header.stamp.sec for r in got if r is not None] == [1, 2, 3, 4, 5]


def test_malformed_payloads_are_counted_and_skipped(bus_pair: tuple[Bus, Bus]) -> None:
    listener, talker = bus_pair
    sub = listener.subscribe("scan", messages.LASER_SCAN, name="scan")
    key = topic_key(0, "robot1", "scan", messages.LASER_SCAN)
    good = messages.serialize(_scan(9), messages.LASER_SCAN)
    attachment = Attachment(1, 0, bytes(16)).encode()

    def send_bad_then_good() -> bool:
        talker.session.put(key, b"\x00\x01\x00\x00garbage", attachment=attachment)
        talker.session.put(key, good[:40], attachment=attachment)
        talker.session.put(key, good, attachment=b"short")
        talker.session.put(key, good, attachment=attachment)
        return sub.receive(0.2) is not None

    wait_for(send_bad_then_good, what="a good scan after bad ones")
    assert listener.counters.get("scan.malformed") >= 3


def test_payload_of_another_type_on_a_topic_is_counted(bus_pair: tuple[Bus, Bus]) -> None:
    listener, talker = bus_pair
    sub = listener.subscribe("scan", messages.LASER_SCAN, name="scan")
    key = topic_key(0, "robot1", "scan", messages.LASER_SCAN)
    cls = messages.message_class
    header = cls("std_msgs/msg/Header")(stamp=cls("builtin_interfaces/msg/Time")(sec=1, nanosec=0), frame_id="x")
    status = messages.serialize(cls("std_msgs/msg/Header")(**vars(header)), "std_msgs/msg/Header")

    def send_and_drain() -> bool:
        talker.session.put(key, status, attachment=Attachment(1, 0, bytes(16)).encode())
        assert sub.receive(0.1) is None
        return listener.counters.get("scan.malformed") > 0

    wait_for(send_and_drain, what="a header-only payload to be refused as a scan")


def test_keep_newest_drops_oldest_and_counts(bus_pair: tuple[Bus, Bus]) -> None:
    listener, talker = bus_pair
    sub = listener.subscribe("camera", messages.LASER_SCAN, policy=DropPolicy.KEEP_NEWEST, maxsize=3, name="camera")
    pub = talker.publisher("camera", messages.LASER_SCAN)
    wait_for(lambda: _publish_and_count(pub, sub), what="the first frame")
    for stamp in range(1, 11):
        pub.publish(_scan(stamp))
    wait_for(lambda: listener.counters.get("camera.received") >= 11, what="all frames")
    stamps = []
    while (item := sub.receive(0.05)) is not None:
        stamps.append(item.message.header.stamp.sec)
    assert stamps == [8, 9, 10]
    assert listener.counters.get("camera.dropped") == listener.counters.get("camera.received") - 3


def test_block_policy_never_drops_silently(bus_pair: tuple[Bus, Bus]) -> None:
    listener, talker = bus_pair
    sub = listener.subscribe("poses", messages.LASER_SCAN, policy=DropPolicy.BLOCK, maxsize=2, name="poses")
    pub = talker.publisher("poses", messages.LASER_SCAN)
    wait_for(lambda: _publish_and_count(pub, sub), what="the first pose")
    for stamp in range(1, 31):
        pub.publish(_scan(stamp))
    stamps: list[int] = []

    def drain() -> bool:
        while (item := sub.receive(0.01)) is not None:
            stamps.append(item.message.header.stamp.sec)
        return 30 in stamps

    wait_for(drain, what="every pose")
    assert stamps[-30:] == list(range(1, 31))
    assert listener.counters.get("poses.dropped") == 0


def test_workers_are_visible_by_liveliness_until_they_stop(bus_pair: tuple[Bus, Bus]) -> None:
    worker_bus, observer = bus_pair
    token = worker_bus.declare_worker("occupancy_mapping")
    wait_for(lambda: observer.alive_workers() == ["occupancy_mapping"], what="the worker token")
    token.undeclare()
    wait_for(lambda: observer.alive_workers() == [], what="the token to go")


def _static_transform(child: str) -> Any:
    cls = messages.message_class
    header = cls("std_msgs/msg/Header")(stamp=cls("builtin_interfaces/msg/Time")(sec=1, nanosec=0),
                                        frame_id="robot1/base_link")
    transform = cls("geometry_msgs/msg/Transform")(
        translation=cls("geometry_msgs/msg/Vector3")(x=0.2, y=0.0, z=0.3),
        rotation=cls("geometry_msgs/msg/Quaternion")(x=0.0, y=0.0, z=0.0, w=1.0))
    stamped = cls("geometry_msgs/msg/TransformStamped")(header=header, child_frame_id=child, transform=transform)
    return cls(messages.TF_MESSAGE)(transforms=[stamped])


def test_a_subscriber_that_starts_late_still_gets_the_static_transforms(bus_pair: tuple[Bus, Bus]) -> None:
    worker, robot = bus_pair
    static = robot.publisher("tf_static", messages.TF_MESSAGE, namespace="robot1")
    static.publish(_static_transform("robot1/laser"))
    static.publish(_static_transform("robot1/fisheye_optical_frame"))
    robot.publisher("tf", messages.TF_MESSAGE, namespace="robot1").publish(_static_transform("robot1/odom"))
    plain = worker.subscribe("tf", messages.TF_MESSAGE, name="tf")  # an ordinary topic: what is gone is gone
    late = worker.subscribe("tf_static", messages.TF_MESSAGE, name="tf_static")  # e.g. a restarted worker
    children: list[str] = []

    def both() -> bool:
        while (item := late.receive(0.05)) is not None:
            children.extend(t.child_frame_id for t in item.message.transforms)
        return len(children) >= 2

    wait_for(both, timeout_s=10, what="the static transforms sent before the subscriber started")
    assert children == ["robot1/laser", "robot1/fisheye_optical_frame"]
    assert late.receive(0.2) is None, "each cached sample is delivered once"
    assert plain.pending() == 0


def test_bad_endpoint_gives_a_clear_error() -> None:
    from shared.settings import ZenohSettings

    with pytest.raises(ConnectionError, match="zenoh"), Bus.open(
            ZenohSettings(listen=["tcp/256.1.1.1:1"]), domain_id=0):
        pass

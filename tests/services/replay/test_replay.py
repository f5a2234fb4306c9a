"""Replaying rosbag2 recordings onto a real zenoh bus on loopback."""

from __future__ import annotations

import math
import threading
from collections import Counter
from collections.abc import Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Any, Literal, NamedTuple

import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from services.replay.replay import ReplayError, ReplayStats, replay_bag
from shared import messages
from shared.bus import Bus, Received, Subscription
from shared.keyexpr import topic_key
from shared.settings import ZenohSettings
from tests.helpers import data_path, free_port, wait_for

STEP_NS = 50_000_000
"""Bag time between two consecutive messages of the sample bag."""
START_NS = 1_700_000_000_000_000_000
BAG_TYPES = ((messages.LASER_SCAN, "scan"), (messages.ODOMETRY, "odom"), (messages.TF_MESSAGE, "tf"),
             (messages.TF_MESSAGE, "tf_static"))


class BagMessage(NamedTuple):
    """One message as written to the sample bag."""

    topic: str
    msgtype: str
    timestamp_ns: int
    rawdata: bytes


def _stamp(ns: int) -> Any:
    return messages.message_class("builtin_interfaces/msg/Time")(sec=ns // 10**9, nanosec=ns % 10**9)


def _header(ns: int, frame: str) -> Any:
    return messages.message_class("std_msgs/msg/Header")(stamp=_stamp(ns), frame_id=frame)


def _scan(ns: int, seed: int) -> Any:
    rng = np.random.default_rng(seed)
    return messages.message_class(messages.LASER_SCAN)(
        header=_header(ns, "laser"), angle_min=-math.pi, angle_max=math.pi, angle_increment=2 * math.pi / 360,
        time_increment=0.0, scan_time=0.1, range_min=0.1, range_max=20.0,
        ranges=rng.uniform(0.2, 15.0, 360).astype(np.float32), intensities=np.zeros(0, np.float32))


def _pose(x_m: float) -> Any:
    cls = messages.message_class
    return cls("geometry_msgs/msg/Pose")(position=cls("geometry_msgs/msg/Point")(x=x_m, y=0.5, z=0.0),
                                         orientation=cls("geometry_msgs/msg/Quaternion")(x=0.0, y=0.0, z=0.0,
                                                                                          w=1.0))


def _odometry(ns: int, x_m: float) -> Any:
    cls = messages.message_class
    twist = cls("geometry_msgs/msg/Twist")(linear=cls("geometry_msgs/msg/Vector3")(x=0.5, y=0.0, z=0.0),
                                           angular=cls("geometry_msgs/msg/Vector3")(x=0.0, y=0.0, z=0.1))
    return cls(messages.ODOMETRY)(
        header=_header(ns, "odom"), child_frame_id="base_link",
        pose=cls("geometry_msgs/msg/PoseWithCovariance")(pose=_pose(x_m), covariance=np.zeros(36)),
        twist=cls("geometry_msgs/msg/TwistWithCovariance")(twist=twist, covariance=np.zeros(36)))


def _tf(ns: int, child: str, x_m: float) -> Any:
    cls = messages.message_class
    transform = cls("geometry_msgs/msg/Transform")(
        translation=cls("geometry_msgs/msg/Vector3")(x=x_m, y=0.0, z=0.0),
        rotation=cls("geometry_msgs/msg/Quaternion")(x=0.0, y=0.0, z=0.0, w=1.0))
    stamped = cls("geometry_msgs/msg/TransformStamped")(header=_header(ns, "base_link"), child_frame_id=child,
                                                        transform=transform)
    return cls(messages.TF_MESSAGE)(transforms=[stamped])


def _sample_messages(count: int) -> list[BagMessage]:
    """``count`` rounds of scan, odometry and tf from robot1, robot2 and the root namespace."""
    out = []
    for topic, msgtype, child in (("/robot1/tf_static", messages.TF_MESSAGE, "laser"),
                                  ("/tf_static", messages.TF_MESSAGE, "camera")):
        rawdata = messages.serialize(_tf(START_NS, child, 0.2), msgtype)
        out.append(BagMessage(topic, msgtype, START_NS + 1, rawdata))
    for i in range(count):
        ns = START_NS + i * STEP_NS
        for robot, offset in (("robot1", 0), ("robot2", STEP_NS // 3), ("", 2 * STEP_NS // 3)):
            prefix = f"/{robot}" if robot else ""
            stamp = ns + offset
            out += [
                BagMessage(f"{prefix}/scan", messages.LASER_SCAN, stamp + 1,
                           messages.serialize(_scan(stamp, seed=stamp), messages.LASER_SCAN)),
                BagMessage(f"{prefix}/odom", messages.ODOMETRY, stamp + 2,
                           messages.serialize(_odometry(stamp, 0.1 * i), messages.ODOMETRY)),
                BagMessage(f"{prefix}/tf", messages.TF_MESSAGE, stamp + 3,
                           messages.serialize(_tf(stamp, "base_link", 0.1 * i), messages.TF_MESSAGE)),
            ]
    return out


def write_sample_bag(path: Path, *, rounds: int = 6, storage: Literal["mcap", "sqlite3"] = "mcap",
                     foreign: bool = False) -> list[BagMessage]:
    """Write a small bag of ``rounds`` x 9 messages (plus two static transforms); return what it holds.

    ``foreign`` adds two topics replay must skip: a type we do not know (``/robot1/blip``) and a
    ``std_msgs/String`` defined differently from ours (``/robot1/chatter``).
    """
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    written = _sample_messages(rounds)
    with Writer(path, version=9, storage_plugin=plugin) as writer:
        connections = {}
        for message in written:
            if message.topic not in connections:
                connections[message.topic] = writer.add_connection(message.topic, message.msgtype,
                                                                   typestore=messages.TYPESTORE)
            writer.write(connections[message.topic], message.timestamp_ns, message.rawdata)
        if foreign:
            store = get_typestore(Stores.EMPTY)
            store.register(get_types_from_msg("uint8 level", "acme_msgs/msg/Blip"))
            store.register(get_types_from_msg("float64 data", "std_msgs/msg/String"))
            for topic, msgtype in (("/robot1/blip", "acme_msgs/msg/Blip"),
                                   ("/robot1/chatter", "std_msgs/msg/String")):
                connection = writer.add_connection(topic, msgtype, typestore=store)
                cls = store.types[msgtype]
                payload = store.serialize_cdr(cls(7) if msgtype.endswith("Blip") else cls(1.5), msgtype)
                for i in range(3):
                    writer.write(connection, START_NS + i * STEP_NS + 4, payload)
    return written


def wait_until_subscribed(bus: Bus, routes: Sequence[tuple[str, str, str]], *,
                          timeout_s: float = 10.0) -> None:
    """Wait until ``bus`` knows of a subscriber for each (namespace, topic, msgtype) in ``routes``.

    zenoh propagates subscriber declarations asynchronously; publishing before they arrive loses
    the samples, so a test must wait for the match before replaying.
    """
    with ExitStack() as stack:
        probes = [stack.enter_context(bus.session.declare_publisher(topic_key(bus.domain_id, *route)))
                  for route in routes]
        wait_for(lambda: all(_matching(probe) for probe in probes), timeout_s=timeout_s,
                 what=f"subscribers for {routes}")


def _matching(publisher: Any) -> bool:
    # zenoh's stub types matching_status as bool; at run time it is a MatchingStatus
    return bool(publisher.matching_status.matching)


def _routes(written: Sequence[BagMessage]) -> list[tuple[str, str, str]]:
    routes = set()
    for message in written:
        *namespace, topic = message.topic.strip("/").split("/")
        routes.add(("/".join(namespace), topic, message.msgtype))
    return sorted(routes)


@contextmanager
def _running(function: Any, /, *args: Any, **kwargs: Any) -> Iterator[Any]:
    """Run ``function`` on a thread; yield its future."""
    with ThreadPoolExecutor(max_workers=1) as pool:
        yield pool.submit(function, *args, **kwargs)


def _drain(subscriptions: Sequence[Subscription], into: list[Received]) -> int:
    for subscription in subscriptions:
        while (item := subscription.receive(0.0)) is not None:
            into.append(item)
    return len(into)


def _name(received: Received) -> str:
    return "/" + "/".join(part for part in (received.namespace, received.topic) if part)


@pytest.fixture(scope="module")
def lone_bus() -> Iterator[Bus]:
    """One unconnected session, for tests that never get as far as publishing."""
    with Bus.open(ZenohSettings(listen=[f"tcp/127.0.0.1:{free_port()}"]), domain_id=0) as bus:
        yield bus


@pytest.fixture
def sample_bag(tmp_path: Path) -> tuple[Path, list[BagMessage]]:
    bag = tmp_path / "sample"
    return bag, write_sample_bag(bag)


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_replay_delivers_every_message_with_namespace_type_and_content_in_order(
        bus_pair: tuple[Bus, Bus], tmp_path: Path, storage: Literal["mcap", "sqlite3"]) -> None:
    listener, talker = bus_pair
    bag = tmp_path / "bag"
    written = write_sample_bag(bag, storage=storage)
    subscriptions = [listener.subscribe(topic, msgtype, name=topic) for msgtype, topic in BAG_TYPES]
    wait_until_subscribed(talker, _routes(written))

    stats = replay_bag(talker, bag, rate=20.0, stop=threading.Event())

    received: list[Received] = []
    wait_for(lambda: _drain(subscriptions, received) >= len(written), what=f"{len(written)} messages")
    assert _drain(subscriptions, received) == len(written)
    for topic in {message.topic for message in written}:
        sent = [m for m in written if m.topic == topic]
        got = [r for r in received if _name(r) == topic]
        assert [r.msgtype for r in got] == [m.msgtype for m in sent]
        assert [messages.serialize(r.message, r.msgtype) for r in got] == [m.rawdata for m in sent], topic
    assert stats.published == Counter(m.topic for m in written)
    assert stats.skipped == {} and stats.passes == 1


def test_replay_keeps_namespaces_and_prefixes_the_extra_one(bus_pair: tuple[Bus, Bus],
                                                           sample_bag: tuple[Path, list[BagMessage]]) -> None:
    listener, talker = bus_pair
    bag, written = sample_bag
    scans = listener.subscribe("scan", messages.LASER_SCAN, namespaces=("site2/*", "site2"))
    wait_until_subscribed(talker, [("site2/robot1", "scan", messages.LASER_SCAN),
                                   ("site2", "scan", messages.LASER_SCAN)])

    stats = replay_bag(talker, bag, rate=50.0, stop=threading.Event(), namespace="/site2/",
                       topics=["scan", "/robot1/scan"])

    received: list[Received] = []
    expected = sum(m.topic in {"/scan", "/robot1/scan"} for m in written)
    wait_for(lambda: _drain([scans], received) >= expected, what="the scans")
    assert {r.namespace for r in received} == {"site2", "site2/robot1"}
    assert stats.published == {"/site2/scan": expected // 2, "/site2/robot1/scan": expected // 2}


def test_replay_at_rate_two_takes_half_the_bag_time(bus_pair: tuple[Bus, Bus], tmp_path: Path) -> None:
    listener, talker = bus_pair
    bag = tmp_path / "timed"
    write_sample_bag(bag, rounds=11)
    odometry = listener.subscribe("odom", messages.ODOMETRY)
    wait_until_subscribed(talker, [("robot1", "odom", messages.ODOMETRY)])

    stats = replay_bag(talker, bag, rate=2.0, stop=threading.Event(), topics=["/robot1/odom"])

    received: list[Received] = []
    wait_for(lambda: _drain([odometry], received) >= 11, what="eleven odometry messages")
    real_time_s = 10 * STEP_NS / 1e9
    arrival_span_s = (received[-1].received_ns - received[0].received_ns) / 1e9
    assert 0.8 * real_time_s / 2 < arrival_span_s < real_time_s
    assert stats.elapsed_s > 0.8 * real_time_s / 2


def test_skips_and_counts_types_it_cannot_send(lone_bus: Bus, tmp_path: Path) -> None:
    talker = lone_bus
    bag = tmp_path / "foreign"
    written = write_sample_bag(bag, rounds=2, foreign=True)

    stats = replay_bag(talker, bag, rate=100.0, stop=threading.Event())

    assert stats.skipped == {"/robot1/blip": 3, "/robot1/chatter": 3}
    assert sum(stats.published.values()) == len(written)


def test_loop_resends_static_transforms_at_the_start_of_each_pass(
        bus_pair: tuple[Bus, Bus], sample_bag: tuple[Path, list[BagMessage]]) -> None:
    listener, talker = bus_pair
    bag, written = sample_bag
    static = listener.subscribe("tf_static", messages.TF_MESSAGE)
    scans = listener.subscribe("scan", messages.LASER_SCAN, namespaces=("robot1",))
    wait_until_subscribed(talker, [("robot1", "tf_static", messages.TF_MESSAGE),
                                   ("robot1", "scan", messages.LASER_SCAN)])
    stop = threading.Event()
    got_static: list[Received] = []
    got_scans: list[Received] = []

    topics = ["/robot1/tf_static", "/robot1/scan"]
    with _running(replay_bag, talker, bag, rate=10.0, loop=True, stop=stop, topics=topics) as future:
        wait_for(lambda: _drain([static], got_static) >= 3, what="three passes of static transforms")
        stop.set()
        stats: ReplayStats = future.result(timeout=5.0)

    assert stats.passes >= 2
    wait_for(lambda: _drain([static], got_static) == stats.published["/robot1/tf_static"],
             what="every static transform sent")
    assert stats.published["/robot1/tf_static"] in {stats.passes, stats.passes + 1}
    wait_for(lambda: _drain([scans], got_scans) == stats.published["/robot1/scan"], what="every scan sent")
    scans_per_pass = sum(m.topic == "/robot1/scan" for m in written)
    assert stats.passes * scans_per_pass <= len(got_scans) <= (stats.passes + 1) * scans_per_pass


def test_stop_ends_a_slow_replay_promptly(lone_bus: Bus,
                                          sample_bag: tuple[Path, list[BagMessage]]) -> None:
    talker = lone_bus
    bag, _ = sample_bag
    stop = threading.Event()
    with _running(replay_bag, talker, bag, rate=0.001, stop=stop) as future:
        stop.set()
        stats: ReplayStats = future.result(timeout=2.0)
    assert stats.passes == 0


@pytest.mark.parametrize("rate", [0.0, -1.0, math.nan, math.inf])
def test_rejects_a_rate_that_is_not_positive_and_finite(lone_bus: Bus,
                                                       sample_bag: tuple[Path, list[BagMessage]],
                                                       rate: float) -> None:
    with pytest.raises(ValueError, match="rate must be a positive finite number"):
        replay_bag(lone_bus, sample_bag[0], rate=rate, stop=threading.Event())


@pytest.mark.parametrize("namespace", ["*", "robot 1", "a/**"])
def test_rejects_a_namespace_that_is_not_a_ros_name(lone_bus: Bus, sample_bag: tuple[Path, list[BagMessage]],
                                                     namespace: str) -> None:
    with pytest.raises(ValueError, match="is not a ROS namespace"):
        replay_bag(lone_bus, sample_bag[0], namespace=namespace, stop=threading.Event())


def test_rejects_paths_that_are_not_rosbag2(lone_bus: Bus, tmp_path: Path) -> None:
    (tmp_path / "notes.txt").write_text("not a bag")
    (tmp_path / "old.bag").write_bytes(b"#ROSBAG V2.0\n")
    (tmp_path / "empty").mkdir()
    cases = {"missing": "no such bag", "notes.txt": "not a readable rosbag2",
             "old.bag": "ROS 1 bag", "empty": "not a readable rosbag2"}
    for name, match in cases.items():
        with pytest.raises(ReplayError, match=match):
            replay_bag(lone_bus, tmp_path / name, stop=threading.Event())


def test_rejects_topics_the_bag_lacks(lone_bus: Bus, sample_bag: tuple[Path, list[BagMessage]]) -> None:
    with pytest.raises(ReplayError, match=r"\['/camera'\] are not in the bag"):
        replay_bag(lone_bus, sample_bag[0], stop=threading.Event(), topics=["/scan", "camera"])


def test_rejects_looping_a_bag_of_one_instant(lone_bus: Bus, tmp_path: Path) -> None:
    bag = tmp_path / "instant"
    write_sample_bag(bag, rounds=0)
    with pytest.raises(ReplayError, match="single instant"):
        replay_bag(lone_bus, bag, loop=True, stop=threading.Event())


def test_replays_every_scan_of_the_real_mac_first_floor_bag(bus_pair: tuple[Bus, Bus]) -> None:
    bag = data_path("bags", "mac_first_floor", "bag")
    listener, talker = bus_pair
    scans = listener.subscribe("scan", messages.LASER_SCAN, maxsize=2000)
    wait_until_subscribed(talker, [("", "scan", messages.LASER_SCAN)])

    topics = ["/scan", "/odom", "/tf", "/tf_static"]
    stats = replay_bag(talker, bag, rate=50.0, stop=threading.Event(), topics=topics)

    received: list[Received] = []
    wait_for(lambda: _drain([scans], received) >= 357, what="the bag's 357 scans")
    assert stats.published == {"/scan": 357, "/odom": 920, "/tf": 953, "/tf_static": 2}
    stamps = [r.message.header.stamp.sec * 10**9 + r.message.header.stamp.nanosec for r in received]
    assert stamps == sorted(stamps)
    assert all(len(r.message.ranges) == 720 for r in received)

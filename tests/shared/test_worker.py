"""The worker contract's helpers: subscribing under every robot namespace, settings sections checked again,
tf into per-robot buffers, input spans; over real zenoh sessions on loopback."""

from __future__ import annotations

from pathlib import Path

import pytest

from shared import messages
from shared.bus import Bus, DropPolicy
from shared.keyexpr import Attachment, topic_key
from shared.metrics import Counters
from shared.settings import DecompositionSettings, Settings
from shared.store import MapStore
from shared.transforms import TransformBuffer
from shared.worker import InputSpan, StageContext, checked, drain, take_transforms
from tests.helpers import wait_for


@pytest.fixture
def context(bus_pair: tuple[Bus, Bus], tmp_path: Path) -> StageContext:
    store = MapStore(f"sqlite:///{tmp_path / 'aisle.db'}")
    store.upgrade()
    settings = Settings(database_url=store.url, robot_namespaces=["robot1", "robot2"])
    return StageContext("stage", bus_pair[0], store, settings, store.ensure_map(settings.map_name), Counters())


def _tf(stamp_s: int, *, w: float = 1.0) -> object:
    cls = messages.message_class
    transform = cls("geometry_msgs/msg/TransformStamped")(
        header=messages.header(stamp_s * 10**9, "odom"), child_frame_id="base_link",
        transform=cls("geometry_msgs/msg/Transform")(
            translation=cls("geometry_msgs/msg/Vector3")(x=1.0, y=2.0, z=0.0),
            rotation=cls("geometry_msgs/msg/Quaternion")(x=0.0, y=0.0, z=0.0, w=w)))
    return cls(messages.TF_MESSAGE)(transforms=[transform])


def test_subscribe_picks_the_queue_policy_by_message_type(context: StageContext) -> None:
    assert context.subscribe("fisheye/image_raw", messages.IMAGE, maxsize=4).policy is DropPolicy.KEEP_NEWEST
    assert context.subscribe("fisheye/camera_info", messages.CAMERA_INFO, maxsize=4).policy is DropPolicy.KEEP_NEWEST
    for topic, msgtype in (("scan", messages.LASER_SCAN), ("tf", messages.TF_MESSAGE), ("odom", messages.ODOMETRY)):
        assert context.subscribe(topic, msgtype, maxsize=10).policy is DropPolicy.BLOCK


def test_subscribe_listens_to_the_configured_robots_only_and_counts_under_the_stage(
        context: StageContext, bus_pair: tuple[Bus, Bus]) -> None:
    _, talker = bus_pair
    tf = context.subscribe("tf", messages.TF_MESSAGE, maxsize=100)
    publishers = {ns: talker.publisher("tf", messages.TF_MESSAGE, namespace=ns) for ns in ("robot1", "robot2", "other")}
    heard: set[str] = set()

    def publish_until_heard() -> bool:
        for publisher in publishers.values():
            publisher.publish(_tf(1))
        heard.update(item.namespace for item in drain(tf))
        return heard >= {"robot1", "robot2"}

    wait_for(publish_until_heard, what="tf from both configured robots")
    assert heard == {"robot1", "robot2"}
    key = topic_key(0, "robot1", "tf", messages.TF_MESSAGE)
    talker.session.put(key, b"\x00\x01\x00\x00garbage", attachment=Attachment(1, 0, bytes(16)).encode())

    def malformed_counted() -> bool:
        tf.receive(0.05)  # skips the malformed sample (and any late good one)
        return context.bus.counters.get("stage.tf.malformed") > 0

    wait_for(malformed_counted, what="the malformed sample to be counted under the stage's name")


def test_take_transforms_fills_each_robots_buffer_and_counts_bad_ones(
        context: StageContext, bus_pair: tuple[Bus, Bus]) -> None:
    _, talker = bus_pair
    tf = context.subscribe("tf", messages.TF_MESSAGE, maxsize=100)
    good = talker.publisher("tf", messages.TF_MESSAGE, namespace="robot1")
    bad = talker.publisher("tf", messages.TF_MESSAGE, namespace="robot2")
    buffers: dict[str, TransformBuffer] = {}

    def publish_and_take() -> bool:
        good.publish(_tf(1))
        bad.publish(_tf(1, w=0.0))  # a zero quaternion
        take_transforms(context, lambda ns: buffers.setdefault(ns, TransformBuffer()), static=None, dynamic=tf,
                        counter="bad_tf")
        return "robot1" in buffers and context.counters.get("stage.bad_tf") > 0

    wait_for(publish_and_take, what="a good and a bad tf message")
    assert buffers["robot1"].lookup("odom", "base_link", 10**9).translation[:2].tolist() == [1.0, 2.0]


def test_context_closes_its_subscriptions(context: StageContext) -> None:
    events = context.map_events()
    scans = context.subscribe("scan", messages.LASER_SCAN, maxsize=10)
    assert events.policy is DropPolicy.KEEP_NEWEST and events.name == "stage.map_events"
    context.close_subscriptions()
    assert not events._handles and not scans._handles


def test_checked_rejects_a_section_built_without_validation() -> None:
    with pytest.raises(ValueError, match="min_change_fraction"):
        checked(DecompositionSettings.model_construct(min_change_fraction=1.5), ValueError)
    assert checked(DecompositionSettings(min_period_s=0.0), ValueError).min_period_s == 0.0


def test_input_span_keeps_the_oldest_and_newest_stamps() -> None:
    span = InputSpan()
    for stamp in (5, 3, 9):
        span.add(stamp)
    assert (span.first_ns, span.last_ns, span.count) == (3, 9, 3)

"""Key expressions and attachments are spelled exactly as rmw_zenoh spells them."""

from __future__ import annotations

import struct

import pytest

from shared import messages
from shared.keyexpr import Attachment, node_token, parse_topic_key, topic_key, topic_selector
from shared.messages import MessageError


def test_topic_key_matches_rmw_zenoh_layout() -> None:
    key = topic_key(0, "robot1", "scan", messages.LASER_SCAN)
    assert key == f"0/robot1/scan/sensor_msgs::msg::dds_::LaserScan_/{messages.type_hash(messages.LASER_SCAN)}"
    assert topic_key(3, "", "/odom", messages.ODOMETRY).startswith("3/odom/nav_msgs::msg::dds_::Odometry_/RIHS01_")


def test_parse_topic_key_tells_the_robot_namespace() -> None:
    parsed = parse_topic_key(topic_key(7, "site/robot_12", "scan", messages.LASER_SCAN))
    assert (parsed.domain_id, parsed.namespace, parsed.topic, parsed.msgtype) == (
        7, "site/robot_12", "scan", messages.LASER_SCAN)
    assert parse_topic_key(topic_key(0, "", "scan", messages.LASER_SCAN)).namespace == ""


@pytest.mark.parametrize("key", ["", "scan", "x/scan/sensor_msgs::msg::dds_::LaserScan_/h", "0/scan/LaserScan/h"])
def test_parse_topic_key_rejects_foreign_keys(key: str) -> None:
    with pytest.raises(MessageError):
        parse_topic_key(key)


def test_selector_covers_every_robot_and_any_hash() -> None:
    assert topic_selector(0, "*", "scan", messages.LASER_SCAN) == "0/**/scan/sensor_msgs::msg::dds_::LaserScan_/*"
    assert topic_selector(0, "robot1", "scan", messages.LASER_SCAN).startswith("0/robot1/scan/")


def test_attachment_is_rmw_zenohs_33_bytes() -> None:
    gid = bytes(range(16))
    raw = Attachment(5, 1_700_000_000_123_456_789, gid).encode()
    assert len(raw) == 33
    assert raw[:16] == struct.pack("<qq", 5, 1_700_000_000_123_456_789)
    assert raw[16] == 16 and raw[17:] == gid
    assert Attachment.decode(raw) == Attachment(5, 1_700_000_000_123_456_789, gid)


@pytest.mark.parametrize("raw", [b"", b"\x00" * 32, b"\x00" * 16 + b"\x0f" + b"\x00" * 16])
def test_malformed_attachment_is_refused(raw: bytes) -> None:
    with pytest.raises(MessageError, match="attachment"):
        Attachment.decode(raw)


def test_node_token_mangles_namespace_like_rmw_zenoh() -> None:
    token = node_token(0, "aac3178e146ba6f1fc6e6a4085e77f21", 4, "aisle", "occupancy_mapping")
    assert token == "@ros2_lv/0/aac3178e146ba6f1fc6e6a4085e77f21/4/4/NN/%/%aisle/occupancy_mapping"


def test_multi_segment_topics_keep_their_namespace_apart() -> None:
    key = topic_key(0, "robot1", "fisheye/image_raw", messages.IMAGE)
    parsed = parse_topic_key(key, topic="fisheye/image_raw")
    assert (parsed.namespace, parsed.topic) == ("robot1", "fisheye/image_raw")
    assert parse_topic_key(topic_key(0, "", "rgbd/depth/image_raw", messages.IMAGE),
                           topic="/rgbd/depth/image_raw").namespace == ""
    with pytest.raises(MessageError, match="not a key of topic"):
        parse_topic_key(key, topic="rgbd/color/image_raw")

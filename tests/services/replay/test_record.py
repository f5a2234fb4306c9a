"""Recording bus traffic into self-describing rosbag2 files."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any, Literal

import pytest
from rosbags.highlevel import AnyReader

from services.replay.record import RecordStats, record
from services.replay.replay import ReplayError, replay_bag
from shared import messages
from shared.bus import Bus
from shared.keyexpr import Attachment, topic_key
from shared.settings import ZenohSettings
from tests.helpers import free_port, wait_for
from tests.services.replay.test_replay import _routes, _running, wait_until_subscribed, write_sample_bag


@pytest.fixture(scope="module")
def lone_bus() -> Iterator[Bus]:
    """One unconnected session, for tests that never get as far as recording."""
    with Bus.open(ZenohSettings(listen=[f"tcp/127.0.0.1:{free_port()}"]), domain_id=0) as bus:
        yield bus


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_record_captures_a_replay_that_reads_back_without_a_typestore(
        bus_pair: tuple[Bus, Bus], tmp_path: Path, storage: Literal["mcap", "sqlite3"]) -> None:
    recorder, talker = bus_pair
    source, out = tmp_path / "source", tmp_path / "recorded"
    written = write_sample_bag(source, rounds=4)
    stop = threading.Event()

    with _running(record, recorder, out, stop=stop, domain_id=0, storage=storage) as future:
        wait_until_subscribed(talker, _routes(written))
        replay_bag(talker, source, rate=50.0, stop=threading.Event())
        wait_for(lambda: recorder.counters.get("record.written") >= len(written),
                 what="every message recorded")
        stop.set()
        stats: RecordStats = future.result(timeout=5.0)

    assert sum(stats.written.values()) == len(written)
    assert (stats.unknown_type, stats.malformed, stats.dropped) == (0, 0, 0)
    with AnyReader([out]) as reader:
        recorded = [(connection.topic, connection.msgtype, bytes(rawdata))
                    for connection, _, rawdata in reader.messages()]
        scan: Any = next(reader.deserialize(raw, msgtype) for _, msgtype, raw in recorded
                    if msgtype == messages.LASER_SCAN)
    for topic in {message.topic for message in written}:
        expected = [(m.topic, m.msgtype, m.rawdata) for m in written if m.topic == topic]
        assert [entry for entry in recorded if entry[0] == topic] == expected
    assert len(scan.ranges) == 360


def test_record_counts_unknown_types_and_malformed_keys_and_carries_on(
        bus_pair: tuple[Bus, Bus], tmp_path: Path) -> None:
    recorder, talker = bus_pair
    out = tmp_path / "recorded"
    stop = threading.Event()
    good_key = topic_key(0, "robot1", "tf", messages.TF_MESSAGE)
    empty_tf = messages.message_class(messages.TF_MESSAGE)(transforms=[])
    payload = messages.serialize(empty_tf, messages.TF_MESSAGE)
    attachment = Attachment(1, 0, bytes(16)).encode()

    with _running(record, recorder, out, stop=stop, domain_id=0, storage="mcap") as future:
        wait_until_subscribed(talker, [("robot1", "tf", messages.TF_MESSAGE)])
        talker.session.put("0/robot1/foo/bogus", b"\x00\x01\x00\x00")
        talker.session.put("0/robot1/blip/acme_msgs::msg::dds_::Blip_/RIHS01_00", b"\x00\x01\x00\x00")
        talker.session.put(good_key.replace("RIHS01_", "RIHS01_ff"), payload)
        talker.session.put(good_key, payload, attachment=attachment)
        wait_for(lambda: recorder.counters.get("record.written") == 1
                 and recorder.counters.get("record.unknown_type") == 2
                 and recorder.counters.get("record.malformed") == 1, what="all four samples handled")
        stop.set()
        stats: RecordStats = future.result(timeout=5.0)

    assert stats.written == {"/robot1/tf": 1}
    with AnyReader([out]) as reader:
        assert [(c.topic, c.msgtype) for c in reader.connections] == [("/robot1/tf", messages.TF_MESSAGE)]


def test_record_refuses_to_overwrite(lone_bus: Bus, tmp_path: Path) -> None:
    with pytest.raises(ReplayError, match="exists already"):
        record(lone_bus, tmp_path, stop=threading.Event(), domain_id=0)


def test_record_rejects_unknown_storage(lone_bus: Bus, tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="storage must be one of"):
        record(lone_bus, tmp_path / "out", stop=threading.Event(), domain_id=0, storage="zip")  # type: ignore[arg-type]

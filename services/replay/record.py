"""Record every ROS 2 topic on the bus into a self-describing rosbag2 file.

zenoh callbacks only queue samples; the calling thread owns the bag and writes them, so the
storage (sqlite3 connections are bound to their thread) never sees two threads. Each
``(namespaced topic, type)`` gets a connection on first sight, carrying the type's definition
from our typestore, so the bag reads back without a default typestore.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections import Counter
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Final, Literal

import zenoh
from rosbags.interfaces import Connection
from rosbags.rosbag2 import StoragePlugin, Writer

from services.replay.replay import ReplayError
from shared.bus import Bus
from shared.keyexpr import TopicKey, parse_topic_key
from shared.messages import TYPESTORE, MessageError, type_hash
from shared.metrics import Counters

log = logging.getLogger(__name__)

_STORAGE_PLUGINS: Final = {"mcap": StoragePlugin.MCAP, "sqlite3": StoragePlugin.SQLITE3}
_POLL_S: Final = 0.1
"""How often the writing loop looks at ``stop`` when nothing arrives."""


@dataclass(frozen=True, slots=True)
class RecordStats:
    """What one :func:`record` call wrote and left out."""

    written: Mapping[str, int]
    """Messages written per namespaced ROS topic name, e.g. ``{"/robot1/scan": 357}``."""
    unknown_type: int
    """Samples of a type not in our typestore, or whose type hash differs from ours."""
    malformed: int
    """Samples whose key is not an rmw_zenoh topic key."""
    dropped: int
    """Samples that found the queue full (the writer fell behind by ``max_pending``)."""
    elapsed_s: float


@dataclass(frozen=True, slots=True)
class _Sample:
    key: str
    payload: bytes
    received_ns: int


def record(
    bus: Bus,
    out: Path,
    *,
    stop: threading.Event,
    domain_id: int,
    storage: Literal["mcap", "sqlite3"] = "mcap",
    max_pending: int = 10_000,
) -> RecordStats:
    """Write every topic sample of ROS domain ``domain_id`` seen on ``bus`` to a new bag ``out``.

    Blocks until ``stop`` is set, then writes what is still queued and closes the bag.
    Progress is counted on ``bus.counters`` as ``record.written``, ``record.unknown_type``,
    ``record.malformed`` and ``record.dropped``.

    Parameters
    ----------
    bus
        Session to listen on; its raw zenoh session subscribes to ``<domain_id>/**``.
    out
        Bag directory to create; it must not exist.
    stop
        Set it to finish the recording.
    domain_id
        ROS domain to record.
    storage
        rosbag2 storage plugin, ``"mcap"`` or ``"sqlite3"``.
    max_pending
        Samples queued for the writer before new ones are dropped (and counted).

    Returns
    -------
    RecordStats
        Messages written per topic, samples left out by reason, elapsed seconds.

    Raises
    ------
    ReplayError
        ``out`` exists already.
    ValueError
        Unknown ``storage``, negative ``domain_id`` or ``max_pending`` below 1.
    """
    if storage not in _STORAGE_PLUGINS:
        raise ValueError(f"storage must be one of {sorted(_STORAGE_PLUGINS)}, not {storage!r}")
    if domain_id < 0:
        raise ValueError(f"domain_id must be >= 0, not {domain_id}")
    if max_pending < 1:
        raise ValueError(f"max_pending must be at least 1, not {max_pending}")
    if out.exists():
        raise ReplayError(f"{out} exists already; not overwriting it")
    started = time.monotonic()
    counts = Counters()

    def count(name: str) -> None:
        counts.incr(name)
        bus.counters.incr(f"record.{name}")

    pending: queue.Queue[_Sample] = queue.Queue(max_pending)

    def enqueue(sample: zenoh.Sample) -> None:
        try:
            pending.put_nowait(_Sample(str(sample.key_expr), sample.payload.to_bytes(), time.time_ns()))
        except queue.Full:
            count("dropped")

    with Writer(out, version=Writer.VERSION_LATEST, storage_plugin=_STORAGE_PLUGINS[storage]) as writer:
        bag = _Bag(writer, count=count)
        with bus.session.declare_subscriber(f"{domain_id}/**", enqueue):
            log.info("recording domain %d to %s", domain_id, out)
            while not stop.is_set():
                try:
                    sample = pending.get(timeout=_POLL_S)
                except queue.Empty:
                    continue
                bag.write(sample)
        while not pending.empty():
            bag.write(pending.get_nowait())
    elapsed_s = time.monotonic() - started
    stats = RecordStats(dict(bag.written), counts.get("unknown_type"), counts.get("malformed"),
                        counts.get("dropped"), elapsed_s)
    log.info("recorded %d messages on %d topics to %s in %.1f s (%d unknown type, %d malformed, "
             "%d dropped)", bag.written.total(), len(bag.written), out, elapsed_s, stats.unknown_type,
             stats.malformed, stats.dropped)
    return stats


class _Bag:
    """The open bag's connections, added as new topics and types turn up.

    Each distinct key is parsed and checked once; later samples cost a dictionary lookup.
    """

    def __init__(self, writer: Writer, *, count: Callable[[str], None]) -> None:
        self._writer = writer
        self._count = count
        self.written: Counter[str] = Counter()
        self._by_key: dict[str, Connection] = {}
        self._by_topic: dict[tuple[str, str], Connection] = {}
        self._refused: dict[str, str] = {}

    def write(self, sample: _Sample) -> None:
        """Write ``sample`` under its topic, or count why not."""
        connection = self._by_key.get(sample.key) or self._connect(sample.key)
        if connection is None:
            self._count(self._refused[sample.key])
            return
        self._writer.write(connection, sample.received_ns, sample.payload)
        self.written[connection.topic] += 1
        self._count("written")

    def _connect(self, key: str) -> Connection | None:
        """The connection for samples on ``key``, or None (logged once) when they cannot be written."""
        if key in self._refused:
            return None
        try:
            parsed = parse_topic_key(key)
        except MessageError as err:
            self._refuse(key, "malformed", str(err))
            return None
        if (problem := _type_problem(parsed)) is not None:
            self._refuse(key, "unknown_type", problem)
            return None
        name = _topic_name(parsed)
        connection = self._by_topic.get((name, parsed.msgtype))
        if connection is None:
            connection = self._writer.add_connection(name, parsed.msgtype, typestore=TYPESTORE)
            self._by_topic[name, parsed.msgtype] = connection
            log.info("recording %s (%s)", name, parsed.msgtype)
        self._by_key[key] = connection
        return connection

    def _refuse(self, key: str, reason: str, detail: str) -> None:
        self._refused[key] = reason
        log.warning("not recording %s: %s", key, detail)


def _type_problem(key: TopicKey) -> str | None:
    """Why samples on ``key`` cannot be written with our type definitions, if they cannot."""
    if key.msgtype not in TYPESTORE.fielddefs:
        return f"{key.msgtype} is not in our typestore"
    if key.type_hash.startswith("RIHS01_") and key.type_hash != type_hash(key.msgtype):
        return f"{key.msgtype} has hash {key.type_hash}, ours is {type_hash(key.msgtype)}"
    return None


def _topic_name(key: TopicKey) -> str:
    return "/" + "/".join(part for part in (key.namespace, key.topic) if part)

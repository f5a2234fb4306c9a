"""The zenoh bus: typed ROS 2 publish/subscribe on rmw_zenoh key expressions.

A ROS 2 robot running rmw_zenoh talks to Aisle directly: same key expressions, same
attachment, CDR payloads. Subscriptions cover every robot by wildcard and say which robot
(namespace) each message came from. Each subscription has a bounded queue with an explicit,
counted drop policy.
"""

from __future__ import annotations

import collections
import enum
import hashlib
import itertools
import json
import logging
import os
import queue
import threading
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import zenoh
import zenoh.ext

from shared.keyexpr import Attachment, node_selector, node_token, parse_topic_key, topic_key, topic_selector
from shared.messages import MessageError, deserialize, serialize
from shared.metrics import Counters
from shared.settings import ZenohSettings

log = logging.getLogger(__name__)

WORKER_NAMESPACE = "aisle"
"""ROS namespace under which every Aisle worker announces itself as a node."""
LATCHED_TOPICS = frozenset({"tf_static"})
"""Topics ROS 2 publishes transient-local ("latched", as tf2's static broadcaster does). As rmw_zenoh does for
transient-local QoS, their publishers keep their last :data:`LATCHED_CACHE` samples (a zenoh advanced publisher)
and their subscribers ask every publisher for them when they start or a publisher appears (a zenoh advanced
subscriber), so a worker started or restarted after a robot sent its static transforms still gets them."""
LATCHED_CACHE = 10
"""Samples a latched topic's publisher keeps for subscribers that join later."""
LATCHED_HISTORY = 100
"""Samples a latched topic's subscriber asks each publisher for (tf2's static listener keeps 100)."""


class DropPolicy(enum.Enum):
    """What a full subscription queue does with the next sample."""

    KEEP_NEWEST = "keep_newest"
    """Drop the oldest queued sample (cameras: only the latest frame matters). Counted."""
    BLOCK = "block"
    """Hold the zenoh receive thread until there is room (scans, poses); after
    ``block_timeout_s`` the sample is dropped, counted and logged as an error."""


@dataclass(frozen=True, slots=True)
class Received:
    """A decoded message and where it came from."""

    message: Any
    msgtype: str
    namespace: str
    topic: str
    attachment: Attachment | None
    received_ns: int


@dataclass(frozen=True, slots=True)
class _Raw:
    key: str
    payload: bytes
    attachment: bytes | None
    received_ns: int


def zenoh_config(settings: ZenohSettings) -> zenoh.Config:
    """A zenoh config from Aisle settings (shared memory off: payloads cross processes by TCP)."""
    config = zenoh.Config.from_file(str(settings.config_file)) if settings.config_file else zenoh.Config()
    config.insert_json5("mode", json.dumps(settings.mode))
    config.insert_json5("connect/endpoints", json.dumps(settings.connect))
    config.insert_json5("listen/endpoints", json.dumps(settings.listen))
    config.insert_json5("scouting/multicast/enabled", json.dumps(settings.multicast_scouting))
    config.insert_json5("transport/shared_memory/enabled", "false")
    config.insert_json5("timestamping/enabled", "true")  # latched topics' publishers need it (rmw_zenoh sets it too)
    return config


class Subscription:
    """A bounded, typed queue of messages on one topic from every matching robot."""

    def __init__(
        self,
        msgtype: str,
        topic: str,
        name: str,
        *,
        policy: DropPolicy,
        maxsize: int,
        counters: Counters,
        block_timeout_s: float = 5.0,
    ) -> None:
        if maxsize < 1:
            raise ValueError("maxsize must be at least 1")
        self.msgtype = msgtype
        self.topic = topic.strip("/")
        self.name = name
        self.policy = policy
        self._counters = counters
        self._block_timeout_s = block_timeout_s
        self._queue: queue.Queue[_Raw] | None = None
        self._ring: collections.deque[_Raw] | None = None
        self._ready = threading.Condition()
        if policy is DropPolicy.BLOCK:
            self._queue = queue.Queue(maxsize)
        else:
            self._ring = collections.deque(maxlen=maxsize)
        self._handles: list[Any] = []

    def close(self) -> None:
        """Stop receiving; queued samples stay readable."""
        for handle in self._handles:
            handle.undeclare()
        self._handles.clear()

    def _on_sample(self, sample: zenoh.Sample) -> None:
        raw = _Raw(
            key=str(sample.key_expr),
            payload=sample.payload.to_bytes(),
            attachment=sample.attachment.to_bytes() if sample.attachment is not None else None,
            received_ns=time.time_ns(),
        )
        self._counters.incr(f"{self.name}.received")
        if self._queue is not None:
            try:
                self._queue.put(raw, timeout=self._block_timeout_s)
            except queue.Full:
                self._counters.incr(f"{self.name}.dropped")
                log.error("%s: queue full for %.1f s, dropped a sample from %s", self.name,
                          self._block_timeout_s, raw.key)
            return
        assert self._ring is not None
        with self._ready:
            if len(self._ring) == self._ring.maxlen:
                self._counters.incr(f"{self.name}.dropped")
            self._ring.append(raw)
            self._ready.notify()

    def _next_raw(self, timeout: float) -> _Raw | None:
        if self._queue is not None:
            try:
                return self._queue.get(timeout=timeout)
            except queue.Empty:
                return None
        assert self._ring is not None
        with self._ready:
            if not self._ring and not self._ready.wait_for(lambda: bool(self._ring), timeout):
                return None
            return self._ring.popleft()

    def pending(self) -> int:
        """Samples waiting in the queue."""
        if self._queue is not None:
            return self._queue.qsize()
        assert self._ring is not None
        return len(self._ring)

    def receive(self, timeout: float = 0.0) -> Received | None:
        """The next well-formed message, or None when none arrives within ``timeout`` seconds.

        Malformed samples (bad key, bad attachment, bad CDR) are logged, counted as
        ``<name>.malformed`` and skipped.
        """
        deadline = time.monotonic() + timeout
        while True:
            raw = self._next_raw(max(0.0, deadline - time.monotonic()))
            if raw is None:
                return None
            try:
                return self._decode(raw)
            except MessageError as err:
                self._counters.incr(f"{self.name}.malformed")
                log.warning("%s: skipped a malformed sample on %s: %s", self.name, raw.key, err)

    def _decode(self, raw: _Raw) -> Received:
        key = parse_topic_key(raw.key, topic=self.topic)
        if key.msgtype != self.msgtype:
            raise MessageError(f"expected {self.msgtype}, key says {key.msgtype}")
        attachment = Attachment.decode(raw.attachment) if raw.attachment is not None else None
        message = deserialize(raw.payload, self.msgtype)
        return Received(message, self.msgtype, key.namespace, key.topic, attachment, raw.received_ns)


class Publisher:
    """Publishes one topic as a ROS 2 node on rmw_zenoh would: CDR payload plus attachment."""

    def __init__(self, publisher: zenoh.Publisher | zenoh.ext.AdvancedPublisher, msgtype: str, gid: bytes) -> None:
        self._publisher = publisher
        self.msgtype = msgtype
        self._gid = gid
        self._sequence = itertools.count(1)
        self._lock = threading.Lock()

    def publish(self, message: Any) -> None:
        self.publish_raw(serialize(message, self.msgtype))

    def publish_raw(self, payload: bytes) -> None:
        """Send already-serialised CDR (as read from a rosbag2 file)."""
        with self._lock:
            attachment = Attachment(next(self._sequence), time.time_ns(), self._gid).encode()
            self._publisher.put(payload, attachment=attachment)

    def close(self) -> None:
        self._publisher.undeclare()  # type: ignore[no-untyped-call]  # zenoh.ext's stub leaves it untyped


class Bus:
    """A zenoh session speaking ROS 2 (rmw_zenoh) on one ROS domain."""

    def __init__(self, session: zenoh.Session, *, domain_id: int, counters: Counters | None = None) -> None:
        self.session = session
        self.domain_id = domain_id
        self.counters = counters if counters is not None else Counters()
        self._zid = str(session.zid())
        self._entity_ids = itertools.count()
        self._subscriptions: list[Subscription] = []

    @classmethod
    @contextmanager
    def open(cls, settings: ZenohSettings, *, domain_id: int, counters: Counters | None = None) -> Iterator[Bus]:
        """Open a zenoh session from settings; closed on exit."""
        try:
            session = zenoh.open(zenoh_config(settings))
        except zenoh.ZError as err:
            raise ConnectionError(f"cannot open a zenoh session ({settings.mode}, listen "
                                  f"{settings.listen}, connect {settings.connect}): {err}") from err
        bus = cls(session, domain_id=domain_id, counters=counters)
        try:
            yield bus
        finally:
            bus.close()

    def close(self) -> None:
        for subscription in self._subscriptions:
            subscription.close()
        self._subscriptions.clear()
        if not self.session.is_closed():
            self.session.close()

    def _gid(self, key: str) -> bytes:
        seed = f"{self._zid}/{next(self._entity_ids)}/{key}/{os.getpid()}".encode()
        return hashlib.blake2b(seed, digest_size=16).digest()

    def publisher(self, topic: str, msgtype: str, *, namespace: str = "", drop_when_congested: bool = False
                  ) -> Publisher:
        """A publisher of ``msgtype`` on ``/<namespace>/<topic>``.

        By default it blocks under congestion rather than losing data; cameras may opt to drop. On a
        :data:`LATCHED_TOPICS` topic it keeps its last samples for subscribers that join later.
        """
        key = topic_key(self.domain_id, namespace, topic, msgtype)
        congestion = zenoh.CongestionControl.DROP if drop_when_congested else zenoh.CongestionControl.BLOCK
        if topic.strip("/") in LATCHED_TOPICS:
            latched = zenoh.ext.declare_advanced_publisher(
                self.session, key, congestion_control=congestion, cache=zenoh.ext.CacheConfig(LATCHED_CACHE),
                publisher_detection=True)
            return Publisher(latched, msgtype, self._gid(key))
        return Publisher(self.session.declare_publisher(key, congestion_control=congestion), msgtype,
                         self._gid(key))

    def subscribe(
        self,
        topic: str,
        msgtype: str,
        *,
        namespaces: Sequence[str] = ("*",),
        policy: DropPolicy = DropPolicy.BLOCK,
        maxsize: int = 1000,
        name: str | None = None,
    ) -> Subscription:
        """Subscribe to ``topic`` of ``msgtype`` under each of ``namespaces`` ("*": every robot).

        On a :data:`LATCHED_TOPICS` topic the subscription also receives what each publisher sent before it
        started (up to :data:`LATCHED_HISTORY` samples a publisher).
        """
        subscription = Subscription(msgtype, topic, name or topic, policy=policy, maxsize=maxsize,
                                    counters=self.counters)
        latched = topic.strip("/") in LATCHED_TOPICS
        for namespace in namespaces:
            selector = topic_selector(self.domain_id, namespace, topic, msgtype)
            if latched:
                history = zenoh.ext.HistoryConfig(detect_late_publishers=True, max_samples=LATCHED_HISTORY)
                subscription._handles.append(zenoh.ext.declare_advanced_subscriber(
                    self.session, selector, subscription._on_sample, history=history, subscriber_detection=True))
            else:
                subscription._handles.append(self.session.declare_subscriber(selector, subscription._on_sample))
        self._subscriptions.append(subscription)
        return subscription

    def declare_worker(self, name: str) -> zenoh.LivelinessToken:
        """Announce a running worker as ROS node ``/aisle/<name>``; gone when the token is dropped."""
        token = node_token(self.domain_id, self._zid, next(self._entity_ids), WORKER_NAMESPACE, name)
        return self.session.liveliness().declare_token(token)

    def alive_workers(self, timeout_s: float = 0.5) -> list[str]:
        """Names of the Aisle workers whose liveliness tokens are visible now."""
        replies = self.session.liveliness().get(node_selector(self.domain_id, WORKER_NAMESPACE),
                                                timeout=timeout_s)
        names = set()
        for reply in replies:
            if reply.ok is not None:
                names.add(str(reply.ok.key_expr).rsplit("/", 1)[-1])
        return sorted(names)

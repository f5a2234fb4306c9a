"""Running a stage worker: liveliness, heartbeats, counted errors, atomic revisions, map events.

A stage implements :class:`Stage`; :func:`run_stage` connects it to the bus and the store and
keeps it alive until ``stop`` is set. Workers are thin: they decode, call pure functions,
persist and publish.
"""

from __future__ import annotations

import datetime as dt
import logging
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any, Protocol, TypeVar

from pydantic import BaseModel, ValidationError

from shared import messages
from shared.bus import WORKER_NAMESPACE, Bus, DropPolicy, Publisher, Received, Subscription
from shared.metrics import Counters
from shared.settings import Settings
from shared.store import MapInfo, MapStore, Revision, RevisionWrite, StoreError, StoreUnavailableError
from shared.transforms import TransformBuffer, add_tf_message

log = logging.getLogger(__name__)

HEARTBEAT_PERIOD_S = 5.0
IDLE_WAIT_S = 0.5
"""Longest a stage waits for its next input before it looks at its stop flag and its periods again, seconds: a
stage with no traffic wakes twice a second (it woke twenty times: 0.2 % of a core per stage, idle)."""
PENDING_WAIT_S = 0.05
"""Longest a stage with a frame waiting for its pose (its transforms not in yet) waits for its next input, seconds:
the frame is taken as soon as its pose arrives, not overtaken by the next frame half a second later."""
MAP_EVENTS_TOPIC = "map_events"
"""Map events go to ROS topic ``/aisle/map_events`` (aisle_msgs/msg/MapEvent)."""
LATEST_ONLY = frozenset({messages.IMAGE, messages.CAMERA_INFO})
"""Message types whose subscriptions keep the newest samples (camera frames: only the latest matters); every
other type holds the sender instead of dropping (scans, poses, tf)."""


@dataclass
class StageContext:
    """What a stage gets to work with."""

    name: str
    bus: Bus
    store: MapStore
    settings: Settings
    map: MapInfo
    counters: Counters
    started_at: dt.datetime = field(default_factory=lambda: dt.datetime.now(dt.UTC))
    _events: Publisher | None = None
    _subscriptions: list[Subscription] = field(default_factory=list)

    def count(self, what: str, amount: int = 1) -> None:
        """Add ``amount`` to counter ``<stage>.<what>`` (nothing for 0: a counter appears when it first counts)."""
        if amount:
            self.counters.incr(f"{self.name}.{what}", amount)

    def subscribe(self, topic: str, msgtype: str, *, maxsize: int) -> Subscription:
        """``topic`` of ``msgtype`` under every robot namespace of the settings, queued up to ``maxsize``.

        Camera frames and camera info (:data:`LATEST_ONLY`) keep the newest and count what they drop; every
        other type holds the sender (:attr:`DropPolicy.BLOCK`). Malformed samples are counted as
        ``<stage>.<topic>.malformed`` and skipped by ``receive``.
        """
        policy = DropPolicy.KEEP_NEWEST if msgtype in LATEST_ONLY else DropPolicy.BLOCK
        subscription = self.bus.subscribe(topic, msgtype, namespaces=self.settings.robot_namespaces, policy=policy,
                                          maxsize=maxsize, name=f"{self.name}.{topic}")
        self._subscriptions.append(subscription)
        return subscription

    def subscribe_transforms(self) -> tuple[Subscription, Subscription]:
        """``tf`` and ``tf_static`` of every robot, queued deep enough for frames waiting for their pose (feed them
        to :func:`take_transforms`)."""
        return (self.subscribe("tf", messages.TF_MESSAGE, maxsize=2000),
                self.subscribe("tf_static", messages.TF_MESSAGE, maxsize=100))

    def map_events(self) -> Subscription:
        """The map events every worker and the API announce on ``/aisle/map_events`` (newest 64 kept)."""
        subscription = self.bus.subscribe(MAP_EVENTS_TOPIC, messages.MAP_EVENT, namespaces=[WORKER_NAMESPACE],
                                          policy=DropPolicy.KEEP_NEWEST, maxsize=64,
                                          name=f"{self.name}.{MAP_EVENTS_TOPIC}")
        self._subscriptions.append(subscription)
        return subscription

    def close_subscriptions(self) -> None:
        """Stop receiving on every subscription made through this context (:func:`run_stage` does so when the
        stage stops or fails; what is queued stays readable)."""
        for subscription in self._subscriptions:
            subscription.close()
        self._subscriptions.clear()

    def commit(self, write: RevisionWrite) -> Revision | None:
        """Store ``write`` as one revision and announce it; None (counted, logged) if the store is down.

        Invalid content raises :class:`StoreError`: that is a bug in the stage, not bad input.
        """
        try:
            revision = self.store.write_revision(self.map.id, write)
        except StoreUnavailableError as err:
            self.count("store_unavailable")
            log.warning("%s: revision not stored, will retry: %s", self.name, err)
            return None
        self.count("revisions")
        self._announce(revision)
        return revision

    def _announce(self, revision: Revision) -> None:
        if self._events is None:
            self._events = self.bus.publisher(MAP_EVENTS_TOPIC, messages.MAP_EVENT, namespace=WORKER_NAMESPACE)
        self._events.publish(map_event(self.map.name, revision))


def map_event(map_name: str, revision: Revision) -> Any:
    """The ``aisle_msgs/msg/MapEvent`` announcing ``revision`` (from its stored summary), stamped now."""
    features = revision.summary.get("features", {})
    return messages.message_class(messages.MAP_EVENT)(
        stamp=messages.time_msg(time.time_ns()),
        map_name=map_name,
        revision_id=revision.id,
        stage=revision.stage,
        layers_updated=list(revision.summary.get("layers_updated", [])),
        feature_kinds=sorted(features),
        features_added=sum(f["added"] for f in features.values()),
        features_removed=sum(f["removed"] for f in features.values()),
        features_moved=sum(f["moved"] for f in features.values()),
        topology_changed=bool(revision.summary.get("topology_changed", False)),
    )


@dataclass
class InputSpan:
    """The stamps of the inputs a stage took since its last revision: the oldest and newest (ns) and how many."""

    first_ns: int | None = None
    last_ns: int | None = None
    count: int = 0

    def add(self, stamp_ns: int) -> None:
        self.first_ns = stamp_ns if self.first_ns is None else min(self.first_ns, stamp_ns)
        self.last_ns = stamp_ns if self.last_ns is None else max(self.last_ns, stamp_ns)
        self.count += 1


SectionT = TypeVar("SectionT", bound=BaseModel)


def checked(section: SectionT, error: type[Exception]) -> SectionT:
    """``section`` validated again (built with ``model_construct``, or changed since); ``error`` if invalid."""
    try:
        return type(section).model_validate(section.model_dump())
    except ValidationError as err:
        raise error(f"{type(section).__name__}: {err}") from err


def drain(subscription: Subscription | None) -> Iterator[Received]:
    """Every message queued on ``subscription`` now (none for None), without waiting."""
    while subscription is not None and (item := subscription.receive()) is not None:
        yield item


def take_transforms(context: StageContext, buffer_of: Callable[[str], TransformBuffer], *,
                    static: Subscription | None, dynamic: Subscription | None = None,
                    counter: str = "bad_transforms") -> None:
    """Add every queued tf_static (first), then tf message to ``buffer_of(namespace)`` of the robot it came from.

    Bad transforms (non-finite, zero quaternion) are counted as ``counter``, logged and skipped.
    """
    for subscription, is_static in ((static, True), (dynamic, False)):
        for item in drain(subscription):
            try:
                add_tf_message(buffer_of(item.namespace), item.message, static=is_static)
            except ValueError as err:
                context.count(counter)
                log.warning("%s: tf from %r skipped: %s", context.name, item.namespace or "/", err)


class Stage(Protocol):
    """One pipeline stage: subscribes in ``__init__`` (through :meth:`StageContext.subscribe`, closed when ``run``
    returns), works in ``run`` until ``stop`` is set."""

    def run(self, stop: threading.Event) -> None: ...


StageFactory = Callable[[StageContext], Stage]


def _beat(context: StageContext) -> None:
    """Store the worker's liveness and counters (bus counters of its own topics included)."""
    own = {k: v for k, v in context.bus.counters.snapshot().items() if k.startswith(f"{context.name}.")}
    try:
        context.store.heartbeat(context.name, {**own, **context.counters.snapshot()},
                                started_at=context.started_at)
    except StoreError as err:
        context.count("heartbeat_failures")
        log.debug("%s: heartbeat not stored: %s", context.name, err)


def _heartbeat(context: StageContext, stop: threading.Event) -> None:
    while True:
        _beat(context)
        if stop.wait(HEARTBEAT_PERIOD_S):
            return


def run_stage(name: str, factory: StageFactory, *, bus: Bus, store: MapStore, settings: Settings,
              stop: threading.Event, restart_delay_s: float = 2.0) -> None:
    """Run stage ``name`` until ``stop``: announced on the bus, heartbeating into the store.

    An unexpected exception inside the stage is logged and counted, and the stage is rebuilt
    after ``restart_delay_s`` (its state comes back from the store).
    """
    map_info = None
    while map_info is None:
        try:
            map_info = store.ensure_map(settings.map_name)
        except StoreUnavailableError as err:
            log.warning("%s: waiting for the database: %s", name, err)
            if stop.wait(restart_delay_s):
                return
    context = StageContext(name, bus, store, settings, map_info, Counters())
    heart = threading.Thread(target=_heartbeat, args=(context, stop), name=f"{name}-heartbeat", daemon=True)
    heart.start()
    token = None
    try:
        while not stop.is_set():
            try:
                stage = factory(context)  # subscribes: only then is the worker announced as alive
                token = token or bus.declare_worker(name)
                stage.run(stop)
            except Exception:
                context.count("crashes")
                log.exception("%s: stage failed; restarting in %.1f s", name, restart_delay_s)
                stop.wait(restart_delay_s)
            finally:
                context.close_subscriptions()
    finally:
        if token is not None:
            token.undeclare()
        heart.join(timeout=HEARTBEAT_PERIOD_S + 1)
        _beat(context)
        log.info("%s: stopped", name)

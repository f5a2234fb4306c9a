"""Replay a rosbag2 recording onto the bus as the robots would have published it.

Each message goes out with its original timing (scaled by ``rate``) and its CDR payload
untouched, on the rmw_zenoh key of its namespaced topic: ``/robot1/scan`` in the bag becomes
topic ``scan`` of robot ``robot1``. Static transforms (``tf_static``, under any namespace) are
sent first at the start of every pass, on a latched topic (:data:`shared.bus.LATCHED_TOPICS`), so a
map worker that joins or restarts mid-replay is sent them at once, as by a robot's tf2 static broadcaster.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import Counter
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from rosbags.highlevel import AnyReader, AnyReaderError
from rosbags.interfaces import Connection

from shared.bus import Bus, Publisher
from shared.messages import TYPESTORE

log = logging.getLogger(__name__)

STATIC_TOPIC = "tf_static"
"""Topic name (last path element) of latched transforms, re-sent at the start of every pass."""


class ReplayError(ValueError):
    """A recording that cannot be replayed or recorded as asked."""


@dataclass(frozen=True, slots=True)
class ReplayStats:
    """What one :func:`replay_bag` call did."""

    published: Mapping[str, int]
    """Messages sent per ROS topic name as published, e.g. ``{"/robot1/scan": 357}``."""
    skipped: Mapping[str, int]
    """Messages left out per bag topic over the complete passes: type not in our typestore,
    defined differently from ours, or not CDR."""
    passes: int
    """Complete passes through the bag (a replay stopped midway does not count its last one)."""
    elapsed_s: float


@dataclass(frozen=True, slots=True)
class _Route:
    """Where the messages of one bag connection go."""

    namespace: str
    topic: str
    msgtype: str

    @property
    def name(self) -> str:
        return "/" + "/".join(part for part in (self.namespace, self.topic) if part)


@contextmanager
def _open_bag(bag: Path) -> Iterator[AnyReader]:
    """An open reader of rosbag2 ``bag``; every way of not being one raises :class:`ReplayError`."""
    if not bag.exists():
        raise ReplayError(f"{bag}: no such bag")
    if bag.suffix == ".bag":
        raise ReplayError(f"{bag} is a ROS 1 bag; convert it to rosbag2 first (rosbags-convert)")
    try:
        reader = AnyReader([bag], default_typestore=TYPESTORE)
        reader.open()
    except (AnyReaderError, OSError) as err:
        raise ReplayError(f"{bag} is not a readable rosbag2 recording: {err}") from err
    try:
        yield reader
    finally:
        reader.close()


def _route(connection: Connection, reader: AnyReader, namespace: str) -> _Route | str:
    """The route of ``connection``, or why its messages cannot be sent."""
    msgtype = connection.msgtype
    if getattr(connection.ext, "serialization_format", None) != "cdr":
        return "not CDR"
    if msgtype not in TYPESTORE.fielddefs:
        return f"unknown type {msgtype}"
    if reader.typestore.hash_rihs01(msgtype) != TYPESTORE.hash_rihs01(msgtype):
        return f"{msgtype} in the bag differs from our definition"
    *bag_namespace, topic = connection.topic.strip("/").split("/")
    full_namespace = "/".join(part for part in (namespace.strip("/"), *bag_namespace) if part)
    return _Route(full_namespace, topic, msgtype)


def _plan(reader: AnyReader, connections: Sequence[Connection], *, namespace: str
          ) -> tuple[dict[int, _Route], Counter[str]]:
    """Routes by connection id of the connections that can be sent; messages per pass of the rest."""
    routes: dict[int, _Route] = {}
    skipped: Counter[str] = Counter()
    for connection in connections:
        route = _route(connection, reader, namespace)
        if isinstance(route, str):
            log.warning("skipping %s (%d messages): %s", connection.topic, connection.msgcount, route)
            skipped[connection.topic] += connection.msgcount
        else:
            routes[connection.id] = route
    return routes, skipped


def _select(reader: AnyReader, topics: Sequence[str] | None) -> list[Connection]:
    if topics is None:
        return list(reader.connections)
    wanted = {"/" + topic.strip("/") for topic in topics}
    if missing := wanted - {connection.topic for connection in reader.connections}:
        raise ReplayError(f"topics {sorted(missing)} are not in the bag, which has "
                          f"{sorted({connection.topic for connection in reader.connections})}")
    return [connection for connection in reader.connections if connection.topic in wanted]


def replay_bag(
    bus: Bus,
    bag: Path,
    *,
    rate: float = 1.0,
    loop: bool = False,
    stop: threading.Event,
    namespace: str = "",
    topics: Sequence[str] | None = None,
) -> ReplayStats:
    """Publish the messages of rosbag2 ``bag`` on ``bus`` with their recorded timing.

    Parameters
    ----------
    bus
        Where to publish; one publisher per topic and type, closed on return.
    bag
        A rosbag2 directory (sqlite3 or MCAP storage) or a single ``.db3`` / ``.mcap`` file.
        Bags without embedded type definitions are read with our typestore.
    rate
        Playback speed factor: 2.0 plays a 10 s bag in 5 s.
    loop
        Start again from the beginning when the bag ends, until ``stop`` is set. Each pass lasts
        the bag's duration divided by ``rate``.
    stop
        Set it to end the replay promptly (between two messages or during a wait).
    namespace
        Extra namespace in front of each topic's own: ``"site2"`` sends ``/robot1/scan`` as
        ``/site2/robot1/scan``.
    topics
        Bag topic names to replay (``"/scan"`` or ``"scan"``); None replays every topic.

    Returns
    -------
    ReplayStats
        Messages published per topic, messages skipped per bag topic, passes, elapsed seconds.

    Raises
    ------
    ReplayError
        ``bag`` is missing, not a rosbag2 recording, lacks a requested topic, or cannot loop
        (it spans a single instant).
    ValueError
        ``rate`` is not a positive finite number, or ``namespace`` is not a ROS namespace.
    """
    if not (math.isfinite(rate) and rate > 0.0):
        raise ValueError(f"rate must be a positive finite number, not {rate}")
    if not all(part.replace("_", "a").isalnum() for part in namespace.strip("/").split("/") if part):
        raise ValueError(f"namespace {namespace!r} is not a ROS namespace")
    started = time.monotonic()
    published: Counter[str] = Counter()
    skipped: Counter[str] = Counter()
    passes = 0
    with _open_bag(bag) as reader:
        if loop and reader.duration <= 1:
            raise ReplayError(f"{bag} spans a single instant; it cannot be looped")
        routes, skipped_per_pass = _plan(reader, _select(reader, topics), namespace=namespace)
        publishers = {route: bus.publisher(route.topic, route.msgtype, namespace=route.namespace)
                      for route in set(routes.values())}
        static = [c for c in reader.connections if c.id in routes and routes[c.id].topic == STATIC_TOPIC]
        timed = [c for c in reader.connections if c.id in routes and c not in static]
        period_s = reader.duration / 1e9 / rate
        try:
            while not stop.is_set():
                pass_start = time.monotonic()
                for connection, _, rawdata in reader.messages(static) if static else ():
                    route = routes[connection.id]
                    publishers[route].publish_raw(rawdata)
                    published[route.name] += 1
                if timed and not _play(reader, timed, routes, publishers, published,
                                       origin_s=pass_start, rate=rate, stop=stop):
                    break
                skipped.update(skipped_per_pass)
                passes += 1
                if not loop or stop.wait(max(0.0, pass_start + period_s - time.monotonic())):
                    break
        finally:
            for publisher in publishers.values():
                publisher.close()
    elapsed_s = time.monotonic() - started
    log.info("replayed %s: %d passes, %d messages in %.1f s, %d skipped", bag, passes,
             published.total(), elapsed_s, skipped.total())
    return ReplayStats(dict(published), dict(skipped), passes, elapsed_s)


def _play(
    reader: AnyReader,
    connections: list[Connection],
    routes: Mapping[int, _Route],
    publishers: Mapping[_Route, Publisher],
    published: Counter[str],
    *,
    origin_s: float,
    rate: float,
    stop: threading.Event,
) -> bool:
    """Send one pass of ``connections`` timed from monotonic ``origin_s``; False if stopped."""
    for connection, timestamp_ns, rawdata in reader.messages(connections):
        due_s = origin_s + (timestamp_ns - reader.start_time) / 1e9 / rate
        if stop.wait(max(0.0, due_s - time.monotonic())):
            return False
        route = routes[connection.id]
        publishers[route].publish_raw(rawdata)
        published[route.name] += 1
    return True

"""Revisions the API writes (human input: WMS bin lists, label tables, places, blocked connections) are announced
on the bus like the stages' own, so the fleet manager misses none, and to the API's own live state, so the
writer's next read sees them."""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable

from shared import messages
from shared.bus import WORKER_NAMESPACE, Bus, Publisher
from shared.store import MapInfo, Revision
from shared.worker import MAP_EVENTS_TOPIC, map_event

log = logging.getLogger(__name__)


class Announcer:
    """Tells ``on_revision`` of each revision the API wrote, and publishes a MapEvent for it on
    ``/aisle/map_events`` when the API has a bus."""

    def __init__(self, bus: Bus | None, on_revision: Callable[[MapInfo, Revision], None] | None = None) -> None:
        self.bus = bus
        self.on_revision = on_revision
        self._publisher: Publisher | None = None
        self._lock = threading.Lock()

    def announce(self, map_info: MapInfo, revision: Revision) -> None:
        if self.on_revision is not None:
            self.on_revision(map_info, revision)
        if self.bus is None:
            return
        with self._lock:
            if self._publisher is None:
                self._publisher = self.bus.publisher(MAP_EVENTS_TOPIC, messages.MAP_EVENT,
                                                     namespace=WORKER_NAMESPACE)
            self._publisher.publish(map_event(map_info.name, revision))
        log.debug("announced revision %d of map %s", revision.id, map_info.name)

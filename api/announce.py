"""Revisions the API writes (human input: WMS bin lists, label tables, places, blocked connections) are announced
on the bus like the stages' own, so the fleet manager misses none."""

from __future__ import annotations

import logging
import threading

from shared import messages
from shared.bus import WORKER_NAMESPACE, Bus, Publisher
from shared.store import MapInfo, Revision
from shared.worker import MAP_EVENTS_TOPIC, map_event

log = logging.getLogger(__name__)


class Announcer:
    """Publishes a MapEvent per revision on ``/aisle/map_events`` when the API has a bus; does nothing without."""

    def __init__(self, bus: Bus | None) -> None:
        self.bus = bus
        self._publisher: Publisher | None = None
        self._lock = threading.Lock()

    def announce(self, map_info: MapInfo, revision: Revision) -> None:
        if self.bus is None:
            return
        with self._lock:
            if self._publisher is None:
                self._publisher = self.bus.publisher(MAP_EVENTS_TOPIC, messages.MAP_EVENT,
                                                     namespace=WORKER_NAMESPACE)
            self._publisher.publish(map_event(map_info.name, revision))
        log.debug("announced revision %d of map %s", revision.id, map_info.name)

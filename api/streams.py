"""Options and bookkeeping of long-lived event streams."""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass, field

from api.errors import ApiConfigError
from shared.store import MapStore


@dataclass(slots=True)
class EventStreams:
    """How event streams poll the store, and how many are open in this process.

    Parameters
    ----------
    poll_s : float
        Seconds between looks at the revisions table while a stream is idle.
    heartbeat_s : float
        Seconds of silence after which a stream sends a comment line, so proxies keep it open.
    """

    poll_s: float = 1.0
    heartbeat_s: float = 15.0
    _open: int = field(default=0, init=False)
    _lock: threading.Lock = field(default_factory=threading.Lock, init=False)
    _newest: dict[int, tuple[float, int]] = field(default_factory=dict, init=False)
    """Map id -> (monotonic time it was read, the map's newest revision id then)."""
    _newest_lock: threading.Lock = field(default_factory=threading.Lock, init=False)

    def __post_init__(self) -> None:
        for name, value in (("event poll interval", self.poll_s), ("event heartbeat interval", self.heartbeat_s)):
            if not (math.isfinite(value) and value > 0):
                raise ApiConfigError(f"{name} must be a positive number of seconds, not {value}")

    @property
    def open(self) -> int:
        """Streams open right now."""
        with self._lock:
            return self._open

    def opened(self) -> None:
        with self._lock:
            self._open += 1

    def closed(self) -> None:
        with self._lock:
            self._open -= 1

    def newest(self, store: MapStore, map_id: int) -> int:
        """The map's newest revision id (0: none), read from the store at most once per ``poll_s`` however many
        streams ask: idle streams then cost one small query a poll between them, not one each. Blocking: call it
        from a worker thread."""
        with self._newest_lock:
            seen = self._newest.get(map_id)
            if seen is not None and time.monotonic() - seen[0] < self.poll_s:
                return seen[1]
            read_at = time.monotonic()
            latest = store.latest_revision(map_id)
            newest = 0 if latest is None else latest.id
            self._newest[map_id] = (read_at, newest)
            return newest

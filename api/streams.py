"""Options and bookkeeping of long-lived event streams."""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass, field

from api.errors import ApiConfigError


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

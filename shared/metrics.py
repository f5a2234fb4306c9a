"""Thread-safe event counters: every dropped, malformed or failed thing is counted here."""

from __future__ import annotations

import threading
from collections import Counter


class Counters:
    """Named monotonically increasing counters, safe to bump from zenoh callback threads."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._counts: Counter[str] = Counter()

    def incr(self, name: str, amount: int = 1) -> None:
        with self._lock:
            self._counts[name] += amount

    def get(self, name: str) -> int:
        with self._lock:
            return self._counts[name]

    def snapshot(self) -> dict[str, int]:
        with self._lock:
            return dict(sorted(self._counts.items()))

    def set(self, name: str, value: int) -> None:
        """Set a counter kept elsewhere (e.g. a stage's own tally) to its current value."""
        with self._lock:
            self._counts[name] = value

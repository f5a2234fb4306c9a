"""A small per-app cache of things derived from one revision of a map (decoded layers, bin indexes).

Entries are keyed by what they were built from, including the revision, so a new revision makes new
keys and old entries simply age out; nothing needs invalidating.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Callable, Hashable
from typing import Any, TypeVar, cast

T = TypeVar("T")


class RevisionCache:
    """A thread-safe LRU of at most ``size`` entries.

    ``get`` builds a missing entry once: concurrent callers asking for the same key wait for that build
    (single flight) instead of building it too; builds of different keys run at the same time.
    """

    def __init__(self, size: int = 16) -> None:
        if size < 1:
            raise ValueError(f"cache size must be at least 1, got {size}")
        self.size = size
        self._entries: OrderedDict[Hashable, Any] = OrderedDict()
        self._building: dict[Hashable, threading.Event] = {}
        self._lock = threading.Lock()

    def get(self, key: Hashable, build: Callable[[], T]) -> T:
        while True:
            with self._lock:
                if key in self._entries:
                    self._entries.move_to_end(key)
                    return cast(T, self._entries[key])
                running = self._building.get(key)
                if running is None:
                    done = self._building[key] = threading.Event()
                    break
            running.wait()  # then take its result, or build it ourselves if that build failed
        try:
            value = build()
            with self._lock:
                self._entries[key] = value
                self._entries.move_to_end(key)
                while len(self._entries) > self.size:
                    self._entries.popitem(last=False)
        finally:
            with self._lock:
                del self._building[key]
            done.set()
        return value


    def discard(self, key: Hashable) -> None:
        """Forget the entry of ``key``, if there is one (e.g. built for a revision whose write failed)."""
        with self._lock:
            self._entries.pop(key, None)

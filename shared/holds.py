"""A process-wide setting held for blocks of work that may overlap in several threads.

Some settings belong to the whole process (the cyclic garbage collector, OpenCV's thread pool), yet the work that
wants them changed runs in blocks, possibly several at once in different threads. A :class:`SharedHold` changes
the setting when the first block begins and puts it back as it was when the last one ends, however the blocks
overlap.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Generic, TypeVar

T = TypeVar("T")


class SharedHold(Generic[T]):
    """``begin()`` when the first of overlapping blocks starts (it returns what ``end`` needs to put the setting
    back), ``end(saved)`` when the last of them ends."""

    def __init__(self, begin: Callable[[], T], end: Callable[[T], None]) -> None:
        self._begin, self._end = begin, end
        self._lock = threading.Lock()
        self._count = 0
        self._saved: list[T] = []  # what the first block's begin returned, while blocks run

    @contextmanager
    def held(self) -> Iterator[None]:
        """Run the block with the setting held (see the class docstring)."""
        with self._lock:
            if self._count == 0:
                self._saved = [self._begin()]
            self._count += 1
        try:
            yield
        finally:
            with self._lock:
                self._count -= 1
                if self._count == 0:
                    self._end(self._saved.pop())

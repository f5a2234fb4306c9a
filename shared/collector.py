"""CPython's cyclic garbage collector held off while large work runs, for the whole process.

Large work that builds many objects (a first decomposition, which imports its step libraries, or a WMS import of
a million objects) sets off full collections, each of which walks every object of the process with the GIL held:
~0.1 s in a process's first decomposition, which the work does not need (it frees its arrays by reference counting
and leaves no large reference cycles behind). :func:`collector_held` holds the collector off for a block; objects
are still freed as soon as nothing refers to them, only reference cycles wait for the collector, which runs as usual
again afterwards. Blocks in several threads overlap safely: the collector is off from the first of them to the end
of the last, and back as it was before the first (a collector switched off by someone else stays off).
"""

from __future__ import annotations

import gc
import threading
from collections.abc import Iterator
from contextlib import contextmanager


class _Holds:
    """How many blocks hold the collector off now, and whether it was on when the first began."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._count = 0
        self._resume = False

    def hold(self) -> None:
        with self._lock:
            if self._count == 0:
                self._resume = gc.isenabled()
                gc.disable()
            self._count += 1

    def release(self) -> None:
        with self._lock:
            self._count -= 1
            if self._count == 0 and self._resume:
                gc.enable()


_HOLDS = _Holds()


@contextmanager
def collector_held() -> Iterator[None]:
    """Run the block with the cyclic garbage collector off (see the module docstring); overlapping blocks, in any
    threads, share one hold, which ends with the last of them."""
    _HOLDS.hold()
    try:
        yield
    finally:
        _HOLDS.release()

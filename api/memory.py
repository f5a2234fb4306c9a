"""Giving memory freed after a large request back to the operating system.

glibc's allocator keeps freed memory of a thread's arena for reuse rather than returning it, so a process that
once parsed a 200 000-bin WMS list keeps the hundreds of MB that took although nothing uses them any more.
``malloc_trim`` returns the free pages of every arena (on glibc; elsewhere this does nothing).
"""

from __future__ import annotations

import ctypes
import gc
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from functools import cache


@cache
def _malloc_trim() -> ctypes._NamedFuncPointer | None:
    """glibc's ``malloc_trim`` from the symbols already loaded in this process, or None elsewhere."""
    try:
        return getattr(ctypes.CDLL(None), "malloc_trim", None)
    except OSError:
        return None


def return_freed_memory() -> None:
    """Return freed heap memory to the operating system where the C library can (glibc ``malloc_trim(0)``)."""
    trim = _malloc_trim()
    if trim is not None:
        trim(0)



class _CollectorPause:
    """The cyclic collector held off while any of several threads asks it to be (see :func:`cyclic_gc_paused`)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._holders = 0  # blocks inside cyclic_gc_paused now
        self._resume = False  # whether the collector was on when the pause began

    def hold(self) -> None:
        with self._lock:
            if self._holders == 0:
                self._resume = gc.isenabled()
                gc.disable()
            self._holders += 1

    def release(self) -> None:
        with self._lock:
            self._holders -= 1
            if self._holders == 0 and self._resume:
                gc.enable()


_PAUSE = _CollectorPause()


@contextmanager
def cyclic_gc_paused() -> Iterator[None]:
    """Hold off CPython's cyclic garbage collector while the block runs (in any thread; overlapping blocks share
    one pause, which ends with the last of them).

    A large request builds hundreds of thousands of objects that live until it ends; every quarter more of them
    sets off a full collection, which walks the whole heap of the process while holding the GIL (0.1 to 0.3 s
    each for a 200 000-bin WMS import in the API process), so every other thread, the event loop answering reads
    included, stalls meanwhile. Objects are still freed as soon as nothing refers to them; only reference
    cycles wait for the collector, which runs as usual again afterwards.
    """
    _PAUSE.hold()
    try:
        yield
    finally:
        _PAUSE.release()

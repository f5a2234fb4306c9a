"""Heavy work in a worker thread of the API process without stalling the event loop that answers reads.

A thread of the same process competes with the event loop for the GIL. Two things of CPython's let it keep the
GIL for long while doing large work (a 200 000-bin WMS import builds about a million objects):

* the cyclic garbage collector: every quarter more long-lived objects sets off a full collection, which walks
  the whole heap of the process with the GIL held (0.1 to 0.3 s each, nine of them in one such import);
* the switch interval: a thread that waits for the GIL gets it only after the holder has run for 5 ms, so a
  read, which gives the GIL up and takes it back several times (socket, database), waits that long each time.

:func:`background_work` holds the collector off (:func:`shared.collector.collector_held`, shared with the other
work that holds it, such as a decomposition) and hands the GIL over every 1 ms while any such work runs.
Objects are still freed as soon as nothing refers to them; only reference cycles wait for the collector,
which runs as usual again afterwards.
"""

from __future__ import annotations

import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager

from shared.collector import collector_held

SWITCH_INTERVAL_S = 0.001
"""The GIL's switch interval while heavy work runs (CPython's default is 0.005 s)."""


class _Holders:
    """The switch interval set for heavy work while any thread asks for it (see :func:`background_work`)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._count = 0  # blocks inside background_work now
        self._switch_interval_s = 0.0  # the switch interval when the first of them began

    def hold(self) -> None:
        with self._lock:
            if self._count == 0:
                self._switch_interval_s = sys.getswitchinterval()
                sys.setswitchinterval(min(SWITCH_INTERVAL_S, self._switch_interval_s))
            self._count += 1

    def release(self) -> None:
        with self._lock:
            self._count -= 1
            if self._count == 0:
                sys.setswitchinterval(self._switch_interval_s)


_HOLDERS = _Holders()


@contextmanager
def background_work() -> Iterator[None]:
    """Run the block (large work in a worker thread) with the collector held off and the GIL handed over often;
    overlapping blocks, in any threads, share one such setting, which ends with the last of them."""
    with collector_held():
        _HOLDERS.hold()
        try:
            yield
        finally:
            _HOLDERS.release()

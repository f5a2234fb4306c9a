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
from contextlib import AbstractContextManager

from shared.holds import SharedHold


def _collector_off() -> bool:
    was_on = gc.isenabled()
    gc.disable()
    return was_on


def _collector_back(was_on: bool) -> None:
    if was_on:  # a collector switched off by someone else stays off
        gc.enable()


_COLLECTOR = SharedHold(_collector_off, _collector_back)


def collector_held() -> AbstractContextManager[None]:
    """Run the block with the cyclic garbage collector off (see the module docstring); overlapping blocks, in any
    threads, share one hold, which ends with the last of them."""
    return _COLLECTOR.held()

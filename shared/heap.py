"""glibc's allocator told to keep freed memory for the next large array rather than hand it back to the kernel.

The stages' array work allocates and frees a few hundred whole-map arrays a run (a decomposition of a 1,700 x 850 px
map: 1.4 to 12 MB each, of the 250 m x 90 m hall up to 72 MB). glibc's malloc, as it starts, maps a block over its
mmap threshold afresh from the kernel and hands free memory over its trim threshold at the heap's top back; both
thresholds grow with the blocks freed, but not far enough for work like this (and the mmap threshold never over 32
MiB): every new array then comes in fresh pages, each a page fault and a page the kernel zeroes (about 20,000 faults
and 0.1 to 0.15 s of system time a decomposition of ``map_with_clutter``, a tenth of its CPU).
:func:`keep_freed_memory` raises both thresholds once for the process: arrays up to the given size come from the heap
and reuse its pages, and up to that much freed memory stays with the process between runs instead of going back to
the kernel. Off glibc (musl, macOS) nothing changes.
"""

from __future__ import annotations

import ctypes
import platform

_M_TRIM_THRESHOLD = -1  # mallopt parameters, from glibc's malloc.h
_M_MMAP_THRESHOLD = -3


def keep_freed_memory(kept_bytes: int) -> bool:
    """Let blocks up to ``kept_bytes`` come from the heap and keep up to ``kept_bytes`` of freed heap (see the module
    docstring); returns whether the allocator took the setting (``False`` off glibc or with ``kept_bytes`` 0, which
    leaves the allocator's own thresholds)."""
    if kept_bytes <= 0 or platform.libc_ver()[0] != "glibc":
        return False
    mallopt = ctypes.CDLL(None).mallopt
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    return bool(mallopt(_M_MMAP_THRESHOLD, kept_bytes)) and bool(mallopt(_M_TRIM_THRESHOLD, kept_bytes))

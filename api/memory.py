"""Giving memory freed after a large request back to the operating system.

glibc's allocator keeps freed memory of a thread's arena for reuse rather than returning it, so a process that
once parsed a 200 000-bin WMS list keeps the hundreds of MB that took although nothing uses them any more.
``malloc_trim`` returns the free pages of every arena (on glibc; elsewhere this does nothing).
"""

from __future__ import annotations

import ctypes
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

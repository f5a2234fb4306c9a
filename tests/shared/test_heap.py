"""glibc's allocator keeping freed memory for the next large arrays (each case in a fresh interpreter: the setting is
process-wide)."""

from __future__ import annotations

import os
import platform
import subprocess
import sys

import pytest
from pydantic import ValidationError

from shared.heap import keep_freed_memory
from shared.settings import Settings

# Ten float images of the 250 m x 90 m hall (72 MB each, over glibc's own largest mmap threshold) made and freed in
# turn, as a decomposition's steps make them; prints whether the setting took and the page faults of the last five.
_ARRAYS = """
import resource, sys
import numpy as np
from shared.heap import keep_freed_memory
took = keep_freed_memory(int(sys.argv[1]))
faults = 0
for i in range(10):
    if i == 5:
        faults = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    a = np.ones((1800, 5000))
    del a
print(took, resource.getrusage(resource.RUSAGE_SELF).ru_minflt - faults)
"""

glibc = pytest.mark.skipif(platform.libc_ver()[0] != "glibc",
                           reason="the allocator setting is glibc's; this C library keeps its own")


def _faults(kept_bytes: int) -> tuple[bool, int]:
    out = subprocess.run([sys.executable, "-c", _ARRAYS, str(kept_bytes)], capture_output=True, text=True, check=True,
                         env={**os.environ, "PYTHONPATH": os.getcwd()}).stdout.split()
    return out[0] == "True", int(out[1])


@glibc
def test_a_large_array_made_again_reuses_the_pages_of_the_one_freed_before() -> None:
    took, kept = _faults(512 * 2**20)
    untouched, fresh = _faults(0)
    assert took and not untouched
    assert fresh > 0  # without the setting each array comes in pages the kernel faults in and zeroes afresh
    assert kept < fresh / 10


def test_zero_leaves_the_allocator_as_it_is() -> None:
    assert keep_freed_memory(0) is False


@pytest.mark.parametrize("kept", [-1, 2**31])
def test_a_kept_size_the_allocator_cannot_take_is_a_settings_error(kept: int) -> None:
    with pytest.raises(ValidationError, match="heap_kept_bytes"):
        Settings(heap_kept_bytes=kept)

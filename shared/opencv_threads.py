"""OpenCV's own thread pool held to one thread while work that runs its own threads beside it goes on.

OpenCV splits many calls (filters, morphology, distance transforms, connected components) over a pool of threads
sized by the cores the process may use. Work that already keeps the second core busy with a thread of its own (the
grid decomposition runs steps beside each other) gains nothing from that pool on a machine of two cores: the
pool's second thread competes with the work's own for the same core, and its hand-offs cost CPU (a decomposition
of ``map_with_clutter``: the same wall time, 14 % less CPU on one OpenCV thread). :func:`opencv_on_one_thread`
sets the pool to one thread for a block and back to what it was after; blocks in several threads overlap safely
(the pool is back when the last of them ends). The pool is the process's: other work running OpenCV meanwhile
runs it on one thread too.
"""

from __future__ import annotations

from contextlib import AbstractContextManager

import cv2

from shared.holds import SharedHold


def _one_thread() -> int:
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    return threads


_OPENCV = SharedHold(_one_thread, cv2.setNumThreads)


def opencv_on_one_thread() -> AbstractContextManager[None]:
    """Run the block with OpenCV's thread pool at one thread (see the module docstring); overlapping blocks, in
    any threads, share one hold, which ends with the last of them."""
    return _OPENCV.held()

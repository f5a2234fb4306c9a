"""OpenCV's thread pool held to one thread while work with threads of its own runs."""

from __future__ import annotations

from collections.abc import Iterator

import cv2
import pytest

from shared.opencv_threads import opencv_on_one_thread
from tests.helpers import after_first_of_overlapping_blocks


@pytest.fixture
def two_opencv_threads() -> Iterator[None]:
    before = cv2.getNumThreads()
    cv2.setNumThreads(2)
    yield
    cv2.setNumThreads(before)


def test_opencv_runs_on_one_thread_in_the_block_and_as_before_after_it(two_opencv_threads: None) -> None:
    with opencv_on_one_thread():
        assert cv2.getNumThreads() == 1
    assert cv2.getNumThreads() == 2


def test_opencv_stays_on_one_thread_until_the_last_of_overlapping_blocks_in_two_threads_ends(
    two_opencv_threads: None,
) -> None:
    assert after_first_of_overlapping_blocks(opencv_on_one_thread, cv2.getNumThreads) == 1
    assert cv2.getNumThreads() == 2


def test_opencv_threads_are_back_after_a_block_that_failed(two_opencv_threads: None) -> None:
    with pytest.raises(RuntimeError), opencv_on_one_thread():
        raise RuntimeError("the decomposition failed")
    assert cv2.getNumThreads() == 2

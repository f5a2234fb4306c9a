"""The cyclic garbage collector held off while large work runs."""

from __future__ import annotations

import gc
import threading
import weakref

import pytest

from shared.collector import collector_held
from tests.helpers import after_first_of_overlapping_blocks


def test_the_collector_is_off_in_the_block_and_on_again_after_it(collector_on: None) -> None:
    with collector_held():
        assert not gc.isenabled()
    assert gc.isenabled()


def test_the_collector_stays_off_until_the_last_of_overlapping_blocks_in_two_threads_ends(collector_on: None) -> None:
    assert not after_first_of_overlapping_blocks(collector_held, gc.isenabled)
    assert gc.isenabled()


def test_the_collector_is_back_after_a_block_that_failed(collector_on: None) -> None:
    with pytest.raises(RuntimeError), collector_held():
        raise RuntimeError("the decomposition failed")
    assert gc.isenabled()


def test_a_collector_switched_off_before_stays_off(collector_on: None) -> None:
    gc.disable()
    with collector_held():
        pass
    assert not gc.isenabled()


def test_cycles_made_in_the_block_are_collected_after_it(collector_on: None) -> None:
    class Node:
        def __init__(self) -> None:
            self.other: Node | None = None

    with collector_held():
        a, b = Node(), Node()
        a.other, b.other = b, a
        gone = threading.Event()
        weakref.finalize(a, gone.set)
        del a, b
        assert not gone.is_set()  # a cycle waits for the collector
    gc.collect()
    assert gone.is_set()

"""The API's memory handling around large requests."""

from __future__ import annotations

import gc
import threading
from collections.abc import Iterator

import pytest

from api.memory import cyclic_gc_paused


@pytest.fixture
def collector_on() -> Iterator[None]:
    was_enabled = gc.isenabled()
    gc.enable()
    yield
    if not was_enabled:
        gc.disable()


def test_the_collector_is_held_off_until_the_last_of_overlapping_pauses_ends(collector_on: None) -> None:
    first_in, second_in, first_out = threading.Event(), threading.Event(), threading.Event()
    seen: dict[str, bool] = {}

    def first() -> None:
        with cyclic_gc_paused():
            first_in.set()
            second_in.wait(10)
        first_out.set()

    thread = threading.Thread(target=first)
    thread.start()
    first_in.wait(10)
    with cyclic_gc_paused():
        second_in.set()
        first_out.wait(10)
        seen["after the first ended"] = gc.isenabled()
    thread.join()
    assert seen == {"after the first ended": False}
    assert gc.isenabled()


def test_the_collector_runs_again_after_a_pause_that_failed(collector_on: None) -> None:
    with pytest.raises(RuntimeError), cyclic_gc_paused():
        assert not gc.isenabled()
        raise RuntimeError("the import failed")
    assert gc.isenabled()


def test_a_collector_switched_off_before_stays_off(collector_on: None) -> None:
    gc.disable()
    with cyclic_gc_paused():
        pass
    assert not gc.isenabled()

"""Heavy work in a worker thread of the API: the interpreter settings it runs with."""

from __future__ import annotations

import gc
import sys

import pytest

from api.background import background_work
from shared.collector import collector_held
from tests.helpers import after_first_of_overlapping_blocks


def test_the_collector_is_held_off_until_the_last_of_overlapping_pauses_ends(collector_on: None) -> None:
    assert not after_first_of_overlapping_blocks(background_work, gc.isenabled)
    assert gc.isenabled()


def test_the_collector_and_the_switch_interval_are_back_after_work_that_failed(collector_on: None) -> None:
    switch_interval_s = sys.getswitchinterval()
    with pytest.raises(RuntimeError), background_work():
        assert not gc.isenabled()
        assert sys.getswitchinterval() < switch_interval_s
        raise RuntimeError("the import failed")
    assert gc.isenabled()
    assert sys.getswitchinterval() == switch_interval_s


def test_a_collector_switched_off_before_stays_off(collector_on: None) -> None:
    gc.disable()
    with background_work():
        pass
    assert not gc.isenabled()


def test_a_decomposition_that_ends_during_an_import_leaves_the_collector_off_until_the_import_ends(
    collector_on: None,
) -> None:
    with background_work():
        with collector_held():  # a decomposition in the same process
            pass
        assert not gc.isenabled()
    assert gc.isenabled()

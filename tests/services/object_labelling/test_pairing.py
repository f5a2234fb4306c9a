"""Colour/depth pairing by stamp."""

from __future__ import annotations

from services.object_labelling.pairing import FramePairer, Stream


def test_pairs_frames_of_equal_stamp_in_either_order() -> None:
    pairer: FramePairer[str] = FramePairer(tolerance_ns=0)
    assert not pairer.add("r1", Stream.DEPTH, 100, "d100")
    assert pairer.add("r1", Stream.COLOUR, 100, "c100")
    assert [(p.stamp_ns, p.colour, p.depth) for p in pairer.take()] == [(100, "c100", "d100")]
    assert pairer.take() == []


def test_frames_outside_the_tolerance_or_of_another_robot_do_not_pair() -> None:
    pairer: FramePairer[str] = FramePairer(tolerance_ns=5)
    pairer.add("r1", Stream.COLOUR, 100, "c")
    assert not pairer.add("r1", Stream.DEPTH, 110, "d")
    assert not pairer.add("r2", Stream.DEPTH, 100, "d")
    assert pairer.add("r1", Stream.DEPTH, 104, "d104")
    assert [p.namespace for p in pairer.take()] == ["r1"]


def test_only_the_newest_pair_per_robot_is_kept_and_older_ones_are_counted() -> None:
    pairer: FramePairer[int] = FramePairer(tolerance_ns=0)
    for stamp in (100, 200, 300):
        pairer.add("r1", Stream.COLOUR, stamp, stamp)
        pairer.add("r1", Stream.DEPTH, stamp, stamp)
    pairs = pairer.take()
    assert [p.stamp_ns for p in pairs] == [300] and pairer.skipped == 2

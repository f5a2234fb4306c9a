"""Regions joined where a floor plan's room parts say they are one room."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pytest

from services.grid_decomposition import DecompositionError, decompose, join_in_parts


def _pieces(*cuts: int) -> npt.NDArray[np.int32]:
    """A 40 x 90 room cut into regions 1, 2, ... at the given columns (as rays or clutter cut a real room)."""
    segments = np.zeros((40, 90), dtype=np.int32)
    edges = [0, *cuts, 90]
    for k, (c0, c1) in enumerate(zip(edges[:-1], edges[1:], strict=True), start=1):
        segments[:, c0:c1] = k
    return segments


def test_pieces_of_one_room_that_one_part_holds_become_one_region() -> None:
    segments = _pieces(30, 60)
    parts = np.ones(segments.shape, dtype=np.int32)
    joined = join_in_parts(segments, parts)
    assert len(np.unique(joined)) == 1 and joined[0, 0] > 0, "three pieces chain into one region"


def test_rooms_in_two_parts_stay_apart() -> None:
    segments = _pieces(45)
    parts = np.where(np.arange(90) < 45, 1, 2)[None, :].repeat(40, axis=0)
    assert np.array_equal(join_in_parts(segments, parts), segments)


def test_a_part_stretched_over_many_rooms_joins_none_of_them() -> None:
    # two small rooms in one corner of a part ten times their size: the plan did not see the walls there
    segments = np.zeros((100, 100), dtype=np.int32)
    segments[:20, :20] = 1
    segments[:20, 20:40] = 2
    parts = np.ones(segments.shape, dtype=np.int32)
    assert np.array_equal(join_in_parts(segments, parts), segments)


def test_regions_mostly_outside_the_part_are_not_joined() -> None:
    segments = _pieces(45)
    parts = np.zeros(segments.shape, dtype=np.int32)
    parts[:, 30:60] = 1  # a third of each piece only
    assert np.array_equal(join_in_parts(segments, parts), segments)


def test_racks_are_never_joined() -> None:
    segments = _pieces(45)
    keep = np.zeros(segments.shape, dtype=bool)
    keep[0, 60] = True
    joined = join_in_parts(segments, np.ones(segments.shape, dtype=np.int32), keep=keep)
    assert np.array_equal(joined, segments)


def test_parts_of_another_shape_raise() -> None:
    with pytest.raises(DecompositionError, match="floor-plan parts of shape"):
        join_in_parts(_pieces(45), np.ones((3, 3), dtype=np.int32))


def _two_rooms_and_a_door() -> npt.NDArray[np.int8]:
    """8 x 4 m at 5 cm: two rooms split by a wall with a 0.9 m door; unknown border."""
    occ = np.full((100, 180), -1, dtype=np.int8)
    occ[5:95, 5:175] = 100
    occ[8:92, 8:172] = 0
    occ[8:92, 88:91] = 100
    occ[40:58, 88:91] = 0
    return occ


def test_decompose_follows_the_floor_plan_where_it_says_one_room_and_stands_alone_without_it() -> None:
    occ = _two_rooms_and_a_door()
    alone = decompose(occ, resolution_m=0.05)
    assert len(alone.regions) == 2
    apart = np.where(np.arange(180) < 89, 1, 2)[None, :].repeat(100, axis=0) * (occ == 0)
    assert len(decompose(occ, resolution_m=0.05, floor_plan_parts=apart).regions) == 2
    one = (occ == 0).astype(np.int32)
    joined = decompose(occ, resolution_m=0.05, floor_plan_parts=one)
    assert len(joined.regions) == 1
    assert joined.segments[50, 40] == joined.segments[50, 140] > 0

"""The previous decomposition as a prior: regions over map that did not change keep their extent."""

from __future__ import annotations

import numpy as np
import pytest

from services.grid_decomposition import DecompositionError
from services.grid_decomposition.continuity import RegionPrior, keep_regions


def _grid(*blocks: tuple[int, slice, slice], shape: tuple[int, int] = (10, 20)) -> np.ndarray:
    out = np.zeros(shape, dtype=np.int32)
    for rid, rows, cols in blocks:
        out[rows, cols] = rid
    return out


def _same_partition(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether two region images cut the cells alike (ids aside)."""
    pairs = np.unique(np.stack([a.ravel(), b.ravel()]), axis=1)
    return bool(np.unique(pairs[0]).size == pairs.shape[1] == np.unique(pairs[1]).size)


def test_a_room_whose_map_did_not_change_is_not_merged_into_its_neighbour() -> None:
    before = _grid((4, slice(None), slice(0, 12)), (9, slice(None), slice(12, 20)))
    merged = _grid((1, slice(None), slice(0, 20)))
    out = keep_regions(merged, RegionPrior(before, np.ones(before.shape, dtype=bool)))
    assert _same_partition(out, before)


def test_where_the_map_changed_the_new_decomposition_decides() -> None:
    before = _grid((4, slice(None), slice(0, 12)), (9, slice(None), slice(12, 20)))
    merged = _grid((1, slice(None), slice(0, 20)))
    unchanged = np.ones(before.shape, dtype=bool)
    unchanged[:, 12:] = False  # the right room was seen anew: its border may go
    out = keep_regions(merged, RegionPrior(before, unchanged))
    assert _same_partition(out, merged)


def test_a_settled_region_grows_into_newly_seen_space_its_continuation_covers() -> None:
    before = _grid((4, slice(None), slice(0, 8)), (9, slice(None), slice(8, 12)), shape=(10, 20))
    unchanged = np.zeros(before.shape, dtype=bool)
    unchanged[:, :12] = True  # columns 12.. were unknown before
    # the new decomposition moves the border between the two rooms and grows the second one
    after = _grid((1, slice(None), slice(0, 6)), (2, slice(None), slice(6, 20)))
    out = keep_regions(after, RegionPrior(before, unchanged))
    assert _same_partition(out, _grid((1, slice(None), slice(0, 8)), (2, slice(None), slice(8, 20))))


def test_a_room_found_mostly_on_newly_seen_ground_stands_whole() -> None:
    before = _grid((4, slice(None), slice(0, 12)))  # a corridor, and rays through a door at its right end
    unchanged = np.zeros(before.shape, dtype=bool)
    unchanged[:, :12] = True  # columns 12.. were unknown before: the room behind the door
    # the new decomposition finds the room, a third of it on the rays the corridor held
    after = _grid((1, slice(None), slice(0, 8)), (2, slice(None), slice(8, 20)))
    out = keep_regions(after, RegionPrior(before, unchanged))
    assert _same_partition(out, after), "the corridor's old cells left inside the room would cut it in pieces"


def test_no_region_is_added_where_the_new_decomposition_has_none() -> None:
    before = _grid((4, slice(None), slice(0, 20)))
    after = _grid((1, slice(None), slice(0, 15)))  # the right end is a wall now
    unchanged = np.ones(before.shape, dtype=bool)
    out = keep_regions(after, RegionPrior(before, unchanged))
    assert np.array_equal(out > 0, after > 0)


def test_pieces_a_kept_region_cuts_off_join_a_neighbour() -> None:
    before = _grid((4, slice(None), slice(2, 10)), (9, slice(None), slice(10, 20)))
    unchanged = np.zeros(before.shape, dtype=bool)
    unchanged[:, :10] = True  # the right room was seen anew
    # a strip along the top, mostly over the kept room 4, crosses it: its 4-cell tip on the left is cut off
    after = _grid((1, slice(2, 10), slice(0, 10)), (2, slice(2, 10), slice(10, 20)), (3, slice(0, 2), slice(0, 14)))
    out = keep_regions(after, RegionPrior(before, unchanged), min_area_px=5)
    expected = _grid((1, slice(None), slice(0, 10)), (2, slice(2, 10), slice(10, 20)), (3, slice(0, 2), slice(10, 14)))
    assert _same_partition(out, expected)


def test_a_settled_region_left_a_few_cells_off_the_places_joins_its_neighbour() -> None:
    # region 9 of the previous step lies now mostly on a rack place found since (the prior leaves places out):
    # its 6 unchanged cells left of the place would be a region of their own
    before = _grid((4, slice(None), slice(0, 10)), (9, slice(0, 3), slice(10, 12)))
    unchanged = np.ones(before.shape, dtype=bool)
    unchanged[:, 12:] = False
    after = _grid((1, slice(None), slice(0, 12)), (2, slice(None), slice(12, 20)))
    out = keep_regions(after, RegionPrior(before, unchanged), min_area_px=10, apart=after == 2)
    assert _same_partition(out, after), "no region under the minimum area, and the place keeps its own cells"


DOOR_PX = 40  # the widest door, 2 m at 0.05 m a cell (``decompose`` passes ``door_max_width_m``)


def test_two_pieces_of_one_room_the_new_decomposition_joins_are_one_region() -> None:
    # a 4 m x 2 m room cut in two down its middle when it was seen in part: nothing but free floor between the
    # halves, a border 2 m long; the map did not change, and the new decomposition holds the room as one
    before = _grid((4, slice(None), slice(0, 40)), (9, slice(None), slice(40, 80)), shape=(40, 80))
    merged = _grid((1, slice(None), slice(0, 80)), shape=(40, 80))
    unchanged = np.ones(before.shape, dtype=bool)
    out = keep_regions(merged, RegionPrior(before, unchanged), join_min_border_px=DOOR_PX - 1)
    assert _same_partition(out, merged)
    # without the join (a border of 0 cells) the prior keeps the old cut
    assert _same_partition(keep_regions(merged, RegionPrior(before, unchanged)), before)


def test_two_offices_behind_a_door_stay_two_regions_when_the_new_decomposition_joins_them() -> None:
    # two 2 m x 3 m offices, the wall between them open by a 0.9 m door; the map did not change
    before = _grid((4, slice(None), slice(0, 40)), (9, slice(None), slice(41, 101)), shape=(60, 101))
    before[10:28, 40] = 4  # the doorway's floor
    merged = np.where(before > 0, 1, 0).astype(np.int32)
    out = keep_regions(merged, RegionPrior(before, np.ones(before.shape, dtype=bool)), join_min_border_px=DOOR_PX)
    assert _same_partition(out, before)


def test_a_room_open_wider_than_a_door_but_narrow_for_its_size_stays_apart() -> None:
    # a 6 m x 6 m room open to a 10 m x 8 m hall along 2.5 m of its side (wider than a door, under 0.6 of its
    # width)
    before = _grid((4, slice(0, 160), slice(None)), (9, slice(161, 281), slice(0, 120)), shape=(281, 200))
    before[160, 40:90] = 4  # the opening's floor
    merged = np.where(before > 0, 1, 0).astype(np.int32)
    out = keep_regions(merged, RegionPrior(before, np.ones(before.shape, dtype=bool)), join_min_border_px=DOOR_PX)
    assert _same_partition(out, before)


def test_a_room_parted_at_its_door_takes_the_floor_inside_the_door_the_corridor_held() -> None:
    # a corridor (rows 0..9) and a room behind a 1 m door; when the room was seen in part, the corridor's region
    # took the floor just inside the door (rows 10..14 of the door's columns) and the room's region began beyond it
    before = _grid((4, slice(0, 10), slice(None)), (4, slice(10, 15), slice(20, 40)), (9, slice(15, 40), slice(10, 50)),
                   (9, slice(10, 15), slice(10, 20)), (9, slice(10, 15), slice(40, 50)), shape=(40, 60))
    unchanged = np.ones(before.shape, dtype=bool)
    # now the fan rule parts the whole room from the corridor at the door's line
    after = _grid((1, slice(0, 10), slice(None)), (2, slice(10, 40), slice(10, 50)), shape=(40, 60))
    prior = RegionPrior(before, unchanged)
    sliver = 5 * 20  # the floor inside the door, 0.25 m^2 at 0.05 m a cell: no room of its own
    out = keep_regions(after, prior, door_rooms=after == 2, sliver_max_px=sliver + 1)
    assert _same_partition(out, after)
    # a room found otherwise (no door room), or floor as large as a room, stays where the prior had it
    assert _same_partition(keep_regions(after, prior, sliver_max_px=sliver + 1), before)
    assert _same_partition(keep_regions(after, prior, door_rooms=after == 2, sliver_max_px=sliver), before)


def test_a_room_parted_at_its_door_does_not_take_a_room_the_prior_kept_inside_it() -> None:
    # a closet (region 7) beside the room's door that no new region continues: it is a region of its own still
    before = _grid((4, slice(0, 10), slice(None)), (9, slice(10, 40), slice(10, 50)), (7, slice(10, 15), slice(40, 50)),
                   shape=(40, 60))
    after = _grid((1, slice(0, 10), slice(None)), (2, slice(10, 40), slice(10, 50)), shape=(40, 60))
    out = keep_regions(after, RegionPrior(before, np.ones(before.shape, dtype=bool)), door_rooms=after == 2,
                       sliver_max_px=600)
    assert _same_partition(out, before)


def test_places_found_anew_at_every_step_do_not_join_as_first_seen() -> None:
    before = _grid((4, slice(0, 10), slice(None)), shape=(40, 60))
    after = _grid((1, slice(0, 10), slice(None)), (2, slice(10, 40), slice(0, 30)), (3, slice(10, 40), slice(30, 60)),
                  shape=(40, 60))
    out = keep_regions(after, RegionPrior(before, np.ones(before.shape, dtype=bool)), first_seen_max_px=1800,
                       first_seen_min_border_px=30, apart=after == 3)
    assert _same_partition(out, after)


def test_a_prior_on_another_grid_is_refused() -> None:
    with pytest.raises(DecompositionError, match="prior"):
        keep_regions(np.zeros((3, 3), np.int32), RegionPrior(np.zeros((3, 4), np.int32), np.ones((3, 4), bool)))
    with pytest.raises(DecompositionError, match="max_changed_share"):
        keep_regions(np.zeros((3, 3), np.int32), RegionPrior(np.zeros((3, 3), np.int32), np.ones((3, 3), bool)),
                     max_changed_share=2.0)


def _first_seen(after: np.ndarray, max_px: int, min_border_px: int, min_px: int) -> np.ndarray:
    """``after`` kept over a prior that held columns 0..5 only (a corridor); columns 6.. are seen for the first time."""
    before = _grid((4, slice(None), slice(0, 6)))
    unchanged = np.zeros(before.shape, dtype=bool)
    unchanged[:, :6] = True
    return keep_regions(after, RegionPrior(before, unchanged), first_seen_max_px=max_px,
                        first_seen_min_border_px=min_border_px, first_seen_min_px=min_px)


_CUT_ROOM = _grid((1, slice(None), slice(0, 6)), (2, slice(None), slice(6, 13)), (3, slice(None), slice(13, 20)))


def test_a_room_seen_for_the_first_time_and_cut_in_two_is_one_region() -> None:
    out = _first_seen(_CUT_ROOM, 200, 5, 30)
    assert _same_partition(out, _grid((1, slice(None), slice(0, 6)), (2, slice(None), slice(6, 20))))


@pytest.mark.parametrize(
    ("max_px", "min_border_px", "min_px"),
    [
        (0, 5, 1),  # off
        (100, 5, 1),  # together larger than a room
        (200, 11, 1),  # a border shorter than asked
        (200, 5, 80),  # a piece too small
    ],
)
def test_first_seen_pieces_stay_apart_outside_the_settings(max_px: int, min_border_px: int, min_px: int) -> None:
    assert _same_partition(_first_seen(_CUT_ROOM, max_px, min_border_px, min_px), _CUT_ROOM)


def test_a_region_mostly_seen_before_does_not_join_a_first_seen_one() -> None:
    before = _grid((4, slice(None), slice(0, 13)))
    unchanged = np.zeros(before.shape, dtype=bool)
    unchanged[:, :13] = True
    after = _grid((2, slice(None), slice(0, 13)), (3, slice(None), slice(13, 20)))
    out = keep_regions(after, RegionPrior(before, unchanged), first_seen_max_px=200, first_seen_min_border_px=5)
    assert _same_partition(out, after)

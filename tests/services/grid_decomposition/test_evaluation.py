"""The ipa room-segmentation protocol."""

from __future__ import annotations

import numpy as np
import pytest

from services.grid_decomposition import DecompositionError, ground_truth_rooms, ipa_scores
from services.grid_decomposition.evaluation import (
    align_offset,
    colour_rooms,
    id_stability,
    matches,
    on_free,
    shift_into,
)
from services.grid_decomposition.keys import stable_ids


def _two_rooms() -> np.ndarray:
    gt = np.zeros((40, 81), dtype=np.uint8)
    gt[5:35, 5:40] = 255
    gt[5:35, 41:76] = 255
    return gt


def test_perfect_segmentation_scores_one() -> None:
    rooms = ground_truth_rooms(_two_rooms())
    s = ipa_scores(rooms * 7, rooms)
    assert (s.recall, s.precision, s.mean_iou, s.n_rooms, s.n_segments) == (1.0, 1.0, 1.0, 2, 2)


def test_merging_two_rooms_keeps_recall_and_halves_iou() -> None:
    rooms = ground_truth_rooms(_two_rooms())
    s = ipa_scores((rooms > 0).astype(np.int32), rooms)
    assert s.recall == 1.0 and s.precision == pytest.approx(0.5) and s.mean_iou == pytest.approx(0.5)


def test_small_segments_and_rooms_are_dropped() -> None:
    rooms = ground_truth_rooms(_two_rooms())
    seg = rooms.copy()
    seg[6:8, 6:8] = 9  # 4 px segment: ignored
    assert ipa_scores(seg, rooms).n_segments == 2


def test_matches_say_which_room_a_mixed_segment_spoils_and_keep_segment_ids() -> None:
    rooms = ground_truth_rooms(_two_rooms())  # two rooms of 30 x 35 px
    seg = np.where(rooms > 0, 42, 0).astype(np.int32)  # one segment over both rooms...
    seg[5:35, 60:76] = 7  # ...but for the right part of the right room
    seg[6:8, 6:8] = 9  # 4 px: not scored
    room_rows, segment_rows = matches(seg, rooms)
    by_room = {r.room: r for r in room_rows}
    assert by_room[1].segment == 42 and by_room[1].recall == pytest.approx(1046 / 1050)
    assert by_room[1].iou == pytest.approx(1046 / 1620)  # the segment also holds 570 px of room 2
    assert by_room[2].segment == 42 and by_room[2].recall == pytest.approx(19 / 35)
    assert by_room[2].iou == pytest.approx(16 / 35)  # its best IoU is segment 7's
    purity = {g.segment: (g.room, g.purity) for g in segment_rows}
    assert set(purity) == {7, 42}
    assert purity[7] == (2, 1.0) and purity[42][0] == 1 and purity[42][1] == pytest.approx(1046 / 1616)
    s = ipa_scores(seg, rooms)  # the terms the scores average
    assert s.recall == pytest.approx(np.mean([r.recall for r in room_rows]))
    assert s.precision == pytest.approx(np.mean([g.purity for g in segment_rows]))
    assert s.mean_iou == pytest.approx(np.mean([r.iou for r in room_rows]))


def test_shape_mismatch_is_an_error() -> None:
    with pytest.raises(DecompositionError, match="shape"):
        ipa_scores(np.zeros((3, 3), np.int32), ground_truth_rooms(_two_rooms()))


def test_ground_truth_rooms_take_only_grey_above_250_like_ipa() -> None:
    gt = _two_rooms()
    gt[5:35, 41:76] = 250  # ipa thresholds at 250: this room is not above it
    assert int(ground_truth_rooms(gt).max()) == 1


def test_segment_pixels_on_walls_lower_precision() -> None:
    rooms = ground_truth_rooms(_two_rooms())
    seg = rooms.copy()
    seg[5:35, 40] = 1  # the wall column between the rooms labelled as room 1
    s = ipa_scores(seg, rooms)
    assert s.recall == 1.0
    assert s.precision == pytest.approx((1.0 + 35 / 36) / 2)


def test_colour_rooms_make_one_room_per_colour_and_skip_background() -> None:
    rgb = np.zeros((20, 40, 3), dtype=np.uint8)
    rgb[:, :15] = (200, 10, 10)
    rgb[:, 25:] = (200, 10, 10)  # the same colour apart: still one room
    rgb[:, 15:25] = (255, 255, 255)
    rooms = colour_rooms(rgb)
    assert int(rooms.max()) == 2 and rooms[0, 0] == rooms[0, 30] != rooms[0, 20]
    no_white = colour_rooms(rgb, background=((0, 0, 0), (255, 255, 255)))
    assert int(no_white.max()) == 1 and no_white[0, 20] == 0


def test_scores_on_free_pixels_ignore_segments_off_the_map() -> None:
    rooms = ground_truth_rooms(_two_rooms())
    free = rooms > 0
    seg = (rooms > 0).astype(np.int32) * 3 + rooms
    seg[0:5, :] = 9  # a segment outside the rooms, off the free space
    s = ipa_scores(on_free(seg, free), on_free(rooms, free))
    assert (s.recall, s.precision, s.n_segments) == (1.0, 1.0, 2)


def test_a_room_with_a_few_free_pixels_is_not_scored() -> None:
    rgb = np.zeros((20, 40, 3), dtype=np.uint8)
    rgb[:, :20] = (200, 10, 10)
    rgb[:, 20:] = (10, 200, 10)  # a second room the map saw only a sliver of
    free = np.zeros((20, 40), dtype=np.bool_)
    free[:, :20] = True
    free[0, 20] = True
    rooms = on_free(colour_rooms(rgb), free)
    s = ipa_scores(on_free(np.ones((20, 40), np.int32), free), rooms)
    assert (s.recall, s.n_rooms) == (1.0, 1)
    room_rows, _ = matches(on_free(np.ones((20, 40), np.int32), free), rooms)
    assert [r.room for r in room_rows] == [int(rooms[0, 0])]


def test_align_offset_finds_where_a_map_grew() -> None:
    rng = np.random.default_rng(0)
    after = rng.random((60, 90)) > 0.5
    before = after[7:50, 20:80]
    assert align_offset(before, after) == (7, 20)
    moved = shift_into(before.astype(np.int32), (7, 20), after.shape)
    assert np.array_equal(moved[7:50, 20:80] > 0, before)


def test_carried_ids_survive_and_split_rooms_lose_theirs() -> None:
    before = np.zeros((30, 60), dtype=np.int32)
    before[:, :30], before[:, 30:] = 4, 7
    after = np.zeros_like(before)
    after[:, :30] = 1  # room 4 again, under another id
    after[:15, 30:], after[15:, 30:] = 2, 3  # room 7 split in two halves
    rooms = ground_truth_rooms(np.full((30, 60), 255, np.uint8))
    carried = stable_ids(before, after, next_id=8).lut[after]
    assert set(np.unique(carried[:, :30])) == {4}
    kept = id_stability(before, carried, rooms)
    assert (kept.kept, kept.matched) == (1, 2)
    assert id_stability(before, before, rooms).share == 1.0

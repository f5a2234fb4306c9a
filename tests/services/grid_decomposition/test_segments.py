"""Segment clean-up: slivers join rooms, open borders join, cuts split, enclosed pieces keep their id."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from services.grid_decomposition.regions import warehouse_floors
from services.grid_decomposition.segments import (
    border_closure,
    fill_bytes_from_neighbours,
    fill_from_neighbours,
    join_small_regions,
    merge_open_segments,
    merge_passages,
    merge_small_segments,
    renumber,
    renumber_mapped,
    same_value_pieces,
    segment_image,
    split_along,
)


def _room_sliver_room() -> np.ndarray:
    """Two rooms with a 3 px sliver (a door strip) between them that touches the left room longer."""
    seg = np.zeros((40, 60), dtype=np.int32)
    seg[0:40, 0:28] = 1
    seg[5:35, 28:31] = 2
    seg[0:40, 31:60] = 3
    seg[0:5, 28:31] = 1
    seg[35:40, 28:31] = 1
    return seg


def test_merge_small_segments_joins_a_sliver_to_the_room_it_shares_most_border_with() -> None:
    out = merge_small_segments(_room_sliver_room(), min_area_px=200)
    assert out[20, 29] == out[20, 10] != out[20, 50]
    assert sorted(np.unique(out).tolist()) == [1, 2]


def test_merge_small_segments_keeps_an_enclosed_piece_and_fixed_segments() -> None:
    seg = _room_sliver_room()
    seg[20, 45] = 0
    seg[15:18, 40:43] = 0
    closet = np.zeros_like(seg)
    closet[15:18, 40:43] = 4
    seg = np.where(closet > 0, 4, seg)
    seg[14, 39:44] = 0
    seg[18, 39:44] = 0
    seg[14:19, 39] = 0
    seg[14:19, 43] = 0  # the closet is walled in
    out = merge_small_segments(seg, min_area_px=200)
    assert out[16, 41] > 0 and out[16, 41] not in (out[20, 10], out[20, 50])
    fixed = np.zeros(5, dtype=bool)
    fixed[2] = True
    kept = merge_small_segments(_room_sliver_room(), min_area_px=200, fixed=fixed)
    assert sorted(np.unique(kept).tolist()) == [1, 2, 3]


def test_a_lone_dropped_strip_takes_the_slivers_merged_into_it_along() -> None:
    seg = _room_sliver_room()
    seg[:, 28:31] = 0  # the rooms apart
    seg[5:6, 45:60] = 0
    seg[2:5, 45:60] = 4  # a lone strip in the right room's corner, walled off ...
    seg[2:5, 44] = 5  # ... with a sliver at its end
    seg[1, 43:61] = 0
    seg[1:6, 43] = 0
    seg[5, 43:61] = 0
    lone = np.zeros(6, dtype=bool)
    lone[4] = True
    absorb = np.zeros(6, dtype=bool)
    absorb[4] = True
    out = merge_small_segments(seg, min_area_px=20, absorb=absorb, lone_dropped=lone)
    assert not out[2:5, 44:60].any()  # the strip and its sliver: no segment
    assert out[20, 10] > 0 and out[20, 50] > 0 and sorted(np.unique(out).tolist()) == [0, 1, 2]


def test_merge_open_segments_joins_open_borders_only() -> None:
    seg = np.zeros((20, 40), dtype=np.int32)
    seg[:, :20] = 1
    seg[:, 20:] = 2
    closed = np.zeros(seg.shape, dtype=bool)
    assert len(np.unique(merge_open_segments(seg, closed))) == 1
    closed[:, 19] = True  # a closed doorway along their whole border
    assert len(np.unique(merge_open_segments(seg, closed))) == 2
    pairs, total, shut = border_closure(seg, closed)
    assert pairs.tolist() == [[1, 2]] and total.tolist() == [20] and shut.tolist() == [20]


def test_split_along_cuts_a_segment_and_gives_the_cut_to_a_side() -> None:
    seg = np.ones((20, 40), dtype=np.int32)
    barrier = np.zeros(seg.shape, dtype=bool)
    barrier[:, 20] = True
    out = split_along(seg, barrier)
    assert out[5, 5] != out[5, 35]
    assert (out > 0).all()
    barrier[:10, 20] = False  # a cut that does not close: nothing to split
    assert len(np.unique(split_along(seg, barrier))) == 1


def test_segment_image_keeps_a_small_enclosed_piece_but_not_a_speck() -> None:
    free = np.zeros((30, 40), dtype=bool)
    free[2:20, 2:38] = True
    free[23:28, 22:28] = True  # a 30 px pocket, walled off
    free[25:27, 32:34] = True  # a 4 px speck, walled off
    face = np.where(free, 1, 0).astype(np.int32)
    face[23:28, 22:28] = 2
    face[25:27, 32:34] = 3
    out = segment_image(face, np.array([0, 1, 2, 3]), free, min_area_px=50)
    assert out[25, 25] > 0 and out[25, 25] != out[10, 10]
    assert out[25, 32] == 0


def test_warehouse_floor_needs_many_storage_faces() -> None:
    component = np.array([0] + [1] * 40 + [2] * 40)
    free_px = np.full(81, 100)
    label = np.full(81, 4)  # rooms
    label[1:21] = 3  # half the faces of component 1 are pallet cells
    label[41:45] = 3  # a few storage-like faces between furniture in component 2
    floors = warehouse_floors(component, free_px, label)
    assert floors.tolist() == [False, True, False]


def _pieces_one_value_at_a_time(seg: np.ndarray) -> np.ndarray:
    """4-connected pieces of each value, numbered by their first pixel in raster order."""
    out = np.zeros(seg.shape, dtype=np.int64)
    offset = 0
    for v in np.unique(seg[seg > 0]):
        n, parts = cv2.connectedComponents((seg == v).astype(np.uint8), connectivity=4)
        out[parts > 0] = parts[parts > 0] + offset
        offset += n - 1
    first = np.full(offset + 1, out.size)
    np.minimum.at(first, out.ravel(), np.arange(out.size))
    rank = np.zeros(offset + 1, dtype=np.int64)
    rank[np.argsort(first[1:]) + 1] = np.arange(1, offset + 1)
    return rank[out]


@pytest.mark.parametrize("seed", range(8))
def test_same_value_pieces_are_the_pieces_of_each_value_in_scan_order(seed: int) -> None:
    rng = np.random.default_rng(seed)
    h, w = (int(v) for v in rng.integers(1, 30, 2))
    seg = np.repeat(np.repeat(rng.integers(0, 4, (h, w)), 2, axis=0), 2, axis=1).astype(np.int32)
    pieces, n = same_value_pieces(seg)
    expected = _pieces_one_value_at_a_time(seg)
    assert n == int(expected.max())
    assert np.array_equal(pieces, expected)


def _grown_step_by_step(seg: np.ndarray, target: np.ndarray, steps: int) -> np.ndarray:
    """Each step every hole next to a labelled pixel takes the largest id among its 8-neighbours."""
    out = seg.copy()
    hole = target & (out == 0)
    for _ in range(steps):
        grown = cv2.dilate(
            out.astype(np.float64), np.ones((3, 3), np.uint8), borderType=cv2.BORDER_CONSTANT, borderValue=0
        )
        take = hole & (grown > 0)
        if not take.any():
            break
        out[take] = grown[take].astype(np.int32)
        hole &= ~take
    return out


@pytest.mark.parametrize("top", [200, 3000, 70000, 2**25])
@pytest.mark.parametrize("steps", [1, 2, 3, 200])
def test_fill_from_neighbours_grows_a_step_at_a_time_through_lines_and_wide_gaps(top: int, steps: int) -> None:
    # faces between one-pixel lines (filled in one step), a band of lines side by side and an unlabelled
    # block (filled over several steps), and a hole with no labelled pixel near it
    rng = np.random.default_rng(top + steps)
    seg = np.repeat(np.repeat(rng.integers(1, top, (12, 14)), 6, axis=0), 6, axis=1).astype(np.int32)
    seg[::6] = 0
    seg[:, ::6] = 0
    seg[20:27] = 0
    seg[40:55, 30:50] = 0
    target = seg == 0
    target[:, 80:] = False
    target[60:, :] = False
    seg[60:, :] = 0
    target[66:70, 10:20] = True
    filled = fill_from_neighbours(seg, target, max_iterations=steps)
    assert np.array_equal(filled, _grown_step_by_step(seg, target, steps))
    # in place when allowed (an image of the caller's own), else in a copy: the same ids either way
    own = seg.copy()
    assert np.array_equal(fill_from_neighbours(own, target, max_iterations=steps, overwrite=True), filled)
    strided = np.asfortranarray(seg)
    assert np.array_equal(fill_from_neighbours(strided, target, max_iterations=steps, overwrite=True), filled)
    assert np.array_equal(strided, seg)
    if top <= 256:  # ids below 256 the same in bytes
        as_bytes = fill_bytes_from_neighbours(seg.astype(np.uint8), target, max_iterations=steps)
        assert as_bytes.dtype == np.uint8 and np.array_equal(as_bytes, filled)
    # the same inside a labelled margin: the holes two pixels or more from the image's edge (no frame is needed)
    for margin in (2, 3):
        inner = np.pad(seg, margin, constant_values=1)
        inside = np.pad(target, margin, constant_values=False)
        filled = fill_from_neighbours(inner, inside, max_iterations=steps)
        assert filled.dtype == np.int32 and np.array_equal(filled, _grown_step_by_step(inner, inside, steps))
        if top <= 256:
            as_bytes = fill_bytes_from_neighbours(inner.astype(np.uint8), inside, max_iterations=steps)
            assert as_bytes.dtype == np.uint8 and np.array_equal(as_bytes, filled)


@pytest.mark.parametrize("holes", ["box", "spread", "none"])
def test_fill_from_neighbours_in_the_callers_own_image_fills_that_image_alike(holes: str) -> None:
    # a small box of holes (framed), holes over most of the image two pixels in (filled where they lie), none
    rng = np.random.default_rng(1)
    seg = np.repeat(np.repeat(rng.integers(1, 50, (8, 9)), 5, axis=0), 5, axis=1).astype(np.int32)
    if holes == "box":
        seg[10:16, 3:30] = 0
    elif holes == "spread":
        seg[2:-2:5, 2:-2] = 0
        seg[2:-2, 2:-2:7] = 0
    target = seg == 0
    expected = fill_from_neighbours(seg, target)
    assert expected is not seg
    own = seg.copy()
    filled = fill_from_neighbours(own, target, overwrite=True)
    assert filled is own and np.array_equal(filled, expected)
    # an image not in C order is not filled where it lies: a C-ordered copy is, and the image is left as it was
    columns = np.asfortranarray(seg)
    filled = fill_from_neighbours(columns, target, overwrite=True)
    assert filled is not columns and np.array_equal(filled, expected)
    assert np.array_equal(columns, seg)


def test_a_strip_between_two_cuts_joins_a_room_and_a_small_room_behind_a_door_stays() -> None:
    # 0.05 m cells: a 4 m wide room cut twice across 0.8 m apart (a strip of 3.2 m²: no room), the lower cut 0.2 m
    # shorter, and a 1.5 m x 1.5 m store room behind a door off the upper part (borders one region only)
    seg = np.zeros((200, 140), dtype=np.int32)
    seg[0:90, 0:80] = 1
    seg[90:106, 0:80] = 2
    seg[106:200, 0:80] = 3
    seg[106:200, 76:80] = 0  # the lower part a little narrower: the strip borders the upper part most
    seg[20:50, 80:110] = 4
    seg[20:30, 80] = 1  # the store room's door wall ...
    seg[40:50, 80] = 1  # ... around a 0.5 m door
    out = merge_passages(seg, max_area_px=1500, max_width_px=20, min_border_px=10)
    assert out[95, 40] == out[50, 40] != out[150, 40]  # the strip is part of the upper room
    assert out[35, 95] not in (out[50, 40], out[150, 40])  # the store room stays a region
    assert sorted(np.unique(out).tolist()) == [0, 1, 2, 3]
    fixed = np.zeros(5, dtype=bool)
    fixed[3] = True  # beside a warehouse floor's region nothing joins
    kept = merge_passages(seg, max_area_px=1500, max_width_px=20, min_border_px=10, fixed=fixed)
    assert len(np.unique(kept)) == 5


def test_a_piece_of_a_corridor_between_two_cuts_stays_between_its_rooms() -> None:
    # a 1 m wide, 3 m long corridor piece (walls along its long sides) between two rooms: it may be a room of its own
    seg = np.zeros((120, 200), dtype=np.int32)
    seg[0:120, 0:70] = 1
    seg[50:70, 70:130] = 2
    seg[0:120, 130:200] = 3
    out = merge_passages(seg, max_area_px=1500, max_width_px=20, min_border_px=10)
    assert sorted(np.unique(out).tolist()) == [0, 1, 2, 3]


@pytest.mark.parametrize("seed", range(4))
def test_renumber_mapped_is_the_renumbered_lookup(seed: int) -> None:
    """Ids joined by a table (some to 0, some to one another, gaps left) then numbered 1..N: as in two steps."""
    rng = np.random.default_rng(seed)
    h, w = (int(v) for v in rng.integers(1, 40, 2))
    seg = np.repeat(rng.integers(0, 12, (h, (w + 2) // 3)), 3, axis=1)[:, :w].astype(np.int32)
    for lut in (np.arange(12, dtype=np.int32), rng.integers(0, 15, 12).astype(np.int32)):
        lut[0] = 0
        expected = renumber(np.take(lut, seg))
        got = renumber_mapped(lut, seg)
        assert got.dtype == np.int32 and got.shape == seg.shape and np.array_equal(got, expected)
    empty = np.zeros((0, 3), dtype=np.int32)
    assert renumber_mapped(np.arange(4, dtype=np.int32), empty).shape == (0, 3)


def test_join_small_regions_gives_a_small_region_to_its_longest_border_but_never_to_a_place() -> None:
    seg = np.ones((10, 20), dtype=np.int32)  # a room
    seg[:, 12:] = seg[0, 8:12] = seg[5, 10:12] = 3  # a place (a bin) round three sides of region 2
    seg[1:5, 10:12] = 2  # 8 cells: 8 cells of border with the place, 4 with the room
    out = join_small_regions(seg, min_area_px=10, apart=seg == 3)
    assert np.array_equal(out == out[9, 0], (seg == 1) | (seg == 2)), "it joins the room"
    assert np.array_equal(out == out[0, 19], seg == 3), "the place neither joins nor takes a small region"
    plain = join_small_regions(seg, min_area_px=10)
    assert np.array_equal(plain == plain[0, 19], seg >= 2), "else it joins the longest border"
    alone = np.zeros((6, 6), dtype=np.int32)
    alone[1:3, 1:3] = 1
    assert not join_small_regions(alone, min_area_px=5).any(), "a small region touching none is loose floor"
    assert join_small_regions(seg, min_area_px=8) is seg, "nothing too small: as it is"

"""The ipa room-segmentation protocol."""

from __future__ import annotations

import numpy as np
import pytest

from services.grid_decomposition import DecompositionError, ground_truth_rooms, ipa_scores


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


def test_shape_mismatch_is_an_error() -> None:
    with pytest.raises(DecompositionError, match="shape"):
        ipa_scores(np.zeros((3, 3), np.int32), ground_truth_rooms(_two_rooms()))

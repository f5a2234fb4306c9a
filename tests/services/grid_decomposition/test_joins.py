"""Learned room joins: pieces of one furnished room join; rooms behind a doorway and floors stay apart; the shipped
model reads back as written."""

from __future__ import annotations

import numpy as np

from services.grid_decomposition.joins import FEATURES, JoinModel, default_model, learned_joins

RES = 0.05


def _room_cut_in_two() -> tuple[np.ndarray, np.ndarray]:
    """A 6 x 4 m room cut at x = 3 m along a gap between two desks (furniture on the cut)."""
    seg = np.zeros((100, 140), dtype=np.int32)
    seg[10:90, 10:70] = 1
    seg[10:90, 70:130] = 2
    desks = np.zeros(seg.shape, dtype=bool)
    desks[20:36, 60:68] = desks[64:80, 72:80] = True
    seg[desks] = 0
    return seg, desks


def _joins(seg: np.ndarray, desks: np.ndarray, fixed: np.ndarray | None = None) -> np.ndarray:
    none = np.zeros(seg.shape, dtype=bool)
    return learned_joins(seg, desks, none, none, resolution_m=RES, model=default_model(), fixed=fixed)


def test_two_pieces_of_a_furnished_room_join() -> None:
    seg, desks = _room_cut_in_two()
    out = _joins(seg, desks)
    assert out[50, 30] == out[50, 110] > 0
    assert np.array_equal(out > 0, seg > 0)


def test_rooms_behind_a_doorway_stay_apart() -> None:
    seg, desks = _room_cut_in_two()
    seg[10:90, 68:72] = 0  # a wall between the two halves
    seg[46:54, 68:72] = 1  # with a 0.4 m wide doorway in it
    out = _joins(seg, desks)
    assert out[50, 30] != out[50, 110]


def test_fixed_floors_are_not_joined() -> None:
    seg, desks = _room_cut_in_two()
    out = _joins(seg, desks, fixed=np.array([False, True, False]))
    assert out[50, 30] != out[50, 110]


def test_the_shipped_model_reads_back_as_written() -> None:
    model = default_model()
    again = JoinModel.from_json(model.to_json())
    x = np.random.default_rng(0).normal(size=(50, len(FEATURES)))
    assert np.array_equal(again.log_odds(x), model.log_odds(x))

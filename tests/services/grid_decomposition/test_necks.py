"""Segments made of rooms joined by narrow necks are split; plain rooms are left alone."""

from __future__ import annotations

import numpy as np

from services.grid_decomposition.necks import split_at_necks


def _rooms(opening_px: int) -> tuple[np.ndarray, np.ndarray]:
    """Two 4 x 4 m rooms at 5 cm, wall between them with an opening; all one segment."""
    free = np.zeros((100, 180), dtype=bool)
    free[10:90, 10:170] = True
    free[10:90, 88:92] = False
    free[50 : 50 + opening_px, 88:92] = True
    return np.where(free, 7, 0).astype(np.int32), free


def test_split_at_necks_separates_two_rooms_joined_by_a_doorway() -> None:
    seg, free = _rooms(16)
    out = split_at_necks(seg, free, resolution_m=0.05)
    assert out[30, 40] > 0 and out[30, 140] > 0 and out[30, 40] != out[30, 140]
    assert ((out > 0) == free).all()
    assert set(np.unique(out[free]).tolist()) == {1, 2}


def test_split_at_necks_keeps_rooms_joined_by_a_wide_opening() -> None:
    seg, free = _rooms(40)
    out = split_at_necks(seg, free, resolution_m=0.05)
    assert np.unique(out[free]).tolist() == [1]


def test_split_at_necks_never_merges_segments() -> None:
    seg, free = _rooms(40)
    seg[:, :90] = np.where(free[:, :90], 3, 0)
    out = split_at_necks(seg, free, resolution_m=0.05)
    assert len(np.unique(out[free])) == 2

"""The place-label table and its parsing, shared by the grid decomposition and the API."""

from __future__ import annotations

import pytest

from shared.places import LABEL_TABLE, PlaceLabelError, parse_label_table, parse_place_label
from shared.vocabulary import PlaceLabel


def test_label_table_has_a_row_per_label_and_is_symmetric_where_it_connects() -> None:
    assert set(LABEL_TABLE) == set(PlaceLabel)
    for label, row in LABEL_TABLE.items():
        for other in row.connectable:
            assert label in LABEL_TABLE[other].connectable or other is PlaceLabel.STORAGE


def test_parse_place_label_accepts_names_and_aliases_in_any_spelling() -> None:
    assert parse_place_label(" Corridor ") is PlaceLabel.CORRIDOR
    assert parse_place_label("pallet-cells") is PlaceLabel.STORAGE
    assert parse_place_label("open") is PlaceLabel.OPEN_AREA
    with pytest.raises(PlaceLabelError, match="unknown place label 'shelf'; use one of none, corridor"):
        parse_place_label("shelf")


def test_parse_label_table_takes_decimal_categories_and_rejects_none() -> None:
    assert parse_label_table({"0": "corridor", "3": "pallet cell"}) == {0: PlaceLabel.CORRIDOR,
                                                                         3: PlaceLabel.STORAGE}
    with pytest.raises(PlaceLabelError, match="category '-1' must be a non-negative integer"):
        parse_label_table({"-1": "corridor"})
    with pytest.raises(PlaceLabelError, match="category 2: 'none' marks occupied or unknown cells"):
        parse_label_table({"2": "none"})
